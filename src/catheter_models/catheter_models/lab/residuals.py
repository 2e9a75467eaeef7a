"""The standard residual tests of nonlinear system identification, each with its 95 % band.

A model that has captured the physics leaves a residual that is white and unrelated to the
input, to the input's rate, to the input's square and to its own past (Billings & Voon 1983,
1986; Ljung, *System Identification*, 2nd ed., ch. 16.6). Each test here checks one of those
claims, and a failed test points at a missing effect of the catalogue (docs/lab.md):

===============  ==========================================  =====================================
name             correlation                                 a significant value suggests
===============  ==========================================  =====================================
autocorrelation  e(t) with e(t - tau), tau >= 1              unmodelled dynamics (plus Ljung-Box)
input_cross      e(t) with u(t - tau)                        gain error; a peak at tau > 0 is a
                                                             ``transport_delay``
rate_cross       e(t) with du/dt(t - tau)                    ``pneumatic_lag`` (phase), viscous
                                                             ``rate_dependence``, ``play``
e_eu             e(t) with e(t - tau) u(t - tau), tau >= 1   unmodelled nonlinear dynamics
u2_e             e(t) with u'^2(t - tau)                     even nonlinearity: ``saturation``,
                                                             ``deadband``, ``asymmetry``
u2_e2            e'^2(t) with u'^2(t - tau)                  error size that depends on the level
abs_rate_e       e(t) with |du/dt|'(t - tau)                 ``rate_dependence`` of the error
time_trend       e(t) with time within its recording         ``drift`` (or ``creep``)
===============  ==========================================  =====================================

(A prime marks a signal with its mean removed; ``u'`` is the input's deviation from its mean,
so ``u'^2`` sees the symmetric part of a nonlinearity instead of repeating ``input_cross``.)
Positive lags mean the residual *follows* the input: a value at ``tau`` is
``corr(e(t), x(t - tau))``. Each correlation is normalised by ``sqrt(sum x^2 sum y^2)`` over the
pooled samples, so it lies in [-1, 1].

**Why decimate.** At 250 Hz consecutive samples of a hysteresis model's residual are almost
equal: slowly varying structural error plus sensor noise. The band ``±1.96/sqrt(N)`` holds only if
``N`` counts roughly independent samples, so both signals are first reduced to
``analysis_rate_hz`` (25 Hz by default) by averaging disjoint blocks, a low-pass filter that,
unlike a sharper anti-alias filter, keeps white noise white (see :func:`_decimate`). Each
recording is averaged on its own, and residual and input alike, so neither is shifted.

**Why segments.** Several recordings are often concatenated into one array. A product
``e(t) x(t - tau)`` whose two samples come from different recordings, or a mean taken across
them, would turn the jump at the boundary into a spurious correlation. Sums are therefore
formed within each recording (each with its own mean removed) and pooled.

**Why a limit beside the band.** ``band`` is the usual per-lag 95 % limit that the literature
plots. A test looks at up to ``2 * max_lag`` lags at once, and with 50 lags a white residual
crosses the per-lag band somewhere most of the time. Because the lab must not invent an effect,
a test is called ``significant`` only if a value crosses ``limit``, the band widened
(Šidák) so that the whole test, all lags together, has a 5 % false-alarm rate. For a single-lag
test (``time_trend``) the two are equal.

The bands assume what the null hypothesis says: that the residual is white. If the
autocorrelation test fails, the cross tests' bands are optimistic; read them by the size and
lag of their peaks rather than by the verdict alone. Products of squares are skewed, so
``u2_e2`` raises about 10 % false alarms (not 5 %) on white Gaussian noise against a smooth
random input; the other tests and Ljung-Box hold 5 % (checked by simulation).
"""

from __future__ import annotations

import itertools
import math
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from scipy.stats import chi2, norm

from catheter_models.errors import ParameterError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

ALPHA: Final = 0.05
"""False-alarm rate of every test (and of the Ljung-Box test): 95 % bands."""

MIN_ANALYSIS_SAMPLES: Final = 50
"""Fewest samples after decimation (2 s at 25 Hz): fewer make a correlation anecdotal."""

MAX_LAG_FRACTION: Final = 0.25
"""Largest lag as a fraction of the analysed samples (Box & Jenkins' rule of thumb N/4)."""

LJUNG_BOX_MAX_LAGS: Final = 20
"""Ljung-Box sums the first ``min(20, N / 5)`` squared autocorrelations."""

