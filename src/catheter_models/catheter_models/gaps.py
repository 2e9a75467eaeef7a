"""Gaps in a stamped stream: samples its own period says should be there and are not.

Every contract stream is periodic and stamped with the instant its value was true, so a lost
sample shows as two consecutive header stamps further apart than one period. The recorder
counts gaps as messages arrive (:class:`StreamGaps`); the tools that read a bag count them
from the stamps they loaded (:func:`find_gaps`). Both apply one rule (:func:`missing_samples`).

A stream's period is learned from the stream itself (the median interval), not taken from the
contract: a rig that samples at 500 Hz or a 1 kHz control loop needs no setting. Sensor streams
run as long as their driver does, so any silence is a loss. Command streams (``pressure/command``,
``angle/desired``) stop between runs, so a silence longer than ``pause_s`` is read as a pause,
not a loss: a lost stretch longer than that in a command stream is not counted.
"""

from __future__ import annotations

import struct
import threading
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from catheter_models.contract import RUN_STREAMS
from catheter_models.units import NS_PER_S, ns_to_s

GAP_FACTOR = 1.5
"""An interval longer than this many periods holds at least one lost sample."""

PAUSE_S = 0.5
"""In a stream that stops between runs, a longer silence is a pause, not a loss [s]."""

_CDR_LE = 1
"""Second byte of a little-endian CDR encapsulation header."""

_LEARN = 32
"""Intervals seen before the period is trusted (earlier ones are judged once it is)."""
_RELEARN = 256
"""The period is re-estimated from this many recent intervals, every as many messages."""


class BagGapWarning(UserWarning):
    """A stream read from a bag lacks samples (the tools say so, then go on)."""


def header_stamp_ns(data: bytes) -> int | None:
    """The ``std_msgs/Header`` stamp [ns] of a serialized message whose first field is one.

    A CDR message starts with a 4-byte encapsulation header, then (for every contract stream)
    ``header.stamp.sec`` (int32) and ``.nanosec`` (uint32). None if too short to hold one.
    Reading 8 bytes costs far less than deserializing, which matters at 5,000 messages/s.
    """
    if len(data) < 12:
        return None
    sec, nanosec = struct.unpack_from("<iI" if data[1] == _CDR_LE else ">iI", data, 4)
    return int(sec) * NS_PER_S + int(nanosec)


@dataclass(frozen=True)
class Gap:
    """Samples missing between two consecutive stamps.

    Attributes:
        after_ns: stamp of the last sample before the gap [ns].
        before_ns: stamp of the first sample after it [ns].
        missing: samples missing, by the stream's period.
    """

    after_ns: int
    before_ns: int
    missing: int

    @property
    def duration_s(self) -> float:
        """The silence [s] (missing samples times the period, plus one period)."""
        return ns_to_s(self.before_ns - self.after_ns)


def pauses_between_runs(topic: str) -> bool:
    """Whether ``topic`` (full or namespace-relative) stops between runs (a RUN_STREAM)."""
    return any(topic == s.name or topic.endswith("/" + s.name) for s in RUN_STREAMS)


def missing_samples(interval_s: float, period_s: float, *, pause_s: float | None) -> int:
    """Samples missing in one interval between consecutive stamps (0 if none, or a pause).

    Args:
        interval_s: the interval [s].
        period_s: the stream's period [s].
        pause_s: silences longer than this are pauses (None: the stream never pauses).
    """
    if not interval_s > GAP_FACTOR * period_s:
        return 0
    if pause_s is not None and interval_s > pause_s:
        return 0
    return max(1, round(interval_s / period_s) - 1)


