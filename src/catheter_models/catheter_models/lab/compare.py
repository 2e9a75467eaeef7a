"""Compare any fitted model with measured recordings, and locate where it fails.

A single RMSE says *how much* a model is off, not *where*. To improve a model (or to decide
which physical effect it lacks, docs/lab.md) a person needs to see the stretches of a
recording where the error is largest, and in which motion regime they fall: does it fail while
loading, at the peaks, in the deadband? This module answers that for every model kind, forward
(pressure -> angle: DRDPI, GPI, SVR, LSTM) or inverse (angle -> pressure: IDRDPI, c-LSTM):

* :func:`compare` runs the model from rest over each recording (as its ``predict`` does),
  scores it with the thesis's metrics (eqs. 5.13-5.15, MAE being the *maximum* error) overall
  and per regime, and ranks fixed windows of the recordings by RMSE to name the worst
  segments with recording, time span and regime, so a person can jump there.
* :func:`write_report` writes a self-contained HTML page with the tables and plots: measured
  against predicted over time with the worst segments shaded, the error over time, the
  hysteresis loops of model and measurement, and the error against pressure and against the
  rate of pressure (where the model's rate dependence shows).

Regimes are a property of the *motion*, not of the model: they are always classified from the
recording's pressure (the drive) and its measured angle, whichever way the model maps, so a
forward and an inverse model of the same bags are scored on the same samples.

Everything inside is SI (rad, Pa gauge, s); text, JSON and plots show degrees and bar.
"""

from __future__ import annotations

import html
import json
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Literal

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.metrics import (
    REGIMES,
    ErrorMetrics,
    classify_regimes,
    compute_metrics,
    metrics_by_regime,
    smoothed_rate,
)
from catheter_models.models.base import Direction, Model, Recording, check_rates
from catheter_models.units import PA_PER_BAR, rad_to_deg

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
OutputUnit = Literal["rad", "pa"]

MAX_PLOTTED_RECORDINGS: Final = 8
"""Reports plot the first this many recordings only, so a report of many bags stays small."""

MIXED: Final = "mixed"
"""Regime name of a segment in which no single regime covers more than half the samples."""

_MAX_SCATTER_POINTS: Final = 20_000
"""Scatter plots thin to this many points: more add file size, not information."""

# SI unit of a model's output -> (display unit, factor from SI to display), for people.
_DISPLAY: Final[Mapping[str, tuple[str, float]]] = {
    "rad": ("deg", float(rad_to_deg(1.0))),
    "pa": ("bar", 1.0 / PA_PER_BAR),
}
# Any unit a caller may ask Segment.text for -> factor from the output's SI unit.
_SCALE: Final[Mapping[str, float]] = {
    "deg": float(rad_to_deg(1.0)),
    "rad": 1.0,
    "bar": 1.0 / PA_PER_BAR,
    "Pa": 1.0,
    "pa": 1.0,
}


def _scale(unit: str) -> float:
    try:
        return _SCALE[unit]
    except KeyError:
        valid = ", ".join(_SCALE)
        raise ParameterError(f"unknown display unit {unit!r}; valid: {valid}") from None


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Segment:
    """A stretch of one recording where the model is worst.

    Attributes:
        recording: Name of the recording (the bag's directory name, or the preset).
        start_s: Start [s] from the recording's first sample (the first instant all of the
            bag's model streams overlap), so a person can find it in a plot or a bag player.
        end_s: End [s], exclusive, same time base.
        regime: The regime covering most samples (see ``metrics.REGIMES``), or ``"mixed"``
            when none covers more than half.
        rmse: RMSE over the segment, in the model output's SI unit (rad or Pa).
        max_abs: Largest absolute error in the segment (eq. 5.13), same unit.
        n_samples: Samples in the segment.
    """

    recording: str
    start_s: float
    end_s: float
    regime: str
    rmse: float
    max_abs: float
    n_samples: int

    def text(self, unit: str) -> str:
        """One line for a person, e.g. ``bag  12.00-13.00 s  peak  RMSE 2.1 deg ...``.

        Args:
            unit: Display unit: ``deg`` or ``rad`` for forward models, ``bar`` or ``Pa`` for
                inverse ones.
        """
        k = _scale(unit)
        return (
            f"{self.recording}  {self.start_s:.2f}-{self.end_s:.2f} s  {self.regime:<11}  "
            f"RMSE {self.rmse * k:.3g} {unit}  max |error| {self.max_abs * k:.3g} {unit}  "
            f"(n={self.n_samples})"
        )