TEST_NAMES: Final = (
    "autocorrelation",
    "input_cross",
    "rate_cross",
    "e_eu",
    "u2_e",
    "u2_e2",
    "abs_rate_e",
    "time_trend",
)
"""Names of the tests in :attr:`ResidualReport.tests`, in this order."""

TEST_LABELS: Final = {
    "autocorrelation": "residual autocorrelation",
    "input_cross": "residual vs input",
    "rate_cross": "residual vs input rate",
    "e_eu": "residual vs past residual × input",
    "u2_e": "residual vs input²",
    "u2_e2": "residual² vs input²",
    "abs_rate_e": "residual vs |input rate|",
    "time_trend": "residual vs time (drift)",
}
"""Each test as a person reads it (reports, ``catheter-lab effects``)."""

# Below this fraction of its raw magnitude, a centred signal is rounding error, not variation:
# a constant residual must give correlations of 0, not normalised noise of order 1.
_RELATIVE_ZERO: Final = 1e-12

_Z95: Final = float(norm.ppf(1.0 - ALPHA / 2.0))


# --------------------------------------------------------------------------------------------
# Results
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class CorrelationTest:
    """One residual test: a normalised correlation at each lag, with its 95 % limits.

    Equality is identity (``eq=False``): the fields hold arrays, which have no single truth
    value, and the arrays are read-only so the result stays frozen.

    Attributes:
        name: Short key, one of :data:`TEST_NAMES`.
        label: What is correlated with what, for a person.
        lags_s: Lags [s] at the analysis rate; positive means the residual follows.
        values: Normalised correlation at each lag, in [-1, 1].
        band: Per-lag 95 % limit ``1.96 / sqrt(N)`` (what the literature plots).
        limit: 95 % limit for all tested lags together (Šidák); ``significant`` uses it.
        significant: Whether any tested ``|value|`` exceeds ``limit`` (the autocorrelation
            does not test lag 0, where it is 1 by definition).
        peak_lag_s: Lag [s] of the largest tested ``|value|``.
        peak_value: The value there, with its sign.
    """

    name: str
    label: str
    lags_s: FloatArray
    values: FloatArray
    band: float
    limit: float
    significant: bool
    peak_lag_s: float
    peak_value: float

    def evidence(self) -> str:
        """One line for a person, e.g. ``residual vs input rate: peak 0.62 at +0.04 s (...)``."""
        where = "" if self.lags_s.size == 1 else f" at {_format_lag(self.peak_lag_s, self)} s"
        verdict = "significant" if self.significant else "not significant"
        return (
            f"{self.label}: peak {self.peak_value:.2f}{where} "
            f"(band ±{self.band:.2g}, limit ±{self.limit:.2g}: {verdict})"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields (plain floats, lists and bools)."""
        return {
            "name": self.name,
            "label": self.label,
            "lags_s": [float(v) for v in self.lags_s],
            "values": [float(v) for v in self.values],
            "band": self.band,
            "limit": self.limit,
            "significant": self.significant,
            "peak_lag_s": self.peak_lag_s,
            "peak_value": self.peak_value,
            "evidence": self.evidence(),
        }


@dataclass(frozen=True)
class LjungBox:
    """The Ljung-Box portmanteau test of whiteness over the first ``dof`` lags.

    It asks one question of all those lags at once, so unlike the per-lag band it needs no
    correction for looking at many lags. No degrees of freedom are subtracted: a physical
    model's parameters are not ARMA coefficients fitted to the residual.

    Attributes:
        statistic: ``Q = N (N + 2) sum_k r_k^2 / (N - k)``, k = 1..dof.
        dof: Number of lags summed (the chi-squared degrees of freedom).
        p_value: Probability of a ``Q`` this large if the residual were white.
        significant: ``p_value < 0.05``: the residual is not white.
    """

    statistic: float
    dof: int
    p_value: float
    significant: bool

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready fields."""
        return {
            "statistic": self.statistic,
            "dof": self.dof,
            "p_value": self.p_value,
            "significant": self.significant,
        }


@dataclass
class ResidualReport:
    """All residual tests of one residual, at the analysis rate.

    Attributes:
        tests: One :class:`CorrelationTest` per name in :data:`TEST_NAMES`, in that order.
        ljung_box: The whiteness test over the first ``min(20, N / 5)`` lags.
        n_samples: ``N``, the samples after decimation, pooled over the recordings.
        rate_hz: The analysis rate after decimation [Hz].
    """

    tests: list[CorrelationTest]
    ljung_box: LjungBox
    n_samples: int
    rate_hz: float

    def significant(self) -> list[str]:
        """Names of the correlation tests that are significant (Ljung-Box is separate)."""
        return [t.name for t in self.tests if t.significant]

    def by_name(self, name: str) -> CorrelationTest:
        """The test called ``name``.

        Raises:
            KeyError: If no test has that name; the message lists the names there are.
        """
        for test in self.tests:
            if test.name == name:
                return test
        known = ", ".join(t.name for t in self.tests)
        raise KeyError(f"no residual test {name!r}; the report has: {known}")

    def text(self) -> str:
        """A compact table for the terminal; ``*`` marks a significant test."""
        lines = [
            f"residual tests: N = {self.n_samples} samples at {self.rate_hz:g} Hz "
            "(band: 95 % per lag; limit: 95 % over all lags)",
            f"  {'test':<16} {'label':<34} {'peak':>6} {'lag [s]':>8} {'band':>6} {'limit':>6}",
        ]
        for t in self.tests:
            lag = "" if t.lags_s.size == 1 else _format_lag(t.peak_lag_s, t)
            mark = "*" if t.significant else " "
            lines.append(
                f"{mark} {t.name:<16} {t.label:<34} {t.peak_value:>6.2f} {lag:>8} "
                f"{t.band:>6.3f} {t.limit:>6.3f}"
            )
        lb = self.ljung_box
        mark = "*" if lb.significant else " "
        lines.append(
            f"{mark} {'ljung_box':<16} Q = {lb.statistic:.1f} over {lb.dof} lags, "
            f"p = {lb.p_value:.3g}"
        )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form of the whole report."""
        return {
            "n_samples": self.n_samples,
            "rate_hz": self.rate_hz,
            "significant": self.significant(),
            "ljung_box": self.ljung_box.to_dict(),
            "tests": [t.to_dict() for t in self.tests],
        }


def _format_lag(lag_s: float, test: CorrelationTest) -> str:
    """A lag with as many decimals as the lag step needs (2 at 25 Hz: ``+0.04``)."""
    step_s = float(np.min(np.abs(np.diff(test.lags_s)))) if test.lags_s.size > 1 else 1.0
    decimals = max(0, math.ceil(-math.log10(step_s) - 1e-9)) if step_s > 0 else 3
    return f"{lag_s:+.{decimals}f}"


# --------------------------------------------------------------------------------------------
# The tests
# --------------------------------------------------------------------------------------------


def residual_tests(
    residual: npt.ArrayLike,
    input_: npt.ArrayLike,
    rate_hz: float,
    *,
    max_lag_s: float = 1.0,
    analysis_rate_hz: float = 25.0,
    segments: Sequence[tuple[int, int]] | None = None,
) -> ResidualReport:
    """Run the standard residual tests on a model's residual against its input.

    Args:
        residual: Model error (measured minus predicted, or the reverse: only signs flip), one
            sample per input sample, any unit (rad for a forward model).
        input_: The model's input at the same samples, any unit (Pa for a forward model).
        rate_hz: Sampling rate of both [Hz] (250 on the rig).
        max_lag_s: Largest lag tested [s]. Cross-correlations run from ``-max_lag_s`` to
            ``+max_lag_s``; the autocorrelation from 0.
        analysis_rate_hz: Rate to decimate to before testing [Hz], so that ``N`` counts roughly
            independent samples. The decimation factor is ``round(rate_hz / analysis_rate_hz)``
            (at least 1), so the rate reached is ``rate_hz`` divided by an integer.
        segments: ``(start, stop)`` sample ranges (stop exclusive) of separate recordings
            concatenated in the arrays. No correlation spans two of them, each has its own mean
            removed, and samples outside every range are ignored. ``None`` means one recording.

    Returns:
        The report: the tests of :data:`TEST_NAMES`, Ljung-Box, and ``N`` and the rate reached.

    Raises:
        ParameterError: (a ValueError) if an array is not 1-D or has non-finite values, the
            lengths differ, a rate or ``max_lag_s`` is not positive, a segment is out of range,
            overlaps another or is too short, or too few samples remain after decimation.
    """
    e = _finite_1d(residual, "residual")
    u = _finite_1d(input_, "input")
    if e.size != u.size:
        raise ParameterError(
            f"residual and input must have equal length, got {e.size} and {u.size} samples"
        )
    _positive(rate_hz, "rate_hz")
    _positive(analysis_rate_hz, "analysis_rate_hz")
    _positive(max_lag_s, "max_lag_s")
    ranges = _check_segments(segments, e.size)

    factor = max(1, round(rate_hz / analysis_rate_hz))
    fs = rate_hz / factor
    max_lag = round(max_lag_s * fs)
    if max_lag < 1:
        raise ParameterError(
            f"max_lag_s = {max_lag_s} s is shorter than one analysis sample "
            f"({1.0 / fs:.3g} s at {fs:g} Hz); use a longer max_lag_s"
        )

    signals = [
        _segment_signals(e, u, segment, rate_hz=rate_hz, factor=factor, fs=fs) for segment in ranges
    ]
    n = sum(s["e"].size for s in signals)
    n_raw = sum(stop - start for start, stop in ranges)
    if n < MIN_ANALYSIS_SAMPLES:
        raise ParameterError(
            f"only {n} samples remain after decimation to {fs:g} Hz (from {n_raw} at "
            f"{rate_hz:g} Hz); the tests need at least {MIN_ANALYSIS_SAMPLES}: "
            "give a longer recording or a higher analysis_rate_hz"
        )
    if max_lag > MAX_LAG_FRACTION * n:
        raise ParameterError(
            f"max_lag_s = {max_lag_s} s is {max_lag} samples at {fs:g} Hz, more than a quarter "
            f"of the {n} samples after decimation; use max_lag_s <= "
            f"{math.floor(MAX_LAG_FRACTION * n) / fs:.3g} s or a longer recording"
        )

    def column(key: str) -> list[FloatArray]:
        return [s[key] for s in signals]

    auto_lags = np.arange(0, max_lag + 1)
    cross_lags = np.arange(-max_lag, max_lag + 1)
    past_lags = np.arange(1, max_lag + 1)
    es = column("e")
    plan: list[tuple[str, list[FloatArray], list[FloatArray], IntArray]] = [
        ("autocorrelation", es, es, auto_lags),
        ("input_cross", es, column("u"), cross_lags),
        ("rate_cross", es, column("rate"), cross_lags),
        ("e_eu", es, column("eu"), past_lags),
        ("u2_e", es, column("u2"), cross_lags),
        ("u2_e2", column("e2"), column("u2"), cross_lags),
        ("abs_rate_e", es, column("abs_rate"), cross_lags),
        ("time_trend", es, column("time"), np.zeros(1, dtype=np.int64)),
    ]
    tests = [
        _make_test(
            name,
            lags,
            _pooled_correlation(ys, xs, lags),
            fs,
            n,
            exclude_lag_zero=name == "autocorrelation",
        )
        for name, ys, xs, lags in plan
    ]
    return ResidualReport(
        tests=tests,
        ljung_box=_ljung_box(es, n),
        n_samples=n,
        rate_hz=fs,
    )


def dominant_lag_s(report: ResidualReport) -> float | None:
    """Lag [s] at which the residual follows the input most, or None if that is not significant.

    A positive value is evidence of a delay the model lacks (``transport_delay``), a size for
    the delay block's first guess.
    """
    test = report.by_name("input_cross")
    return test.peak_lag_s if test.significant else None


def _segment_signals(
    e: FloatArray,
    u: FloatArray,
    segment: tuple[int, int],
    *,
    rate_hz: float,
    factor: int,
    fs: float,
) -> dict[str, FloatArray]:
    """The centred, decimated signals of one recording that the tests correlate."""
    start, stop = segment
    if stop - start < 2 * factor:
        raise ParameterError(
            f"segment ({start}, {stop}) has {stop - start} samples, fewer than 2 blocks of "
            f"{factor} for decimation; drop it or give a longer recording"
        )
    e_seg = e[start:stop]
    u_seg = u[start:stop]
    # The rate is differentiated at the recording rate, where the central difference is exact
    # in phase and nearly in gain; the decimation filter then removes the amplified noise.
    rate_seg = np.gradient(u_seg) * rate_hz
    e_d = _centred(_decimate(e_seg, factor))
    u_d = _centred(_decimate(u_seg, factor))
    rate_d = _decimate(rate_seg, factor)
    time_s = np.arange(e_d.size, dtype=np.float64) / fs
    return {
        "e": e_d,
        "u": u_d,
        "rate": _centred(rate_d),
        "eu": _centred(e_d * u_d),
        "u2": _centred(u_d**2),
        "e2": _centred(e_d**2),
        "abs_rate": _centred(np.abs(rate_d)),
        "time": _centred(time_s),
    }


def _decimate(x: FloatArray, factor: int) -> FloatArray:
    """Mean of each block of ``factor`` samples; a last, partial block is dropped.

    Why block means rather than ``scipy.signal.decimate`` or ``resample_poly``: their filters
    roll off around the new Nyquist frequency, which colours white noise. Decimated from 250 to
    25 Hz, white noise then has autocorrelations of about ±0.04 at the first lags, beyond the
    band for a 2-minute recording, and the whiteness tests flag a perfect model most of the
    time. Means over disjoint blocks of white noise are exactly white. The block mean is still
    a low-pass filter (gain 0.99 at 2 Hz, 0.64 at the new Nyquist frequency): it keeps the slow
    structural error, and what it aliases of broadband sensor noise stays white. Residual and
    input get the same filter, so neither is shifted against the other.
    """
    if factor == 1:
        return x.copy()
    n_blocks = x.size // factor
    return np.asarray(x[: n_blocks * factor].reshape(n_blocks, factor).mean(axis=1))


def _centred(x: FloatArray) -> FloatArray:
    """``x`` minus its mean; exactly zero if what remains is rounding error."""
    scale = float(np.max(np.abs(x))) if x.size else 0.0
    c = x - np.mean(x)
    if float(np.max(np.abs(c))) <= _RELATIVE_ZERO * scale:
        return np.zeros_like(c)
    return c


def _pooled_correlation(ys: list[FloatArray], xs: list[FloatArray], lags: IntArray) -> FloatArray:
    """``sum y(t) x(t - k)`` within each recording, pooled, over ``sqrt(sum x^2 sum y^2)``.

    A signal with no variance carries no evidence: its correlations are 0, not undefined.
    """
    num = np.zeros(lags.size)
    for y, x in zip(ys, xs, strict=True):
        n = y.size
        for i, k in enumerate(lags):
            if abs(k) >= n:
                continue
            if k >= 0:
                num[i] += float(y[k:] @ x[: n - k])
            else:
                num[i] += float(y[: n + k] @ x[-k:])
    den = math.sqrt(sum(float(y @ y) for y in ys) * sum(float(x @ x) for x in xs))
    if den == 0.0:
        return np.zeros(lags.size)
    return np.clip(num / den, -1.0, 1.0)


def _make_test(
    name: str,
    lags: IntArray,
    values: FloatArray,
    fs: float,
    n: int,
    *,
    exclude_lag_zero: bool,
) -> CorrelationTest:
    tested = lags != 0 if exclude_lag_zero else np.ones(lags.size, dtype=bool)
    n_tested = int(np.count_nonzero(tested))
    # Šidák: each of the n_tested lags at level 1 - (1 - alpha)^(1/n), so all together at alpha.
    per_lag_alpha = 1.0 - (1.0 - ALPHA) ** (1.0 / n_tested)
    z_all = float(norm.ppf(1.0 - per_lag_alpha / 2.0))
    band = _Z95 / math.sqrt(n)
    limit = z_all / math.sqrt(n)
    idx = np.flatnonzero(tested)
    peak = int(idx[np.argmax(np.abs(values[idx]))])
    lags_s = lags.astype(np.float64) / fs
    values = values.astype(np.float64)
    lags_s.setflags(write=False)
    values.setflags(write=False)
    return CorrelationTest(
        name=name,
        label=TEST_LABELS[name],
        lags_s=lags_s,
        values=values,
        band=band,
        limit=limit,
        significant=bool(np.any(np.abs(values[idx]) > limit)),
        peak_lag_s=float(lags_s[peak]),
        peak_value=float(values[peak]),
    )


def _ljung_box(es: list[FloatArray], n: int) -> LjungBox:
    dof = max(1, min(LJUNG_BOX_MAX_LAGS, n // 5))
    lags = np.arange(1, dof + 1)
    r = _pooled_correlation(es, es, lags)
    q = float(n * (n + 2) * np.sum(r**2 / (n - lags)))
    p = float(chi2.sf(q, dof))
    return LjungBox(statistic=q, dof=dof, p_value=p, significant=p < ALPHA)


# --------------------------------------------------------------------------------------------
# Checks
# --------------------------------------------------------------------------------------------


def _finite_1d(values: npt.ArrayLike, name: str) -> FloatArray:
    arr = np.asarray(values, dtype=np.float64)
    if arr.ndim != 1:
        raise ParameterError(f"{name} must be 1-D, got shape {arr.shape}")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        i = int(bad[0])
        raise ParameterError(
            f"{name}[{i}] is {arr[i]} ({bad.size} non-finite sample(s) in all); the tests need "
            "finite values: drop or interpolate the gaps, or split the recording into segments"
        )
    return arr


def _positive(value: float, name: str) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ParameterError(f"{name} must be a finite number > 0, got {value}")


def _check_segments(
    segments: Sequence[tuple[int, int]] | None, n_samples: int
) -> list[tuple[int, int]]:
    """Segments as sorted ``(start, stop)`` ints, checked to lie in range and not overlap."""
    if segments is None:
        return [(0, n_samples)]
    if len(segments) == 0:
        raise ParameterError("segments is empty; pass None for one recording")
    ranges: list[tuple[int, int]] = []
    for seg in segments:
        start, stop = (int(v) for v in seg)
        if not 0 <= start < stop <= n_samples:
            raise ParameterError(
                f"segment ({start}, {stop}) must satisfy 0 <= start < stop <= {n_samples} "
                "(the arrays' length)"
            )
        ranges.append((start, stop))
    ranges.sort()
    for (a_start, a_stop), (b_start, b_stop) in itertools.pairwise(ranges):
        if b_start < a_stop:
            raise ParameterError(
                f"segments ({a_start}, {a_stop}) and ({b_start}, {b_stop}) overlap; each "
                "sample may belong to one recording only"
            )
    return ranges


# --------------------------------------------------------------------------------------------
# Plot
# --------------------------------------------------------------------------------------------


def plot_residual_tests(report: ResidualReport, path: Path) -> Path:
    """Write one PNG: a panel per test, values against lag with the 95 % band shaded.

    The grey band is the per-lag 95 % band, the dashed lines the limit over all lags;
    a significant test has a red title. The last panel states N, the rate and Ljung-Box.
    Drawn on a bare :class:`matplotlib.figure.Figure` (Agg canvas), so it works headless and
    does not change the process's pyplot backend.

    Args:
        report: What :func:`residual_tests` returned.
        path: PNG file to write; its directory is created if missing.

    Returns:
        ``path``.
    """
    from matplotlib.figure import Figure

    n_panels = len(report.tests) + 1
    n_cols = 3
    n_rows = math.ceil(n_panels / n_cols)
    fig = Figure(figsize=(4.2 * n_cols, 2.8 * n_rows), layout="constrained")
    axes = fig.subplots(n_rows, n_cols, squeeze=False).ravel()
    for ax, test in zip(axes, report.tests, strict=False):
        lags = test.lags_s
        ax.axhspan(-test.band, test.band, color="0.85", lw=0)
        for sign in (-1.0, 1.0):
            ax.axhline(sign * test.limit, color="0.45", ls="--", lw=0.8)
        ax.axhline(0.0, color="0.2", lw=0.6)
        color = "tab:red" if test.significant else "tab:blue"
        ax.vlines(lags, 0.0, test.values, color=color, lw=1.0)
        ax.plot(lags, test.values, "o", color=color, ms=3)
        top = max(1.3 * test.limit, 1.1 * float(np.max(np.abs(test.values))))
        ax.set_ylim(-min(top, 1.05), min(top, 1.05))
        if lags.size == 1:
            ax.set_xlim(-1.0, 1.0)
            ax.set_xticks([0.0])
        ax.set_xlabel("lag [s]")
        title = test.label + (" (significant)" if test.significant else "")
        ax.set_title(title, fontsize=9, color="tab:red" if test.significant else "black")
    info = axes[len(report.tests)]
    info.axis("off")
    lb = report.ljung_box
    lines = [
        f"N = {report.n_samples} at {report.rate_hz:g} Hz",
        f"Ljung-Box Q = {lb.statistic:.1f} ({lb.dof} lags)",
        f"p = {lb.p_value:.3g}" + (" (not white)" if lb.significant else ""),
        textwrap.fill("significant: " + (", ".join(report.significant()) or "none"), 40),
    ]
    info.text(
        0.02,
        0.95,
        "\n".join(lines),
        va="top",
        fontsize=9,
        color="tab:red" if lb.significant else "black",
        transform=info.transAxes,
    )
    for ax in axes[n_panels:]:
        ax.axis("off")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    return path
