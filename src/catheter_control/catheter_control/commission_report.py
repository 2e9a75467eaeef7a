"""``commission``'s HTML report: what was recorded, what the lab found, the loop, the tracking.

Written at the end of every ``commission`` run, also a failed or interrupted one (it then
says where it stopped and why): a person reads one page, with the pictures beside the
numbers, and the exact commands that would redo each step by hand.
"""

from __future__ import annotations

import html
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

from catheter_control.commission_rig import RigChoice
from catheter_control.tracking_report import VentedFloor


class _Step(Protocol):
    done: bool
    seconds: float
    commands: list[str]
    output: str
    facts: dict[str, Any]


class _State(Protocol):
    @property
    def steps(self) -> Mapping[str, _Step]: ...


class CommissionView(Protocol):
    """What the report reads of a commissioning (``commission.Commission`` has it)."""

    out_dir: Path
    choice: RigChoice
    protocol: str
    trajectories: tuple[str, ...]

    @property
    def state(self) -> _State:
        """commission.json's steps."""
        ...

    @property
    def tune_dir(self) -> Path:
        """Where the tuning wrote its gains and report."""
        ...

    def bag(self, name: str) -> Path:
        """A recording's bag directory."""
        ...

    def scores(self) -> dict[str, dict[str, float]]:
        """RMSE [deg] by candidate and trajectory."""
        ...


def _rel(path: Path, start: Path) -> str:
    return html.escape(os.path.relpath(path, start))


def _recording_plot(bag: Path, out: Path) -> Path | None:
    """Command, measured pressure and bend over time; None if the bag cannot be read."""
    import numpy as np
    from matplotlib.figure import Figure

    from catheter_models.bag import load_bag
    from catheter_models.contract import SENSOR_RATE_HZ
    from catheter_models.errors import CatheterError

    if out.exists() and out.stat().st_mtime >= bag.stat().st_mtime:
        return out
    try:
        series = load_bag(bag).aligned(SENSOR_RATE_HZ)
    except CatheterError:
        return None
    fig = Figure(figsize=(9.0, 3.6), layout="constrained")
    ax, ax2 = fig.subplots(2, 1, sharex=True)
    ax.plot(series.t_s, np.asarray(series.pressure_command_pa) / 1e5, lw=0.8, label="command")
    ax.plot(series.t_s, np.asarray(series.pressure_measured_pa) / 1e5, lw=0.8, label="measured")
    ax.set_ylabel("pressure [bar]")
    ax.legend(loc="upper right", fontsize=8)
    ax2.plot(series.t_s, np.degrees(series.angle_rad), lw=0.8, color="C2")
    ax2.set_ylabel("bend [deg]")
    ax2.set_xlabel("time [s]")
    fig.suptitle(f"recording {bag.name}")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90)
    return out


def _table(header: list[str], rows: list[list[str]]) -> str:
    head = "".join(f"<th>{h}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c}</td>" for c in row) + "</tr>" for row in rows)
    return f"<table><tr>{head}</tr>{body}</table>"


