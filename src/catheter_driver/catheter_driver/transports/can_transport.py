"""A :class:`FrameTransport` over python-can, with any of its interfaces.

``interface`` is python-can's name (``socketcan``, ``pcan``, ``kvaser``, ``virtual``, ...);
python-can itself imports the chosen interface only when asked. ``can`` is imported here and
only here.
"""

from __future__ import annotations

import contextlib
from typing import Any

import can

from catheter_driver.transports.base import FrameTransport, TransportError
from catheter_models.errors import ParameterError

_MAX_STANDARD_ID = 0x7FF
_MAX_EXTENDED_ID = 0x1FFFFFFF


class CanTransport(FrameTransport):
    """A CAN bus through python-can.

    Args:
        interface: python-can interface name, e.g. ``socketcan`` or ``virtual``.
        channel: interface channel, e.g. ``can0``; for ``virtual``, any name shared by peers.
        bitrate: bus rate [bit/s]; None leaves the interface's setting (SocketCAN sets it with
            ``ip link``, not from here).
        receive_own_messages: whether frames this bus sends come back from ``recv``.
        **options: further keyword arguments for ``can.Bus`` (interface-specific).
    """

    def __init__(
        self,
        interface: str = "socketcan",
        channel: str = "can0",
        bitrate: int | None = None,
        receive_own_messages: bool = False,
        **options: Any,
    ) -> None:
        if not interface:
            raise ParameterError("CAN interface is empty; e.g. 'socketcan' or 'virtual'")
        if bitrate is not None and not bitrate > 0:
            raise ParameterError(f"CAN bitrate must be > 0 bit/s or unset, got {bitrate!r}")
        self.interface = interface
        self.channel = channel
        self.bitrate = bitrate
        self.receive_own_messages = receive_own_messages
        self.options = options
        self._bus: can.BusABC | None = None

    def describe(self) -> str:
        """E.g. ``can socketcan:can0 500000 bit/s``."""
        rate = f" {self.bitrate} bit/s" if self.bitrate else ""
        return f"can {self.interface}:{self.channel}{rate}"

    def open(self) -> None:
        """Open the bus."""
        self.close()
        kwargs: dict[str, Any] = dict(self.options)
        if self.bitrate is not None:
            kwargs["bitrate"] = self.bitrate
        try:
            self._bus = can.Bus(
                interface=self.interface,
                channel=self.channel,
                receive_own_messages=self.receive_own_messages,
                **kwargs,
            )
        except (can.CanError, OSError, ValueError, ImportError) as exc:
            raise TransportError(f"cannot open {self.describe()}: {exc}") from None

    def close(self) -> None:
        """Shut the bus down (idempotent)."""
        bus, self._bus = self._bus, None
        if bus is not None:
            # Already gone is fine: closed is what the caller wanted.
            with contextlib.suppress(can.CanError, OSError):
                bus.shutdown()

    @property
    def is_open(self) -> bool:
        """Whether the bus is open."""
        return self._bus is not None

    def _require(self) -> can.BusABC:
        if self._bus is None:
            raise TransportError(f"{self.describe()} is not open")
        return self._bus

    def send(self, arbitration_id: int, data: bytes) -> None:
        """Send one frame (see :meth:`FrameTransport.send`)."""
        bus = self._require()
        if not 0 <= arbitration_id <= _MAX_EXTENDED_ID:
            raise TransportError(
                f"CAN id 0x{arbitration_id:X} is outside 0..0x{_MAX_EXTENDED_ID:X}"
            )
        if len(data) > 8:
            raise TransportError(f"CAN frame data is {len(data)} bytes; classic CAN carries 8")
        msg = can.Message(
            arbitration_id=arbitration_id,
            data=data,
            is_extended_id=arbitration_id > _MAX_STANDARD_ID,
        )
        try:
            bus.send(msg)
        except (can.CanError, OSError, ValueError) as exc:
            raise TransportError(f"send on {self.describe()} failed: {exc}") from None

    def recv(self, timeout_s: float) -> tuple[int, bytes] | None:
        """The next data frame, or None on timeout (see :meth:`FrameTransport.recv`)."""
        bus = self._require()
        deadline_left_s = timeout_s
        try:
            while True:
                msg = bus.recv(timeout=deadline_left_s)
                if msg is None:
                    return None
                # Error and remote frames carry no data for a device; skip, keep waiting once.
                if msg.is_error_frame or msg.is_remote_frame:
                    deadline_left_s = 0.0
                    continue
                return msg.arbitration_id, bytes(msg.data)
        except (can.CanError, OSError, ValueError) as exc:
            raise TransportError(f"receive on {self.describe()} failed: {exc}") from None
