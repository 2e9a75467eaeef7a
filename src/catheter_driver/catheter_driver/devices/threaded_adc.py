"""A laser ADC whose samples are taken off the wire by a reader thread.

The thread stamps each sample with ``time.monotonic()`` as it arrives, so a node that calls
:meth:`read_samples` late still gets true receive times, and the OS buffer never overflows
while the node is busy.
"""

from __future__ import annotations

import threading
import time
from abc import abstractmethod
from collections import deque

from catheter_driver.devices.base import LaserAdc, LaserSample
from catheter_driver.errors import DeviceError
from catheter_driver.protocols.laser_adc import AdcFrame, seq_gap

_POLL_S = 0.05
"""Longest the reader blocks in one read, so close() returns promptly."""


class ThreadedLaserAdc(LaserAdc):
    """Base of the laser ADC devices: a reader thread and a bounded sample queue.

    Subclasses open and close their link and take frames off it in :meth:`_poll`.

    Args:
        max_samples: samples kept when nobody reads (the oldest drop): 10 000 = 40 s at 250 Hz.
    """

    def __init__(self, max_samples: int = 10_000) -> None:
        super().__init__()
        self._samples: deque[LaserSample] = deque(maxlen=max_samples)
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._error: DeviceError | None = None
        self._last_seq: int | None = None
        self.samples_lost = 0
        """Samples missing from the sequence counter (gaps), since creation."""

    @abstractmethod
    def _open_link(self) -> None:
        """Open the transport."""

    @abstractmethod
    def _close_link(self) -> None:
        """Close the transport."""

    @abstractmethod
    def _link_open(self) -> bool:
        """Whether the transport is open."""

    @abstractmethod
    def _poll(self, timeout_s: float) -> list[AdcFrame]:
        """Frames received within ``timeout_s`` (maybe none). Raises DeviceError if down."""

    def _open(self) -> None:
        """Open the link and start the reader thread."""
        self.close()
        self._open_link()
        with self._cond:
            self._samples.clear()
            self._error = None
            self._last_seq = None
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=type(self).__name__, daemon=True)
        self._thread.start()

    def close(self) -> None:
        """Stop the reader and close the link (idempotent)."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)
        self._close_link()
        with self._cond:
            self._cond.notify_all()

    @property
    def is_open(self) -> bool:
        """Whether the link is open and the reader running."""
        return self._link_open() and self._thread is not None and self._thread.is_alive()

    def read_samples(self, timeout_s: float) -> list[LaserSample]:
        """Every sample since the last call (see the base class).

        Samples that arrived before the link failed are returned first; the failure is
        raised on the call after.
        """
        deadline_s = time.monotonic() + timeout_s
        with self._cond:
            while not self._samples and self._error is None and self._thread is not None:
                left_s = deadline_s - time.monotonic()
                if left_s <= 0.0:
                    break
                self._cond.wait(left_s)
            if self._samples:
                out = list(self._samples)
                self._samples.clear()
                return out
            if self._error is not None:
                raise self._error
            if self._thread is None:
                raise DeviceError(f"{self.describe()} is not open")
            return []

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                frames = self._poll(_POLL_S)
            except DeviceError as exc:
                self.counters.last_error = str(exc)
                with self._cond:
                    self._error = exc
                    self._cond.notify_all()
                return
            if not frames:
                continue
            receive_s = time.monotonic()
            with self._cond:
                for frame in frames:
                    if self._last_seq is not None:
                        self.samples_lost += seq_gap(self._last_seq, frame.seq)
                    self._last_seq = frame.seq
                    self._samples.append(LaserSample(frame.seq, frame.voltage_v, receive_s))
                self._cond.notify_all()
