"""Writing rosbag2 MCAP bags: the streaming recorder core.

``BagRecorder`` is what the recorder node wraps (it imports no rclpy). It takes messages that are
already CDR-serialized, as a raw subscription delivers them, and writes a rosbag2 directory::

    <dir>/metadata.yaml
    <dir>/<dirname>_0.mcap

A recorder on the rig gets killed (kill -9, power, a hung driver). To lose at most
``flush_period_s`` of data, the recorder finalizes the open MCAP chunk, flushes the file and
rewrites ``metadata.yaml`` (atomically) at that period. A killed recording then has every
flushed chunk intact but no MCAP footer; ``catheter-lab bag repair`` recovers it.

A recorder that cannot write (the disk is full, an I/O error) stops at the first failure with
a :class:`BagWriteError` naming the error, the file and the time (:class:`WriteFailure`), and
writes nothing more: ``close`` then cuts the file back to its last complete flush, so it is
exactly what a killed recording leaves (every flushed chunk, no footer; ``bag repair``
recovers it), and ``metadata.yaml`` counts what that holds. A partly written chunk after it
would make the file unreadable past it, and a footer after a failed write cannot be trusted.
``close`` says which it left: :class:`CloseOutcome`. Those three types live in
``bag.write_failure``; bags built from sampled arrays (``write_bag_from_arrays``) in
``bag.from_arrays``.
"""

from __future__ import annotations

import contextlib
import datetime as dt
import os
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Final, Literal, NamedTuple

from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import CompressionType, Writer

from catheter_models import __version__
from catheter_models.bag.messages import kilted_typestore
from catheter_models.bag.metadata import (
    METADATA_FILE,
    BagSummary,
    QosProfile,
    TopicSummary,
    dump_yaml,
    qos_from_channel_string,
    qos_to_channel_string,
    write_metadata,
)
from catheter_models.bag.write_failure import BagWriteError, CloseOutcome, WriteFailure
from catheter_models.errors import BagError, ParameterError
from catheter_models.units import NS_PER_S, s_to_ns

DEFAULT_FLUSH_PERIOD_S: Final = 0.5
DEFAULT_CHUNK_SIZE_BYTES: Final = 1024 * 1024
LIBRARY: Final = f"catheter_models/{__version__}"

Compression = Literal["none", "lz4", "zstd"]
_COMPRESSION: Final[Mapping[str, CompressionType]] = {
    "none": CompressionType.NONE,
    "lz4": CompressionType.LZ4,
    "zstd": CompressionType.ZSTD,
}


class SchemaText(NamedTuple):
    """A message definition as an MCAP schema carries it.

    Attributes:
        encoding: ``"ros2msg"`` or ``"ros2idl"``.
        text: The concatenated definition (the type, then its dependencies).
    """

    encoding: str
    text: str


@dataclass
class _Topic:
    name: str
    msgtype: str
    channel_id: int
    offered_qos: tuple[Mapping[str, Any], ...]
    type_description_hash: str
    message_count: int = 0


@dataclass
class _LogExtent:
    """Log-time extent of the messages written so far [ns, epoch]."""

    first_ns: int | None = None
    last_ns: int | None = None

    def add(self, log_time_ns: int) -> None:
        self.first_ns = log_time_ns if self.first_ns is None else min(self.first_ns, log_time_ns)
        self.last_ns = log_time_ns if self.last_ns is None else max(self.last_ns, log_time_ns)


@dataclass
class _FlushState:
    """When the last flush happened: log time [ns, epoch] and wall clock [s]."""

    log_ns: int | None
    wall_s: float


