"""Error metrics of the thesis (eqs. 5.13-5.15), overall and per motion regime.

In the thesis "MAE" is the **maximum** absolute error (eq. 5.13), not the mean; this module
keeps that meaning, so numbers compare with the thesis's tables. NRMSE (eq. 5.15) divides
RMSE by the range of the *reference* (measured or desired) signal and is a fraction here;
:meth:`ErrorMetrics.format` shows it in percent.

Regimes say *where* a model fails: while the drive rises (loading) or falls (unloading), on
plateaus, in the deadband, during fast motion, and at the drive's peaks and valleys. Rates come
from a Savitzky-Golay smoothed drive, so sensor noise does not flip a sample between regimes.
Metrics take arrays in whatever unit the caller uses (SI inside the stack: rad or Pa).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt
from scipy.signal import find_peaks, savgol_filter

from .errors import ParameterError
from .units import PA_PER_BAR, rad_to_deg

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

REGIMES: Final = ("loading", "unloading", "plateau", "deadband", "fast_motion", "peak", "valley")
"""Names of the masks :func:`classify_regimes` returns, in this order."""

DEFAULT_MIN_REGIME_SAMPLES: Final = 25
"""0.1 s at 250 Hz: fewer samples make a maximum error or an RMSE anecdotal."""

# How format() turns a metric in the inputs' SI unit into the unit asked for.
_DISPLAY_SCALE: Final[Mapping[str, float]] = {
    "deg": float(rad_to_deg(1.0)),
    "rad": 1.0,
    "bar": 1.0 / PA_PER_BAR,
    "Pa": 1.0,
}


# --------------------------------------------------------------------------------------------
# Eqs. 5.13-5.15
# --------------------------------------------------------------------------------------------


def _finite_1d(values: npt.ArrayLike, name: str) -> FloatArray:
    """``values`` as a non-empty 1-D float64 array, or ParameterError naming what is wrong."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise ParameterError(f"{name} must be 1-D, got shape {arr.shape}")
    if arr.size == 0:
        raise ParameterError(f"{name} is empty; metrics need at least one sample")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        raise ParameterError(
            f"{name}[{i}] is {arr[i]} ({bad.size} non-finite sample(s) in all); metrics need "
            "finite values: drop or interpolate the gaps first"
        )
    return arr


