"""Checking an MCAP file record by record: what is whole, what is damaged, what is lost.

``scan`` reads up to the first bad record; this module reads past it. Every top-level record
carries its own length, so a chunk whose bytes are damaged is skipped and the records after it
are read on. For each chunk it checks what can be checked:

* the chunk decompresses (zstd, lz4 or none) and gives exactly the header's
  ``uncompressed_size`` bytes;
* its CRC matches, or the CRC is 0 (the writer did not compute one): then the bytes *cannot be
  verified*, which is said, since a flipped bit may still decompress;
* the records inside it are framed (each length fits, they end where the chunk ends), every
  message's log time lies in the chunk's time span and its channel is defined;
* its message count per channel equals the message index records written after it.

Across the file, the messages read per channel are compared with the summary's ``Statistics``
record. Nothing here raises for damage inside the file: damage is reported, with the chunk, its
time span and the messages lost. ``BagError`` is raised only for a file that is no MCAP at all
(0 bytes, no MCAP magic), where there is nothing to recover.

Truncation and corruption are told apart: a file that ends inside a record, or after its last
complete record, with no footer, is *truncated* (a recorder killed or a disk full); a record
that cannot be read while the file goes on (or ends with its footer) is *corrupt*.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import BinaryIO, Final, Literal

from mcap.data_stream import ReadDataStream
from mcap.records import (
    Channel,
    Chunk,
    Footer,
    Header,
    Message,
    MessageIndex,
    Schema,
    Statistics,
)
from mcap.stream_reader import get_chunk_data_stream

from catheter_models.bag.metadata import locate_bag
from catheter_models.bag.scan import MCAP_MAGIC, has_footer
from catheter_models.errors import BagError
from catheter_models.units import NS_PER_S

_OPCODE_HEADER: Final = 0x01
_OPCODE_FOOTER: Final = 0x02
_OPCODE_SCHEMA: Final = 0x03
_OPCODE_CHANNEL: Final = 0x04
_OPCODE_MESSAGE: Final = 0x05
_OPCODE_CHUNK: Final = 0x06
_OPCODE_MESSAGE_INDEX: Final = 0x07
_OPCODE_STATISTICS: Final = 0x0B
_KNOWN_OPCODES: Final = frozenset(range(0x01, 0x10))
_RECORD_PREFIX: Final = struct.Struct("<BQ")
_MESSAGE_PREFIX: Final = struct.Struct("<HIQQ")

MessageSink = Callable[[Channel, Schema | None, Message], None]
CrcState = Literal["verified", "unverifiable", "mismatch"]


@dataclass
class ChunkCheck:
    """What one chunk held and whether it could be trusted.

    Attributes:
        index: Position among the file's chunks (0 first).
        offset_bytes: Where the chunk record starts in the file.
        start_ns: The chunk's first message log time (its header) [ns since the epoch].
        end_ns: Its last message log time [ns].
        compression: ``"zstd"``, ``"lz4"`` or ``""``.
        crc: ``verified``, ``unverifiable`` (CRC 0: not computed by the writer) or
            ``mismatch``.
        messages: Messages read from it per channel id (none if it could not be read).
        indexed: Messages per channel id listed by the index records after it.
        problem: Why the chunk is corrupt; None if it is whole.
    """

    index: int
    offset_bytes: int
    start_ns: int
    end_ns: int
    compression: str
    crc: CrcState = "verified"
    messages: list[Message] = field(default_factory=list, repr=False)
    indexed: dict[int, int] = field(default_factory=dict)
    problem: str | None = None

    @property
    def expected_count(self) -> int | None:
        """Messages the chunk should hold, by its index; None if no index followed it."""
        return sum(self.indexed.values()) if self.indexed else None


@dataclass
class McapCheck:
    """What a full read of one MCAP file found.

    Attributes:
        path: The file.
        size_bytes: Its size.
        complete: The footer was reached.
        truncated: Why the file counts as truncated (it stops with no footer); None if not.
        problems: Corruption found outside chunks (records that cannot be read), for a person.
        chunks: Every chunk, whole or not.
        valid_end_bytes: Offset just past the last complete record.
        has_header: The MCAP header record was read whole.
        schemas: Schema records by id.
        channels: Channel records by id.
        recovered: Messages read from whole records, per channel id.
        first_ns: Earliest recovered log time [ns]; None if nothing was recovered.
        last_ns: Latest recovered log time [ns].
        statistics: Messages per channel id by the summary's ``Statistics`` record; None if the
            file has none (a truncated file has no summary).
    """

    path: Path
    size_bytes: int
    complete: bool = False
    truncated: str | None = None
    problems: list[str] = field(default_factory=list)
    chunks: list[ChunkCheck] = field(default_factory=list)
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    recovered: dict[int, int] = field(default_factory=dict)
    valid_end_bytes: int = 0
    has_header: bool = False
    first_ns: int | None = None
    last_ns: int | None = None
    statistics: dict[int, int] | None = None

    @property
    def corrupt_chunks(self) -> list[ChunkCheck]:
        """Chunks that could not be trusted (their messages are not recovered)."""
        return [c for c in self.chunks if c.problem is not None]

    @property
    def unverifiable_chunks(self) -> list[ChunkCheck]:
        """Whole chunks whose CRC is 0, so their bytes could not be verified."""
        return [c for c in self.chunks if c.problem is None and c.crc == "unverifiable"]

    @property
    def bytes_discarded(self) -> int:
        """Bytes after the last complete record of a truncated file [bytes]."""
        return 0 if self.truncated is None else self.size_bytes - self.valid_end_bytes

    @property
    def corrupt(self) -> bool:
        """Any record or chunk could not be read or trusted."""
        return bool(self.problems or self.corrupt_chunks)

    def topic_of(self, channel_id: int) -> str:
        """The topic of a channel id (``channel <id>`` if it was never defined)."""
        channel = self.channels.get(channel_id)
        return channel.topic if channel is not None else f"channel {channel_id}"

    def recovered_by_topic(self) -> dict[str, int]:
        """Recovered messages per topic (defined channels without messages count 0)."""
        counts = {c.topic: 0 for c in self.channels.values()}
        for channel_id, n in self.recovered.items():
            topic = self.topic_of(channel_id)
            counts[topic] = counts.get(topic, 0) + n
        return counts

    def lost_by_topic(self) -> dict[str, int]:
        """Messages the file should hold but that could not be recovered, per topic.

        Against the summary's statistics when the file has them; otherwise what the index
        records of corrupt chunks list.
        """
        lost: dict[str, int] = {}
        if self.statistics is not None:
            for channel_id, expected in self.statistics.items():
                missing = expected - self.recovered.get(channel_id, 0)
                if missing > 0:
                    topic = self.topic_of(channel_id)
                    lost[topic] = lost.get(topic, 0) + missing
            return lost
        for chunk in self.corrupt_chunks:
            for channel_id, n in chunk.indexed.items():
                topic = self.topic_of(channel_id)
                lost[topic] = lost.get(topic, 0) + n
        return lost

    def lines(self, start_ns: int | None = None) -> list[str]:
        """Truncation, corruption and unverifiable chunks of this file, one a line.

        What is lost is said over the whole bag (:meth:`BagCheck.loss_summary`).

        Args:
            start_ns: Times are given in seconds from here (default: the first recovered
                message).
        """
        origin = start_ns if start_ns is not None else (self.first_ns or 0)
        out: list[str] = []
        if self.truncated is not None:
            out.append(f"TRUNCATED: {self.path.name}: {self.truncated}")
        out += [f"CORRUPT: {self.path.name}: {p}" for p in self.problems]
        for chunk in self.corrupt_chunks:
            expected = chunk.expected_count
            count = "an unknown number of" if expected is None else str(expected)
            out.append(
                f"CORRUPT: {self.path.name}: chunk {chunk.index} at byte {chunk.offset_bytes} "
                f"({_span(chunk.start_ns, chunk.end_ns, origin)}): {chunk.problem}; its "
                f"{count} messages are lost"
            )
        unverifiable = self.unverifiable_chunks
        if unverifiable:
            first, last = unverifiable[0], unverifiable[-1]
            out.append(
                f"UNVERIFIED: {self.path.name}: {len(unverifiable)} of {len(self.chunks)} "
                f"chunks carry no CRC (0), so their bytes cannot be verified "
                f"({_span(first.start_ns, last.end_ns, origin)}); their size, record framing, "
                "time spans and counts were checked and hold"
            )
        return out


def _span(start_ns: int, end_ns: int, origin_ns: int) -> str:
    return (
        f"t = {(start_ns - origin_ns) / NS_PER_S:.3f} to {(end_ns - origin_ns) / NS_PER_S:.3f} s, "
        f"{(end_ns - start_ns) / NS_PER_S:.3f} s"
    )


def verify_mcap(path: Path, on_message: MessageSink | None = None) -> McapCheck:
    """Read every record of an MCAP file, past damage, and say what is whole.

    Args:
        path: The ``.mcap`` file.
        on_message: Called for each message of a whole record or chunk, in file order, with
            its channel and schema (None for a schemaless channel). Messages of a corrupt
            chunk are never passed on.

    Returns:
        What was found.

    Raises:
        BagError: The file is empty or does not start with the MCAP magic (nothing to read).
    """
    size = path.stat().st_size
    if size == 0:
        msg = f"{path} is empty (0 bytes): no MCAP data at all, nothing to recover"
        raise BagError(msg)
    check = McapCheck(path=path, size_bytes=size)
    footer_at_end = has_footer(path)
    with path.open("rb") as stream:
        magic = stream.read(len(MCAP_MAGIC))
        if magic != MCAP_MAGIC:
            msg = (
                f"{path} is not an MCAP file: it does not start with the MCAP magic (its first "
                f"{len(magic)} bytes are {magic[:8]!r}); nothing to recover"
            )
            raise BagError(msg)
        _Walker(check, stream, footer_at_end, on_message).walk()
    return check


class _Walker:
    """The record loop of :func:`verify_mcap`."""

    def __init__(
        self,
        check: McapCheck,
        stream: BinaryIO,
        footer_at_end: bool,
        on_message: MessageSink | None,
    ) -> None:
        self.check = check
        self.stream = stream
        self.footer_at_end = footer_at_end
        self.on_message = on_message
        self.pending: ChunkCheck | None = None
        self.position = len(MCAP_MAGIC)

    def walk(self) -> None:
        check = self.check
        while True:
            prefix = self.stream.read(_RECORD_PREFIX.size)
            if not prefix:
                self._ended("the file stops after its last complete record, with no footer")
                break
            if len(prefix) < _RECORD_PREFIX.size:
                self._ended(f"the file ends inside a record at byte {self.position}")
                break
            opcode, length = _RECORD_PREFIX.unpack(prefix)
            start = self.position
            if start + _RECORD_PREFIX.size + length > check.size_bytes:
                if self.footer_at_end:
                    check.problems.append(
                        f"the record at byte {start} claims {length} bytes, past the end of the "
                        "file; its length is damaged and nothing after it can be read"
                    )
                    self._finish_pending()
                else:
                    self._ended(
                        f"the file ends inside a record: the last complete record ends at byte "
                        f"{start} of {check.size_bytes}"
                    )
                break
            body = self.stream.read(length)
            self.position = start + _RECORD_PREFIX.size + length
            check.valid_end_bytes = self.position
            if opcode != _OPCODE_MESSAGE_INDEX:
                self._finish_pending()
            if opcode == _OPCODE_FOOTER:
                check.complete = True
                self._take(opcode, body, start)
                break
            self._take(opcode, body, start)

    def _ended(self, reason: str) -> None:
        self._finish_pending()
        self.check.truncated = reason

    def _take(self, opcode: int, body: bytes, start: int) -> None:
        check = self.check
        if opcode not in _KNOWN_OPCODES:
            check.problems.append(f"the record at byte {start} has an unknown opcode {opcode:#x}")
            return
        data = ReadDataStream(io.BytesIO(body))
        try:
            if opcode == _OPCODE_CHUNK:
                self._open_chunk(Chunk.read(data), start)
            elif opcode == _OPCODE_MESSAGE_INDEX:
                self._index(MessageIndex.read(data), start)
            elif opcode == _OPCODE_SCHEMA:
                schema = Schema.read(data)
                check.schemas.setdefault(schema.id, schema)
            elif opcode == _OPCODE_CHANNEL:
                channel = Channel.read(data)
                check.channels.setdefault(channel.id, channel)
            elif opcode == _OPCODE_MESSAGE:
                self._emit([Message.read(data, len(body))], where=f"byte {start}")
            elif opcode == _OPCODE_STATISTICS:
                stats = Statistics.read(data)
                check.statistics = dict(stats.channel_message_counts)
            elif opcode == _OPCODE_HEADER:
                Header.read(data)
                check.has_header = True
            elif opcode == _OPCODE_FOOTER:
                Footer.read(data)
        except Exception as exc:  # any parse failure is damage, said by name
            check.problems.append(
                f"the record at byte {start} (opcode {opcode:#x}) cannot be read "
                f"({type(exc).__name__}: {exc or 'too short'})"
            )

    def _open_chunk(self, chunk: Chunk, start: int) -> None:
        entry = ChunkCheck(
            index=len(self.check.chunks),
            offset_bytes=start,
            start_ns=chunk.message_start_time,
            end_ns=chunk.message_end_time,
            compression=chunk.compression,
        )
        self.check.chunks.append(entry)
        self.pending = entry
        try:
            data = _decompress(chunk)
        except _ChunkDamageError as exc:
            entry.problem = str(exc)
            return
        if len(data) != chunk.uncompressed_size:
            entry.problem = (
                f"it decompresses to {len(data)} bytes, its header says {chunk.uncompressed_size}"
            )
            return
        if chunk.uncompressed_crc == 0:
            entry.crc = "unverifiable"
        elif zlib.crc32(data) != chunk.uncompressed_crc:
            entry.crc = "mismatch"
            entry.problem = (
                f"its CRC does not match (header {chunk.uncompressed_crc:#010x}, bytes "
                f"{zlib.crc32(data):#010x})"
            )
            return
        entry.problem = self._split(entry, data)

    def _split(self, entry: ChunkCheck, data: bytes) -> str | None:
        """Parse the records inside a chunk; the reason it is corrupt, or None."""
        pos = 0
        while pos < len(data):
            if pos + _RECORD_PREFIX.size > len(data):
                return f"a record inside it is cut off at byte {pos} of {len(data)}"
            opcode, length = _RECORD_PREFIX.unpack_from(data, pos)
            body_at = pos + _RECORD_PREFIX.size
            if body_at + length > len(data):
                return (
                    f"a record inside it at byte {pos} claims {length} bytes, past the chunk's "
                    f"end ({len(data)} bytes): its framing is broken"
                )
            body = data[body_at : body_at + length]
            if opcode == _OPCODE_MESSAGE:
                if length < _MESSAGE_PREFIX.size:
                    return f"a message inside it at byte {pos} is {length} bytes, too short"
                channel_id, sequence, log_ns, publish_ns = _MESSAGE_PREFIX.unpack_from(body)
                if not entry.start_ns <= log_ns <= entry.end_ns:
                    return (
                        f"a message inside it at byte {pos} has log time {log_ns}, outside the "
                        f"chunk's span [{entry.start_ns}, {entry.end_ns}]"
                    )
                entry.messages.append(
                    Message(
                        channel_id=channel_id,
                        sequence=sequence,
                        log_time=log_ns,
                        publish_time=publish_ns,
                        data=body[_MESSAGE_PREFIX.size :],
                    )
                )
            elif opcode in (_OPCODE_SCHEMA, _OPCODE_CHANNEL):
                try:
                    stream = ReadDataStream(io.BytesIO(body))
                    if opcode == _OPCODE_SCHEMA:
                        schema = Schema.read(stream)
                        self.check.schemas.setdefault(schema.id, schema)
                    else:
                        channel = Channel.read(stream)
                        self.check.channels.setdefault(channel.id, channel)
                except Exception as exc:  # damage inside the chunk, said
                    return (
                        f"a {'schema' if opcode == _OPCODE_SCHEMA else 'channel'} record "
                        f"inside it at byte {pos} cannot be read ({type(exc).__name__})"
                    )
            elif opcode not in _KNOWN_OPCODES:
                return f"a record inside it at byte {pos} has an unknown opcode {opcode:#x}"
            pos = body_at + length
        return None

    def _index(self, index: MessageIndex, start: int) -> None:
        if self.pending is None:
            self.check.problems.append(f"a message index at byte {start} follows no chunk")
            return
        self.pending.indexed[index.channel_id] = len(index.records)

    def _finish_pending(self) -> None:
        entry, self.pending = self.pending, None
        if entry is None:
            return
        if entry.problem is None and entry.indexed:
            held: dict[int, int] = {}
            for message in entry.messages:
                held[message.channel_id] = held.get(message.channel_id, 0) + 1
            # Per indexed channel: a file cut inside the index records after the chunk lacks
            # the records of the remaining channels, which is truncation, not damage.
            differ = {
                ch: (held.get(ch, 0), n) for ch, n in entry.indexed.items() if held.get(ch, 0) != n
            }
            if differ:
                said = ", ".join(
                    f"{self.check.topic_of(ch)}: {h} held, {n} indexed"
                    for ch, (h, n) in sorted(differ.items())
                )
                entry.problem = f"its messages do not match its index ({said})"
        if entry.problem is None:
            unknown = {m.channel_id for m in entry.messages} - set(self.check.channels)
            if unknown:
                entry.problem = f"its messages name channel(s) {sorted(unknown)}, never defined"
        if entry.problem is None:
            self._emit(entry.messages, where=f"chunk {entry.index}")
        entry.messages = []

    def _emit(self, messages: list[Message], where: str) -> None:
        check = self.check
        for message in messages:
            channel = check.channels.get(message.channel_id)
            if channel is None:
                check.problems.append(
                    f"a message in {where} is on channel {message.channel_id}, which no "
                    "earlier record defines"
                )
                continue
            check.recovered[message.channel_id] = check.recovered.get(message.channel_id, 0) + 1
            log_ns = message.log_time
            check.first_ns = log_ns if check.first_ns is None else min(check.first_ns, log_ns)
            check.last_ns = log_ns if check.last_ns is None else max(check.last_ns, log_ns)
            if self.on_message is not None:
                self.on_message(channel, check.schemas.get(channel.schema_id), message)


class _ChunkDamageError(Exception):
    """A chunk's bytes cannot be decompressed (the message says how)."""


