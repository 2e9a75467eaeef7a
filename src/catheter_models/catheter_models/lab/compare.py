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

This module holds the numerics and the public entry points; how a result reads
(:mod:`.compare_text`), its figures (:mod:`.compare_plots`) and its HTML page
(:mod:`.compare_report`) are their own modules, and :func:`write_report` is re-exported here.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.lab.compare_report import MAX_PLOTTED_RECORDINGS, write_report
from catheter_models.lab.compare_text import (
    MIXED,
    comparison_dict,
    comparison_text,
    display_unit_of,
    segment_text,
)
from catheter_models.metrics import (
    REGIMES,
    ErrorMetrics,
    classify_regimes,
    compute_metrics,
    metrics_by_regime,
)
from catheter_models.models.base import Direction, Model, Recording, check_rates

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
OutputUnit = Literal["rad", "pa"]

__all__ = [
    "MAX_PLOTTED_RECORDINGS",
    "MIXED",
    "BoolArray",
    "Comparison",
    "FloatArray",
    "OutputUnit",
    "RecordingComparison",
    "Segment",
    "compare",
    "write_report",
]


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
        return segment_text(self, unit)


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
        return display_unit_of(self.output_unit)[0]

    @property
    def display_scale(self) -> float:
        """Factor from the output's SI unit to :attr:`display_unit`."""
        return display_unit_of(self.output_unit)[1]

    def text(self) -> str:
        """The report a person reads in the terminal (MAE = maximum absolute error)."""
        return comparison_text(self)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary in display units (deg or bar; NRMSE a fraction)."""
        return comparison_dict(self)


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
