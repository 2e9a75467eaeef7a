"""What every emulator shares: a serving thread, fault injection, start/stop."""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod
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