class StreamGaps:
    """Counts gaps in one stream, message by message.

    Args:
        pauses: whether the stream stops between runs (see the module docstring).
        pause_s: the longest silence read as a loss in such a stream [s].
        keep: gaps kept for the report (the counts cover all of them).

    Thread-safe: the recorder adds stamps from its writer thread while its /diagnostics
    timer reads the gaps; a read that iterated the deque while a stamp was added raised
    "deque mutated during iteration" and killed the recorder mid-run (exit 1).
    """

    def __init__(self, *, pauses: bool, pause_s: float = PAUSE_S, keep: int = 100) -> None:
        self.pause_s = pause_s if pauses else None
        self.samples = 0
        self.lost = 0
        """Samples missing, over all gaps."""
        self.gap_count = 0
        self.out_of_order = 0
        """Stamps not later than the one before (counted; one that falls in the latest gap
        takes a sample off it)."""
        self.gaps: deque[Gap] = deque(maxlen=keep)
        """The most recent gaps."""
        self.period_s: float | None = None
        self._intervals: deque[int] = deque(maxlen=_RELEARN)
        self._pending: list[tuple[int, int]] = []
        self._last_ns: int | None = None
        self._lock = threading.Lock()

    def add(self, stamp_ns: int) -> None:
        """One message's header stamp [ns]."""
        with self._lock:
            self._add(stamp_ns)

    def _add(self, stamp_ns: int) -> None:
        self.samples += 1
        last, self._last_ns = self._last_ns, stamp_ns
        if last is None:
            return
        if stamp_ns <= last:
            self.out_of_order += 1
            self._last_ns = last
            self._fill(stamp_ns)
            return
        interval_ns = stamp_ns - last
        self._intervals.append(interval_ns)
        if self.period_s is None:
            self._pending.append((last, stamp_ns))
            if len(self._intervals) >= _LEARN:
                self._learn()
                pending, self._pending = self._pending, []
                for a, b in pending:
                    self._judge(a, b)
            return
        if self.samples % _RELEARN == 0:
            self._learn()
        self._judge(last, stamp_ns)

    def _fill(self, stamp_ns: int) -> None:
        """A late sample inside the latest gap was not lost after all."""
        if not self.gaps:
            return
        gap = self.gaps[-1]
        if gap.after_ns < stamp_ns < gap.before_ns:
            self.lost -= 1
            self.gaps.pop()
            if gap.missing > 1:
                self.gaps.append(Gap(gap.after_ns, gap.before_ns, gap.missing - 1))
            else:
                self.gap_count -= 1

    def _learn(self) -> None:
        self.period_s = ns_to_s(float(np.median(np.fromiter(self._intervals, np.int64))))

    def _judge(self, after_ns: int, before_ns: int) -> None:
        assert self.period_s is not None
        missing = missing_samples(
            ns_to_s(before_ns - after_ns), self.period_s, pause_s=self.pause_s
        )
        if missing:
            self.lost += missing
            self.gap_count += 1
            self.gaps.append(Gap(after_ns, before_ns, missing))

    @property
    def longest_s(self) -> float:
        """The longest kept gap [s] (0 if none)."""
        with self._lock:
            return max((g.duration_s for g in self.gaps), default=0.0)


def find_gaps(
    t_s: NDArray[np.floating], *, pauses: bool, pause_s: float = PAUSE_S
) -> tuple[float, list[tuple[float, float, int]]]:
    """Gaps in a loaded stream: its period [s] and (after_s, before_s, missing) per gap.

    Args:
        t_s: the stream's stamps [s], ascending.
        pauses: whether the stream stops between runs.
        pause_s: the longest silence read as a loss in such a stream [s].
    """
    t = np.asarray(t_s, dtype=float)
    if t.size < 3:
        return float("nan"), []
    dt = np.diff(t)
    period_s = float(np.median(dt[dt > 0])) if np.any(dt > 0) else float("nan")
    if not period_s > 0.0:
        return period_s, []
    limit = pause_s if pauses else None
    out: list[tuple[float, float, int]] = []
    for i in np.flatnonzero(dt > GAP_FACTOR * period_s):
        missing = missing_samples(float(dt[i]), period_s, pause_s=limit)
        if missing:
            out.append((float(t[i]), float(t[i + 1]), missing))
    return period_s, out


def describe_gaps(
    name: str, t_s: NDArray[np.floating], *, pauses: bool, origin_s: float = 0.0
) -> str | None:
    """One line on a stream's gaps for a person (None if it has none).

    Args:
        name: the stream's name.
        t_s: its stamps [s].
        pauses: whether the stream stops between runs.
        origin_s: subtracted from the times shown [s].
    """
    period_s, found = find_gaps(t_s, pauses=pauses)
    return say_gaps(name, period_s, found, origin_s=origin_s)


def say_gaps(
    name: str, period_s: float, found: list[tuple[float, float, int]], *, origin_s: float = 0.0
) -> str | None:
    """:func:`describe_gaps` for what :func:`find_gaps` already returned."""
    if not found:
        return None
    lost = sum(m for _, _, m in found)
    after_s, before_s, _ = max(found, key=lambda g: g[1] - g[0])
    return (
        f"{name} lacks {lost} samples in {len(found)} gap(s) at its {1.0 / period_s:.0f} Hz; "
        f"the longest {1e3 * (before_s - after_s):.0f} ms, after t = {after_s - origin_s:.3f} s"
    )
