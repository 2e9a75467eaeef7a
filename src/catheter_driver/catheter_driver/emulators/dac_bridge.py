"""A serial DAC bridge driving the emulated rig's valve."""

from __future__ import annotations

import time

from catheter_driver.emulators.base import Emulator, HostFailsafe
from catheter_driver.emulators.rig_core import EmulatedRig
from catheter_driver.protocols import dac_bridge
from catheter_driver.transports.base import ByteTransport, TransportError

_GARBAGE = b"\x00\xa5\x81\x02\x13\xa5"
"""Injected junk with false starts (a SET reply header, a lone sync byte)."""


class DacBridgeEmulator(Emulator):
    """Answers SET and GET; SET applies the output to the rig's valve.

    A SET above ``max_mv`` is refused with OUT_OF_RANGE and the output stays as it was: a
    bridge never applies something other than what it was told.

    Fail-safe (docs/protocols/dac_bridge.md): when no SET has arrived for
    ``failsafe_timeout_s``, the bridge drives 0 mV (valve vented) until the next SET, whether
    the host is silent, hung, or its cable is gone (:meth:`PtyEndpoint.close` while the
    emulator runs: the bridge stays powered).

    Args:
        rig: the emulated rig.
        endpoint: the emulator's end of the line (e.g. :class:`PtyEndpoint`).
        scaling: output <-> valve pressure (must match the driver's to be meaningful).
        max_mv: highest output the DAC can produce [mV].
        failsafe_timeout_s: SET silence after which the output drops to 0 [s]; inf: never.
    """

    def __init__(
        self,
        rig: EmulatedRig,
        endpoint: ByteTransport,
        *,
        scaling: dac_bridge.DacScaling | None = None,
        max_mv: int = 10_000,
        failsafe_timeout_s: float = 0.2,
    ) -> None:
        super().__init__("dac-bridge-emulator")
        self.rig = rig
        self.endpoint = endpoint
        self.scaling = scaling if scaling is not None else dac_bridge.DacScaling()
        self.max_mv = max_mv
        self.output_mv = 0
        """The output being driven [mV]."""
        self.failsafe = HostFailsafe(failsafe_timeout_s, self._vent)
        self._parser = dac_bridge.DacFrameParser()

    def _open(self) -> None:
        self.endpoint.open()

    def _close(self) -> None:
        self.endpoint.close()

    def _vent(self) -> None:
        self.output_mv = 0
        self.rig.command(0.0)

    def _serve(self, timeout_s: float) -> None:
        wait_s = self.failsafe.wait_s(time.monotonic(), timeout_s)
        try:
            data = self.endpoint.read(256, wait_s)
        except TransportError:
            # The line is gone (unplugged, or closed by stop()): the bridge keeps its
            # fail-safe running and waits instead of spinning on a dead line.
            self._stop.wait(wait_s)
            data = b""
        for frame in self._parser.feed(data):
            self._send(self._reply(frame))
        self.failsafe.check(time.monotonic())

    def _reply(self, frame: dac_bridge.DacFrame) -> bytes:
        if frame.cmd == dac_bridge.CMD_SET:
            mv = frame.millivolts
            if mv > self.max_mv:
                return dac_bridge.encode_error(dac_bridge.DacErrorCode.OUT_OF_RANGE)
            self.output_mv = mv
            self.rig.command(self.scaling.mv_to_pa(mv))
            self.failsafe.fed(time.monotonic())
            return dac_bridge.encode_reply(dac_bridge.CMD_SET, mv)
        if frame.cmd == dac_bridge.CMD_GET:
            return dac_bridge.encode_reply(dac_bridge.CMD_GET, self.output_mv)
        return dac_bridge.encode_error(dac_bridge.DacErrorCode.UNKNOWN_COMMAND)

    def _send(self, reply: bytes) -> None:
        fault = self._take_fault()
        if fault == "no_reply":
            return
        if fault == "bad_crc":
            reply = reply[:-1] + bytes((reply[-1] ^ 0xFF,))
        elif fault == "garbage":
            reply = _GARBAGE + reply
        try:
            self.endpoint.write(reply)
        except TransportError:
            return  # closed under us by stop()
