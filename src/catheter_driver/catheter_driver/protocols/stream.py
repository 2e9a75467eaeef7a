"""The resynchronising loop every byte-stream protocol here shares.

A subclass says where a frame could start and how long it is, whether its checksum holds and
what it decodes to; this class finds frames in whatever bytes arrive, in whatever chunks,
drops garbage a byte at a time (so a valid frame right behind a false start is never lost)
and counts what it dropped.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Generic, TypeVar

from catheter_driver.protocols import ParserCounters

T = TypeVar("T")

NEED_MORE = -1
"""``_frame_length`` result: the bytes so far could start a frame; wait for more."""
NOT_A_FRAME = 0
"""``_frame_length`` result: no frame starts here; drop a byte."""


class StreamParser(ABC, Generic[T]):
    """Streaming frame parser: ``feed`` bytes, get decoded frames; never raises on input.

    Args:
        max_buffer: most bytes held while waiting for a frame to complete; beyond it the
            oldest are dropped (a stream of garbage must not grow memory).
    """

    def __init__(self, max_buffer: int = 4096) -> None:
        self.counters = ParserCounters()
        self._buf = bytearray()
        self._max_buffer = max_buffer
        self._in_garbage = False

    @abstractmethod
    def _frame_length(self, buf: bytearray, start: int) -> int:
        """Total length of a frame starting at ``buf[start]``, or NEED_MORE / NOT_A_FRAME."""

    @abstractmethod
    def _crc_ok(self, frame: bytes) -> bool:
        """Whether the frame's checksum holds."""

    @abstractmethod
    def _decode(self, frame: bytes) -> T | None:
        """The frame's value, or None if a field is invalid despite a good checksum."""

    def reset(self) -> None:
        """Forget buffered bytes (before a new request, so a stale reply cannot match it)."""
        self._buf.clear()
        self._in_garbage = False

    @property
    def buffered(self) -> int:
        """Bytes held, waiting for a frame to complete."""
        return len(self._buf)

    def _drop(self, n: int) -> None:
        self.counters.bytes_dropped += n
        if not self._in_garbage:
            self.counters.frame_errors += 1
            self._in_garbage = True

    def _complete_frame_at(self, buf: bytearray, start: int) -> T | None:
        """The decoded frame at ``start`` if one lies there complete and valid."""
        n = self._frame_length(buf, start)
        if n <= 0 or start + n > len(buf):
            return None
        frame = bytes(buf[start : start + n])
        return self._decode(frame) if self._crc_ok(frame) else None

    def feed(self, data: bytes) -> list[T]:
        """Add received bytes; return every frame completed by them, oldest first."""
        buf = self._buf
        buf += data
        out: list[T] = []
        i = 0
        while i < len(buf):
            n = self._frame_length(buf, i)
            if n == NOT_A_FRAME:
                self._drop(1)
                i += 1
                continue
            if n == NEED_MORE or i + n > len(buf):
                # A false start (garbage that looks like a header) would hold every later
                # frame hostage until enough bytes arrive; if a complete valid frame already
                # lies further on, the false start was garbage.
                ahead = next(
                    (j for j in range(i + 1, len(buf)) if self._complete_frame_at(buf, j)),
                    None,
                )
                if ahead is None:
                    break
                self._drop(ahead - i)
                i = ahead
                continue
            frame = bytes(buf[i : i + n])
            if not self._crc_ok(frame):
                self.counters.crc_failures += 1
                self.counters.bytes_dropped += 1
                self._in_garbage = True  # the rest of this frame is not a new error
                i += 1
                continue
            value = self._decode(frame)
            if value is None:
                self._drop(1)
                i += 1
                continue
            out.append(value)
            self.counters.frames_ok += 1
            self._in_garbage = False
            i += n
        del buf[:i]
        if len(buf) > self._max_buffer:
            excess = len(buf) - self._max_buffer
            self._drop(excess)
            del buf[:excess]
        return out
