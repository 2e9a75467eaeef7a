"""Loading any bag that meets the interface contract into SI arrays.

``load_bag`` reads with ``rosbags`` (``AnyReader``), so it reads bags from this stack, from
``ros2 bag record`` on the rig, and from ``rosbags``' own writer alike. Messages are decoded with
the definitions embedded in the bag (the Kilted store only when a bag embeds none).

Times come from each message's ``header.stamp`` (the time the value was true), never from the
receive time, and are given in seconds since the bag's start (its earliest log time).

What a loaded bag is (``BagData``, ``StampedSeries``) and how its series are resampled onto
one time base (``BagData.aligned`` -> ``AlignedSeries``) is ``bag.series``; this module turns a
file into one: it refuses truncated and damaged bags, resolves the topics and decodes them.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
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
from catheter_models.bag.series import BagData, StampedSeries, _frozen
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
from catheter_models.units import AMBIENT_PRESSURE_PA, NS_PER_S

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
