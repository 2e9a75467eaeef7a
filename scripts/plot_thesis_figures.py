"""Render the simulated rig's equivalents of thesis figs. 4.3 and 4.4.

Each figure plots the measured bend [deg] against the command pressure [bar] for the four
training frequencies (0.2/0.4/0.6/0.8 Hz, in the thesis's colours black/green/blue/red),
driven by eq. 4.1 (zero baseline, fig. 4.3) or eq. 4.2 (non-zero baseline, fig. 4.4) with
A = 1.5 bar and tau = 0.15 1/s, on the simulated rig with its default (thesis) settings. As
in the thesis, the first (major) loop of each frequency is drawn wide and the later (minor)
loops thin, and the deadband is marked.

Run with ``make figures`` (``.venv/bin/python scripts/plot_thesis_figures.py``); the PNGs go to
``docs/figures/``.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import matplotlib as mpl

mpl.use("Agg")  # files only; no display is needed or wanted on a build machine

import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt
from matplotlib.axes import Axes
from matplotlib.lines import Line2D

from catheter_models.plant import Plant, PlantConfig
from catheter_models.signals import get_preset
from catheter_models.units import pa_to_bar, rad_to_deg

FloatArray = npt.NDArray[np.float64]
Baseline = Literal["zero", "nonzero"]

REPO_ROOT = Path(__file__).resolve().parent.parent
OUT_DIR = REPO_ROOT / "docs" / "figures"
FREQUENCIES_HZ = (0.2, 0.4, 0.6, 0.8)
THESIS_COLOURS = {0.2: "black", 0.4: "green", 0.6: "blue", 0.8: "red"}
"""Colours of the thesis's figs. 4.3/4.4, sec. 4.2."""
RATE_HZ = 250.0


@dataclass(frozen=True)
class FigureSpec:
    """One thesis figure: which equation drives it and where it is saved."""

    baseline: Baseline
    number: str
    filename: str
    equation: str
    """Matplotlib mathtext of the driving equation."""
    title: str


FIGURES = (
    FigureSpec(
        baseline="zero",
        number="4.3",
        filename="fig_4_3_zero_baseline.png",
        equation=r"$p_1(t) = A\,e^{-\tau t}\,(\sin(2\pi f t - \pi/2) + 1)$",
        title="zero baseline",
    ),
    FigureSpec(
        baseline="nonzero",
        number="4.4",
        filename="fig_4_4_nonzero_baseline.png",
        equation=r"$p_2(t) = A\,e^{-\tau t}\,\sin(2\pi f t - \pi/2) + A$",
        title="non-zero baseline",
    ),
)


@dataclass(frozen=True)
class Run:
    """One simulated training run, in display units."""

    freq_hz: float
    t_s: FloatArray
    command_bar: FloatArray
    measured_deg: FloatArray


def simulate(baseline: Baseline, freq_hz: float, config: PlantConfig) -> Run:
    """Drive a fresh rig at rest with the thesis's training preset.

    Args:
        baseline: ``"zero"`` (eq. 4.1) or ``"nonzero"`` (eq. 4.2).
        freq_hz: Excitation frequency f [Hz], one of the training frequencies.
        config: Plant configuration.

    Returns:
        Command pressure [bar] and measured (laser, eq. 3.3) bend [deg] over time [s].
    """
    signal = get_preset(f"train_{baseline}_f{freq_hz:g}").generate(RATE_HZ)
    out = Plant(config).simulate(signal.values_si)
    return Run(
        freq_hz=freq_hz,
        t_s=signal.t_s,
        command_bar=pa_to_bar(out.pressure_command_pa),
        measured_deg=rad_to_deg(out.angle_rad),
    )


