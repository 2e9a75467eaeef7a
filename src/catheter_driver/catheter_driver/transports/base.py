"""The two wires a device can sit behind: a byte stream (serial) and a frame bus (CAN).

Like python-can's ``BusABC``, each is a small abstract class; a backend implements only the
I/O. Every failure of the underlying library (port unplugged, bus down) surfaces as
:class:`TransportError`, a :class:`~catheter_driver.errors.DeviceError`, so callers
never catch pyserial or python-can exceptions.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType

from catheter_driver.errors import DeviceError


class TransportError(DeviceError):
    """The transport failed: not open, port gone, bus down. The message names the port."""


class _Openable(ABC):
    """Open/close and context-manager plumbing shared by both transport kinds."""

    @abstractmethod
    def open(self) -> None:
        """Open the port or bus. Raises TransportError if it cannot."""

    @abstractmethod
    def close(self) -> None:
        """Close the port or bus (idempotent)."""

    @property
    @abstractmethod
    def is_open(self) -> bool:
        """Whether the port or bus is open."""

    @abstractmethod
    def describe(self) -> str:
        """One line naming the transport and its port or channel."""

    def __enter__(self) -> _Openable:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


class ByteTransport(_Openable):
    """A byte stream: RS232/RS485 through a USB adapter, a pty, a TCP serial server."""

    @abstractmethod
    def write(self, data: bytes) -> None:
        """Send all of ``data``.

        Raises:
            TransportError: the port is closed or gone.
        """

    @abstractmethod
    def read(self, n: int, timeout_s: float) -> bytes:
        """Up to ``n`` bytes, returning as soon as at least one has arrived.

        Args:
            n: most bytes to return.
            timeout_s: longest wait for the first byte [s]; 0 polls.

        Returns:
            The bytes read; empty if none arrived within ``timeout_s``.

        Raises:
            TransportError: the port is closed or gone.
        """

    @abstractmethod
    def reset_input(self) -> None:
        """Discard bytes received but not yet read (stale replies before a new request)."""


class FrameTransport(_Openable):
    """A frame bus: CAN through SocketCAN, a USB-CAN adapter, or python-can's virtual bus."""

    @abstractmethod
    def send(self, arbitration_id: int, data: bytes) -> None:
        """Send one frame (11-bit id up to 0x7FF, 29-bit above).

        Raises:
            TransportError: the bus is closed or down, or the frame is invalid.
        """

    @abstractmethod
    def recv(self, timeout_s: float) -> tuple[int, bytes] | None:
        """The next frame as ``(arbitration_id, data)``, or None after ``timeout_s`` [s].

        Raises:
            TransportError: the bus is closed or down.
        """
