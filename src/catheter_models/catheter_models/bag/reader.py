"""Loading any bag that meets the interface contract into SI arrays.

``load_bag`` reads with ``rosbags`` (``AnyReader``), so it reads bags from this stack, from
``ros2 bag record`` on the rig, and from ``rosbags``' own writer alike. Messages are decoded with
the definitions embedded in the bag (the Kilted store only when a bag embeds none).

Times come from each message's ``header.stamp`` (the time the value was true), never from the
receive time, and are given in seconds since the bag's start (its earliest log time).
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.interfaces import Connection
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError

from catheter_models.bag.messages import (
    distance_of,
    gauge_pressure_of,
    joint_position_of,
    kilted_typestore,
)
from catheter_models.bag.metadata import BagLayout, bag_custom_data, locate_bag
from catheter_models.bag.plausible import (
    Finding,
    ImplausibleBagError,
    PlausibilityReport,
    StreamSamples,
    check_streams,
)
from catheter_models.bag.scan import REPAIR_COMMAND, has_footer, scan_mcap, truncated_bag_error
from catheter_models.bag.verify import verify_bag
from catheter_models.contract import (
    ANGLE_DESIRED,
    DEFAULT_NAMESPACE,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    REQUIRED_BAG_TOPICS,
    TIP_ANGLE,
    TIP_DISTANCE,
    TopicSpec,
    qualify,
)
from catheter_models.errors import (
    BagError,
    CatheterError,
    MissingTopicError,
    ParameterError,
)
from catheter_models.gaps import describe_gaps, pauses_between_runs
from catheter_models.units import AMBIENT_PRESSURE_PA, NS_PER_S

FloatArray = npt.NDArray[np.float64]

SERIES_TOPICS: Final = (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE, ANGLE_DESIRED, TIP_DISTANCE)
"""The contract's stamped scalar streams that ``load_bag`` turns into series."""
_BY_NAME: Final = {spec.name: spec for spec in SERIES_TOPICS}
_UNITS: Final = {
    PRESSURE_COMMAND.name: "Pa (gauge)",
    PRESSURE_MEASURED.name: "Pa (gauge)",
    TIP_ANGLE.name: "rad",
    ANGLE_DESIRED.name: "rad",
    TIP_DISTANCE.name: "m",
}
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


# -- loading ----------------------------------------------------------------------------------


