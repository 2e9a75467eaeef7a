"""Recovering a bag whose recorder was killed: every complete message, into a new bag.

The original is never modified. The new bag keeps the original's message bytes, log and publish
times, message definitions, QoS and ``custom_data``, and says in ``custom_data`` where it came
from and what was lost.
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType

from mcap.records import Channel, Message, Schema
from mcap.well_known import MessageEncoding

from catheter_models.bag.metadata import BagLayout, custom_data_of, locate_bag
from catheter_models.bag.scan import McapScan, scan_mcap
from catheter_models.bag.writer import BagRecorder, SchemaText
from catheter_models.errors import BagError


@dataclass(frozen=True, eq=False)
class RepairReport:
    """What ``repair_bag`` recovered.

    Attributes:
        source: The bag that was read (unchanged).
        output: The new, complete bag directory.
        was_complete: True if every source file already had its footer (nothing was lost).
        messages_per_topic: Recovered messages by topic.
        bytes_discarded: Bytes of incomplete records dropped from the ends of the files.
        stop_reasons: Why each incomplete file's scan stopped, for a person.
    """

    source: Path
    output: Path
    was_complete: bool
    messages_per_topic: Mapping[str, int]
    bytes_discarded: int
    stop_reasons: tuple[str, ...]

    @property
    def message_count(self) -> int:
        """Recovered messages, over all topics."""
        return sum(self.messages_per_topic.values())

    def describe(self) -> str:
        """A few lines for a person at the rig."""
        state = "was already complete" if self.was_complete else "was truncated"
        lines = [
            f"{self.source} {state}; wrote {self.output}",
            f"recovered {self.message_count} messages, discarded {self.bytes_discarded} bytes",
        ]
        lines += [f"  {topic}: {count}" for topic, count in sorted(self.messages_per_topic.items())]
        lines += [f"  stopped: {reason}" for reason in self.stop_reasons]
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
        Counts per topic and bytes discarded.

    Raises:
        BagError: ``output`` exists, the bag is not MCAP, or a channel is not ROS 2 CDR with a
            schema (nothing this stack could write back faithfully).
    """
    layout = locate_bag(path)
    not_mcap = [f for f in layout.storage_files if f.suffix != ".mcap"]
    if not_mcap:
        msg = f"cannot repair {layout.path}: {[str(f) for f in not_mcap]} are not MCAP files"
        raise BagError(msg)
    target = Path(output) if output is not None else default_repair_output(layout.path)
    recorder = BagRecorder(target, custom_data=custom_data_of(layout.metadata), flush_period_s=None)
    try:
        scans = _copy_all(recorder, layout)
        recovered = sum(s.message_count for s in scans)
        discarded = sum(s.bytes_discarded for s in scans)
        recorder.set_custom_data("repaired_from", str(layout.path))
        recorder.set_custom_data("repair_recovered_messages", str(recovered))
        recorder.set_custom_data("repair_discarded_bytes", str(discarded))
        recorder.close()
    except BaseException:
        recorder.close()
        # A half-written "repaired" bag would pass for a good one; the directory is ours
        # (BagRecorder created it exclusively), so remove it.
        shutil.rmtree(target)
        raise
    per_topic: dict[str, int] = {}
    for scan in scans:
        for topic, count in scan.topic_counts().items():
            per_topic[topic] = per_topic.get(topic, 0) + count
    return RepairReport(
        source=layout.path,
        output=target,
        was_complete=all(s.complete for s in scans),
        messages_per_topic=MappingProxyType(per_topic),
        bytes_discarded=discarded,
        stop_reasons=tuple(f"{s.path.name}: {s.stop_reason}" for s in scans if s.stop_reason),
    )


def _copy_all(recorder: BagRecorder, layout: BagLayout) -> list[McapScan]:
    copier = _Copier(recorder, layout)
    scans: list[McapScan] = []
    for mcap_file in layout.mcap_files:
        scan = scan_mcap(mcap_file, on_message=copier.copy)
        scans.append(scan)
        # Topics whose messages were all lost still belong in the repaired bag's listing.
        for channel in scan.channels.values():
            copier.ensure_topic(channel, scan.schemas.get(channel.schema_id))
    return scans


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
