"""A Keller transmitter on the Keller bus, reading the emulated rig's line pressure."""

from __future__ import annotations

import threading

from catheter_driver.emulators.base import Emulator
from catheter_driver.emulators.rig_core import EmulatedRig
from catheter_driver.protocols import keller
from catheter_driver.transports.base import ByteTransport, TransportError

_GARBAGE = b"\x00\xff\x37\x49\x01\x30\x13"
"""Injected junk: holds false starts (55, 73 and 1, 48) so the driver must resync."""


class KellerEmulator(Emulator):
    """Answers F48 and F73 like a Keller 21Y/30 series transmitter.

    F73 channel P1 (and P2) report the rig's measured line pressure in bar, TOB1/T a fixed
    23 degC; other channels answer "incorrect parameter", other functions "non-implemented".
    After :meth:`power_cycle` F73 answers "not initialised" until the next F48.

    Args:
        rig: the emulated rig whose pressure is read.
        endpoint: the emulator's end of the line (e.g. :class:`PtyEndpoint`).
        address: this device's address 1..249 (it also answers the transparent 250).
        reference: "gauge" (PR type) or "absolute" (PAA type, reads ambient at 0 gauge).
        echo: echo every request back first, like an RS485 adapter without echo suppression.
    """

    TEMPERATURE_C = 23.0

    def __init__(
        self,
        rig: EmulatedRig,
        endpoint: ByteTransport,
        *,
        address: int = 1,
        reference: str = "gauge",
        echo: bool = False,
    ) -> None:
        super().__init__(f"keller-emulator-{address}")
        keller.encode_value_reply(address, 0.0)  # validates the address
        self.rig = rig
        self.endpoint = endpoint
        self.address = address
        self.reference = keller.check_reference(reference)
        self.echo = echo
        self.requests = 0
        """Requests addressed to this device, since creation."""
        self._parser = keller.KellerRequestParser()
        self._initialised = threading.Event()

    def power_cycle(self) -> None:
        """Forget the F48 initialisation, as after a power loss."""
        self._initialised.clear()

    def _open(self) -> None:
        self.endpoint.open()

    def _close(self) -> None:
        self.endpoint.close()

    def _serve(self, timeout_s: float) -> None:
        try:
            data = self.endpoint.read(256, timeout_s)
        except TransportError:
            # The line is gone (unplugged, or closed by stop()): wait, do not spin.
            self._stop.wait(timeout_s)
            return
        for request in self._parser.feed(data):
            if request.address not in (self.address, keller.TRANSPARENT_ADDRESS):
                continue
            self.requests += 1
            raw = bytes((request.address, request.function)) + request.payload
            reply = self._reply(request)
            self._send(keller.with_crc(raw) if self.echo else b"", reply)

    def _reply(self, request: keller.KellerRequest) -> bytes:
        if request.function == keller.FN_INIT and not request.payload:
            state = 1 if self._initialised.is_set() else 0
            self._initialised.set()
            return keller.encode_init_reply(
                keller.KellerInitReply(self.address, 5, 20, 24, 10, 10, state)
            )
        if request.function == keller.FN_READ_FLOAT and len(request.payload) == 1:
            if not self._initialised.is_set():
                code = keller.KellerErrorCode.NOT_INITIALISED
                return keller.encode_exception_reply(self.address, request.function, code)
            channel = request.payload[0]
            if channel in (keller.CHANNEL_P1, keller.CHANNEL_P2):
                value = keller.gauge_pa_to_bar(
                    self.rig.measured_pressure_pa, self.reference, self.rig.ambient_pa
                )
                return keller.encode_value_reply(self.address, value)
            if channel in (keller.CHANNEL_T, keller.CHANNEL_TOB1, keller.CHANNEL_TOB2):
                return keller.encode_value_reply(self.address, self.TEMPERATURE_C)
            code = keller.KellerErrorCode.INCORRECT_PARAMETER
            return keller.encode_exception_reply(self.address, request.function, code)
        code = (
            keller.KellerErrorCode.ERRONEOUS_DATA
            if request.function in (keller.FN_INIT, keller.FN_READ_FLOAT)
            else keller.KellerErrorCode.NON_IMPLEMENTED_FUNCTION
        )
        return keller.encode_exception_reply(self.address, request.function, code)

    def _send(self, echo: bytes, reply: bytes) -> None:
        fault = self._take_fault()
        if fault == "no_reply":
            return
        if fault == "bad_crc":
            reply = reply[:-1] + bytes((reply[-1] ^ 0xFF,))
        elif fault == "garbage":
            reply = _GARBAGE + reply
        try:
            self.endpoint.write(echo + reply)
        except TransportError:
            return  # closed under us by stop()