def load_bag(
    path: Path | str,
    namespace: str = DEFAULT_NAMESPACE,
    ambient_pa: float = AMBIENT_PRESSURE_PA,
    topics: Collection[str] | None = None,
    *,
    require_plausible: bool = False,
) -> BagData:
    """Load a bag that meets the interface contract, and check its data is plausible.

    Topics are found under ``namespace`` first; failing that, by their contract name as a
    suffix in any namespace (a bag recorded at the root or under another namespace), as long
    as exactly one topic matches.

    Args:
        path: A rosbag2 directory, or one ``.mcap`` file.
        namespace: Namespace the contract's relative topics were published in.
        ambient_pa: Ambient pressure [Pa absolute] to subtract from ``FluidPressure``.
        topics: Contract names to load (e.g. ``["pressure/command", "tip/angle"]``); each must
            be present. None: the required topics, plus ``tip/distance`` and
            ``angle/desired`` when present.
        require_plausible: Refuse a bag whose data fails the plausibility check
            (``bag.plausible``). What trains, compares or tunes a model asks for this
            (``models.data.recording_from_bag``); without it the findings are only reported
            in ``plausibility``, for tools that look at any bag (``bag info``, plots).

    Returns:
        The series in SI units, with the bag's ``custom_data``, counts of dropped samples and
        the plausibility findings (warnings, and refusals when accepted).

    Raises:
        TruncatedBagError: An MCAP file has no footer (killed recorder); says how to repair.
        MissingTopicError: A required (or requested) topic is absent or has no messages;
            names it (and lists the bag's topics).
        ImplausibleBagError: The data of a loaded topic fails the plausibility check
            (``bag.plausible``: values against the contract, stamps, non-finite share); names
            each finding. Only with ``require_plausible``.
        BagError: A topic is ambiguous or has the wrong type, a ``JointState`` lacks the
            ``bend`` joint, messages are unstamped, or the bag cannot be read.
        ParameterError: ``topics`` names something that is not a contract stream.
    """
    layout = locate_bag(path)
    _refuse_truncated(layout)
    integrity = _refuse_damaged(layout)
    wanted = _wanted(topics)
    must_have = _must_have(wanted, topics is None)
    try:
        with AnyReader([layout.reader_path()], default_typestore=kilted_typestore()) as reader:
            available = _available_topics(reader.connections)
            resolved = _resolve_all(layout.path, wanted, available, namespace, must_have)
            start_ns = int(reader.start_time)
            collected = _collect(reader, resolved, ambient_pa)
    except CatheterError:
        raise
    except (AnyReaderError, Rosbag2ReaderError) as exc:
        if "checksum" in str(exc).lower() or "crc" in str(exc).lower():
            msg = f"bag {layout.path} is damaged (a checksum does not match): {exc}"
        else:
            msg = f"bag {layout.path} cannot be read as a rosbag2 bag: {exc}"
        raise BagError(msg) from None
    except Exception as exc:
        # Damaged bytes inside a chunk surface from whatever decodes them (the zstd or lz4
        # decompressor, the CDR deserializer) as their own exception types.
        msg = (
            f"bag {layout.path} is damaged: reading it failed with {type(exc).__name__}: {exc}. "
            "Its footer is intact, so this is not a cut-off recording (`catheter-lab bag "
            "repair` does not apply); record it again or restore it from a copy"
        )
        raise BagError(msg) from exc

    empty = [acc.topic for acc in collected.values() if acc.name in must_have and not acc.values]
    if empty:
        msg = (
            f"bag {layout.path} has required topic(s) {', '.join(empty)} but no messages on "
            "them; a bag holds data on every required topic"
        )
        raise MissingTopicError(msg)
    for acc in collected.values():
        acc.refuse_unstamped()
    # Checked before anything is dropped or sorted, so nothing the loader tidies goes unsaid.
    report = check_streams([acc.samples() for acc in collected.values()], start_ns, ambient_pa)
    report = PlausibilityReport(integrity + report.findings)
    if report.refusals and require_plausible:
        raise ImplausibleBagError(layout.path, report)
    series: dict[str, StampedSeries] = {}
    dropped: dict[str, int] = {}
    out_of_range: dict[str, int] = {}
    for name, acc in collected.items():
        series[name], dropped[name], out_of_range[name] = acc.finish(start_ns)
    return BagData(
        path=layout.path,
        start_time_ns=start_ns,
        series=MappingProxyType(series),
        custom_data=MappingProxyType(bag_custom_data(layout)),
        dropped=MappingProxyType(dropped),
        out_of_range=MappingProxyType(out_of_range),
        ambient_pa=float(ambient_pa),
        plausibility=report,
    )


def _refuse_truncated(layout: BagLayout) -> None:
    incomplete = [f for f in layout.mcap_files if not has_footer(f)]
    if incomplete:
        raise truncated_bag_error(layout.path, [scan_mcap(f) for f in layout.mcap_files])