def _mark_deadband(ax: Axes, opening_bar: float, y_top: float) -> None:
    """Shade the pressures where the muscle does not pull from rest, with a bracket label."""
    ax.axvspan(0.0, opening_bar, color="tab:red", alpha=0.07, zorder=0, lw=0)
    y = 0.93 * y_top
    # A bracket like the thesis's red one, spanning the deadband on the pressure axis.
    ax.annotate(
        "",
        xy=(0.0, y),
        xytext=(opening_bar, y),
        arrowprops={"arrowstyle": "|-|", "color": "tab:red", "lw": 1.4, "shrinkA": 0, "shrinkB": 0},
    )
    ax.text(
        0.5 * opening_bar,
        y - 0.02 * y_top,
        f"deadband from rest\n0–{opening_bar:.2g} bar",
        color="tab:red",
        ha="center",
        va="top",
        fontsize=9,
        linespacing=1.1,
    )


def plot_figure(spec: FigureSpec, runs: list[Run], config: PlantConfig, path: Path) -> None:
    """Draw one figure: bend against command, major loop wide, minor loops thin.

    Args:
        spec: Which thesis figure.
        runs: One run per training frequency.
        config: The plant configuration the runs used (for the deadband mark and caption).
        path: PNG to write.
    """
    fig, ax = plt.subplots(figsize=(8.0, 5.6), dpi=150, layout="constrained")
    y_top = 1.12 * max(float(run.measured_deg.max()) for run in runs)
    opening_bar = pa_to_bar(config.effect_param("deadband", "opening_pressure_pa"))
    _mark_deadband(ax, opening_bar, y_top)

    for rank, run in enumerate(runs):
        colour = THESIS_COLOURS[run.freq_hz]
        period_s = 1.0 / run.freq_hz
        major = run.t_s <= period_s
        # Share the boundary sample so the thin minor loops continue the wide major one.
        minor = run.t_s >= run.t_s[np.flatnonzero(major)[-1]]
        # Slower loops are narrower and sit inside faster ones: draw them on top.
        z_major = 10 - rank
        ax.plot(
            run.command_bar[major],
            run.measured_deg[major],
            color=colour,
            lw=2.2,
            label=f"{run.freq_hz:g} Hz",
            zorder=z_major,
        )
        ax.plot(
            run.command_bar[minor],
            run.measured_deg[minor],
            color=colour,
            lw=0.7,
            alpha=0.8,
            zorder=5 - rank,
        )

    ax.set_xlim(0.0, 3.05)
    ax.set_ylim(-1.0, y_top)
    ax.set_xlabel("command pressure $p$ [bar, gauge]")
    ax.set_ylabel(r"measured bending angle $\theta$ [deg]")
    ax.set_title(
        f"Fig. {spec.number} (simulated): hysteresis, {spec.title}\n{spec.equation}"
        r",   $A = 1.5$ bar, $\tau = 0.15\ \mathrm{s}^{-1}$",
        fontsize=11,
    )
    ax.grid(True, lw=0.4, alpha=0.5)
    freq_legend = ax.legend(title="excitation f", loc="upper left", bbox_to_anchor=(0.0, 0.8))
    ax.add_artist(freq_legend)
    style_handles = [
        Line2D([], [], color="0.3", lw=2.2, label="major loop (first period)"),
        Line2D([], [], color="0.3", lw=0.7, label="minor loops"),
    ]
    ax.legend(handles=style_handles, loc="lower right", bbox_to_anchor=(1.0, 0.06), fontsize=9)
    ax.text(
        0.99,
        0.015,
        "simulated rig, default (thesis) settings; laser at 250 Hz with noise",
        transform=ax.transAxes,
        ha="right",
        va="bottom",
        fontsize=8,
        color="0.35",
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    """Simulate the eight training runs and write figs. 4.3 and 4.4 as PNG."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out-dir", type=Path, default=OUT_DIR, help="where the PNGs go")
    parser.add_argument("--seed", type=int, default=0, help="sensor-noise seed")
    args = parser.parse_args(argv)

    config = PlantConfig.thesis_rig(seed=args.seed)
    for spec in FIGURES:
        runs = [simulate(spec.baseline, f, config) for f in FREQUENCIES_HZ]
        path = args.out_dir / spec.filename
        plot_figure(spec, runs, config, path)
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
