"""Bad bags made from a good one, for the plausibility and honest-repair tests.

Two kinds:

* **bad data** (:func:`rewrite`): the good bag's model streams (``pressure/command``,
  ``pressure/measured``, ``tip/angle``) decoded, changed by an edit (values, stamps) and written
  again with the bag writer, each message at its original log time, so the file itself is whole;
* **bad bytes** (:func:`damage_chunk`, :func:`zero_crc`, ...): a copy of the good bag with bytes
  of one chunk changed, the way a disk, a copy or a hand does.
"""

from __future__ import annotations

import shutil
import struct
import zlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import zstandard
from rosbags.highlevel import AnyReader

from catheter_models.bag import BagRecorder
from catheter_models.bag.messages import (
    fluid_pressure_cdr,
    gauge_pressure_of,
    joint_position_of,
    joint_state_cdr,
    kilted_typestore,
)
from catheter_models.bag.verify import verify_mcap
from catheter_models.contract import (
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    qualify,
)
from catheter_models.units import AMBIENT_PRESSURE_PA

REPO = Path(__file__).resolve().parents[2]
GOOD_BAG = REPO / "bags" / "model_test_up_chirp"
"""A shipped sample bag (zstd chunks with CRCs, 22 s, 5,000-5,700 messages a topic)."""
MODEL_TOPICS = (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE)


@dataclass
class Stream:
    """One topic's samples in file order: log times, header stamps [ns], values (SI)."""

    log_ns: npt.NDArray[np.int64]
    stamp_ns: npt.NDArray[np.int64]
    values: npt.NDArray[np.float64]


Edit = Callable[[str, Stream], Stream]
"""Given a contract name and its stream, the stream to write instead."""


def read_streams(bag: Path = GOOD_BAG) -> dict[str, Stream]:
    """The model streams of a bag, decoded, in file order."""
    rows: dict[str, list[tuple[int, int, float]]] = {s.name: [] for s in MODEL_TOPICS}
    by_topic = {qualify(s): s.name for s in MODEL_TOPICS}
    with AnyReader([bag], default_typestore=kilted_typestore()) as reader:
        connections = [c for c in reader.connections if c.topic in by_topic]
        for conn, log_ns, raw in reader.messages(connections=connections):
            msg = reader.deserialize(raw, conn.msgtype)
            name = by_topic[conn.topic]
            if name == TIP_ANGLE.name:
                stamp, value = joint_position_of(msg, topic=conn.topic)
            else:
                stamp, value = gauge_pressure_of(msg, AMBIENT_PRESSURE_PA)
            rows[name].append((int(log_ns), int(stamp), float(value)))
    return {
        name: Stream(
            np.array([r[0] for r in got], dtype=np.int64),
            np.array([r[1] for r in got], dtype=np.int64),
            np.array([r[2] for r in got], dtype=np.float64),
        )
        for name, got in rows.items()
    }


def rewrite(out: Path, edit: Edit, source: Path = GOOD_BAG) -> Path:
    """Write the model streams of ``source``, changed by ``edit``, into a new bag ``out``."""
    streams = {name: edit(name, s) for name, s in read_streams(source).items()}
    messages: list[tuple[int, str, bytes]] = []
    for name, s in streams.items():
        topic = qualify(name)
        for log_ns, stamp_ns, value in zip(s.log_ns, s.stamp_ns, s.values, strict=True):
            if name == TIP_ANGLE.name:
                data = joint_state_cdr(int(stamp_ns), float(value))
            else:
                data = fluid_pressure_cdr(
                    int(stamp_ns), float(value), ambient_pa=AMBIENT_PRESSURE_PA
                )
            messages.append((int(log_ns), topic, data))
    messages.sort(key=lambda m: m[0])  # file order is log order, as a recorder writes it
    with BagRecorder(
        out, custom_data={"made_from": source.name}, flush_period_s=None, compression="zstd"
    ) as rec:
        for spec in MODEL_TOPICS:
            rec.add_topic(qualify(spec), spec.msgtype)
        for log_ns, topic, data in messages:
            rec.write(topic, data, log_ns, log_ns)
    return out


def values(name: str, change: Callable[[npt.NDArray[np.float64]], npt.ArrayLike]) -> Edit:
    """An edit that changes the values of one topic only."""

    def edit(this: str, s: Stream) -> Stream:
        if this != name:
            return s
        return Stream(s.log_ns, s.stamp_ns, np.asarray(change(s.values.copy()), dtype=np.float64))

    return edit


def stamps(change: Callable[[npt.NDArray[np.int64]], npt.ArrayLike]) -> Edit:
    """An edit that changes the header stamps of every model topic (log times kept)."""

    def edit(_this: str, s: Stream) -> Stream:
        return Stream(s.log_ns, np.asarray(change(s.stamp_ns.copy()), dtype=np.int64), s.values)

    return edit


