"""A person-readable summary of a bag: topics, types, counts, rates, duration, gaps, custom_data.

Gaps are found from the header stamps of every stream (``catheter_models.gaps``), so a bag
that a recorder without gap counting wrote, or one written elsewhere, is judged too.

A truncated or damaged bag is summarised too (from the records that can be read whole,
``bag.verify``), with what was lost and the repair command, since that is exactly when someone
runs ``catheter-lab bag info``. Its findings come first: truncation, corrupt chunks (which and
when), chunks that cannot be verified (CRC 0), messages lost against the summary's statistics
and ``metadata.yaml``, then the plausibility check's findings (``bag.plausible``), the same
``catheter-lab train``/``compare``/``tune`` would refuse or warn about.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

from mcap.records import Channel, Message, Schema
from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import ReaderError as Rosbag2ReaderError

from catheter_models.bag.messages import kilted_typestore
from catheter_models.bag.metadata import BagLayout, bag_custom_data, locate_bag
from catheter_models.bag.scan import REPAIR_COMMAND
from catheter_models.bag.verify import BagCheck, MessageSink, verify_bag
from catheter_models.errors import BagError, CatheterError
from catheter_models.gaps import StreamGaps, header_stamp_ns, pauses_between_runs
from catheter_models.units import NS_PER_S, ns_to_s

_STAMPED_STREAMS = {
    "sensor_msgs/msg/FluidPressure",
    "sensor_msgs/msg/JointState",
    "sensor_msgs/msg/Range",
}
"""Stream types whose first field is a header stamp (the contract's streams)."""


@dataclass
class _TopicStats:
    msgtype: str
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    gaps: StreamGaps | None = None

    def add(self, log_time_ns: int, data: bytes | None = None) -> None:
        if self.gaps is not None and data is not None:
            stamp_ns = header_stamp_ns(data)
            if stamp_ns is not None:
                self.gaps.add(stamp_ns)
        self.count += 1
        self.first_ns = log_time_ns if self.first_ns is None else min(self.first_ns, log_time_ns)
        self.last_ns = log_time_ns if self.last_ns is None else max(self.last_ns, log_time_ns)

    @property
    def rate_hz(self) -> float | None:
        """Mean message rate over the topic's own span [Hz]; None below two messages."""
        if self.count < 2 or self.first_ns is None or self.last_ns is None:
            return None
        span_ns = self.last_ns - self.first_ns
        return None if span_ns <= 0 else (self.count - 1) * NS_PER_S / span_ns


@dataclass(frozen=True)
class BagInspection:
    """What ``catheter-lab bag info`` prints, and whether it found a problem.

    Attributes:
        text: The summary, findings first.
        problem: True if the bag as it is loses or refuses data: truncated, corrupt, messages
            lost, ``metadata.yaml`` disagreeing, or a plausibility refusal. Chunks that cannot
            be verified and plausibility warnings are said but are not problems.
    """

    text: str
    problem: bool


def bag_info(path: Path | str) -> str:
    """Summarise a bag directory or ``.mcap`` file as text (see :func:`inspect_bag`).

    Raises:
        BagError: The path is not a bag, or an MCAP file in it is empty or not MCAP.
    """
    return inspect_bag(path).text


def inspect_bag(path: Path | str) -> BagInspection:
    """Summarise a bag: its findings, then topics, counts, rates, duration, gaps, custom_data.

    Rates are mean receive (log-time) rates per topic [Hz]; the duration is from the first to
    the last log time [s]. Counts are of the messages that can be read whole.

    Raises:
        BagError: The path is not a bag, or an MCAP file in it is empty or not MCAP.
    """
    layout = locate_bag(path)
    stats: dict[str, _TopicStats] = {}
    header: list[str] = []
    problem = False
    if layout.mcap_files:
        check = verify_bag(layout.path, on_message=_counter(stats))
        for f in check.files:
            for channel in f.channels.values():
                schema = f.schemas.get(channel.schema_id)
                stats.setdefault(
                    channel.topic, _new_stats(channel.topic, schema.name if schema else "?")
                )
        header += _integrity_lines(layout, check)
        problem = not check.intact
    else:
        _read_other(layout, stats)
    plausibility, refused = _plausibility(layout, damaged=problem)
    lines = header + _format(layout.path, stats, bag_custom_data(layout)) + plausibility
    return BagInspection("\n".join(lines), problem or refused)


def _integrity_lines(layout: BagLayout, check: BagCheck) -> list[str]:
    out: list[str] = []
    truncated = [f for f in check.files if f.truncated is not None]
    if truncated:
        out.append(
            f"TRUNCATED: {', '.join(f.path.name for f in truncated)} has no MCAP footer "
            f"(recorder killed or disk full?); {sum(f.bytes_discarded for f in truncated)} "
            "bytes at the end are incomplete. Counts below are the recoverable messages. "
            f"Repair with: {REPAIR_COMMAND} {layout.path}"
        )
    findings = [line for line in check.lines() if not line.startswith("TRUNCATED")]
    out += findings
    if check.corrupt:
        out.append(
            "Counts below are the messages that can be read whole; "
            f"{REPAIR_COMMAND} {layout.path} copies them into a new bag"
        )
    return out


def _read_other(layout: BagLayout, stats: dict[str, _TopicStats]) -> None:
    """A bag in another storage format (SQLite): read with rosbags."""
    try:
        with AnyReader([layout.reader_path()], default_typestore=kilted_typestore()) as reader:
            for conn in reader.connections:
                stats.setdefault(conn.topic, _new_stats(conn.topic, conn.msgtype))
            for conn, log_ns, raw in reader.messages():
                stats[conn.topic].add(log_ns, raw)
    except (AnyReaderError, Rosbag2ReaderError) as exc:
        msg = f"bag {layout.path} cannot be read as a rosbag2 bag: {exc}"
        raise BagError(msg) from None


def _plausibility(layout: BagLayout, *, damaged: bool) -> tuple[list[str], bool]:
    """The plausibility section, and whether it refuses the bag."""
    from catheter_models.bag.reader import load_bag

    title = "plausibility (what train, compare and tune check):"
    if damaged:
        return [f"{title} not checked: repair the bag first"], False
    try:
        report = load_bag(layout.path).plausibility
    except CatheterError as exc:
        return [f"{title} not checked: {exc}"], False
    if not report.findings:
        return [f"{title} none found"], False
    return [title] + [f"  {line}" for line in report.lines()], bool(report.refusals)


def _new_stats(topic: str, msgtype: str) -> _TopicStats:
    if msgtype not in _STAMPED_STREAMS:
        return _TopicStats(msgtype)
    return _TopicStats(msgtype, gaps=StreamGaps(pauses=pauses_between_runs(topic)))


def _counter(stats: dict[str, _TopicStats]) -> MessageSink:
    def count(channel: Channel, schema: Schema | None, message: Message) -> None:
        entry = stats.setdefault(
            channel.topic, _new_stats(channel.topic, schema.name if schema else "?")
        )
        entry.add(message.log_time, message.data)

    return count


def _format(path: Path, stats: dict[str, _TopicStats], custom: dict[str, str]) -> list[str]:
    firsts = [s.first_ns for s in stats.values() if s.first_ns is not None]
    lasts = [s.last_ns for s in stats.values() if s.last_ns is not None]
    total = sum(s.count for s in stats.values())
    lines = [f"bag:       {path}", f"messages:  {total}"]
    if firsts and lasts:
        start = datetime.fromtimestamp(ns_to_s(min(firsts)), tz=timezone.utc)
        lines.append(f"start:     {start.isoformat(timespec='milliseconds')}")
        lines.append(f"duration:  {ns_to_s(max(lasts) - min(firsts)):.3f} s")
    lines.append("topics:")
    width = max((len(t) for t in stats), default=0)
    type_width = max((len(s.msgtype) for s in stats.values()), default=0)
    for topic, s in sorted(stats.items()):
        rate = "-" if s.rate_hz is None else f"{s.rate_hz:.1f} Hz"
        lines.append(
            f"  {topic:<{width}}  {s.msgtype:<{type_width}}  {s.count:>8} msgs  {rate:>10}"
        )
    checked = {t: s.gaps for t, s in sorted(stats.items()) if s.gaps is not None}
    if checked:
        lines.append("gaps (from header stamps):")
    for topic, g in checked.items():
        said = (
            f"lost {g.lost} samples in {g.gap_count} gap(s), longest {g.longest_s * 1e3:.0f} ms"
            if g.lost
            else "none"
        )
        lines.append(f"  {topic:<{width}}  {said}")
    lines.append("custom_data:" if custom else "custom_data: (none)")
    lines += [f"  {key}: {value}" for key, value in sorted(custom.items())]
    return lines
