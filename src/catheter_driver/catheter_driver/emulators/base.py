"""What every emulator shares: a serving thread, fault injection, start/stop, fail-safe."""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Literal

from catheter_models.errors import ParameterError

Fault = Literal["none", "no_reply", "bad_crc", "garbage"]
"""Faults an emulator can inject into its replies or stream:

* ``no_reply``: say nothing (a device that is off or unplugged at its end);
* ``bad_crc``: send frames with a corrupted checksum (CAN: a frame of the wrong length);
* ``garbage``: send random bytes before each frame (CAN: a junk frame before each frame).
"""
FAULTS: tuple[Fault, ...] = ("none", "no_reply", "bad_crc", "garbage")


class Emulator(ABC):
    """A device emulator with a serving thread and injectable faults.

    Args:
        name: thread name.
    """

    def __init__(self, name: str) -> None:
        self._name = name
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._fault_lock = threading.Lock()
        self._fault: Fault = "none"
        self._fault_left: int | None = None
        self.error: BaseException | None = None
        """An exception that ended the serving thread, kept for the owner to report."""

    def inject(self, fault: Fault, count: int | None = None) -> None:
        """Inject ``fault`` into the next ``count`` replies or frames (None: until cleared).

        Raises:
            ParameterError: unknown fault.
        """
        if fault not in FAULTS:
            raise ParameterError(f"unknown fault {fault!r}; valid: {', '.join(FAULTS)}")
        with self._fault_lock:
            self._fault = fault
            self._fault_left = count

    @property
    def fault(self) -> Fault:
        """The fault being injected now ("none" if none)."""
        with self._fault_lock:
            return self._fault

    def _take_fault(self) -> Fault:
        """The fault for the frame about to be sent (counts a limited injection down)."""
        with self._fault_lock:
            fault = self._fault
            if fault != "none" and self._fault_left is not None:
                self._fault_left -= 1
                if self._fault_left <= 0:
                    self._fault, self._fault_left = "none", None
            return fault

    def start(self) -> None:
        """Open the endpoint and start serving."""
        self._open()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=self._name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        """Stop serving and close the endpoint (the driver sees its port or bus go away)."""
        self._stop.set()
        thread, self._thread = self._thread, None
        if thread is not None and thread is not threading.current_thread():
            thread.join(2.0)
        self._close()

    @property
    def running(self) -> bool:
        """Whether the serving thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    def _run(self) -> None:
        try:
            while not self._stop.is_set():
                self._serve(0.05)
        except BaseException as exc:  # kept for the owner; a silent death would hang tests
            self.error = exc
            raise

    @abstractmethod
    def _open(self) -> None:
        """Open the emulator's end of the wire."""

    @abstractmethod
    def _close(self) -> None:
        """Close the emulator's end of the wire."""

    @abstractmethod
    def _serve(self, timeout_s: float) -> None:
        """Handle what arrived within ``timeout_s`` (streaming emulators may just wait)."""


class HostFailsafe:
    """A set-point device's own fail-safe: vent when its host goes silent.

    Real valve interfaces do this in the device (a bridge firmware watchdog, a CANopen
    RPDO or heartbeat timeout): if no set-point arrives for ``timeout_s``, the output drops
    to zero and stays there until the next set-point. The host that crashes, hangs or loses
    its cable thus never leaves the muscle inflated. Armed by each set-point; disarmed when
    it trips (it trips once per silence).

    Args:
        timeout_s: silence that trips it [s]; ``math.inf`` disables it.
        vent: what tripping does (called on the serving thread).
    """

    def __init__(self, timeout_s: float, vent: Callable[[], None]) -> None:
        if not timeout_s > 0.0:
            raise ParameterError(f"failsafe_timeout_s must be > 0 s, got {timeout_s!r}")
        self.timeout_s = timeout_s
        self._vent = vent
        self._lock = threading.Lock()
        self._deadline_s: float | None = None
        self.trips = 0
        """Times it has vented, since creation."""
        self.tripped_at_s: float | None = None
        """Monotonic time of the latest trip [s]; None before any."""
        self.last_setpoint_s: float | None = None
        """Monotonic time of the latest set-point [s]; None before any."""

    def fed(self, now_s: float) -> None:
        """A set-point arrived at ``now_s``: re-arm."""
        with self._lock:
            self.last_setpoint_s = now_s
            self._deadline_s = now_s + self.timeout_s

    def wait_s(self, now_s: float, longest_s: float) -> float:
        """How long the serving thread may block before it must :meth:`check` again [s]."""
        with self._lock:
            if self._deadline_s is None:
                return longest_s
            return min(longest_s, max(self._deadline_s - now_s, 0.0))

    def check(self, now_s: float) -> bool:
        """Vent if armed and silent for ``timeout_s``; True if it vented now."""
        with self._lock:
            if self._deadline_s is None or now_s < self._deadline_s:
                return False
            self._deadline_s = None
            self.trips += 1
            self.tripped_at_s = now_s
        self._vent()
        return True

    def state(self) -> dict[str, object]:
        """Plain values for a status report."""
        with self._lock:
            return {
                "timeout_s": self.timeout_s,
                "armed": self._deadline_s is not None,
                "trips": self.trips,
                "tripped_at_s": self.tripped_at_s,
                "last_setpoint_s": self.last_setpoint_s,
            }