def _refuse_damaged(layout: BagLayout) -> tuple[Finding, ...]:
    """Refuse a bag whose MCAP data is damaged; what it cannot verify or that disagrees.

    A chunk that fails its CRC, does not decompress, is not framed or does not match its
    index is damage: refused (an index-based reader may skip such a chunk without a word).
    Chunks without a CRC (unverifiable) and a ``metadata.yaml`` that counts other messages
    than the data holds become findings (a warning; a refusal), named like the plausibility
    check's.
    """
    if not layout.mcap_files:
        return ()
    check = verify_bag(layout.path)
    if check.corrupt or any(f.lost_by_topic() for f in check.files):
        msg = (
            f"bag {layout.path} is damaged: {'; '.join(check.lines())}. Its footer is intact, "
            f"so this is not a cut-off recording; `{REPAIR_COMMAND} {layout.path}` copies the "
            "readable messages into a new bag and counts what is lost, or restore it from a copy"
        )
        raise BagError(msg)
    findings: list[Finding] = []
    for f in check.files:
        chunks = f.unverifiable_chunks
        if chunks:
            findings.append(
                Finding(
                    topic=f.path.name,
                    check="unverified chunks",
                    severity="warn",
                    count=len(chunks),
                    total=len(f.chunks),
                    first_s=None,
                    unit="chunks",
                    detail="chunks carry no CRC (0), so their bytes cannot be verified (size, "
                    "framing, time spans and counts hold); a flipped bit may pass unseen",
                )
            )
    disagree = check.metadata_disagrees()
    if disagree:
        findings.append(
            Finding(
                topic="metadata.yaml",
                check="message counts",
                severity="refuse",
                count=len(disagree),
                total=len(check.recovered_by_topic()),
                first_s=None,
                unit="topics",
                detail="metadata.yaml does not count what the data holds: " + "; ".join(disagree),
            )
        )
    return tuple(findings)


def _wanted(topics: Collection[str] | None) -> list[TopicSpec]:
    if topics is None:
        return list(SERIES_TOPICS)
    if isinstance(topics, str):
        topics = [topics]
    unknown = [t for t in topics if t not in _BY_NAME]
    if unknown:
        msg = f"cannot load {unknown}: load_bag reads the contract streams {sorted(_BY_NAME)}"
        raise ParameterError(msg)
    return [_BY_NAME[t] for t in topics]


def _available_topics(connections: list[Connection]) -> dict[str, set[str]]:
    available: dict[str, set[str]] = {}
    for conn in connections:
        available.setdefault(conn.topic, set()).add(conn.msgtype)
    return available


def _describe(available: Mapping[str, set[str]]) -> str:
    return ", ".join(f"{t} ({'/'.join(sorted(ty))})" for t, ty in sorted(available.items()))


def _resolve(
    bag: Path, spec: TopicSpec, available: Mapping[str, set[str]], namespace: str
) -> str | None:
    """The bag's topic for ``spec``: under ``namespace``, else the one topic ending in it."""
    exact = qualify(spec, namespace)
    if exact in available:
        return exact
    suffix = "/" + spec.name.lstrip("/")
    matches = sorted(t for t in available if t == suffix or t.endswith(suffix))
    if len(matches) > 1:
        msg = (
            f"bag {bag}: {spec.name!r} is ambiguous: {' and '.join(matches)} both match and "
            f"neither is {exact}; pass namespace= to choose"
        )
        raise BagError(msg)
    return matches[0] if matches else None


def _must_have(wanted: list[TopicSpec], defaults: bool) -> frozenset[str]:
    """The contract's required topics by default; everything asked for when named."""
    if defaults:
        return frozenset(s.name for s in REQUIRED_BAG_TOPICS)
    return frozenset(s.name for s in wanted)


def _resolve_all(
    bag: Path,
    wanted: list[TopicSpec],
    available: Mapping[str, set[str]],
    namespace: str,
    must_have: frozenset[str],
) -> dict[str, str]:
    resolved: dict[str, str] = {}
    missing: list[str] = []
    for spec in wanted:
        topic = _resolve(bag, spec, available, namespace)
        if topic is None:
            if spec.name in must_have:
                missing.append(qualify(spec, namespace))
            continue
        found = available[topic]
        if found != {spec.msgtype}:
            msg = (
                f"bag {bag}: topic {topic} has type {' and '.join(sorted(found))}; "
                f"the contract expects {spec.msgtype}"
            )
            raise BagError(msg)
        resolved[spec.name] = topic
    if missing:
        msg = (
            f"bag {bag} lacks required topic(s) {', '.join(missing)} (searched the namespace "
            f"{namespace!r}, then any namespace). The bag has: {_describe(available) or 'none'}"
        )
        raise MissingTopicError(msg)
    return resolved