def _decompress(chunk: Chunk) -> bytes:
    """The chunk's records, decompressed by ``mcap``'s own zstd or lz4 support."""
    if chunk.compression not in ("", "zstd", "lz4"):
        msg = f"its compression {chunk.compression!r} is unknown (MCAP knows zstd, lz4 and none)"
        raise _ChunkDamageError(msg)
    try:
        stream, length = get_chunk_data_stream(chunk, validate_crc=False)
        return stream.read(length)
    except Exception as exc:  # each decoder raises its own types
        what = chunk.compression or "uncompressed"
        msg = f"its {what} data cannot be decompressed ({type(exc).__name__}: {exc})"
        raise _ChunkDamageError(msg) from None


@dataclass
class BagCheck:
    """What a full read of a bag's MCAP files found, and what its ``metadata.yaml`` claims.

    Attributes:
        path: The bag.
        files: One check per MCAP file, in playback order.
        metadata_counts: Messages per topic by ``metadata.yaml``; None without one.
        metadata_end_ns: The last log time ``metadata.yaml`` covers [ns]; None without one.
    """

    path: Path
    files: list[McapCheck]
    metadata_counts: dict[str, int] | None = None
    metadata_end_ns: int | None = None

    @property
    def truncated(self) -> bool:
        """A file stops with no footer."""
        return any(f.truncated is not None for f in self.files)

    @property
    def corrupt(self) -> bool:
        """A record or chunk could not be read or trusted."""
        return any(f.corrupt for f in self.files)

    @property
    def unverified_chunks(self) -> int:
        """Whole chunks whose bytes could not be verified (CRC 0)."""
        return sum(len(f.unverifiable_chunks) for f in self.files)

    @property
    def first_ns(self) -> int | None:
        """The earliest recovered log time [ns]."""
        firsts = [f.first_ns for f in self.files if f.first_ns is not None]
        return min(firsts) if firsts else None

    @property
    def last_ns(self) -> int | None:
        """The latest recovered log time [ns]."""
        lasts = [f.last_ns for f in self.files if f.last_ns is not None]
        return max(lasts) if lasts else None

    def recovered_by_topic(self) -> dict[str, int]:
        """Readable messages per topic, over the files."""
        out: dict[str, int] = {}
        for f in self.files:
            for topic, n in f.recovered_by_topic().items():
                out[topic] = out.get(topic, 0) + n
        return out

    def lost_by_topic(self) -> dict[str, int]:
        """Messages lost per topic: the files' own accounts, else what metadata.yaml counts."""
        out: dict[str, int] = {}
        for f in self.files:
            for topic, n in f.lost_by_topic().items():
                out[topic] = out.get(topic, 0) + n
        if self.metadata_counts is not None:
            recovered = self.recovered_by_topic()
            for topic, claimed in self.metadata_counts.items():
                missing = claimed - recovered.get(topic, 0)
                if missing > out.get(topic, 0):
                    out[topic] = missing
        return {t: n for t, n in out.items() if n > 0}

    @property
    def lost_messages(self) -> int:
        """Messages lost over all topics."""
        return sum(self.lost_by_topic().values())

    @property
    def intact(self) -> bool:
        """Nothing truncated, corrupt or lost, and metadata.yaml agrees with the data."""
        return not (
            self.truncated or self.corrupt or self.lost_messages or self.metadata_disagrees()
        )

    def metadata_disagrees(self) -> list[str]:
        """Topics whose metadata.yaml count differs from the readable messages, for a person.

        A truncated bag's metadata.yaml is the recorder's last flush, so it may count fewer
        than the file holds; only a complete bag's must match exactly.
        """
        if self.metadata_counts is None:
            return []
        recovered = self.recovered_by_topic()
        # Messages the files themselves account as lost (a corrupt chunk's index, the
        # summary's statistics) explain as much of a difference; those are said as lost.
        accounted: dict[str, int] = {}
        for f in self.files:
            for topic, n in f.lost_by_topic().items():
                accounted[topic] = accounted.get(topic, 0) + n
        out = []
        for topic in sorted(set(self.metadata_counts) | set(recovered)):
            claimed = self.metadata_counts.get(topic, 0)
            held = recovered.get(topic, 0)
            if claimed == held + accounted.get(topic, 0):
                continue
            if claimed > held or not self.truncated:
                out.append(f"{topic}: metadata.yaml says {claimed}, the data holds {held}")
        return out

    def lines(self) -> list[str]:
        """Every finding, one a line (empty: whole, verified and agreeing)."""
        origin = self.first_ns
        out: list[str] = []
        for f in self.files:
            out += f.lines(origin)
        disagree = self.metadata_disagrees()
        if disagree:
            out.append("METADATA: metadata.yaml does not match the data: " + "; ".join(disagree))
        lost = self.lost_by_topic()
        if lost:
            out.append("LOST: " + self.loss_summary())
        return out

    def loss_summary(self) -> str:
        """How many messages were lost, on which topics, and from when, in one sentence."""
        lost = self.lost_by_topic()
        said = ", ".join(f"{t}: {n}" for t, n in sorted(lost.items()))
        text = f"{sum(lost.values())} messages are not in the readable data ({said})"
        origin = self.first_ns or 0
        spans = [_span(c.start_ns, c.end_ns, origin) for f in self.files for c in f.corrupt_chunks]
        if spans:
            text += f"; corrupt chunks cover {'; '.join(spans)}"
        last = self.last_ns
        if self.truncated and last is not None:
            text += f"; the readable data ends at t = {(last - origin) / NS_PER_S:.3f} s"
            if self.metadata_end_ns is not None and self.metadata_end_ns > last:
                text += (
                    f", metadata.yaml covers {(self.metadata_end_ns - last) / NS_PER_S:.3f} s more"
                )
        return text


def verify_bag(path: Path | str, on_message: MessageSink | None = None) -> BagCheck:
    """:func:`verify_mcap` over a bag's MCAP files, and ``metadata.yaml`` against the data.

    Raises:
        BagError: The path is not a bag, or a file in it is empty or not MCAP.
    """
    layout = locate_bag(path)
    files = [verify_mcap(f, on_message) for f in layout.mcap_files]
    counts: dict[str, int] | None = None
    end_ns: int | None = None
    info = layout.metadata
    if info is not None:
        counts = {}
        for entry in info.get("topics_with_message_count") or []:
            meta = entry.get("topic_metadata", {}) if isinstance(entry, dict) else {}
            name, n = meta.get("name"), entry.get("message_count")
            if isinstance(name, str) and isinstance(n, int):
                counts[name] = counts.get(name, 0) + n
        start = (info.get("starting_time") or {}).get("nanoseconds_since_epoch")
        duration = (info.get("duration") or {}).get("nanoseconds")
        if isinstance(start, int) and isinstance(duration, int) and start > 0:
            end_ns = start + duration
    return BagCheck(layout.path, files, counts, end_ns)
