"""Shared helpers for fuzzing the streaming parsers (imported by the protocol tests)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from hypothesis import strategies as st


def feed_in_chunks(parser: Any, data: bytes, cuts: Sequence[int]) -> list[Any]:
    """Feed ``data`` split at ``cuts`` (positions, any order) and collect every frame."""
    out: list[Any] = []
    last = 0
    for cut in sorted({c % (len(data) + 1) for c in cuts}):
        out += parser.feed(data[last:cut])
        last = cut
    out += parser.feed(data[last:])
    return out


def garbage_without(forbidden: set[int], max_size: int = 40) -> st.SearchStrategy[bytes]:
    """Random bytes that contain none of ``forbidden`` (so no frame can start in them)."""
    allowed = [b for b in range(256) if b not in forbidden]
    return st.lists(st.sampled_from(allowed), max_size=max_size).map(bytes)


CUTS = st.lists(st.integers(min_value=0, max_value=10_000), max_size=8)


def interleave(garbage: Sequence[bytes], frames: Sequence[bytes]) -> bytes:
    """garbage[0] + frames[0] + garbage[1] + ... + garbage[-1]."""
    out = bytearray()
    for i, frame in enumerate(frames):
        out += garbage[i % len(garbage)] if garbage else b""
        out += frame
    out += garbage[-1] if garbage else b""
    return bytes(out)


Encoder = Callable[..., bytes]


def spurious_frame_before(decode: Callable[[bytes], Any], data: bytes, end: int) -> bool:
    """Whether a checksum-valid frame starts anywhere in ``data[:end]``.

    A truncated or corrupted frame followed by a good one can, by chance (1 in 256 for a
    CRC-8, 1 in 65536 for a CRC-16), form a valid frame across the boundary; no parser can
    tell it from a real one. Properties that expect the good frame exclude those cases.
    """
    for i in range(end):
        for n in range(3, 13):
            try:
                decode(data[i : i + n])
            except ValueError:  # FrameError
                continue
            return True
    return False
