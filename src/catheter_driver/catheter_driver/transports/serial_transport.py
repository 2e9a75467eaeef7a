"""A :class:`ByteTransport` over pyserial's ``serial_for_url``.

Any URL pyserial knows works: a device path (``/dev/ttyUSB0``, ``COM3``), a pty slave path
from an emulator, ``loop://``, ``socket://host:port``, ``rfc2217://host:port``. pyserial is
imported here and only here, so a node that uses CAN alone never needs it.
"""

from __future__ import annotations

import contextlib

import serial

from catheter_driver.transports.base import ByteTransport, TransportError
from catheter_models.errors import ParameterError

try:
    import termios

    # tcflush/tcsetattr on a hung-up tty raise termios.error, which is not an OSError.
    _PLATFORM_ERRORS: tuple[type[Exception], ...] = (termios.error,)
except ImportError:  # Windows has no termios; pyserial raises SerialException there
    _PLATFORM_ERRORS = ()

_ERRORS = (serial.SerialException, OSError, ValueError, TypeError, *_PLATFORM_ERRORS)
"""What pyserial lets through when a port fails: all become TransportError here."""

_PARITIES = {"N": serial.PARITY_NONE, "E": serial.PARITY_EVEN, "O": serial.PARITY_ODD}
_STOPBITS = {1: serial.STOPBITS_ONE, 2: serial.STOPBITS_TWO}


class SerialTransport(ByteTransport):
    """A serial port by URL.

    Args:
        url: device path or pyserial URL.
        baudrate: line rate [bit/s]; ignored by pty, ``loop://`` and sockets.
        parity: "N", "E" or "O".
        stopbits: 1 or 2.
        write_timeout_s: longest a write may block [s] (a hung adapter must not hang the node).
    """

    def __init__(
        self,
        url: str,
        baudrate: int = 9600,
        parity: str = "N",
        stopbits: int = 1,
        write_timeout_s: float = 0.5,
    ) -> None:
        if not url:
            raise ParameterError("serial port URL is empty; give a device path or pyserial URL")
        if parity not in _PARITIES:
            raise ParameterError(f"parity must be one of {', '.join(_PARITIES)}, got {parity!r}")
        if stopbits not in _STOPBITS:
            raise ParameterError(f"stopbits must be 1 or 2, got {stopbits!r}")
        if not baudrate > 0:
            raise ParameterError(f"baudrate must be > 0 bit/s, got {baudrate!r}")
        self.url = url
        self.baudrate = int(baudrate)
        self.parity = parity
        self.stopbits = stopbits
        self.write_timeout_s = write_timeout_s
        self._port: serial.SerialBase | None = None
        self._timeout_s: float | None = None

    def describe(self) -> str:
        """E.g. ``serial /dev/ttyUSB0 9600 8N1``."""
        return f"serial {self.url} {self.baudrate} 8{self.parity}{self.stopbits}"

    def open(self) -> None:
        """Open the port and discard anything already buffered."""
        self.close()
        try:
            port = serial.serial_for_url(
                self.url,
                baudrate=self.baudrate,
                parity=_PARITIES[self.parity],
                stopbits=_STOPBITS[self.stopbits],
                timeout=0,
                write_timeout=self.write_timeout_s,
            )
            port.reset_input_buffer()
        except _ERRORS as exc:
            raise TransportError(f"cannot open {self.describe()}: {exc}") from None
        self._port = port
        self._timeout_s = 0.0

    def close(self) -> None:
        """Close the port (idempotent; errors while closing a dead port are ignored)."""
        port, self._port = self._port, None
        if port is not None:
            # Already gone is fine: closed is what the caller wanted.
            with contextlib.suppress(*_ERRORS):
                port.close()

    @property
    def is_open(self) -> bool:
        """Whether the port is open."""
        return self._port is not None and bool(self._port.is_open)

    def _require(self) -> serial.SerialBase:
        if self._port is None:
            raise TransportError(f"{self.describe()} is not open")
        return self._port

    def write(self, data: bytes) -> None:
        """Send all of ``data`` (see :meth:`ByteTransport.write`)."""
        port = self._require()
        try:
            port.write(data)
        except _ERRORS as exc:
            raise TransportError(f"write to {self.describe()} failed: {exc}") from None

    def read(self, n: int, timeout_s: float) -> bytes:
        """Up to ``n`` bytes, as soon as one arrives (see :meth:`ByteTransport.read`)."""
        port = self._require()
        try:
            # Setting the timeout reconfigures some ports (a syscall), so only on change.
            if self._timeout_s != timeout_s:
                port.timeout = timeout_s
                self._timeout_s = timeout_s
            first = port.read(1)
            if not first or n <= 1:
                return bytes(first)
            waiting = port.in_waiting
            if waiting <= 0:
                return bytes(first)
            port.timeout = 0
            self._timeout_s = 0.0
            return bytes(first) + bytes(port.read(min(n - 1, waiting)))
        except _ERRORS as exc:
            raise TransportError(f"read from {self.describe()} failed: {exc}") from None

    def reset_input(self) -> None:
        """Discard buffered input."""
        port = self._require()
        try:
            port.reset_input_buffer()
        except _ERRORS as exc:
            raise TransportError(f"reset of {self.describe()} failed: {exc}") from None
