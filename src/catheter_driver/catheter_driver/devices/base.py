"""The devices of the thesis's rig as small abstract classes, whatever wire carries them.

A driver node talks to a :class:`PressureTransmitter`, a :class:`ValveSetpoint` and a
:class:`LaserAdc`; which protocol and transport sit behind each is a name in the node's
parameters (``devices.factory``). Emulators implement the same wire protocols, so the real
node code runs against them unchanged. Nothing here imports rclpy.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

from catheter_driver.errors import DeviceError


@dataclass
class DeviceCounters:
    """Health of one device link since it was created (diagnostics read these).

    Attributes:
        frames_ok: frames received and accepted.
        frame_errors: frames dropped as malformed (bad length, bad header, garbage).
        crc_failures: frames dropped for a bad checksum.
        timeouts: requests that got no reply in time.
        reconnects: successful re-opens after the link was lost.
        device_errors: exception replies from the device itself.
    """

    frames_ok: int = 0
    frame_errors: int = 0
    crc_failures: int = 0
    timeouts: int = 0
    reconnects: int = 0
    device_errors: int = 0
    last_error: str = field(default="")

    def as_dict(self) -> dict[str, object]:
        """Flat key/values for /diagnostics."""
        return {
            "frames_ok": self.frames_ok,
            "frame_errors": self.frame_errors,
            "crc_failures": self.crc_failures,
            "timeouts": self.timeouts,
            "reconnects": self.reconnects,
            "device_errors": self.device_errors,
            "last_error": self.last_error,
        }


class Device(ABC):
    """A device behind some transport. ``open`` may be called again after ``close``."""

    def __init__(self) -> None:
        self.counters = DeviceCounters()
        self._opened_before = False

    def open(self) -> None:
        """Open the link and initialise the device. Raises DeviceError if it cannot.

        Every successful open after the first counts as a reconnect, here and only here, so
        a driver that re-opens a lost device never counts it twice. A failed open records
        the error and closes whatever was half opened, also here, for every backend.
        """
        try:
            self._open()
        except DeviceError as exc:
            self.counters.last_error = str(exc)
            self.close()
            raise
        if self._opened_before:
            self.counters.reconnects += 1
        self._opened_before = True

    @abstractmethod
    def _open(self) -> None:
        """Open the link and initialise the device (backend-specific)."""

    @abstractmethod
    def close(self) -> None:
        """Close the link (idempotent)."""

    @property
    @abstractmethod
    def is_open(self) -> bool:
        """Whether the link is open."""

    def describe(self) -> str:
        """One line naming the protocol and transport, for logs and diagnostics."""
        return type(self).__name__


class PressureTransmitter(Device):
    """The line pressure transmitter (thesis: Keller 21Y series, RS485)."""

    @abstractmethod
    def read_gauge_pa(self) -> float:
        """One reading of the line pressure, gauge [Pa].

        Raises:
            DeviceTimeout: no reply in time.
            DeviceError: the link is down or the device answered with an error.
        """


class ValveSetpoint(Device):
    """The proportional pressure regulator's set-point input (thesis: Festo, 0-3 bar)."""

    @abstractmethod
    def write_setpoint_pa(self, gauge_pa: float) -> None:
        """Command a set-point, gauge [Pa]. The caller has already clamped it."""

    def read_back_pa(self) -> float | None:
        """The set-point the device reports it holds, gauge [Pa]; None if it cannot say."""
        return None


@dataclass(frozen=True)
class LaserSample:
    """One laser reading from the ADC bridge.

    Attributes:
        seq: the bridge's sample counter (wraps; gaps show lost samples).
        voltage_v: the laser's analog output [V] (eq. 3.1 input).
        receive_s: monotonic time the frame was taken off the wire [s].
    """

    seq: int
    voltage_v: float
    receive_s: float


class LaserAdc(Device):
    """The laser distance sensor's analog output, sampled by an ADC bridge (250 Hz)."""

    @abstractmethod
    def read_samples(self, timeout_s: float) -> list[LaserSample]:
        """Every complete sample received since the last call.

        Waits up to ``timeout_s`` for at least one. Malformed frames are counted and
        dropped, never raised.

        Raises:
            DeviceError: the link is down.
        """