class BagRecorder:
    """Streams already-serialized CDR messages into a new rosbag2 MCAP bag.

    Registers each schema and channel once and caches the ids. Thread-safe: a ROS node may call
    ``write`` from several callback threads and ``flush`` from a timer.

    Example::

        with BagRecorder(bag_dir, custom_data={"signal": "chirp"}) as rec:
            rec.add_topic("/catheter/pressure/command", "sensor_msgs/msg/FluidPressure")
            rec.write("/catheter/pressure/command", cdr_bytes, log_time_ns, publish_time_ns)

    Args:
        path: Bag directory to create. It must not exist: a recording is never overwritten.
        custom_data: Experiment description for ``metadata.yaml`` (signal name and parameters,
            plant/hardware identity, software version, model in use). Strings only.
        flush_period_s: Finalize the chunk, flush the file and rewrite ``metadata.yaml`` when this
            much log time or wall time has passed since the last flush [s]. None: only at close
            (batch writers that have no crash to survive).
        compression: MCAP chunk compression. ``"none"`` is rosbag2's own default and what every
            reader handles; ``"zstd"``/``"lz4"`` shrink files 3-10x.
        chunk_size_bytes: Finalize a chunk early when it grows past this size [bytes].
        fsync: Also force data to disk at each flush. A kill -9 loses nothing the OS already
            has, so this only matters for power loss; it costs a few ms per flush.
        clock: Wall clock [s] for the flush period; injectable for tests.

    Raises:
        BagError: ``path`` already exists.
    """

    def __init__(
        self,
        path: Path | str,
        *,
        custom_data: Mapping[str, str] | None = None,
        flush_period_s: float | None = DEFAULT_FLUSH_PERIOD_S,
        compression: Compression = "none",
        chunk_size_bytes: int = DEFAULT_CHUNK_SIZE_BYTES,
        fsync: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        if flush_period_s is not None and not flush_period_s > 0.0:
            msg = f"flush_period_s is {flush_period_s}; expected a positive period [s] or None"
            raise ParameterError(msg)
        if compression not in _COMPRESSION:
            msg = f"compression {compression!r} unknown; expected one of {sorted(_COMPRESSION)}"
            raise ParameterError(msg)
        self._custom_data: dict[str, str] = {}
        for key, value in (custom_data or {}).items():
            self._check_custom(key, value)
            self._custom_data[key] = value

        self.path = Path(path)
        try:
            # mkdir without exist_ok is the atomic check: two recorders cannot both win.
            self.path.mkdir(parents=True, exist_ok=False)
        except FileExistsError:
            msg = (
                f"bag directory {self.path} already exists; recordings are never overwritten, "
                "choose a new name"
            )
            raise BagError(msg) from None
        self.mcap_path = self.path / f"{self.path.name}_0.mcap"

        self._flush_period_ns = None if flush_period_s is None else s_to_ns(flush_period_s)
        self._flush_period_s = flush_period_s
        self._fsync = fsync
        self._clock = clock
        self._lock = threading.Lock()
        self._topics: dict[str, _Topic] = {}
        self._schema_ids: dict[str, int] = {}
        self._extent = _LogExtent()
        self._flushed = _FlushState(log_ns=None, wall_s=clock())
        self._closed = False
        self._failure: WriteFailure | None = None
        self._outcome: CloseOutcome | None = None

        self._stream: IO[bytes] = self.mcap_path.open("xb")
        self._writer = Writer(
            self._stream,
            chunk_size=chunk_size_bytes,
            compression=_COMPRESSION[compression],
        )
        self._writer.start(profile=Profile.ROS2, library=LIBRARY)
        self._stream.flush()
        self._good_offset = self._stream.tell()
        """Where the file's last complete flush ends [bytes]: a failed write cuts back to it."""
        self._good_summary = self._summary()
        """What the file holds up to ``_good_offset`` (``metadata.yaml`` after a failure)."""
        # A provisional metadata.yaml from the start: even a recording killed before its first
        # flush is a directory that tools recognise as a bag and can repair.
        write_metadata(self.path, self._summary(), fsync=fsync)

    # -- context manager ----------------------------------------------------------------------

    def __enter__(self) -> BagRecorder:
        """Return self; the bag is already open."""
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        """Close the bag, also on error: what was written is valid data worth keeping."""
        self.close()

    # -- public API ---------------------------------------------------------------------------

    @property
    def closed(self) -> bool:
        """True once ``close`` has run."""
        return self._closed

    @property
    def failure(self) -> WriteFailure | None:
        """Why writing stopped (disk full, I/O error); None while the bag writes."""
        return self._failure

    @property
    def outcome(self) -> CloseOutcome | None:
        """What ``close`` left (None before it ran)."""
        return self._outcome

    @property
    def message_count(self) -> int:
        """Messages written so far, over all topics."""
        with self._lock:
            return sum(t.message_count for t in self._topics.values())

    @property
    def custom_data(self) -> dict[str, str]:
        """A copy of the experiment description as it stands."""
        with self._lock:
            return dict(self._custom_data)

    def set_custom_data(self, key: str, value: str) -> None:
        """Set one ``custom_data`` entry; it reaches ``metadata.yaml`` at the next flush.

        Raises:
            TypeError: ``key`` or ``value`` is not a string (rosbag2 stores strings only).
            BagError: The bag is closed.
        """
        self._check_custom(key, value)
        with self._lock:
            # Also after a failed write: close() puts it into metadata.yaml if the disk lets it.
            if self._closed:
                self._check_open()
            self._custom_data[key] = value

    def add_topic(
        self,
        topic: str,
        msgtype: str,
        *,
        offered_qos: Sequence[QosProfile] | str = (),
        schema: SchemaText | None = None,
        type_description_hash: str | None = None,
    ) -> None:
        """Register a topic. Adding the same topic with the same type again does nothing.

        Args:
            topic: Full topic name, e.g. ``/catheter/pressure/command``.
            msgtype: ROS type, e.g. ``sensor_msgs/msg/FluidPressure``.
            offered_qos: QoS profiles the publishers offered, or a serialized profile string as
                an MCAP channel carries it (used when copying channels from another bag).
            schema: Message definition to embed. None: take it from the Kilted type store.
            type_description_hash: RIHS01 hash of the type. None: from the Kilted type store
                when ``schema`` is None, else empty (unknown).

        Raises:
            BagError: The topic exists with another type, the type is not in the Kilted type
                store and no ``schema`` was given, or the bag is closed.
        """
        if isinstance(offered_qos, str):
            qos = tuple(qos_from_channel_string(offered_qos, topic=topic))
        else:
            qos = tuple(p.to_yaml_dict() for p in offered_qos)
        with self._lock:
            self._check_open()
            known = self._topics.get(topic)
            if known is not None:
                if known.msgtype != msgtype:
                    msg = (
                        f"topic {topic} is already recorded as {known.msgtype}; "
                        f"cannot add it again as {msgtype}"
                    )
                    raise BagError(msg)
                return
            if schema is None:
                schema, digest = self._kilted_schema(msgtype)
            else:
                digest = ""
            if type_description_hash is not None:
                digest = type_description_hash
            schema_id = self._schema_ids.get(msgtype)
            if schema_id is None:
                schema_id = self._writer.register_schema(
                    name=msgtype, encoding=schema.encoding, data=schema.text.encode("utf-8")
                )
                self._schema_ids[msgtype] = schema_id
            channel_id = self._writer.register_channel(
                topic=topic,
                message_encoding=MessageEncoding.CDR,
                schema_id=schema_id,
                # Both keys as rosbag2_storage_mcap writes them, so `ros2 bag info` on the bare
                # .mcap shows QoS and type hash.
                metadata={
                    "offered_qos_profiles": qos_to_channel_string(qos),
                    "topic_type_hash": digest,
                },
            )
            self._topics[topic] = _Topic(topic, msgtype, channel_id, qos, digest)

    def write(
        self, topic: str, serialized_cdr: bytes, log_time_ns: int, publish_time_ns: int
    ) -> None:
        """Append one serialized message.

        Args:
            topic: A topic registered with ``add_topic``.
            serialized_cdr: The message as CDR bytes, encapsulation header included.
            log_time_ns: Receive (log) time [ns, epoch]; what rosbag2 orders playback by.
            publish_time_ns: Publish (send) time [ns, epoch]; the log time if unknown.

        Raises:
            BagWriteError: The file could not be written (disk full, I/O error), now or
                before; nothing more is written after the first failure.
            BagError: The topic was not added, or the bag is closed.
        """
        with self._lock:
            self._check_open()
            entry = self._topics.get(topic)
            if entry is None:
                msg = (
                    f"topic {topic} was not added to bag {self.path}; call add_topic first "
                    f"(added: {sorted(self._topics) or 'none'})"
                )
                raise BagError(msg)
            try:
                # A chunk that fills up is written out here, so this can meet the disk too.
                self._writer.add_message(
                    channel_id=entry.channel_id,
                    log_time=int(log_time_ns),
                    data=serialized_cdr,
                    publish_time=int(publish_time_ns),
                )
            except OSError as exc:
                raise self._fail("write", exc) from exc
            entry.message_count += 1
            self._extent.add(int(log_time_ns))
            if self._flush_due(int(log_time_ns)):
                self._flush_locked()

    def flush(self) -> None:
        """Finalize the open chunk, flush the file and rewrite ``metadata.yaml`` now.

        Raises:
            BagWriteError: The file could not be written, now or before.
            BagError: The bag is closed.
        """
        with self._lock:
            self._check_open()
            self._flush_locked()

    def close(self) -> CloseOutcome:
        """Finish the MCAP file (summary and footer) and write the final ``metadata.yaml``.

        After a failed write (or if finishing fails) the file is cut back to its last complete
        flush instead, which ``catheter-lab bag repair`` recovers, and ``metadata.yaml``
        counts what it holds. Never raises for the disk: what it left is the outcome.
        Safe to call more than once; later calls return the same outcome.
        """
        with self._lock:
            if self._outcome is not None:
                return self._outcome
            # Marked first so a failure below (disk full) is not retried on a broken writer.
            self._closed = True
            if self._failure is None:
                try:
                    self._finish_locked()
                except OSError as exc:
                    self._failure = WriteFailure.of(self.mcap_path, "close", exc)
                else:
                    summary = self._summary()
                    note = f"{self.path}: finished, {summary.message_count} messages"
                    try:
                        write_metadata(self.path, summary, fsync=self._fsync)
                    except OSError as exc:
                        # The MCAP file is whole and carries its own copy of the summary.
                        note += (
                            f"; metadata.yaml is its last flush's ({exc.strerror}), the "
                            "summary inside the .mcap file is complete"
                        )
                    self._outcome = CloseOutcome(
                        True,
                        summary.message_count,
                        self._extent.last_ns,
                        None,
                        note,
                        {t.name: t.message_count for t in summary.topics},
                    )
                    return self._outcome
            self._outcome = self._cut_back_locked(self._failure)
            return self._outcome

    # -- internals ----------------------------------------------------------------------------

    @staticmethod
    def _check_custom(key: object, value: object) -> None:
        if not isinstance(key, str) or not isinstance(value, str):
            msg = (
                f"custom_data entry {key!r}: {value!r} is not str -> str; rosbag2 stores strings "
                "only, so format numbers and lists (e.g. json.dumps) first"
            )
            raise TypeError(msg)

    def _check_open(self) -> None:
        if self._failure is not None:
            raise BagWriteError(self._failure)
        if self._closed:
            msg = f"bag {self.path} is closed; open a new BagRecorder to record more"
            raise BagError(msg)

    def _fail(self, operation: str, exc: OSError) -> BagWriteError:
        """Remember the first failure (nothing more is written) and the error to raise."""
        if self._failure is None:
            self._failure = WriteFailure.of(self.mcap_path, operation, exc)
        return BagWriteError(self._failure)

    def _finish_locked(self) -> None:
        try:
            self._writer.add_metadata("rosbag2", {"serialized_metadata": self._summary_yaml_body()})
            self._writer.finish()
            self._stream.flush()
            if self._fsync:
                os.fsync(self._stream.fileno())
        finally:
            self._stream.close()

    def _cut_back_locked(self, failure: WriteFailure) -> CloseOutcome:
        """Leave the file as its last complete flush left it, and say what it holds.

        The stream is closed first (its buffer may still try to write), then the file is
        truncated to the flush's end, so nothing half-written stays after the last whole
        chunk. metadata.yaml, as that flush wrote it, already counts what the file holds; it
        is rewritten with the custom_data set since (the loss counts) if the disk takes it.
        """
        problems = []
        with contextlib.suppress(OSError):  # the buffered bytes are past the cut anyway
            self._stream.close()
        try:
            os.truncate(self.mcap_path, self._good_offset)
        except OSError as exc:
            problems.append(f"could not cut it back to its last flush ({exc.strerror})")
        kept = self._good_summary
        try:
            write_metadata(
                self.path, replace(kept, custom_data=dict(self._custom_data)), fsync=self._fsync
            )
        except OSError as exc:
            problems.append(
                f"metadata.yaml is its last flush's ({exc.strerror}): the loss counts since "
                "are not in it"
            )
            # What the failed rewrite left (empty on a full disk) is not part of the bag.
            (self.path / f".{METADATA_FILE}.tmp").unlink(missing_ok=True)
        until_ns = kept.end_time_ns if kept.message_count else None
        when = (
            "nothing"
            if until_ns is None
            else f"{kept.message_count} messages up to "
            + dt.datetime.fromtimestamp(until_ns / NS_PER_S).isoformat(timespec="milliseconds")
        )
        note = (
            f"{self.path} is not finished: it holds {when} (its last complete flush), no "
            f"footer; `catheter-lab bag repair {self.path}` recovers it"
        )
        if problems:
            note += "; " + "; ".join(problems)
        per_topic = {t.name: t.message_count for t in kept.topics}
        return CloseOutcome(False, kept.message_count, until_ns, failure, note, per_topic)

    @staticmethod
    def _kilted_schema(msgtype: str) -> tuple[SchemaText, str]:
        store = kilted_typestore()
        if msgtype not in store.types:
            msg = (
                f"message type {msgtype} is not in the ROS 2 Kilted type store; pass its "
                "definition as schema=SchemaText('ros2msg', text)"
            )
            raise BagError(msg)
        text, _ = store.generate_msgdef(msgtype, ros_version=2)
        return SchemaText(SchemaEncoding.ROS2, text), store.hash_rihs01(msgtype)

    def _flush_due(self, log_time_ns: int) -> bool:
        if self._flush_period_ns is None or self._flush_period_s is None:
            return False
        if self._flushed.log_ns is None:
            self._flushed.log_ns = log_time_ns
        return (
            log_time_ns - self._flushed.log_ns >= self._flush_period_ns
            or self._clock() - self._flushed.wall_s >= self._flush_period_s
        )

    def _flush_locked(self) -> None:
        try:
            self._writer.flush()
            if self._fsync:
                os.fsync(self._stream.fileno())
        except OSError as exc:
            raise self._fail("flush", exc) from exc
        offset, summary = self._stream.tell(), self._summary()
        self._flushed.log_ns = self._extent.last_ns
        self._flushed.wall_s = self._clock()
        # Only after the data is out: the counts in metadata.yaml never exceed the file's.
        try:
            write_metadata(self.path, summary, fsync=self._fsync)
        except OSError as exc:
            # metadata.yaml still counts the flush before: a cut back goes there too, so the
            # two agree (a disk that refuses 5 kB refuses the next chunk anyway).
            raise self._fail("flush", exc) from exc
        self._good_offset, self._good_summary = offset, summary

    def _summary(self) -> BagSummary:
        return BagSummary(
            relative_file_path=self.mcap_path.name,
            topics=tuple(
                TopicSummary(
                    name=t.name,
                    msgtype=t.msgtype,
                    message_count=t.message_count,
                    offered_qos=t.offered_qos,
                    type_description_hash=t.type_description_hash,
                )
                for t in self._topics.values()
            ),
            start_time_ns=self._extent.first_ns or 0,
            end_time_ns=self._extent.last_ns or 0,
            custom_data=dict(self._custom_data),
        )

    def _summary_yaml_body(self) -> str:
        return dump_yaml(self._summary().to_yaml_dict()).strip()
