"""Tracking report of a run (no ROS): align measured bend on the set-points, score, plot.

Set-points (``angle/desired``) and measurements (``tip/angle``) are aligned on their header
stamps, the time each value was true, never on receive time (docs/interfaces.md).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt

from catheter_models.errors import CatheterError
from catheter_models.metrics import (
    ErrorMetrics,
    classify_regimes,
    compute_metrics,
    metrics_by_regime,
)
from catheter_models.units import rad_to_deg

FloatArray = npt.NDArray[np.float64]


class TrackingError(CatheterError):
    """The run has too little data to score (e.g. no measurement during the trajectory)."""


@dataclass(frozen=True)
class TrackingResult:
    """A scored run: aligned series (SI) and metrics (rad; shown in degrees)."""

    t_s: FloatArray
    desired_rad: FloatArray
    measured_rad: FloatArray
    overall: ErrorMetrics
    by_regime: dict[str, ErrorMetrics | None]

    def text(self, title: str) -> str:
        """The report a person reads in the terminal (degrees; MAE = maximum abs error)."""
        lines = [
            f"Tracking report: {title}",
            f"  samples {self.overall.n_samples} over {self.t_s[-1] - self.t_s[0]:.1f} s",
            f"  RMSE  {rad_to_deg(self.overall.rmse):7.3f} deg",
            f"  MAE   {rad_to_deg(self.overall.mae):7.3f} deg   (maximum absolute error, eq. 5.13)",
            "  NRMSE "
            + ("    n/a" if self.overall.nrmse is None else f"{100 * self.overall.nrmse:7.2f} %"),
            "  by regime:",
        ]
        for name, m in self.by_regime.items():
            if m is None:
                lines.append(f"    {name:<12} (too few samples)")
            else:
                lines.append(
                    f"    {name:<12} RMSE {rad_to_deg(m.rmse):6.3f} deg  "
                    f"MAE {rad_to_deg(m.mae):6.3f} deg  n={m.n_samples}"
                )
        return "\n".join(lines)

    def to_json(self) -> dict[str, object]:
        """Metrics in degrees for a machine-readable report."""

        def conv(m: ErrorMetrics | None) -> dict[str, float | int | None] | None:
            if m is None:
                return None
            return {
                "rmse_deg": rad_to_deg(m.rmse),
                "mae_deg": rad_to_deg(m.mae),
                "nrmse": m.nrmse,
                "n_samples": m.n_samples,
            }

        return {
            "overall": conv(self.overall),
            "by_regime": {k: conv(v) for k, v in self.by_regime.items()},
        }


def score_run(
    desired_stamps_s: npt.ArrayLike,
    desired_rad: npt.ArrayLike,
    measured_stamps_s: npt.ArrayLike,
    measured_rad: npt.ArrayLike,
    window_s: tuple[float, float] | None = None,
) -> TrackingResult:
    """Interpolate the measurement onto the set-point stamps within the window and score it.

    Args:
        desired_stamps_s: header stamps of the set-points (``angle/desired``) [s].
        desired_rad: set-points in force [rad].
        measured_stamps_s: header stamps of the ``tip/angle`` samples [s].
        measured_rad: measured bend [rad].
        window_s: only set-points with stamps in [start, end] are scored (the trajectory,
            not the ramp-down after it).
    """
    td = np.asarray(desired_stamps_s, dtype=float)
    yd = np.asarray(desired_rad, dtype=float)
    tm = np.asarray(measured_stamps_s, dtype=float)
    ym = np.asarray(measured_rad, dtype=float)
    order = np.argsort(tm, kind="stable")
    tm, ym = tm[order], ym[order]
    keep = np.isfinite(td) & np.isfinite(yd)
    if window_s is not None:
        keep &= (td >= window_s[0]) & (td <= window_s[1])
    # Only score where a measurement brackets the set-point: no extrapolation.
    if tm.size < 2:
        raise TrackingError(f"only {tm.size} tip/angle samples were received; nothing to score")
    keep &= (td >= tm[0]) & (td <= tm[-1])
    td, yd = td[keep], yd[keep]
    if td.size < 10:
        raise TrackingError(
            f"only {td.size} set-points overlap the tip/angle measurements; "
            "was the rig publishing during the trajectory?"
        )
    ym_on_d = np.interp(td, tm, ym)
    overall = compute_metrics(ym_on_d, yd)
    regimes = classify_regimes(td - td[0], yd, ym_on_d, deadband_drive_threshold=math.radians(1.0))
    return TrackingResult(td - td[0], yd, ym_on_d, overall, metrics_by_regime(ym_on_d, yd, regimes))


def save_plot(result: TrackingResult, path: Path, title: str) -> Path:
    """Save the run's plot: desired and measured, error, and measured against desired.

    The last panel is thesis fig. 11.6: a straight line when hysteresis is compensated.
    """
    d = rad_to_deg(result.desired_rad)
    m = rad_to_deg(result.measured_rad)
    fig = plt.figure(figsize=(12, 7), constrained_layout=True)
    grid = fig.add_gridspec(2, 3)
    ax_t = fig.add_subplot(grid[0, :2])
    ax_e = fig.add_subplot(grid[1, :2], sharex=ax_t)
    ax_x = fig.add_subplot(grid[:, 2])
    ax_t.plot(result.t_s, d, label="desired", color="black", lw=1.2)
    ax_t.plot(result.t_s, m, label="measured", color="tab:red", lw=1.0)
    ax_t.set_ylabel("bend [deg]")
    ax_t.legend(loc="upper right")
    ax_t.set_title(title)
    ax_e.plot(result.t_s, m - d, color="tab:blue", lw=0.8)
    ax_e.axhline(0.0, color="grey", lw=0.5)
    ax_e.set_xlabel("time [s]")
    ax_e.set_ylabel("error [deg]")
    o = result.overall
    ax_e.set_title(
        f"RMSE {rad_to_deg(o.rmse):.2f} deg, MAE {rad_to_deg(o.mae):.2f} deg"
        + ("" if o.nrmse is None else f", NRMSE {100 * o.nrmse:.1f} %"),
        fontsize=10,
    )
    lim = (min(d.min(), m.min()) - 1, max(d.max(), m.max()) + 1)
    ax_x.plot(lim, lim, color="grey", lw=0.8, ls="--", label="ideal")
    ax_x.plot(d, m, color="tab:red", lw=0.8, label="measured")
    ax_x.set_xlim(lim)
    ax_x.set_ylim(lim)
    ax_x.set_aspect("equal")
    ax_x.set_xlabel("desired [deg]")
    ax_x.set_ylabel("measured [deg]")
    ax_x.legend(loc="upper left")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def save_json(result: TrackingResult, path: Path, extra: dict[str, object]) -> Path:
    """Metrics (degrees) and run facts as JSON."""
    path.write_text(json.dumps({**extra, **result.to_json()}, indent=2) + "\n")
    return path


def _floats(reports: list[dict[str, str]], key: str) -> list[float]:
    out = []
    for values in reports:
        try:
            out.append(float(values[key]))
        except (KeyError, ValueError):
            continue  # not reported yet (e.g. no command received before this report)
    return out


def timing_summary(
    compensator: list[dict[str, str]], driver: list[dict[str, str]]
) -> dict[str, float | int | str | None]:
    """The control loop's timing over a run, from the nodes' 1 Hz /diagnostics values.

    Args:
        compensator: the compensator's status values, in order, from the first report after
            the run started to the first after it ended.
        driver: the same for the node that received the commands (sim_hardware or
            valve_driver).

    Ticks and missed deadlines are the nodes' own counters, differenced over the run (to
    within one report period). Percentiles are reported by the nodes over their recent
    window (5000 ticks): the worst window of the run is kept, which bounds the run's own.
    """
    ticks = _floats(compensator, "ticks")
    missed = _floats(compensator, "missed_deadlines")

    def worst(reports: list[dict[str, str]], key: str) -> float | None:
        found = _floats(reports, key)
        return max(found) if found else None

    n_ticks = int(ticks[-1] - ticks[0]) if len(ticks) >= 2 else 0
    n_missed = int(missed[-1] - missed[0]) if len(missed) >= 2 else 0
    rate = _floats(compensator, "control_rate_hz")
    return {
        "control_rate_hz": rate[-1] if rate else None,
        "realtime": compensator[-1].get("realtime") if compensator else None,
        "ticks": n_ticks,
        "missed_deadlines": n_missed,
        "missed_fraction": n_missed / (n_ticks + n_missed) if n_ticks else None,
        "lateness_p99_ms": worst(compensator, "lateness_p99_ms"),
        "compute_p99_ms": worst(compensator, "compute_p99_ms"),
        "command_latency_p50_ms": worst(driver, "command_latency_p50_ms"),
        "command_latency_p99_ms": worst(driver, "command_latency_p99_ms"),
        "command_latency_max_ms": worst(driver, "command_latency_max_ms"),
    }


def timing_text(timing: dict[str, float | int | str | None]) -> str:
    """One paragraph a person reads: did the loop hold its deadlines?"""

    def ms(key: str) -> str:
        value = timing.get(key)
        return f"{value:.3f} ms" if isinstance(value, float | int) else "n/a"

    fraction = timing.get("missed_fraction")
    missed = f"{100 * fraction:.3f} %" if isinstance(fraction, float | int) else "n/a"
    return "\n".join(
        [
            f"Control loop at {timing.get('control_rate_hz') or 0:g} Hz "
            f"({timing.get('realtime') or 'scheduling unknown'}):",
            f"  ticks {timing['ticks']}, missed deadlines {timing['missed_deadlines']} ({missed})",
            f"  lateness p99 {ms('lateness_p99_ms')}, compute p99 {ms('compute_p99_ms')}",
            f"  command latency, tick to driver: p50 {ms('command_latency_p50_ms')}, "
            f"p99 {ms('command_latency_p99_ms')}, max {ms('command_latency_max_ms')}",
        ]
    )
