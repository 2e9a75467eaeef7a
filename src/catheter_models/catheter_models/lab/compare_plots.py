"""The figures of a comparison report (:mod:`catheter_models.lab.compare`).

Measured against predicted over time with the worst segments shaded, the hysteresis loops of
model and measurement, the error against pressure and against the rate of pressure, and the
RMSE per regime. Each function returns a bare :class:`matplotlib.figure.Figure` (Agg canvas,
no pyplot state), so it works headless; matplotlib is imported only when a figure is drawn,
so scoring a model from the command line does not pay for it. Apart from the numerics and
the HTML page so that restyling a plot touches neither.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

import numpy as np

from catheter_models.metrics import smoothed_rate
from catheter_models.models.base import Direction
from catheter_models.units import PA_PER_BAR, rad_to_deg

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from catheter_models.lab.compare import Comparison, FloatArray, RecordingComparison, Segment

_MAX_SCATTER_POINTS: Final = 20_000
"""Scatter plots thin to this many points: more add file size, not information."""


def _series(rc: RecordingComparison, direction: Direction) -> tuple[FloatArray, FloatArray]:
    """(pressure [Pa], measured angle [rad]) of a recording, whichever way the model maps."""
    if direction == "forward":
        return rc.input_si, rc.measured_si
    return rc.measured_si, rc.input_si


def _thin(n: int) -> slice:
    return slice(None, None, max(1, math.ceil(n / _MAX_SCATTER_POINTS)))


def _binned(
    x: FloatArray, y: FloatArray, n_bins: int = 20, min_count: int = 10
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Bin centres, mean and RMS of ``y`` in equal-width bins of ``x`` (sparse bins dropped)."""
    lo, hi = float(np.min(x)), float(np.max(x))
    if not hi > lo:
        empty = np.zeros(0)
        return empty, empty, empty
    edges = np.linspace(lo, hi, n_bins + 1)
    idx = np.clip(np.digitize(x, edges) - 1, 0, n_bins - 1)
    count = np.bincount(idx, minlength=n_bins).astype(np.float64)
    total = np.bincount(idx, weights=y, minlength=n_bins)
    squares = np.bincount(idx, weights=y * y, minlength=n_bins)
    keep = count >= min_count
    centres = 0.5 * (edges[:-1] + edges[1:])
    mean = total[keep] / count[keep]
    rms = np.sqrt(squares[keep] / count[keep])
    return centres[keep], mean, rms


def _error_scatter(ax: Axes, x: FloatArray, err: FloatArray, xlabel: str, unit: str) -> None:
    cut = _thin(x.size)
    ax.scatter(x[cut], err[cut], s=3, alpha=0.15, color="tab:blue", lw=0, rasterized=True)
    centres, mean, rms = _binned(x, err)
    ax.plot(centres, mean, color="black", lw=1.5, label="binned mean")
    ax.plot(centres, rms, color="tab:red", lw=1.2, ls="--", label="binned RMS")
    ax.axhline(0.0, color="grey", lw=0.5)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(f"error [{unit}]")
    ax.legend(loc="upper right", fontsize=8)


