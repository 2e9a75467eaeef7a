"""What ``catheter-lab tune`` shows a person: the fitted steps, the loop's margins, its step.

One HTML page with PNGs beside it (no script), like the lab's comparison reports.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from catheter_models.feedback.law import FeedbackGains, PIDFeedback
from catheter_models.feedback.tune import (
    LoopModel,
    Margins,
    fitted_steps,
    frequency_grid,
    loop_response,
)
from catheter_models.models.base import Recording

MAX_STEPS_PLOTTED = 12


def closed_loop_step(
    model: LoopModel,
    gains: FeedbackGains,
    step_rad: float = math.radians(2.0),
    duration_s: float = 2.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The identified linear loop's answer to a set-point step, with the feedback alone.

    Returns time [s], bend [rad], command [Pa]. No clamp: this shows the design, not the rig.
    """
    from scipy import signal

    dt = 1.0 / model.rate_hz
    num = np.array([model.gain_rad_per_pa])
    den = np.array([model.time_constant_s, 1.0])
    if model.resonance_hz > 0.0:
        wn = 2.0 * math.pi * model.resonance_hz
        num = num * wn**2
        den = np.polymul(den, [1.0, 2.0 * model.resonance_damping * wn, wn**2])
    a, b, c, d, _ = signal.cont2discrete(signal.tf2ss(num, den), dt, method="zoh")
    delay = round((model.delay_s + model.measurement_age_s) / dt)  # the loop sees both
    n = round(duration_s / dt)
    x = np.zeros((a.shape[0], 1))
    queue = [0.0] * (delay + 1)
    fb = PIDFeedback(gains, model.rate_hz)
    bend = np.zeros(n)
    command = np.zeros(n)
    y = 0.0
    for k in range(n):
        u = fb.command(
            step_rad,
            y,
            0.0,
            dt_s=dt,
            low_pa=-math.inf,
            high_pa=math.inf,
            floor_pa=-math.inf,
            ceiling_pa=math.inf,
        )
        queue.append(u)
        u_in = queue.pop(0)
        y = float((c @ x)[0, 0] + d[0, 0] * u_in)
        x = a @ x + b * u_in
        bend[k] = y
        command[k] = u
    return np.arange(n) * dt, bend, command


def _steps_figure(recordings: Sequence[Recording], model: LoopModel) -> Figure:
    steps = fitted_steps(recordings, model)
    steps.sort(key=lambda s: -float(np.max(np.abs(s[1]))))
    shown = steps[:MAX_STEPS_PLOTTED]
    cols = 4
    rows = max(1, math.ceil(len(shown) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(12, 2.4 * rows), squeeze=False)
    for ax, (t, measured, modelled, continues) in zip(axes.ravel(), shown, strict=False):
        ax.plot(t, np.degrees(measured), color="0.3", lw=1.0, label="measured")
        ax.plot(t, np.degrees(modelled), color="tab:red", lw=1.2, label="model")
        ax.set_title("keeps direction" if continues else "reverses the friction", fontsize=8)
        ax.set_xlabel("s")
        ax.set_ylabel("bend change [deg]")
    for ax in axes.ravel()[len(shown) :]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f"The largest of {len(steps)} steps, and the fitted loop model")
    fig.tight_layout()
    return fig


def _loop_figure(model: LoopModel, gains: FeedbackGains, found: Margins) -> Figure:
    w = frequency_grid(model.rate_hz)
    loop = loop_response(model, gains, w)
    t, bend, command = closed_loop_step(model, gains)
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    hz = w / (2.0 * math.pi)
    axes[0].loglog(hz, np.abs(loop), color="tab:blue", label="|loop|")
    axes[0].loglog(hz, 1.0 / np.abs(1.0 + loop), color="tab:orange", label="|sensitivity|")
    axes[0].axhline(1.0, color="0.6", lw=0.8)
    axes[0].axhline(found.max_sensitivity, color="tab:orange", lw=0.8, ls=":")
    axes[0].set_xlabel("Hz")
    axes[0].legend(fontsize=8)
    axes[0].set_title(f"crossover {found.crossover_hz:.2f} Hz, Ms {found.max_sensitivity:.2f}")
    near = np.abs(loop) < 4.0
    axes[1].plot(loop.real[near], loop.imag[near], color="tab:blue")
    theta = np.linspace(0, 2 * math.pi, 200)
    r = 1.0 / found.max_sensitivity
    axes[1].plot(-1 + r * np.cos(theta), r * np.sin(theta), color="tab:orange", ls=":")
    axes[1].plot([-1], [0], "kx")
    axes[1].set_xlim(-3, 1)
    axes[1].set_ylim(-2.5, 1.5)
    axes[1].set_aspect("equal")
    axes[1].set_title(f"Nyquist: GM {found.gain_margin:.2f}, PM {found.phase_margin_deg:.0f} deg")
    axes[2].plot(t, np.degrees(bend), color="tab:blue", label="bend [deg]")
    axes[2].axhline(2.0, color="0.6", lw=0.8)
    axes[2].set_xlabel("s")
    axes[2].set_title("2 deg set-point step, feedback alone (model)")
    twin = axes[2].twinx()
    twin.plot(t, command / 1e5, color="tab:green", lw=0.8)
    twin.set_ylabel("command [bar]", color="tab:green")
    fig.tight_layout()
    return fig


def write_tune_report(
    recordings: Sequence[Recording],
    model: LoopModel,
    gains: FeedbackGains,
    found: Margins,
    out_dir: Path,
) -> Path:
    """Write ``out_dir/index.html`` (and ``tune.json``); returns its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = []
    for fig, name in (
        (_steps_figure(recordings, model), "steps.png"),
        (_loop_figure(model, gains, found), "loop.png"),
    ):
        fig.savefig(out_dir / name, dpi=90)
        plt.close(fig)
        names.append(name)
    record = {"model": asdict(model), "margins": asdict(found), "gains": asdict(gains)}
    (out_dir / "tune.json").write_text(json.dumps(record, indent=2) + "\n")
    esc = html.escape
    rows = "".join(
        f"<tr><td>{esc(k)}</td><td>{esc(f'{v:.4g}' if isinstance(v, float) else str(v))}</td></tr>"
        for k, v in asdict(gains).items()
        if k != "tuning"
    )
    page = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8"><title>Feedback tuning</title></head><body>',
        "<h1>Feedback tuning</h1>",
        f"<p>From {esc(', '.join(r.name for r in recordings))}.</p>",
        f"<p><b>Loop model:</b> {esc(model.describe())}</p>",
        f"<p><b>Design:</b> {esc(str(gains.tuning.get('method', '')))}; "
        f"{esc(found.describe())}</p>",
        f"<table>{rows}</table>",
        *(f'<img src="{esc(n)}" alt="{esc(n)}">' for n in names),
        "</body></html>",
    ]
    path = out_dir / "index.html"
    path.write_text("\n".join(page) + "\n")
    return path