def write_report(
    job: CommissionView, failure: str, model_dir: Path, target_rmse_deg: float
) -> Path:
    """Write ``OUT/report/index.html``; returns its path.

    Args:
        job: The commissioning, done or stopped.
        failure: Why it stopped ('' if it did not).
        model_dir: Where the commissioned model is written.
        target_rmse_deg: The tracking target each trajectory is held to [deg].
    """
    out = job.out_dir / "report"
    out.mkdir(parents=True, exist_ok=True)
    steps = job.state.steps
    parts: list[str] = [
        "<!doctype html><meta charset='utf-8'><title>Commissioning report</title>",
        "<style>body{font-family:sans-serif;max-width:1000px;margin:auto}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 8px}"
        ".miss{color:#b00}pre{background:#f6f6f6;padding:6px;overflow-x:auto}</style>",
        "<h1>Commissioning report</h1>",
        f"<p>Rig: {html.escape(job.choice.describe())}; protocol {job.protocol}; "
        f"directory {html.escape(str(job.out_dir))}</p>",
    ]
    select = steps.get("select")
    if failure:
        parts.append(
            f"<p class='miss'><b>Not commissioned.</b> Stopped: {html.escape(failure)}</p>"
        )
    elif select is not None:
        f = select.facts
        parts.append(
            f"<p><b>Commissioned:</b> {html.escape(str(f['compensator']))} with feedback "
            f"{html.escape(str(f['feedback']))}"
            + (
                f" and its pressure input-shaped ({html.escape(str(f['feedforward_shaping']))}) "
                "against the tip's ringing"
                if f.get("feedforward_shaping", "none") != "none"
                else ""
            )
            + f", in <code>{_rel(model_dir, out)}"
            "</code>: <code>follow_trajectory --model-dir "
            f"{html.escape(str(model_dir))}</code></p>"
        )
        if f.get("misses"):
            misses = ", ".join(f"{t} ({r:.3f}°)" for t, r in f["misses"].items())
            parts.append(
                f"<p class='miss'>Not reached: the {target_rmse_deg}° RMSE target on {misses}.</p>"
            )
            for t, floor in f.get("misses_vented_floor", {}).items():
                vented = VentedFloor.from_json(floor)
                if vented.matters:
                    parts.append(
                        f"<p>{html.escape(t)}: the catheter {html.escape(vented.text())} (the "
                        "dotted line in its plot).</p>"
                    )

    # Time per step.
    rows = [
        [
            html.escape(name),
            f"{rec.seconds:.0f}"
            if rec.done
            else "skipped"
            if rec.facts.get("skipped")
            else "not done",
        ]
        for name, rec in steps.items()
        if name != "select"
    ]
    total = sum(rec.seconds for rec in steps.values())
    parts += [
        "<h2>Steps and their time</h2>",
        _table(["step", "wall time [s]"], rows),
        f"<p>Total {total:.0f} s ({total / 60:.1f} min).</p>",
    ]

    # Recordings.
    parts.append("<h2>What was recorded</h2>")
    for part in ("train", "test"):
        rec = steps.get(f"record_{part}")
        bag = job.bag(part)
        if rec is None or not bag.exists():
            continue
        check: dict[str, Any] = rec.facts.get("check", {})
        parts.append(
            f"<p><b>{part}</b> ({html.escape(str(bag))}): {check.get('duration_s', 0):.0f} s, "
            f"{check.get('samples', 0)} samples at the model rate; command spans "
            f"{check.get('command_span_bar', 0):.2f} bar, measured pressure "
            f"{check.get('measured_span_bar', 0):.2f} bar, bend "
            f"{check.get('bend_span_deg', 0):.1f}°; "
            f"{check.get('commands_missing', 0)} of {check.get('commands_expected', 0)} commands "
            "missing from the recording.</p>"
        )
        plot = _recording_plot(bag, out / f"recording_{part}.png")
        if plot is not None:
            parts.append(f"<img src='{_rel(plot, out)}' width='900'>")

    # The lab.
    explain = steps.get("explain")
    if explain is not None and explain.done:
        parts.append("<h2>What the lab found</h2>")
        expl_dir = job.out_dir / "forward" / "explain"
        parts.append(f"<pre>{html.escape(_tail_after(explain.output, 'step'))}</pre>")
        for name in ("history.png", "diagnosis.png"):
            if (expl_dir / name).exists():
                parts.append(f"<img src='{_rel(expl_dir / name, out)}' width='700'>")

    # The loop.
    tune = steps.get("tune")
    if tune is not None and tune.done:
        parts.append("<h2>The feedback loop</h2>")
        lines = [
            ln for ln in tune.output.splitlines() if ln.startswith(("loop model", "PI:", "margins"))
        ]
        parts.append(f"<pre>{html.escape(chr(10).join(lines))}</pre>")
        tune_report = job.tune_dir / "report" / "index.html"
        if tune_report.exists():
            parts.append(
                f"<p><a href='{_rel(tune_report, out)}'>The tuning report</a> (steps "
                "fitted, loop response, margins).</p>"
            )

    # Tracking.
    scores = job.scores()
    if scores:
        parts.append(f"<h2>Tracking, closed loop (RMSE [°], target ≤ {target_rmse_deg}°)</h2>")
        rows = []
        for cand, by_traj in scores.items():
            cells = [html.escape(cand)]
            for t in job.trajectories:
                r = by_traj.get(t)
                cls = " class='miss'" if r is not None and r > target_rmse_deg else ""
                cells.append("-" if r is None else f"<span{cls}>{r:.3f}</span>")
            rows.append(cells)
        parts.append(_table(["candidate", *job.trajectories], rows))
        retried = [
            (name.split(":", 2)[1:], rec.facts["retried_after"])
            for name, rec in steps.items()
            if name.startswith("follow:") and rec.facts.get("retried_after")
        ]
        skipped: dict[str, tuple[list[str], str]] = {}
        for name, rec in steps.items():
            if name.startswith("follow:") and rec.facts.get("skipped"):
                _, cand, t = name.split(":", 2)
                skipped.setdefault(cand, ([], str(rec.facts["skipped"])))[0].append(t)
        for cand, (ts, why) in skipped.items():
            parts.append(
                f"<p>{html.escape(cand)} was not followed on {html.escape(', '.join(ts))}: "
                f"{html.escape(why)}.</p>"
            )
        for (cand, t), why in retried:
            parts.append(
                f"<p>{html.escape(cand)} on {html.escape(t)} was followed twice: the first run "
                f"stopped part-way ({html.escape(str(why))}); the score is the second's.</p>"
            )
        for cand in scores:
            for t in job.trajectories:
                png = job.out_dir / "runs" / cand / t / "tracking.png"
                if png.exists():
                    parts.append(
                        f"<h3>{html.escape(cand)}: {html.escape(t)}</h3>"
                        f"<img src='{_rel(png, out)}' width='800'>"
                    )

    # By hand.
    parts.append("<h2>The same by hand</h2><pre>")
    for name, rec in steps.items():
        for line in rec.commands:
            parts.append(html.escape(f"# {name}\n{line}") + "\n")
    parts.append("</pre>")
    index = out / "index.html"
    index.write_text("\n".join(parts) + "\n")
    return index


def _tail_after(text: str, marker: str) -> str:
    """The explanation's table and verdict: what follows its first line starting ``marker``."""
    lines = text.splitlines()
    for i, line in enumerate(lines):
        if line.strip().startswith(marker) and "train" in line:
            return "\n".join(lines[i:])
    return "\n".join(lines[-30:])