def plot_time(
    comparison: Comparison, rc: RecordingComparison, segments: Sequence[tuple[int, Segment]]
) -> Figure:
    """Measured and predicted over time with the worst segments shaded; the error below."""
    from matplotlib.figure import Figure

    unit, k = comparison.display_unit, comparison.display_scale
    quantity = "bend" if comparison.direction == "forward" else "pressure"
    fig = Figure(figsize=(12, 6), layout="constrained")
    ax_y, ax_e = fig.subplots(2, 1, sharex=True, height_ratios=[3, 2])
    for rank, seg in segments:
        for ax in (ax_y, ax_e):
            ax.axvspan(seg.start_s, seg.end_s, color="tab:orange", alpha=0.25, lw=0)
        ax_y.annotate(
            f"#{rank}",
            (0.5 * (seg.start_s + seg.end_s), 0.98),
            xycoords=("data", "axes fraction"),
            ha="center",
            va="top",
            fontsize=8,
            color="tab:orange",
        )
    ax_y.plot(rc.t_s, rc.measured_si * k, color="black", lw=1.0, label="measured")
    ax_y.plot(rc.t_s, rc.predicted_si * k, color="tab:red", lw=0.9, label="model")
    ax_y.set_ylabel(f"{quantity} [{unit}]")
    ax_y.legend(loc="upper right", fontsize=8)
    ax_y.set_title(f"{rc.name}: {rc.overall.format(unit)}  (shaded: worst segments)", fontsize=10)
    ax_e.plot(rc.t_s, rc.error_si * k, color="tab:blue", lw=0.7)
    ax_e.axhline(0.0, color="grey", lw=0.5)
    ax_e.set_xlabel("time from the recording's start [s]")
    ax_e.set_ylabel(f"model - measured [{unit}]")
    return fig


def plot_loops(comparison: Comparison, rc: RecordingComparison) -> Figure:
    """Hysteresis loops of model and measurement; error against pressure and its rate."""
    from matplotlib.figure import Figure

    unit, k = comparison.display_unit, comparison.display_scale
    pressure_pa, _ = _series(rc, comparison.direction)
    pressure_bar = pressure_pa / PA_PER_BAR
    _, rate_pa_per_s = smoothed_rate(rc.t_s, pressure_pa)
    err = rc.error_si * k
    fig = Figure(figsize=(15, 4.6), layout="constrained")
    ax_l, ax_p, ax_r = fig.subplots(1, 3)
    if comparison.direction == "forward":
        x_in = pressure_bar
        x_label, y_label = "pressure [bar]", "bend [deg]"
    else:
        x_in = rad_to_deg(rc.input_si)
        x_label, y_label = "desired bend [deg]", "pressure [bar]"
    ax_l.plot(x_in, rc.measured_si * k, color="black", lw=0.8, label="measured")
    ax_l.plot(x_in, rc.predicted_si * k, color="tab:red", lw=0.8, label="model")
    ax_l.set_xlabel(x_label)
    ax_l.set_ylabel(y_label)
    ax_l.set_title("hysteresis loops", fontsize=10)
    ax_l.legend(loc="upper left", fontsize=8)
    _error_scatter(ax_p, pressure_bar, err, "pressure [bar]", unit)
    ax_p.set_title("error against pressure", fontsize=10)
    _error_scatter(ax_r, np.abs(rate_pa_per_s) / PA_PER_BAR, err, "|pressure rate| [bar/s]", unit)
    ax_r.set_title("error against |rate of pressure|", fontsize=10)
    fig.suptitle(rc.name, fontsize=11)
    return fig


def plot_regimes(comparison: Comparison) -> Figure:
    """RMSE per regime (pooled over recordings), the overall RMSE as a line."""
    from matplotlib.figure import Figure

    unit, k = comparison.display_unit, comparison.display_scale
    names = list(comparison.by_regime)
    values = [0.0 if (m := comparison.by_regime[n]) is None else m.rmse * k for n in names]
    fig = Figure(figsize=(8, 3.6), layout="constrained")
    ax = fig.subplots()
    bars = ax.bar(names, values, color="tab:blue")
    ax.bar_label(bars, fmt="%.2f", fontsize=8)
    for bar, name in zip(bars, names, strict=True):
        if comparison.by_regime[name] is None:
            ax.annotate("n/a", (bar.get_x() + bar.get_width() / 2, 0.0), ha="center", va="bottom")
    ax.axhline(comparison.overall.rmse * k, color="tab:red", ls="--", lw=1.0, label="overall")
    ax.set_ylabel(f"RMSE [{unit}]")
    ax.set_title(f"{comparison.model_kind}: RMSE per regime, all recordings", fontsize=10)
    ax.legend(loc="upper right", fontsize=8)
    ax.tick_params(axis="x", labelrotation=20)
    return fig