@dataclass
class RecordingComparison:
    """The model against one recording: aligned series (SI) and scores.

    Attributes:
        name: The recording's name.
        rate_hz: Sample rate [Hz].
        t_s: Sample times [s] from the recording's start.
        input_si: What the model was fed (pressure [Pa] forward, angle [rad] inverse).
        measured_si: The measured output (angle [rad] forward, pressure [Pa] inverse).
        predicted_si: The model's output, same unit.
        overall: Metrics of predicted against measured (SI unit of the output).
        by_regime: Metrics per regime; None where a regime has too few samples.
        regimes: The regime masks (from the recording's pressure and angle).
    """

    name: str
    rate_hz: float
    t_s: FloatArray
    input_si: FloatArray
    measured_si: FloatArray
    predicted_si: FloatArray
    overall: ErrorMetrics
    by_regime: dict[str, ErrorMetrics | None]
    regimes: dict[str, BoolArray]

    @property
    def error_si(self) -> FloatArray:
        """Model minus measurement (positive: the model says more than happened)."""
        return np.asarray(self.predicted_si - self.measured_si, dtype=np.float64)


@dataclass
class Comparison:
    """A model against a set of recordings: pooled scores and the worst segments.

    Attributes:
        model_kind: The model's kind (``drdpi``, ``clstm``, ...).
        direction: ``forward`` (pressure -> angle) or ``inverse`` (angle -> pressure).
        recordings: One comparison per recording, in the order given.
        overall: Metrics over all samples of all recordings, concatenated.
        by_regime: Metrics per regime over all recordings (NRMSE normalised by the range of
            all measurements, so regimes compare with the overall figure).
        worst: The worst segments, worst first.
        output_unit: SI unit of the output: ``rad`` (forward) or ``pa`` (inverse).
    """

    model_kind: str
    direction: Direction
    recordings: list[RecordingComparison]
    overall: ErrorMetrics
    by_regime: dict[str, ErrorMetrics | None]
    worst: list[Segment]
    output_unit: OutputUnit

    @property
    def display_unit(self) -> str:
        """Unit people read the output in: ``deg`` or ``bar``."""
        return _DISPLAY[self.output_unit][0]

    @property
    def display_scale(self) -> float:
        """Factor from the output's SI unit to :attr:`display_unit`."""
        return _DISPLAY[self.output_unit][1]

    def _mapping(self) -> str:
        if self.direction == "forward":
            return "forward: pressure -> angle"
        return "inverse: angle -> pressure"

    def text(self) -> str:
        """The report a person reads in the terminal (MAE = maximum absolute error)."""
        unit, k = self.display_unit, self.display_scale
        n = self.overall.n_samples
        rates = sorted({r.rate_hz for r in self.recordings})
        duration_s = sum(r.t_s.size / r.rate_hz for r in self.recordings)
        lines = [
            f"Compare {self.model_kind} ({self._mapping()}) with {len(self.recordings)} "
            f"recording(s): {n} samples, {duration_s:.1f} s at "
            + ", ".join(f"{r:g}" for r in rates)
            + " Hz",
            f"  RMSE  {self.overall.rmse * k:8.3f} {unit}",
            f"  MAE   {self.overall.mae * k:8.3f} {unit}   (maximum absolute error, eq. 5.13)",
            "  NRMSE "
            + ("     n/a" if self.overall.nrmse is None else f"{100 * self.overall.nrmse:8.2f} %"),
            "",
            f"  by regime      RMSE [{unit}]  MAE [{unit}]   NRMSE  samples",
        ]
        for name, m in self.by_regime.items():
            if m is None:
                lines.append(f"    {name:<12} (too few samples)")
                continue
            nrmse = "    n/a" if m.nrmse is None else f"{100 * m.nrmse:6.2f} %"
            lines.append(
                f"    {name:<12} {m.rmse * k:10.3f}  {m.mae * k:9.3f}  {nrmse}  {m.n_samples:7d}"
            )
        if len(self.recordings) > 1:
            lines += ["", "  by recording"]
            width = max(len(r.name) for r in self.recordings)
            for r in self.recordings:
                lines.append(f"    {r.name:<{width}}  {r.overall.format(unit)}")
        lines += ["", "  worst segments (time from the recording's start)"]
        if not self.worst:
            lines.append("    none")
        for i, seg in enumerate(self.worst, 1):
            lines.append(f"    {i}. {seg.text(unit)}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary in display units (deg or bar; NRMSE a fraction)."""
        unit, k = self.display_unit, self.display_scale
        return {
            "model_kind": self.model_kind,
            "direction": self.direction,
            "unit": unit,
            "overall": _metrics_dict(self.overall, unit, k),
            "by_regime": {name: _metrics_dict(m, unit, k) for name, m in self.by_regime.items()},
            "recordings": [
                {
                    "name": r.name,
                    "rate_hz": r.rate_hz,
                    "duration_s": r.t_s.size / r.rate_hz,
                    "overall": _metrics_dict(r.overall, unit, k),
                    "by_regime": {
                        name: _metrics_dict(m, unit, k) for name, m in r.by_regime.items()
                    },
                }
                for r in self.recordings
            ],
            "worst": [
                {
                    "recording": s.recording,
                    "start_s": s.start_s,
                    "end_s": s.end_s,
                    "regime": s.regime,
                    f"rmse_{unit}": s.rmse * k,
                    f"max_abs_{unit}": s.max_abs * k,
                    "n_samples": s.n_samples,
                }
                for s in self.worst
            ],
        }


def _metrics_dict(m: ErrorMetrics | None, unit: str, k: float) -> dict[str, Any] | None:
    if m is None:
        return None
    return {
        f"rmse_{unit}": m.rmse * k,
        f"mae_{unit}": m.mae * k,
        "nrmse": m.nrmse,
        "n_samples": m.n_samples,
    }


# --------------------------------------------------------------------------------------------
# Comparing
# --------------------------------------------------------------------------------------------


def compare(
    model: Model,
    recordings: Sequence[Recording],
    *,
    n_worst: int = 5,
    window_s: float = 1.0,
) -> Comparison:
    """Run ``model`` over each recording from rest and score it overall, per regime, per window.

    Args:
        model: Any fitted model, forward or inverse.
        recordings: Measured (or simulated) recordings at the model's sample rate.
        n_worst: How many windows to report as worst; adjacent ones merge into one segment,
            so there may be fewer segments than this.
        window_s: Length [s] of the non-overlapping windows the recordings are cut into to
            locate the errors (a tail shorter than half a window joins the window before).

    Returns:
        The comparison; errors are model minus measurement.

    Raises:
        NotFittedError: The model has not been fitted or loaded.
        RateMismatchError: A recording's rate differs from the model's (resample the bag at
            the model's rate).
        InsufficientDataError: No recordings.
        ParameterError: ``n_worst`` or ``window_s`` out of range, or a recording too short to
            classify its regimes.
    """
    if n_worst < 0:
        raise ParameterError(f"n_worst must be >= 0, got {n_worst}")
    if not (math.isfinite(window_s) and window_s > 0.0):
        raise ParameterError(f"window_s must be finite and > 0 (e.g. 1.0), got {window_s!r}")
    # Fitted first: an unfitted model has no rate to check the recordings against.
    rate_hz = model.fitted_rate_hz
    check_rates(model.kind, recordings, rate_hz)
    output_unit: OutputUnit = "rad" if model.direction == "forward" else "pa"

    per_recording = [_compare_one(model, rec) for rec in recordings]
    predicted = np.concatenate([r.predicted_si for r in per_recording])
    measured = np.concatenate([r.measured_si for r in per_recording])
    overall = compute_metrics(predicted, measured)
    pooled_masks = {
        name: np.concatenate([r.regimes[name] for r in per_recording]) for name in REGIMES
    }
    span = float(np.ptp(measured))
    by_regime = metrics_by_regime(
        predicted, measured, pooled_masks, normalization_range=span if span > 0.0 else None
    )
    worst = _worst_segments(per_recording, n_worst, window_s)
    return Comparison(
        model_kind=model.kind,
        direction=model.direction,
        recordings=per_recording,
        overall=overall,
        by_regime=by_regime,
        worst=worst,
        output_unit=output_unit,
    )


def _compare_one(model: Model, recording: Recording) -> RecordingComparison:
    x, measured = recording.io(model.direction)
    predicted = np.asarray(model.predict(x), dtype=np.float64)
    if predicted.shape != measured.shape:
        raise ParameterError(
            f"{model.kind} returned {predicted.size} samples for the {measured.size} of "
            f"recording {recording.name!r}"
        )
    t_s = np.arange(len(recording), dtype=np.float64) / recording.rate_hz
    regimes = classify_regimes(t_s, recording.pressure_pa, recording.angle_rad)
    return RecordingComparison(
        name=recording.name,
        rate_hz=recording.rate_hz,
        t_s=t_s,
        input_si=np.asarray(x, dtype=np.float64),
        measured_si=np.asarray(measured, dtype=np.float64),
        predicted_si=predicted,
        overall=compute_metrics(predicted, measured),
        by_regime=metrics_by_regime(predicted, measured, regimes),
        regimes=regimes,
    )


def _windows(n: int, size: int) -> list[tuple[int, int]]:
    """Half-open index windows of ``size`` covering ``n`` samples; a short tail joins the last."""
    bounds = [(start, min(start + size, n)) for start in range(0, n, size)]
    if len(bounds) > 1 and 2 * (bounds[-1][1] - bounds[-1][0]) < size:
        tail = bounds.pop()
        bounds[-1] = (bounds[-1][0], tail[1])
    return bounds


def _dominant_regime(regimes: Mapping[str, BoolArray], start: int, stop: int) -> str:
    """The regime covering the largest share of ``[start, stop)``, if more than half."""
    best, share = MIXED, 0.5
    n = stop - start
    for name, mask in regimes.items():
        covered = int(np.count_nonzero(mask[start:stop])) / n
        if covered > share:
            best, share = name, covered
    return best


def _worst_segments(
    recordings: Sequence[RecordingComparison], n_worst: int, window_s: float
) -> list[Segment]:
    """Rank fixed windows by RMSE, keep ``n_worst``, merge neighbours, sort worst first.

    Fixed windows (rather than a threshold on the error) give the same answer for a good and a
    bad model alike: always the places to look at first.
    """
    # (rmse, recording index, window index, start, stop)
    scored: list[tuple[float, int, int, int, int]] = []
    for ri, rec in enumerate(recordings):
        err = rec.error_si
        size = max(1, round(window_s * rec.rate_hz))
        for wi, (start, stop) in enumerate(_windows(err.size, size)):
            scored.append((float(np.sqrt(np.mean(err[start:stop] ** 2))), ri, wi, start, stop))
    scored.sort(key=lambda s: (-s[0], s[1], s[2]))
    chosen = sorted(scored[:n_worst], key=lambda s: (s[1], s[2]))

    merged: list[tuple[int, int, int]] = []  # (recording index, start, stop)
    last: tuple[int, int] | None = None  # (recording index, window index) of the previous
    for _, ri, wi, start, stop in chosen:
        if last is not None and last == (ri, wi - 1):
            merged[-1] = (ri, merged[-1][1], stop)
        else:
            merged.append((ri, start, stop))
        last = (ri, wi)

    segments = []
    for ri, start, stop in merged:
        rec = recordings[ri]
        err = rec.error_si[start:stop]
        segments.append(
            Segment(
                recording=rec.name,
                start_s=start / rec.rate_hz,
                end_s=stop / rec.rate_hz,
                regime=_dominant_regime(rec.regimes, start, stop),
                rmse=float(np.sqrt(np.mean(err**2))),
                max_abs=float(np.max(np.abs(err))),
                n_samples=stop - start,
            )
        )
    segments.sort(key=lambda s: -s.rmse)
    return segments


# --------------------------------------------------------------------------------------------
# Report
# --------------------------------------------------------------------------------------------


def _series(rc: RecordingComparison, direction: Direction) -> tuple[FloatArray, FloatArray]:
    """(pressure [Pa], measured angle [rad]) of a recording, whichever way the model maps."""
    if direction == "forward":
        return rc.input_si, rc.measured_si
    return rc.measured_si, rc.input_si


def _file_stem(index: int, name: str) -> str:
    """A safe, unique file name stem for a recording's plots."""
    return f"{index:02d}_" + (re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "recording")


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


def _plot_time(
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


def _plot_loops(comparison: Comparison, rc: RecordingComparison) -> Figure:
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


def _plot_regimes(comparison: Comparison) -> Figure:
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


def _metrics_row(label: str, m: ErrorMetrics | None, k: float) -> str:
    cells = [html.escape(label)]
    if m is None:
        cells += ["n/a", "n/a", "n/a", "too few"]
    else:
        nrmse = "n/a" if m.nrmse is None else f"{100 * m.nrmse:.2f} %"
        cells += [f"{m.rmse * k:.3f}", f"{m.mae * k:.3f}", nrmse, str(m.n_samples)]
    return "<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>"


_CSS: Final = """
body { font-family: sans-serif; max-width: 1500px; margin: 1em auto; padding: 0 1em; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
th { background: #f0f0f0; }
img { max-width: 100%; display: block; margin: 0.5em 0 1.5em; }
.note { color: #555; }
"""


def write_report(comparison: Comparison, out_dir: Path, title: str) -> Path:
    """Write ``out_dir/index.html`` with the tables and plots; returns its path.

    The page is plain HTML (no script, images by relative path), so the directory can be
    copied, archived or attached as it is. Plots cover the first
    :data:`MAX_PLOTTED_RECORDINGS` recordings; the tables cover all. ``comparison.json``
    beside it holds :meth:`Comparison.to_dict`.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    unit, k = comparison.display_unit, comparison.display_scale
    esc = html.escape

    def save(fig: Figure, name: str) -> str:
        fig.savefig(out_dir / name, dpi=90)
        return name

    summary_png = save(_plot_regimes(comparison), "regimes.png")
    ranked = list(enumerate(comparison.worst, 1))
    figures: list[tuple[str, list[str]]] = []
    for i, rc in enumerate(comparison.recordings[:MAX_PLOTTED_RECORDINGS]):
        stem = _file_stem(i, rc.name)
        mine = [(rank, s) for rank, s in ranked if s.recording == rc.name]
        figures.append(
            (
                rc.name,
                [
                    save(_plot_time(comparison, rc, mine), f"{stem}_time.png"),
                    save(_plot_loops(comparison, rc), f"{stem}_loops.png"),
                ],
            )
        )
    (out_dir / "comparison.json").write_text(json.dumps(comparison.to_dict(), indent=2) + "\n")

    head = "<tr><th>{}</th><th>RMSE [{u}]</th><th>MAE [{u}]</th><th>NRMSE</th><th>samples</th></tr>"
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{esc(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{esc(title)}</h1>",
        f"<p>Model <b>{esc(comparison.model_kind)}</b> ({esc(comparison._mapping())}) against "
        f"{len(comparison.recordings)} recording(s). Errors are model minus measurement, in "
        f"{esc(unit)}; MAE is the <em>maximum</em> absolute error (thesis eq. 5.13); NRMSE is "
        "RMSE over the range of the measurement (eq. 5.15). Regimes are classified from the "
        "recording's pressure and measured bend.</p>",
        "<h2>Metrics</h2><table>",
        head.format("", u=esc(unit)),
        _metrics_row("overall", comparison.overall, k),
    ]
    parts += [_metrics_row(name, m, k) for name, m in comparison.by_regime.items()]
    parts.append("</table>")
    parts.append(f'<img src="{esc(summary_png)}" alt="RMSE per regime">')
    if len(comparison.recordings) > 1:
        parts += ["<h2>Recordings</h2><table>", head.format("recording", u=esc(unit))]
        parts += [_metrics_row(r.name, r.overall, k) for r in comparison.recordings]
        parts.append("</table>")
    parts += [
        "<h2>Worst segments</h2>",
        f'<p class="note">Fixed windows ranked by RMSE, neighbours merged; time in seconds from '
        f"the recording's start. Regime: the one covering most samples ({MIXED} if none covers "
        "more than half).</p>",
        "<table><tr><th>#</th><th>recording</th><th>from [s]</th><th>to [s]</th>"
        f"<th>regime</th><th>RMSE [{esc(unit)}]</th><th>max |error| [{esc(unit)}]</th>"
        "<th>samples</th></tr>",
    ]
    for rank, s in ranked:
        cells = [
            str(rank),
            esc(s.recording),
            f"{s.start_s:.2f}",
            f"{s.end_s:.2f}",
            esc(s.regime),
            f"{s.rmse * k:.3f}",
            f"{s.max_abs * k:.3f}",
            str(s.n_samples),
        ]
        parts.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    parts.append("</table>")
    for name, images in figures:
        parts.append(f"<h2>{esc(name)}</h2>")
        parts += [f'<img src="{esc(src)}" alt="{esc(name)}">' for src in images]
    skipped = len(comparison.recordings) - len(figures)
    if skipped > 0:
        parts.append(
            f'<p class="note">{skipped} more recording(s) not plotted (the first '
            f"{MAX_PLOTTED_RECORDINGS} are); their metrics are in the tables above.</p>"
        )
    parts.append("</body></html>")
    index = out_dir / "index.html"
    index.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return index
