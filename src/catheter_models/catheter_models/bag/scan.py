"""Reading an MCAP file record by record, up to the first incomplete record.

A recorder killed mid-write leaves an MCAP file with no summary and no footer, usually ending
inside a chunk. Index-based readers (``rosbags``, ``mcap``'s seeking reader) refuse such a file.
This module reads it front to back with ``mcap``'s ``StreamReader`` and keeps every record that
is complete; the loader uses it to say what is recoverable, the repair tool to recover it.

``StreamReader`` alone is not safe on a truncated file: its byte source returns short reads
silently, so a chunk cut off mid-way would be parsed from partial data. ``_ExactReader`` turns
any short read into ``mcap``'s own ``EndOfFile``, so the scan stops cleanly at the last whole
record and never yields a partial one.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Final, cast

from mcap.exceptions import EndOfFile, InvalidMagic, RecordLengthLimitExceeded
from mcap.records import Channel, Footer, Header, Message, Schema
from mcap.stream_reader import CRCValidationError, StreamReader

from catheter_models.errors import BagError, TruncatedBagError

MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
_FOOTER_OPCODE: Final = 0x02
_FOOTER_RECORD_LENGTH: Final = 20
_TAIL_BYTES: Final = 9 + _FOOTER_RECORD_LENGTH + len(MCAP_MAGIC)
REPAIR_COMMAND: Final = "catheter-lab bag repair"


def has_footer(path: Path) -> bool:
    """True if an MCAP file ends with a footer record and the closing magic.

    This is what index-based readers check first; a killed recorder leaves neither.
    """
    size = path.stat().st_size
    if size < len(MCAP_MAGIC) + _TAIL_BYTES:
        return False
    with path.open("rb") as stream:
        stream.seek(size - _TAIL_BYTES)
        tail = stream.read(_TAIL_BYTES)
    opcode = tail[0]
    (length,) = struct.unpack_from("<Q", tail, 1)
    return (
        opcode == _FOOTER_OPCODE
        and length == _FOOTER_RECORD_LENGTH
        and tail[-len(MCAP_MAGIC) :] == MCAP_MAGIC
    )


class _ExactReader(io.BufferedIOBase):
    """A byte source whose ``read(n)`` returns exactly ``n`` bytes or raises ``EndOfFile``.

    ``position`` counts the bytes consumed, i.e. where the next record starts.
    """

    def __init__(self, raw: BinaryIO) -> None:
        super().__init__()
        self._raw = raw
        self.position = 0

    def readable(self) -> bool:
        """Always readable."""
        return True

    def read(self, size: int | None = -1, /) -> bytes:
        """Read exactly ``size`` bytes (all remaining if ``size`` is negative or None)."""
        if size is None or size < 0:
            data = self._raw.read()
            self.position += len(data)
            return data
        data = self._raw.read(size)
        if len(data) != size:
            raise EndOfFile
        self.position += size
        return data


MessageSink = Callable[[Channel, Schema | None, Message], None]


@dataclass
class McapScan:
    """What a front-to-back read of one MCAP file found.

    Attributes:
        path: The file.
        file_size_bytes: Its size.
        complete: True if the scan reached the footer and closing magic.
        valid_end_bytes: Offset just past the last complete record.
        stop_reason: Why the scan stopped early, for a person; None if complete.
        header: The MCAP header record, if it was complete.
        schemas: Schema records by id.
        channels: Channel records by id, in the order first seen.
        message_counts: Complete messages per channel id.
    """

    path: Path
    file_size_bytes: int
    complete: bool = False
    valid_end_bytes: int = 0
    stop_reason: str | None = None
    header: Header | None = None
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    message_counts: dict[int, int] = field(default_factory=dict)

    @property
    def message_count(self) -> int:
        """Complete messages, over all channels."""
        return sum(self.message_counts.values())

    @property
    def bytes_discarded(self) -> int:
        """Bytes after the last complete record (the incomplete tail) [bytes]."""
        return 0 if self.complete else self.file_size_bytes - self.valid_end_bytes

    def topic_counts(self) -> dict[str, int]:
        """Complete messages per topic (channels without messages count 0)."""
        counts: dict[str, int] = {}
        for channel_id, channel in self.channels.items():
            counts[channel.topic] = counts.get(channel.topic, 0) + self.message_counts.get(
                channel_id, 0
            )
        return counts


def scan_mcap(path: Path, on_message: MessageSink | None = None) -> McapScan:
    """Read every complete record of an MCAP file, stopping at the first incomplete one.

    Args:
        path: The ``.mcap`` file.
        on_message: Called for each complete message with its channel and schema (None for a
            schemaless channel), in file order.

    Returns:
        What was found; ``complete`` tells whether the file was whole.

    Raises:
        BagError: The file is not MCAP, or a message refers to a channel never defined.
    """
    scan = McapScan(path=path, file_size_bytes=path.stat().st_size)
    with path.open("rb") as raw:
        source = _ExactReader(raw)
        # validate_crcs: a chunk is only trusted if its CRC (when written) matches.
        reader = StreamReader(cast(BinaryIO, source), validate_crcs=True)
        try:
            for record in reader.records:
                scan.valid_end_bytes = source.position
                if isinstance(record, Header):
                    scan.header = record
                elif isinstance(record, Schema):
                    scan.schemas.setdefault(record.id, record)
                elif isinstance(record, Channel):
                    scan.channels.setdefault(record.id, record)
                elif isinstance(record, Message):
                    _take_message(scan, record, on_message)
                elif isinstance(record, Footer):
                    scan.complete = True
        except EndOfFile:
            scan.complete = False
            if scan.valid_end_bytes == scan.file_size_bytes:
                scan.stop_reason = "the file stops after its last complete record, with no footer"
            else:
                scan.stop_reason = (
                    f"the file ends inside a record: the last complete record ends at byte "
                    f"{scan.valid_end_bytes} of {scan.file_size_bytes}"
                )
        except CRCValidationError as exc:
            scan.complete = False
            scan.stop_reason = f"a record after byte {scan.valid_end_bytes} is corrupt ({exc})"
        except RecordLengthLimitExceeded as exc:
            scan.complete = False
            scan.stop_reason = f"a record after byte {scan.valid_end_bytes} is corrupt ({exc})"
        except InvalidMagic:
            if scan.valid_end_bytes == 0:
                msg = f"{path} is not an MCAP file (it does not start with the MCAP magic)"
                raise BagError(msg) from None
            # The closing magic after the footer is damaged; everything before it is whole.
            scan.complete = False
            scan.stop_reason = "the closing MCAP magic after the footer is damaged"
    return scan


def _take_message(scan: McapScan, record: Message, on_message: MessageSink | None) -> None:
    channel = scan.channels.get(record.channel_id)
    if channel is None:
        msg = (
            f"{scan.path}: message at byte {scan.valid_end_bytes} is on channel "
            f"{record.channel_id}, which no earlier record defines; the file is corrupt"
        )
        raise BagError(msg)
    scan.message_counts[record.channel_id] = scan.message_counts.get(record.channel_id, 0) + 1
    if on_message is not None:
        on_message(channel, scan.schemas.get(channel.schema_id), record)


def truncated_bag_error(bag_path: Path, scans: list[McapScan]) -> TruncatedBagError:
    """The error ``load_bag`` raises for a bag whose MCAP file(s) lack a footer."""
    broken = [s for s in scans if not s.complete]
    recoverable = sum(s.message_count for s in scans)
    discarded = sum(s.bytes_discarded for s in scans)
    per_topic: dict[str, int] = {}
    for scan in scans:
        for topic, count in scan.topic_counts().items():
            per_topic[topic] = per_topic.get(topic, 0) + count
    topics_text = ", ".join(f"{t}: {c}" for t, c in sorted(per_topic.items())) or "none"
    files_text = "; ".join(f"{s.path.name}: {s.stop_reason}" for s in broken)
    if recoverable == 0:
        msg = (
            f"bag {bag_path} is truncated (no MCAP footer): {files_text}. 0 complete messages "
            f"are recoverable; {discarded} bytes at the end are incomplete. There is nothing "
            "to repair: record it again"
        )
        return TruncatedBagError(msg)
    msg = (
        f"bag {bag_path} is truncated (no MCAP footer; the recorder was probably killed): "
        f"{files_text}. {recoverable} complete messages are recoverable ({topics_text}); "
        f"{discarded} bytes at the end are incomplete. Repair it into a new bag with: "
        f"{REPAIR_COMMAND} {bag_path}"
    )
    return TruncatedBagError(msg)
