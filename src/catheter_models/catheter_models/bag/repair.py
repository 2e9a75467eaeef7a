"""Recovering a bag: every message that can be read whole, into a new bag, and what was lost.

The original is never modified. The new bag keeps the original's message bytes, log and publish
times, message definitions, QoS and ``custom_data``, and says in ``custom_data`` where it came
from and what was lost.

It reads with ``verify`` (past damage, chunk by chunk), so it tells a truncated bag (a killed
recorder, a full disk: the file stops) from a corrupt one (a chunk that fails its CRC, does not
decompress or is not framed; the chunk's messages are lost and the rest recovered), says how
many messages were lost on which topic and from when, and says when chunks could not be
verified (CRC 0). A bag is called whole only when nothing was lost and every chunk verified.
A file with nothing to recover (0 bytes, no MCAP magic or header, no complete message) is
refused, and no bag is written.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from mcap.records import Channel, Message, Schema
from mcap.well_known import MessageEncoding

from catheter_models.bag.metadata import BagLayout, custom_data_of, locate_bag
from catheter_models.bag.verify import BagCheck, verify_bag
from catheter_models.bag.writer import BagRecorder, SchemaText
from catheter_models.errors import BagError


@dataclass(frozen=True, eq=False)
class RepairReport:
    """What ``repair_bag`` recovered.

    Attributes:
        source: The bag that was read (unchanged).
        output: The new, complete bag directory.
        was_complete: True only if the source was whole: every file had its footer, no
            record or chunk was damaged, no message was lost, metadata.yaml agreed.
        messages_per_topic: Recovered messages by topic.
        bytes_discarded: Bytes of incomplete records dropped from the ends of the files.
        stop_reasons: Every finding (truncation, corruption, unverified chunks, lost messages,
            metadata.yaml disagreeing), for a person.
        truncated: A file stopped with no footer.
        corrupt: A record or chunk was damaged (its messages are lost).
        lost_per_topic: Messages lost by topic.
        unverified_chunks: Chunks copied that carry no CRC, so could not be verified.
    """

    source: Path
    output: Path
    was_complete: bool
    messages_per_topic: Mapping[str, int]
    bytes_discarded: int
    stop_reasons: tuple[str, ...]
    truncated: bool = False
    corrupt: bool = False
    lost_per_topic: Mapping[str, int] = field(default_factory=lambda: MappingProxyType({}))
    unverified_chunks: int = 0

    @property
    def message_count(self) -> int:
        """Recovered messages, over all topics."""
        return sum(self.messages_per_topic.values())

    @property
    def lost_messages(self) -> int:
        """Messages lost, over all topics."""
        return sum(self.lost_per_topic.values())

    def describe(self) -> str:
        """A few lines for a person at the rig: what it was, what was recovered and lost."""
        states = [
            word for word, on in (("truncated", self.truncated), ("corrupt", self.corrupt)) if on
        ]
        if self.was_complete and not self.unverified_chunks:
            state = "was whole (every chunk verified, nothing lost)"
        elif self.was_complete:
            state = (
                f"lost nothing that can be checked, but {self.unverified_chunks} chunk(s) carry "
                "no CRC and could not be verified"
            )
        else:
            state = "was " + (" and ".join(states) or "incomplete")
            state += f": {self.lost_messages} messages lost" if self.lost_messages else ""
        lines = [
            f"{self.source} {state}; wrote {self.output}",
            f"recovered {self.message_count} messages, discarded {self.bytes_discarded} bytes",
        ]
        lines += [f"  {topic}: {count}" for topic, count in sorted(self.messages_per_topic.items())]
        lines += [f"  {reason}" for reason in self.stop_reasons]
        return "\n".join(lines)


def default_repair_output(path: Path) -> Path:
    """``<bag>_repaired`` beside a bag directory, ``<stem>_repaired`` beside a lone file."""
    if path.is_file():
        return path.with_name(f"{path.stem}_repaired")
    return path.with_name(f"{path.name}_repaired")


def repair_bag(path: Path | str, output: Path | str | None = None) -> RepairReport:
    """Copy every complete message of a (possibly truncated) MCAP bag into a new, complete bag.

    Args:
        path: The bag directory or ``.mcap`` file to recover. It is only read.
        output: New bag directory; must not exist. Default: ``<path>_repaired``.

    Returns:
        Counts per topic, bytes discarded, and every finding (``was_complete`` only if whole).

    Raises:
        BagError: ``output`` exists; the bag is not MCAP; a file is empty, lacks the MCAP
            magic or a complete header, or no complete message can be read (nothing to
            recover: no bag is written); or a channel is not ROS 2 CDR with a schema (nothing
            this stack could write back faithfully).
    """
    layout = locate_bag(path)
    not_mcap = [f for f in layout.storage_files if f.suffix != ".mcap"]
    if not_mcap:
        msg = f"cannot repair {layout.path}: {[str(f) for f in not_mcap]} are not MCAP files"
        raise BagError(msg)
    target = Path(output) if output is not None else default_repair_output(layout.path)
    if target.exists():
        msg = f"repair output {target} already exists; choose a new directory (-o)"
        raise BagError(msg)
    # A first pass without writing: a file with nothing to recover is refused before any
    # "repaired" bag exists.
    _refuse_nothing_to_recover(layout, _check(layout))
    recorder = BagRecorder(target, custom_data=custom_data_of(layout.metadata), flush_period_s=None)
    try:
        check = _copy_all(recorder, layout)
        recovered = sum(check.recovered_by_topic().values())
        discarded = sum(f.bytes_discarded for f in check.files)
        lost = check.lost_by_topic()
        recorder.set_custom_data("repaired_from", str(layout.path))
        recorder.set_custom_data("repair_recovered_messages", str(recovered))
        recorder.set_custom_data("repair_discarded_bytes", str(discarded))
        recorder.set_custom_data("repair_lost_messages", str(sum(lost.values())))
        findings = check.lines()
        if findings:
            recorder.set_custom_data("repair_findings", " | ".join(findings))
        outcome = recorder.close()
        if not outcome.finished:
            msg = f"the repaired bag {target} could not be finished: {outcome.note}"
            raise BagError(msg)
    except BaseException:
        recorder.close()
        # A half-written "repaired" bag would pass for a good one; the directory is ours
        # (BagRecorder created it exclusively), so remove it.
        shutil.rmtree(target, ignore_errors=True)
        raise
    return RepairReport(
        source=layout.path,
        output=target,
        was_complete=check.intact,
        messages_per_topic=MappingProxyType(check.recovered_by_topic()),
        bytes_discarded=discarded,
        stop_reasons=tuple(findings),
        truncated=check.truncated,
        corrupt=check.corrupt,
        lost_per_topic=MappingProxyType(lost),
        unverified_chunks=check.unverified_chunks,
    )


def _check(layout: BagLayout) -> BagCheck:
    return verify_bag(layout.path)


def _refuse_nothing_to_recover(layout: BagLayout, check: BagCheck) -> None:
    headless = [f.path.name for f in check.files if not f.has_header]
    if headless:
        msg = (
            f"cannot repair {layout.path}: {', '.join(headless)} ends before its MCAP header "
            "is complete; nothing to recover (no bag written)"
        )
        raise BagError(msg)
    if not sum(check.recovered_by_topic().values()):
        said = "; ".join(check.lines()) or "the files hold no message"
        msg = (
            f"cannot repair {layout.path}: not one complete message can be read ({said}); "
            "nothing to recover (no bag written)"
        )
        raise BagError(msg)


def _copy_all(recorder: BagRecorder, layout: BagLayout) -> BagCheck:
    copier = _Copier(recorder, layout)
    check = verify_bag(layout.path, on_message=copier.copy)
    for f in check.files:
        # Topics whose messages were all lost still belong in the repaired bag's listing.
        for channel in f.channels.values():
            copier.ensure_topic(channel, f.schemas.get(channel.schema_id))
    return check


class _Copier:
    """Registers each source channel once in the new bag and copies messages verbatim."""

    def __init__(self, recorder: BagRecorder, layout: BagLayout) -> None:
        self._recorder = recorder
        self._added: set[str] = set()
        self._hashes = _type_hashes(layout)

    def ensure_topic(self, channel: Channel, schema: Schema | None) -> None:
        if channel.topic in self._added:
            return
        if channel.message_encoding != MessageEncoding.CDR:
            msg = (
                f"channel {channel.topic} is encoded as {channel.message_encoding!r}; "
                "a rosbag2 bag needs 'cdr'"
            )
            raise BagError(msg)
        if schema is None:
            msg = (
                f"channel {channel.topic} has no schema (id {channel.schema_id} is undefined); "
                "its messages cannot be decoded, so the bag cannot be repaired faithfully"
            )
            raise BagError(msg)
        digest = channel.metadata.get("topic_type_hash") or self._hashes.get(channel.topic, "")
        self._recorder.add_topic(
            channel.topic,
            schema.name,
            offered_qos=channel.metadata.get("offered_qos_profiles", ""),
            schema=SchemaText(schema.encoding, schema.data.decode("utf-8")),
            type_description_hash=digest,
        )
        self._added.add(channel.topic)

    def copy(self, channel: Channel, schema: Schema | None, message: Message) -> None:
        self.ensure_topic(channel, schema)
        self._recorder.write(channel.topic, message.data, message.log_time, message.publish_time)


def _type_hashes(layout: BagLayout) -> dict[str, str]:
    """Type hashes by topic from the original ``metadata.yaml`` (older MCAPs lack them)."""
    hashes: dict[str, str] = {}
    if layout.metadata is None:
        return hashes
    for entry in layout.metadata.get("topics_with_message_count") or []:
        meta = entry.get("topic_metadata", {}) if isinstance(entry, dict) else {}
        name, digest = meta.get("name"), meta.get("type_description_hash")
        if isinstance(name, str) and isinstance(digest, str):
            hashes[name] = digest
    return hashes