def duplicated(_this: str, s: Stream) -> Stream:
    """Every message twice: the same stamp and value, logged 1 us apart."""
    return Stream(
        np.repeat(s.log_ns, 2) + np.tile(np.array([0, 1000], dtype=np.int64), s.log_ns.size),
        np.repeat(s.stamp_ns, 2),
        np.repeat(s.values, 2),
    )


# -- bad bytes ----------------------------------------------------------------------------------


def copy_good(out: Path, source: Path = GOOD_BAG) -> Path:
    """A copy of the good bag (directory), its MCAP file at ``out / <name>.mcap``."""
    shutil.copytree(source, out)
    return out


def mcap_of(bag: Path) -> Path:
    """The bag's one MCAP file."""
    (path,) = sorted(bag.glob("*.mcap"))
    return path


@dataclass(frozen=True)
class ChunkAt:
    """Where a chunk's fields are in the file."""

    offset: int
    crc_at: int
    data_at: int
    data_length: int
    start_ns: int
    end_ns: int
    messages: int


def chunk_at(bag: Path, index: int) -> ChunkAt:
    """The byte positions of chunk ``index`` of the bag's MCAP file."""
    path = mcap_of(bag)
    check = verify_mcap(path)
    chunk = check.chunks[index]
    raw = path.read_bytes()
    at = chunk.offset_bytes + 9  # opcode and record length
    crc_at = at + 24  # message start, end, uncompressed size
    (compression_length,) = struct.unpack_from("<I", raw, crc_at + 4)
    length_at = crc_at + 8 + compression_length
    (data_length,) = struct.unpack_from("<Q", raw, length_at)
    return ChunkAt(
        offset=chunk.offset_bytes,
        crc_at=crc_at,
        data_at=length_at + 8,
        data_length=data_length,
        start_ns=chunk.start_ns,
        end_ns=chunk.end_ns,
        messages=chunk.expected_count or 0,
    )


def zero_crc(bag: Path, index: int) -> ChunkAt:
    """Set chunk ``index``'s CRC to 0 ("not computed"): its bytes can no longer be verified."""
    where = chunk_at(bag, index)
    path = mcap_of(bag)
    raw = bytearray(path.read_bytes())
    raw[where.crc_at : where.crc_at + 4] = b"\0\0\0\0"
    path.write_bytes(bytes(raw))
    return where


def flip_bit(bag: Path, byte_at: int, bit: int) -> None:
    """Flip one bit of the bag's MCAP file."""
    path = mcap_of(bag)
    raw = bytearray(path.read_bytes())
    raw[byte_at] ^= 1 << bit
    path.write_bytes(bytes(raw))


def find_flip(where: ChunkAt, bag: Path, want: str) -> tuple[int, int]:
    """(byte, bit) in the chunk's compressed data whose flip gives ``want``:

    * ``"decodes"``: the data still decompresses to the right size, every record inside framed
      as before, only message bytes differ (a CRC is the only thing that can catch it);
    * ``"rejected"``: the zstd decoder refuses the frame;
    * ``"reframed"``: it decompresses to the right size, but a record inside is framed
      differently (a length or an opcode changed).

    Searched from the middle of the data, deterministically, so the same bit every run.
    """
    raw = mcap_of(bag).read_bytes()
    data = bytearray(raw[where.data_at : where.data_at + where.data_length])
    good = zstandard.ZstdDecompressor().decompress(bytes(data), max_output_size=1 << 26)
    for byte in range(len(data) // 2, len(data)):
        for bit in range(8):
            data[byte] ^= 1 << bit
            try:
                out = zstandard.ZstdDecompressor().decompress(
                    bytes(data), max_output_size=len(good)
                )
                got = "other"
                if len(out) == len(good) and not _same_framing(out, good, headers=False):
                    got = "reframed"
                elif len(out) == len(good) and _same_framing(out, good) and out != good:
                    got = "decodes"
            except zstandard.ZstdError:
                got = "rejected"
            data[byte] ^= 1 << bit
            if got == want:
                return where.data_at + byte, bit
    raise AssertionError(f"no bit in the chunk gives {want!r}")


def _same_framing(a: bytes, b: bytes, *, headers: bool = True) -> bool:
    """The record opcodes and lengths inside two chunks agree (and message headers)."""
    pos = 0
    while pos < len(b):
        if a[pos : pos + 9] != b[pos : pos + 9]:
            return False
        opcode, length = struct.unpack_from("<BQ", b, pos)
        if headers and opcode == 0x05 and a[pos + 9 : pos + 31] != b[pos + 9 : pos + 31]:
            return False
        pos += 9 + length
    return True


def crc_of(bag: Path, where: ChunkAt) -> int:
    """The CRC the chunk's header holds."""
    (crc,) = struct.unpack_from("<I", mcap_of(bag).read_bytes(), where.crc_at)
    return int(crc)


def uncompressed_crc(bag: Path, where: ChunkAt) -> int:
    """The CRC of the chunk's data as it decompresses now."""
    raw = mcap_of(bag).read_bytes()
    data = raw[where.data_at : where.data_at + where.data_length]
    return zlib.crc32(zstandard.ZstdDecompressor().decompress(data, max_output_size=1 << 26))
