"""The line pressure transmitter on the Keller bus (thesis: Keller series 21Y over RS485)."""

from __future__ import annotations

import math
import time
from typing import cast

from catheter_driver.devices.base import PressureTransmitter
from catheter_driver.errors import DeviceError, DeviceTimeout
from catheter_driver.protocols import keller
from catheter_driver.transports import ByteTransport, make_transport
from catheter_models.errors import ParameterError

_READ_CHUNK = 64


class KellerTransmitter(PressureTransmitter):
    """Keller transmitter: F48 at open, F73 on every reading.

    Args:
        transport: the serial line (opened and closed by this device).
        address: device address 1..249, or 250 (transparent: whichever device is connected).
        channel: F73 channel; 1 = P1, the pressure sensor.
        reference: "gauge" for PR types (reads 0 at ambient), "absolute" for PAA types.
        ambient_pa: ambient pressure subtracted from absolute readings [Pa].
        timeout_s: longest wait for a reply [s]. At 9600 baud an F73 exchange takes ~15 ms.
        echo: the RS485 adapter echoes what is sent; skip the echo before the reply.
    """

    def __init__(
        self,
        transport: ByteTransport,
        *,
        address: int = keller.TRANSPARENT_ADDRESS,
        channel: int = keller.CHANNEL_P1,
        reference: str = "gauge",
        ambient_pa: float = 101325.0,
        timeout_s: float = 0.1,
        echo: bool = False,
    ) -> None:
        super().__init__()
        # Validate by encoding once: the encoders own the ranges.
        keller.encode_read_request(address, channel)
        if not (math.isfinite(timeout_s) and timeout_s > 0.0):
            raise ParameterError(f"timeout_s must be finite and > 0 s, got {timeout_s!r}")
        if not math.isfinite(ambient_pa):
            raise ParameterError(f"ambient_pa must be finite, got {ambient_pa!r}")
        self.transport = transport
        self.address = address
        self.channel = channel
        self.reference = keller.check_reference(reference)
        self.ambient_pa = ambient_pa
        self.timeout_s = timeout_s
        self.echo = echo
        self.device_info: keller.KellerInitReply | None = None
        """The F48 reply of the last successful open."""
        self.last_status = 0
        """STAT byte of the last F73 reply, passed through for diagnostics."""
        self._parser = keller.KellerReplyParser()

    @classmethod
    def from_params(
        cls,
        *,
        port: str,
        baudrate: int = 9600,
        parity: str = "N",
        stopbits: int = 1,
        address: int = keller.TRANSPARENT_ADDRESS,
        channel: int = keller.CHANNEL_P1,
        reference: str = "gauge",
        ambient_pa: float = 101325.0,
        timeout_s: float = 0.1,
        echo: bool = False,
    ) -> KellerTransmitter:
        """Build over a serial port from plain parameters (the node passes ROS parameters).

        Args:
            port: device path or pyserial URL of the RS485 adapter.
            baudrate: 9600 is Keller's factory setting; 115200 allows > 50 readings/s.
            parity: "N", "E" or "O" (Keller: N).
            stopbits: 1 or 2 (Keller: 1).
            address: device address 1..249, or 250 for whichever device is connected.
            channel: F73 channel (1 = P1).
            reference: "gauge" (PR types) or "absolute" (PAA types).
            ambient_pa: ambient pressure for absolute types [Pa].
            timeout_s: reply timeout [s].
            echo: skip the RS485 adapter's echo of each request.
        """
        transport = make_transport(
            "serial", url=port, baudrate=baudrate, parity=parity, stopbits=stopbits
        )
        return cls(
            cast(ByteTransport, transport),
            address=address,
            channel=channel,
            reference=reference,
            ambient_pa=ambient_pa,
            timeout_s=timeout_s,
            echo=echo,
        )

    def describe(self) -> str:
        """E.g. ``keller address 1 channel 1 (gauge) on serial /dev/ttyUSB0 9600 8N1``."""
        return (
            f"keller address {self.address} channel {self.channel} ({self.reference}) on "
            f"{self.transport.describe()}"
        )

    def _open(self) -> None:
        """Open the line and initialise the device (F48).

        Raises:
            DeviceTimeout: the device does not answer F48.
            DeviceError: the port cannot be opened or the device refuses F48.
        """
        self.transport.open()
        self._initialise()

    def close(self) -> None:
        """Close the line."""
        self.transport.close()

    @property
    def is_open(self) -> bool:
        """Whether the line is open."""
        return self.transport.is_open

    def read_gauge_pa(self) -> float:
        """F73 on the pressure channel, converted to gauge [Pa] (see the base class)."""
        try:
            reply = self._transact(keller.encode_read_request(self.address, self.channel))
            if (
                isinstance(reply, keller.KellerExceptionReply)
                and reply.code == keller.KellerErrorCode.NOT_INITIALISED
            ):
                # The device lost power and came back: initialise once and ask again.
                self._initialise()
                reply = self._transact(keller.encode_read_request(self.address, self.channel))
            if isinstance(reply, keller.KellerExceptionReply):
                raise DeviceError(f"{self.describe()}: {reply.describe()}")
            if not isinstance(reply, keller.KellerValueReply):
                raise DeviceError(f"{self.describe()}: F73 answered with {reply!r}")
            if not math.isfinite(reply.value):
                raise DeviceError(
                    f"{self.describe()}: channel {self.channel} reads {reply.value!r}, not a "
                    "finite pressure (sensor fault?)"
                )
        except DeviceError as exc:
            self.counters.last_error = str(exc)
            raise
        self.last_status = reply.status
        return keller.bar_to_gauge_pa(reply.value, self.reference, self.ambient_pa)

    def _initialise(self) -> None:
        reply = self._transact(keller.encode_init_request(self.address))
        if isinstance(reply, keller.KellerExceptionReply):
            raise DeviceError(f"{self.describe()}: {reply.describe()}")
        if not isinstance(reply, keller.KellerInitReply):
            raise DeviceError(f"{self.describe()}: F48 answered with {reply!r}")
        self.device_info = reply

    def _transact(self, request: bytes) -> keller.KellerReply:
        """Send one request and return the first reply to it (exceptions included)."""
        function = request[1]
        # A late reply to an earlier, timed-out request must not answer this one.
        self.transport.reset_input()
        self._parser.reset()
        self.transport.write(request)
        echo_left = request if self.echo else b""
        deadline_s = time.monotonic() + self.timeout_s
        while True:
            left_s = deadline_s - time.monotonic()
            if left_s <= 0.0:
                self.counters.timeouts += 1
                raise DeviceTimeout(
                    f"{self.describe()}: no reply to function {function} within "
                    f"{self.timeout_s:g} s"
                )
            chunk = self.transport.read(_READ_CHUNK, left_s)
            if echo_left and chunk:
                chunk, echo_left = _strip_echo(chunk, echo_left)
            replies = self._parser.feed(chunk)
            self._sync_counters()
            for reply in replies:
                if not keller.reply_address_matches(self.address, reply.address):
                    continue  # another device on a shared bus
                if isinstance(reply, keller.KellerExceptionReply):
                    self.counters.device_errors += 1
                    if reply.function == function:
                        return reply
                elif (function == keller.FN_INIT) == isinstance(reply, keller.KellerInitReply):
                    return reply

    def _sync_counters(self) -> None:
        parsed = self._parser.counters
        self.counters.frames_ok = parsed.frames_ok
        self.counters.frame_errors = parsed.frame_errors
        self.counters.crc_failures = parsed.crc_failures


def _strip_echo(chunk: bytes, echo_left: bytes) -> tuple[bytes, bytes]:
    """Remove the adapter's echo of our request from the front of ``chunk``.

    Returns the rest of the chunk and the echo still expected. If the bytes differ from the
    request, the adapter does not echo after all: nothing is stripped and no echo is expected.
    """
    n = min(len(chunk), len(echo_left))
    if chunk[:n] != echo_left[:n]:
        return chunk, b""
    return chunk[n:], echo_left[n:]