class _Accumulator:
    """Collects one topic's decoded samples, then makes a sorted, frozen series."""

    def __init__(self, name: str, topic: str, msgtype: str) -> None:
        self.name = name
        self.topic = topic
        self.msgtype = msgtype
        self.stamps_ns: list[int] = []
        self.log_ns: list[int] = []
        self.values: list[float] = []
        self.in_range: list[bool] = []
        self.unstamped = 0

    def add(self, log_ns: int, stamp_ns: int, value: float, in_range: bool = True) -> None:
        if stamp_ns == 0:
            self.unstamped += 1
        self.log_ns.append(log_ns)
        self.stamps_ns.append(stamp_ns)
        self.values.append(value)
        self.in_range.append(in_range)

    def samples(self) -> StreamSamples:
        """The samples as the file holds them, for the plausibility check."""
        return StreamSamples(
            name=self.name,
            topic=self.topic,
            stamps_ns=np.asarray(self.stamps_ns, dtype=np.int64),
            log_ns=np.asarray(self.log_ns, dtype=np.int64),
            values=np.asarray(self.values, dtype=np.float64),
        )

    def refuse_unstamped(self) -> None:
        if self.unstamped:
            msg = (
                f"{self.unstamped} of {len(self.stamps_ns)} messages on {self.topic} have "
                "header.stamp = 0 (unstamped); the contract requires the time the value was "
                "true, so they cannot be aligned"
            )
            raise BagError(msg)

    def finish(self, start_ns: int) -> tuple[StampedSeries, int, int]:
        self.refuse_unstamped()
        stamps = np.asarray(self.stamps_ns, dtype=np.int64)
        values = np.asarray(self.values, dtype=np.float64)
        finite = np.isfinite(values)
        in_range = np.asarray(self.in_range, dtype=bool)
        keep = finite & in_range
        # Stable sort: header stamps may arrive out of order (several publishers, network).
        order = np.argsort(stamps[keep], kind="stable")
        t_s = (stamps[keep][order] - start_ns).astype(np.float64) / NS_PER_S
        series = StampedSeries(
            name=self.name,
            topic=self.topic,
            msgtype=self.msgtype,
            t_s=_frozen(t_s),
            values=_frozen(values[keep][order]),
            unit=_UNITS[self.name],
            message_count=len(self.stamps_ns),
            arrival_age_s=_arrival_age_s(
                np.asarray(self.log_ns, dtype=np.int64)[keep], stamps[keep]
            ),
        )
        return series, int(np.count_nonzero(~finite)), int(np.count_nonzero(finite & ~in_range))


def _arrival_age_s(log_ns: npt.NDArray[np.int64], stamps_ns: npt.NDArray[np.int64]) -> float:
    """Median (log time - stamp) [s], at least 0 (see ``StampedSeries.arrival_age_s``)."""
    if log_ns.size == 0:
        return 0.0
    return max(0.0, float(np.median(log_ns - stamps_ns)) / NS_PER_S)


def _decode(name: str, msg: Any, topic: str, ambient_pa: float) -> tuple[int, float, bool]:
    """(header stamp [ns], SI value, in valid range) of one decoded message."""
    if name in (PRESSURE_COMMAND.name, PRESSURE_MEASURED.name):
        stamp_ns, value = gauge_pressure_of(msg, ambient_pa)
        return stamp_ns, value, True
    if name in (TIP_ANGLE.name, ANGLE_DESIRED.name):
        stamp_ns, value = joint_position_of(msg, topic=topic)
        return stamp_ns, value, True
    stamp_ns, value, in_range = distance_of(msg)
    return stamp_ns, value, in_range


def _collect(
    reader: AnyReader, resolved: Mapping[str, str], ambient_pa: float
) -> dict[str, _Accumulator]:
    by_topic = {topic: name for name, topic in resolved.items()}
    accs = {
        name: _Accumulator(name, topic, _BY_NAME[name].msgtype) for name, topic in resolved.items()
    }
    connections = [c for c in reader.connections if c.topic in by_topic]
    # An empty connection list would mean "all topics" to rosbags.
    if not connections:
        return accs
    for conn, log_ns, raw in reader.messages(connections=connections):
        name = by_topic[conn.topic]
        msg = reader.deserialize(raw, conn.msgtype)
        accs[name].add(int(log_ns), *_decode(name, msg, conn.topic, ambient_pa))
    return accs
