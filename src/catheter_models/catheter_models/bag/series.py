"""A loaded bag's series, and their resampling onto one time base.

``StampedSeries`` (one topic's values against their header stamps), ``BagData`` (a bag's
series with its counts and findings) and ``AlignedSeries`` (what ``BagData.aligned`` resamples
them to: set-points held, measurements interpolated, on a grid laid through the command
stamps). Apart from ``bag.reader``, which turns a file into a ``BagData``: this is what the
analysis works with, and it knows time bases, not files (no ``rosbags``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from catheter_models.bag.plausible import PlausibilityReport
from catheter_models.contract import (
    ANGLE_DESIRED,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
)
from catheter_models.errors import BagError, ParameterError
from catheter_models.gaps import describe_gaps, pauses_between_runs
from catheter_models.units import NS_PER_S

FloatArray = npt.NDArray[np.float64]
_HELD: Final = frozenset({PRESSURE_COMMAND.name, ANGLE_DESIRED.name})
"""Set-points: each holds until the next, so they are resampled by zero-order hold."""
HOLD_TOLERANCE: Final = 0.25
"""A time point this share of a period (the smaller of the time base's and the set-point
stream's own) or less before a set-point's stamp already takes that set-point. Without it, a
grid point that falls on a stamp took the previous value whenever float rounding put it a
femtosecond early, so a command sampled at the grid rate had samples repeated and dropped; a
quarter period also absorbs a controller's jitter and still never applies a value more than a
quarter period before its stamp."""


def _frozen(values: npt.ArrayLike) -> FloatArray:
    """A read-only float64 copy: series are shared, so nobody may edit them in place."""
    arr = np.array(values, dtype=np.float64)
    arr.flags.writeable = False
    return arr


@dataclass(frozen=True, eq=False)
class StampedSeries:
    """One topic's values against their header stamps.

    Attributes:
        name: The contract name, e.g. ``"pressure/command"``.
        topic: The full topic name in the bag.
        msgtype: Its ROS type.
        t_s: Header stamps [s] since the bag start, sorted (read-only).
        values: Values in SI (read-only); ``unit`` says which.
        unit: ``"Pa (gauge)"``, ``"rad"`` or ``"m"``.
        message_count: Messages on the topic, including the dropped ones.
        arrival_age_s: Median of log time minus header stamp [s], at least 0: how old a
            sample was when the recorder had it. A driver that stamps the time the value was
            true (a laser's sample, back-dated past its transport) shows its latency here,
            which the stamps alone hide; a controller on the same host gets the sample as
            late. 0 when the clocks differ (stamps after arrival).
    """

    name: str
    topic: str
    msgtype: str
    t_s: FloatArray
    values: FloatArray
    unit: str
    message_count: int
    arrival_age_s: float = 0.0

    def __len__(self) -> int:
        """Number of kept samples."""
        return int(self.t_s.size)


@dataclass(frozen=True, eq=False)
class AlignedSeries:
    """Signals resampled onto one time base.

    Attributes:
        t_s: Common time base [s] since the bag start.
        pressure_command_pa: Valve set-point [Pa gauge], zero-order hold.
        pressure_measured_pa: Line pressure [Pa gauge], linear interpolation.
        angle_rad: Bending angle [rad], linear interpolation.
        angle_desired_rad: Set-point angle [rad], zero-order hold; None if not in the bag.
        distance_m: Laser distance [m], linear interpolation; None if not in the bag.
    """

    t_s: FloatArray
    pressure_command_pa: FloatArray
    pressure_measured_pa: FloatArray
    angle_rad: FloatArray
    angle_desired_rad: FloatArray | None
    distance_m: FloatArray | None

    def __len__(self) -> int:
        """Number of samples."""
        return int(self.t_s.size)


@dataclass(frozen=True, eq=False)
class BagData:
    """A bag's science content, in SI units.

    Attributes:
        path: What was loaded (directory or ``.mcap`` file).
        start_time_ns: The bag start [ns since the Unix epoch]; every ``t_s`` counts from here.
        series: Loaded series by contract name (``"pressure/command"``, ``"tip/angle"``, ...).
        custom_data: The experiment description from ``metadata.yaml``.
        dropped: Samples left out because the value was NaN or infinite, by contract name.
        out_of_range: ``Range`` readings left out because they lie outside the message's own
            [min_range, max_range] (the message definition says to discard them), by name.
        ambient_pa: Ambient pressure [Pa absolute] subtracted to get gauge pressure.
        plausibility: What the plausibility check found (``bag.plausible``), warnings and
            refusals alike (``load_bag(require_plausible=True)`` raises on a refusal instead).
    """

    path: Path
    start_time_ns: int
    series: Mapping[str, StampedSeries]
    custom_data: Mapping[str, str]
    dropped: Mapping[str, int]
    out_of_range: Mapping[str, int]
    ambient_pa: float
    plausibility: PlausibilityReport = field(default_factory=PlausibilityReport)

    @property
    def pressure_command(self) -> StampedSeries:
        """``pressure/command`` [Pa gauge]."""
        return self._get(PRESSURE_COMMAND.name)

    @property
    def pressure_measured(self) -> StampedSeries:
        """``pressure/measured`` [Pa gauge]."""
        return self._get(PRESSURE_MEASURED.name)

    @property
    def tip_angle(self) -> StampedSeries:
        """``tip/angle`` [rad]."""
        return self._get(TIP_ANGLE.name)

    @property
    def angle_desired(self) -> StampedSeries | None:
        """``angle/desired`` [rad], or None if the bag has no such topic."""
        return self.series.get(ANGLE_DESIRED.name)

    @property
    def tip_distance(self) -> StampedSeries | None:
        """``tip/distance`` [m], or None if the bag has no such topic."""
        return self.series.get(TIP_DISTANCE.name)

    def gap_report(self) -> list[str]:
        """One line per loaded stream that lacks samples, by its stamps (empty: none does).

        Command streams stop between runs; only silences shorter than ``gaps.PAUSE_S`` in them
        count (see :mod:`catheter_models.gaps`).
        """
        lines = []
        for name, series in self.series.items():
            line = describe_gaps(name, series.t_s, pauses=pauses_between_runs(name))
            if line is not None:
                lines.append(line)
        return lines

    def _get(self, name: str) -> StampedSeries:
        try:
            return self.series[name]
        except KeyError:
            msg = f"{name} was not loaded from {self.path}; loaded: {sorted(self.series)}"
            raise BagError(msg) from None

    def aligned(
        self, rate_hz: float | None = None, reference: str = TIP_ANGLE.name
    ) -> AlignedSeries:
        """Resample the series onto one time base built from header stamps.

        Set-points (``pressure/command``, ``angle/desired``) are held from one stamp to the
        next (zero-order hold), as a valve or controller holds them: a value stamped at ``s``
        applies from ``s``, and a time point at most :data:`HOLD_TOLERANCE` of a period before
        ``s`` (the smaller of the time base's period and the stream's own median interval)
        already takes it. Measurements are interpolated linearly. The time base covers only
        the span every included series covers, so nothing is extrapolated (a set-point's span
        starts that tolerance before its first stamp). Optional series (``angle/desired``,
        ``tip/distance``) are included when loaded and non-empty, and then bound that span
        too; load without them (``topics=``) to drop them.

        A uniform grid (``rate_hz``) is laid on the phase of the ``pressure/command`` stamps
        (their median offset modulo the command's own period), so its points fall on the
        commands' stamps: a command stream at the grid rate maps one sample to one grid point,
        none repeated or dropped, whether its stamps are exact, jitter by less than the
        tolerance, or have lost samples between them; at another rate every grid point takes
        the latest command, and a command at a whole multiple or fraction of the grid rate
        keeps a regular pattern (each held the same number of points, or every k-th taken).

        Gaps (see :meth:`gap_report`): over lost samples or a pause a set-point holds its last
        value until the next stamp, as the valve did, and a measurement is interpolated
        linearly between the samples either side; the grid is not cut.

        Args:
            rate_hz: None: use the stamps of ``reference``. Otherwise a uniform grid at this
                rate [Hz], on the command's phase, from the first such point in the span.
            reference: Contract name of the series whose stamps are the time base.

        Raises:
            BagError: A required series is missing or empty, ``reference`` was not loaded, or
                the series share no common time span.
            ParameterError: ``rate_hz`` is not a positive finite rate.
        """
        command = self._nonempty(PRESSURE_COMMAND.name)
        measured = self._nonempty(PRESSURE_MEASURED.name)
        angle = self._nonempty(TIP_ANGLE.name)
        desired = self._usable(ANGLE_DESIRED.name)
        distance = self._usable(TIP_DISTANCE.name)
        if reference not in self.series:
            msg = f"reference {reference!r} was not loaded; choose one of {sorted(self.series)}"
            raise BagError(msg)
        used = [s for s in (command, measured, angle, desired, distance) if s is not None]
        if rate_hz is not None and not (math.isfinite(rate_hz) and rate_hz > 0.0):
            msg = f"rate_hz is {rate_hz}; expected a positive finite rate [Hz] or None"
            raise ParameterError(msg)
        # Integer nanoseconds (as the stamps were recorded): a grid point on a stamp compares
        # equal to it, exactly, instead of by float rounding.
        stamps_ns = {s.name: _to_ns(s.t_s) for s in used}
        if rate_hz is None:
            ref_ns = _to_ns(self._nonempty(reference).t_s)
            base_period_ns = _median_period_ns(ref_ns)
        else:
            base_period_ns = NS_PER_S / rate_hz
        tolerance_ns = {
            s.name: _hold_tolerance_ns(stamps_ns[s.name], base_period_ns)
            for s in used
            if s.name in _HELD
        }
        start_ns = max(float(stamps_ns[s.name][0]) - tolerance_ns.get(s.name, 0.0) for s in used)
        end_ns = min(float(stamps_ns[s.name][-1]) for s in used)
        if end_ns < start_ns:
            spans = ", ".join(f"{s.topic} [{s.t_s[0]:.3f}, {s.t_s[-1]:.3f}] s" for s in used)
            msg = f"the series of {self.path} share no common time span: {spans}"
            raise BagError(msg)
        if rate_hz is None:
            grid_ns = ref_ns[(ref_ns >= start_ns) & (ref_ns <= end_ns)]
        else:
            grid_ns = _grid_ns(stamps_ns[command.name], start_ns, end_ns, base_period_ns)
        t_s = grid_ns / NS_PER_S

        def resample(series: StampedSeries) -> FloatArray:
            if series.name in _HELD:
                return _hold(series, stamps_ns[series.name], grid_ns, tolerance_ns[series.name])
            return np.asarray(np.interp(t_s, series.t_s, series.values), dtype=np.float64)

        return AlignedSeries(
            t_s=_frozen(t_s),
            pressure_command_pa=_frozen(resample(command)),
            pressure_measured_pa=_frozen(resample(measured)),
            angle_rad=_frozen(resample(angle)),
            angle_desired_rad=None if desired is None else _frozen(resample(desired)),
            distance_m=None if distance is None else _frozen(resample(distance)),
        )

    def _nonempty(self, name: str) -> StampedSeries:
        series = self._get(name)
        if len(series) == 0:
            msg = (
                f"{series.topic} has no usable samples in {self.path} "
                f"({series.message_count} messages, {self.dropped.get(name, 0)} non-finite, "
                f"{self.out_of_range.get(name, 0)} out of range)"
            )
            raise BagError(msg)
        return series

    def _usable(self, name: str) -> StampedSeries | None:
        """An optional series if loaded and not empty (its drop counts say why if empty)."""
        series = self.series.get(name)
        return series if series is not None and len(series) > 0 else None


def _to_ns(t_s: FloatArray) -> FloatArray:
    """Stamps [s since the bag start] back to whole nanoseconds (as float64, exact to 2**53)."""
    return np.round(np.asarray(t_s, dtype=np.float64) * NS_PER_S)


def _median_period_ns(stamps_ns: FloatArray) -> float:
    """A stream's period [ns]: its median interval between distinct stamps (NaN if none)."""
    dt = np.diff(stamps_ns)
    dt = dt[dt > 0.0]
    return float(np.median(dt)) if dt.size else math.nan


def _hold_tolerance_ns(stamps_ns: FloatArray, base_period_ns: float) -> float:
    """:data:`HOLD_TOLERANCE` of the smaller of the time base's and the stream's period."""
    periods = [p for p in (base_period_ns, _median_period_ns(stamps_ns)) if math.isfinite(p)]
    return HOLD_TOLERANCE * min(periods) if periods else 0.0


def _grid_ns(
    command_ns: FloatArray, start_ns: float, end_ns: float, period_ns: float
) -> FloatArray:
    """A uniform grid over [start, end] [ns] through the command stamps' typical phase.

    The phase is the median offset of the command stamps in the span from the first of them,
    modulo the grid's period (or, for commands faster than the grid, the whole fraction of it
    nearest their own period) and wrapped to within half of that, so jitter either side of
    the nominal instants and lost samples do not move it. The modulus is the grid's exact
    period, not the commands' median interval: over thousands of samples the median's own
    error would add up to a phase that means nothing. A grid through the phase lies on the
    commands' nominal stamps, where :data:`HOLD_TOLERANCE` maps each to one point.
    """
    inside = command_ns[(command_ns >= start_ns) & (command_ns <= end_ns)]
    command_period_ns = _median_period_ns(inside)
    if inside.size < 2 or not math.isfinite(command_period_ns):
        anchor_ns = start_ns
    else:
        modulus_ns = period_ns / max(1, round(period_ns / command_period_ns))
        offsets = inside - inside[0]
        wrapped = (offsets + modulus_ns / 2.0) % modulus_ns - modulus_ns / 2.0
        anchor_ns = float(inside[0] + np.round(np.median(wrapped)))
    # The first grid point at or after the span's start; the small margins keep a point that
    # lies on the start or the end when the period is not a whole number of nanoseconds.
    first = math.ceil((start_ns - anchor_ns) / period_ns - 1e-9)
    t0_ns = anchor_ns + first * period_ns
    n = math.floor((end_ns - t0_ns) / period_ns + 1e-9) + 1
    return t0_ns + np.arange(max(n, 0), dtype=np.float64) * period_ns


def _hold(
    series: StampedSeries, stamps_ns: FloatArray, grid_ns: FloatArray, tolerance_ns: float
) -> FloatArray:
    """Zero-order hold: the last value stamped at or before each time plus the tolerance."""
    index = np.searchsorted(stamps_ns, grid_ns + tolerance_ns, side="right") - 1
    return np.asarray(series.values[np.clip(index, 0, None)], dtype=np.float64)