def _pair(predicted: npt.ArrayLike, reference: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    p = _finite_1d(predicted, "predicted")
    r = _finite_1d(reference, "reference")
    if p.shape != r.shape:
        raise ParameterError(
            f"predicted and reference must have equal length, got {p.size} and {r.size}"
        )
    return p, r


def max_abs_error(predicted: npt.ArrayLike, reference: npt.ArrayLike) -> float:
    """Eq. 5.13, the thesis's "MAE": the *maximum* of ``|predicted - reference|``.

    Args:
        predicted: Model output or measured response, any unit.
        reference: Ground truth or desired signal, same unit and length.

    Returns:
        The largest absolute error, in the inputs' unit.

    Raises:
        ParameterError: If an input is empty, not 1-D, non-finite, or the lengths differ.
    """
    p, r = _pair(predicted, reference)
    return float(np.max(np.abs(p - r)))


def rmse(predicted: npt.ArrayLike, reference: npt.ArrayLike) -> float:
    """Eq. 5.14: root mean square error, in the inputs' unit.

    Raises:
        ParameterError: If an input is empty, not 1-D, non-finite, or the lengths differ.
    """
    p, r = _pair(predicted, reference)
    return float(np.sqrt(np.mean((p - r) ** 2)))


def nrmse(
    predicted: npt.ArrayLike,
    reference: npt.ArrayLike,
    *,
    normalization_range: float | None = None,
) -> float:
    """Eq. 5.15: RMSE divided by the reference's range ``max - min``, as a fraction.

    Args:
        predicted: Model output or measured response.
        reference: Ground truth or desired signal; its range normalizes the RMSE.
        normalization_range: Use this range (inputs' unit) instead of the reference's own,
            e.g. the whole run's range when scoring one regime of it.

    Returns:
        NRMSE as a fraction (0.05 means 5 %).

    Raises:
        ParameterError: If an input is invalid, or the range is zero (a constant reference
            has no range to normalize by) or not finite.
    """
    p, r = _pair(predicted, reference)
    span = _normalization_range(r, normalization_range)
    if span is None:
        raise ParameterError(
            "NRMSE is undefined: the reference is constant (range 0); pass "
            "normalization_range > 0, e.g. the range of the whole run"
        )
    return float(np.sqrt(np.mean((p - r) ** 2))) / span


def _normalization_range(reference: FloatArray, given: float | None) -> float | None:
    if given is not None:
        if not (math.isfinite(given) and given > 0.0):
            raise ParameterError(f"normalization_range must be finite and > 0, got {given!r}")
        return given
    span = float(np.max(reference) - np.min(reference))
    return span if span > 0.0 else None


@dataclass(frozen=True)
class ErrorMetrics:
    """The thesis's three metrics for one signal or one regime.

    Attributes:
        rmse: Root mean square error (eq. 5.14), in the inputs' unit (rad or Pa in the stack).
        mae: Maximum absolute error (eq. 5.13; *maximum*, as in the thesis), inputs' unit.
        nrmse: RMSE over the reference range (eq. 5.15) as a fraction, or None when the
            reference was constant and no range was given.
        n_samples: Number of samples scored.
    """

    rmse: float
    mae: float
    nrmse: float | None
    n_samples: int

    def format(self, unit: str = "deg") -> str:
        """One line for a person, e.g. ``RMSE 1.70 deg  MAE 4.40 deg  NRMSE 5.30 %  (n=5000)``.

        Args:
            unit: Display unit. ``"deg"`` or ``"rad"`` for metrics computed on radians,
                ``"bar"`` or ``"Pa"`` for metrics computed on pascal.

        Raises:
            ParameterError: If the unit is not one of those.
        """
        try:
            scale = _DISPLAY_SCALE[unit]
        except KeyError:
            valid = ", ".join(_DISPLAY_SCALE)
            raise ParameterError(f"unknown display unit {unit!r}; valid: {valid}") from None
        nrmse_text = "n/a" if self.nrmse is None else f"{100.0 * self.nrmse:.2f} %"
        return (
            f"RMSE {self.rmse * scale:.3g} {unit}  MAE {self.mae * scale:.3g} {unit}  "
            f"NRMSE {nrmse_text}  (n={self.n_samples})"
        )


def compute_metrics(
    predicted: npt.ArrayLike,
    reference: npt.ArrayLike,
    *,
    normalization_range: float | None = None,
) -> ErrorMetrics:
    """RMSE, MAE (maximum) and NRMSE of ``predicted`` against ``reference``.

    Args:
        predicted: Model output or measured response.
        reference: Ground truth or desired signal, same unit and length.
        normalization_range: Range for NRMSE (inputs' unit); default the reference's range.

    Returns:
        The metrics; ``nrmse`` is None if the reference is constant and no range is given.

    Raises:
        ParameterError: If an input is empty, not 1-D, non-finite, or the lengths differ.
    """
    p, r = _pair(predicted, reference)
    err = p - r
    rmse_value = float(np.sqrt(np.mean(err**2)))
    span = _normalization_range(r, normalization_range)
    return ErrorMetrics(
        rmse=rmse_value,
        mae=float(np.max(np.abs(err))),
        nrmse=None if span is None else rmse_value / span,
        n_samples=int(p.size),
    )


# --------------------------------------------------------------------------------------------
# Regimes
# --------------------------------------------------------------------------------------------


def smoothed_rate(
    t_s: npt.ArrayLike, drive: npt.ArrayLike, *, smoothing_window_s: float = 0.1
) -> tuple[FloatArray, FloatArray]:
    """Savitzky-Golay smoothed drive and its time derivative.

    The window is a number of samples (``smoothing_window_s`` over the median step), and
    the rate uses the actual stamps, so a jittery or gappy recording still gives rates in the
    right unit.

    Args:
        t_s: Sample times [s], strictly increasing.
        drive: The drive signal (pressure [Pa] or desired angle [rad]).
        smoothing_window_s: Savitzky-Golay window [s] (quadratic fit).

    Returns:
        ``(smoothed_drive, rate_per_s)``: the drive in its unit and its rate in unit/s.

    Raises:
        ParameterError: If the arrays are invalid or too short for the window.
    """
    t = _finite_1d(t_s, "t_s")
    x = _finite_1d(drive, "drive")
    if t.shape != x.shape:
        raise ParameterError(f"t_s and drive must have equal length, got {t.size} and {x.size}")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise ParameterError(
            f"t_s must increase strictly; t_s[{i}] = {t[i]} follows t_s[{i - 1}] = {t[i - 1]}"
        )
    if not (math.isfinite(smoothing_window_s) and smoothing_window_s > 0.0):
        raise ParameterError(
            f"smoothing_window_s must be finite and > 0 (e.g. 0.1), got {smoothing_window_s!r}"
        )
    step_s = float(np.median(dt))
    # Odd and at least 5 samples, so a quadratic fit still smooths.
    window = max(5, round(smoothing_window_s / step_s) | 1)
    if window > x.size:
        raise ParameterError(
            f"the signal has {x.size} samples, fewer than the {window}-sample smoothing window "
            f"({smoothing_window_s} s); record longer or shorten smoothing_window_s"
        )
    smooth: FloatArray = np.asarray(savgol_filter(x, window, 2, mode="interp"), dtype=np.float64)
    # Rate as (dx/dk) / (dt/dk), both Savitzky-Golay slopes over sample index k: a least-
    # squares slope never has the wrong sign on monotone data (differentiating the smoothed
    # drive would: a quadratic fit overshoots at a ramp's corner), and dividing by the local
    # time step keeps the unit right on jittery or gappy stamps.
    dx_dk = savgol_filter(x, window, 2, deriv=1, mode="interp")
    dt_dk = savgol_filter(t, window, 2, deriv=1, mode="interp")
    rate: FloatArray = np.asarray(dx_dk / dt_dk, dtype=np.float64)
    return smooth, rate


def _runs(mask: BoolArray) -> list[tuple[int, int]]:
    """Half-open ``(start, stop)`` index runs where ``mask`` is True."""
    edges = np.diff(np.concatenate(([0], mask.astype(np.int8), [0])))
    starts = np.flatnonzero(edges == 1)
    stops = np.flatnonzero(edges == -1)
    return list(zip(starts.tolist(), stops.tolist(), strict=True))


def _drop_short_runs(t_s: FloatArray, mask: BoolArray, min_duration_s: float) -> BoolArray:
    """``mask`` without its runs shorter than ``min_duration_s`` (first to last sample)."""
    out = mask.copy()
    for start, stop in _runs(mask):
        if t_s[stop - 1] - t_s[start] < min_duration_s:
            out[start:stop] = False
    return out


def _threshold(absolute: float | None, fraction: float, scale: float, name: str) -> float:
    if absolute is not None:
        if not (math.isfinite(absolute) and absolute >= 0.0):
            raise ParameterError(f"{name} must be finite and >= 0, got {absolute!r}")
        return absolute
    if not 0.0 < fraction < 1.0:
        raise ParameterError(f"the fraction for {name} must be in (0, 1), got {fraction!r}")
    return fraction * scale


def classify_regimes(
    t_s: npt.ArrayLike,
    drive: npt.ArrayLike,
    angle_rad: npt.ArrayLike,
    *,
    deadband_drive_threshold: float = 1.0e5,
    deadband_angle_rad: float = math.radians(1.0),
    rate_threshold_per_s: float | None = None,
    rate_threshold_fraction: float = 0.05,
    plateau_min_duration_s: float = 0.25,
    min_motion_duration_s: float = 0.1,
    fast_rate_threshold_per_s: float | None = None,
    fast_rate_fraction: float = 0.5,
    extremum_prominence: float | None = None,
    extremum_prominence_fraction: float = 0.05,
    extremum_tolerance: float | None = None,
    extremum_tolerance_fraction: float = 0.01,
    extremum_window_s: float = 0.1,
    smoothing_window_s: float = 0.1,
) -> dict[str, BoolArray]:
    """Masks of the motion regimes of a run, one boolean per sample.

    ``drive`` is what moves the catheter: commanded or measured gauge pressure [Pa], or the
    desired angle [rad] when scoring a controller. Thresholds are in the drive's unit, so the
    defaults (1e5 = 1 bar opening pressure) suit a pressure drive; pass your own for angles.
    Rate thresholds default to fractions of the run's peak rate (the 99th percentile of
    ``|rate|``, robust to a single spike), so they need no unit.

    Regimes (a sample may be in several, e.g. a valley inside the deadband):

    - ``loading``: smoothed drive rate above ``+rate_threshold`` for at least
      ``min_motion_duration_s`` (shorter runs are noise that got through the smoothing).
    - ``unloading``: the same, below ``-rate_threshold``.
    - ``plateau``: neither loading nor unloading for at least ``plateau_min_duration_s``;
      the short still moments at a sine's turning points are peaks or valleys, not plateaus.
    - ``deadband``: drive below ``deadband_drive_threshold`` and ``|angle|`` below
      ``deadband_angle_rad``: the PAM has not opened, the tip has not moved (thesis fig. 4.3:
      about 0-1 bar).
    - ``fast_motion``: ``|rate| >= fast_rate_threshold``.
    - ``peak`` / ``valley``: around a local maximum / minimum of the smoothed drive whose
      prominence is at least ``extremum_prominence``: the stretch within
      ``extremum_tolerance`` of the extremum's value (a held or noisy top counts whole),
      widened by ``extremum_window_s`` each side. The first sample counts as an extremum when
      the drive moves away from it (a run starts from rest); the last does not (a cut).

    A drive that never changes is all plateau, and in no other rate-based regime.

    Args:
        t_s: Sample times [s], strictly increasing.
        drive: Drive signal, pressure [Pa] or desired angle [rad].
        angle_rad: Measured bending angle [rad], same length.
        deadband_drive_threshold: Opening threshold, drive unit (default 1e5 Pa = 1 bar).
        deadband_angle_rad: Largest |angle| [rad] still counted as "not moved".
        rate_threshold_per_s: Rate separating loading/unloading from still, drive unit/s;
            None for ``rate_threshold_fraction`` of the peak rate.
        rate_threshold_fraction: See above.
        plateau_min_duration_s: Shortest still stretch [s] that counts as a plateau.
        min_motion_duration_s: Shortest loading or unloading stretch [s]; shorter ones are
            taken for noise and counted as still.
        fast_rate_threshold_per_s: Rate from which motion is fast, drive unit/s; None for
            ``fast_rate_fraction`` of the peak rate.
        fast_rate_fraction: See above.
        extremum_prominence: Smallest prominence of a peak or valley, drive unit; None for
            ``extremum_prominence_fraction`` of the drive's range.
        extremum_prominence_fraction: See above.
        extremum_tolerance: How far below a peak's value (above a valley's) the peak region
            reaches, drive unit; None for ``extremum_tolerance_fraction`` of the range.
        extremum_tolerance_fraction: See above.
        extremum_window_s: Half-width [s] of the peak and valley masks around each extremum.
        smoothing_window_s: Savitzky-Golay window [s] for the drive and its rate.

    Returns:
        A dict with one boolean array per name in :data:`REGIMES`.

    Raises:
        ParameterError: If an array is invalid, the lengths differ, or a threshold is out of
            its range.
    """
    angle = _finite_1d(angle_rad, "angle_rad")
    smooth, rate = smoothed_rate(t_s, drive, smoothing_window_s=smoothing_window_s)
    if angle.shape != smooth.shape:
        raise ParameterError(
            f"angle_rad must have the length of drive, got {angle.size} and {smooth.size}"
        )
    t = np.asarray(t_s, dtype=np.float64)
    for name, value in (
        ("deadband_drive_threshold", deadband_drive_threshold),
        ("deadband_angle_rad", deadband_angle_rad),
        ("plateau_min_duration_s", plateau_min_duration_s),
        ("min_motion_duration_s", min_motion_duration_s),
        ("extremum_window_s", extremum_window_s),
    ):
        if not (math.isfinite(value) and value >= 0.0):
            raise ParameterError(f"{name} must be finite and >= 0, got {value!r}")

    abs_rate = np.abs(rate)
    peak_rate = float(np.percentile(abs_rate, 99.0))
    still_rate = _threshold(
        rate_threshold_per_s, rate_threshold_fraction, peak_rate, "rate_threshold_per_s"
    )
    fast_rate = _threshold(
        fast_rate_threshold_per_s, fast_rate_fraction, peak_rate, "fast_rate_threshold_per_s"
    )
    drive_span = float(np.ptp(smooth))
    prominence = _threshold(
        extremum_prominence, extremum_prominence_fraction, drive_span, "extremum_prominence"
    )
    tolerance = _threshold(
        extremum_tolerance, extremum_tolerance_fraction, drive_span, "extremum_tolerance"
    )

    deadband = (smooth < deadband_drive_threshold) & (np.abs(angle) < deadband_angle_rad)
    raw = np.asarray(drive, dtype=np.float64)
    if np.all(raw == raw[0]):
        # Rounding leaves ~1e-12 "rates" and wiggles on a constant drive; relative thresholds
        # would turn that dust into motion and extrema.
        none = np.zeros(raw.size, dtype=np.bool_)
        return {
            "loading": none,
            "unloading": none.copy(),
            "plateau": ~none,
            "deadband": deadband,
            "fast_motion": none.copy(),
            "peak": none.copy(),
            "valley": none.copy(),
        }

    loading = _drop_short_runs(t, rate > still_rate, min_motion_duration_s)
    unloading = _drop_short_runs(t, rate < -still_rate, min_motion_duration_s)
    plateau = _drop_short_runs(t, ~loading & ~unloading, plateau_min_duration_s)
    return {
        "loading": loading,
        "unloading": unloading,
        "plateau": plateau,
        "deadband": deadband,
        "fast_motion": abs_rate >= fast_rate,
        "peak": _extremum_mask(t, smooth, prominence, tolerance, extremum_window_s),
        "valley": _extremum_mask(t, -smooth, prominence, tolerance, extremum_window_s),
    }


def _extremum_mask(
    t_s: FloatArray, x: FloatArray, prominence: float, tolerance: float, half_width_s: float
) -> BoolArray:
    """Samples near a prominent local maximum of ``x``.

    Near means: in the contiguous stretch around the maximum that stays within ``tolerance``
    of its value, widened by ``half_width_s`` on each side. A flat or noisy top is thus
    covered whole, the same way whether the drive is a clean command or a measurement.
    """
    mask = np.zeros(x.size, dtype=np.bool_)
    if prominence <= 0.0:
        return mask
    # A run starts from rest, so its first sample is a real turning point if the drive then
    # moves away; a low sample in front lets find_peaks see it. The end is a cut, not a turn.
    floor = float(np.min(x)) - (float(np.ptp(x)) + 1.0)
    peaks, _ = find_peaks(np.concatenate(([floor], x)), prominence=prominence, plateau_size=1)
    for i in (peaks - 1).tolist():
        below = np.flatnonzero(x < x[i] - tolerance)
        k = int(np.searchsorted(below, i))
        first = int(below[k - 1]) + 1 if k > 0 else 0
        last = int(below[k]) - 1 if k < below.size else x.size - 1
        lo = int(np.searchsorted(t_s, t_s[first] - half_width_s, side="left"))
        hi = int(np.searchsorted(t_s, t_s[last] + half_width_s, side="right"))
        mask[lo:hi] = True
    return mask


def metrics_by_regime(
    predicted: npt.ArrayLike,
    reference: npt.ArrayLike,
    regimes: Mapping[str, npt.ArrayLike],
    *,
    min_samples: int = DEFAULT_MIN_REGIME_SAMPLES,
    normalization_range: float | None = None,
) -> dict[str, ErrorMetrics | None]:
    """The metrics of each regime's samples.

    NRMSE is normalized by the *whole* reference's range (unless given), not the regime's
    own, so a plateau (range near zero) gets a meaningful number comparable with the overall.

    Args:
        predicted: Model output or measured response.
        reference: Ground truth or desired signal, same unit and length.
        regimes: Boolean masks by name, e.g. from :func:`classify_regimes`.
        min_samples: Fewest samples a regime needs to be scored.
        normalization_range: Range for NRMSE, inputs' unit; default the reference's range.

    Returns:
        Metrics by regime name; None where a regime has fewer than ``min_samples`` samples.

    Raises:
        ParameterError: If the inputs are invalid or a mask is not boolean of their length.
    """
    p, r = _pair(predicted, reference)
    if min_samples < 1:
        raise ParameterError(f"min_samples must be >= 1, got {min_samples}")
    span = _normalization_range(r, normalization_range)
    out: dict[str, ErrorMetrics | None] = {}
    for name, mask_like in regimes.items():
        mask = np.asarray(mask_like)
        if mask.dtype != np.bool_ or mask.shape != p.shape:
            raise ParameterError(
                f"regime {name!r} must be a boolean mask of length {p.size}, got dtype "
                f"{mask.dtype} and shape {mask.shape}"
            )
        n = int(np.count_nonzero(mask))
        if n < min_samples:
            out[name] = None
            continue
        out[name] = compute_metrics(p[mask], r[mask], normalization_range=span)
    return out
