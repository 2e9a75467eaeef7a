"""A CANopen analog-output module driving the emulated rig's valve."""

from __future__ import annotations

import contextlib
import threading
import time

from catheter_driver.emulators.base import Emulator, HostFailsafe
from catheter_driver.emulators.rig_core import EmulatedRig
from catheter_driver.protocols import FrameError, canopen_ao
from catheter_driver.transports.base import FrameTransport, TransportError

_JUNK_FRAME = b"\x01"
"""A PDO too short for an int16: what a mis-mapped or corrupted PDO looks like."""


class CanopenAoEmulator(Emulator):
    """Applies RPDO set-points to the rig's valve and reports them back by TPDO.

    Like a CiA 401 module it ignores PDOs until NMT "start remote node" (if
    ``require_nmt_start``). Every applied RPDO is answered by a TPDO with the raw value now
    driven (event-driven transmission).

    Fail-safe (docs/protocols/canopen_valve.md): when no RPDO has been applied for
    ``failsafe_timeout_s`` (CiA 301 RPDO event timer), the module drives ``raw_at_zero``
    (valve vented), reports it by TPDO, and holds it until the next RPDO.

    Args:
        rig: the emulated rig.
        transport: the emulator's bus (e.g. python-can ``virtual`` on the driver's channel).
        node_id: this module's node id, 1..127.
        scaling: raw value <-> valve pressure (must match the driver's to be meaningful).
        require_nmt_start: ignore PDOs until started.
        failsafe_timeout_s: RPDO silence after which the output drops to zero [s]; inf: never.
    """

    def __init__(
        self,
        rig: EmulatedRig,
        transport: FrameTransport,
        *,
        node_id: int = 1,
        scaling: canopen_ao.AoScaling | None = None,
        require_nmt_start: bool = True,
        failsafe_timeout_s: float = 0.2,
    ) -> None:
        super().__init__(f"canopen-ao-emulator-{node_id}")
        self.rig = rig
        self.transport = transport
        self.node_id = canopen_ao.check_node_id(node_id)
        self.scaling = scaling if scaling is not None else canopen_ao.AoScaling()
        self.require_nmt_start = require_nmt_start
        self.raw = 0
        """Raw value being driven."""
        self.rpdos_applied = 0
        self.frames_refused = 0
        """PDOs dropped as malformed."""
        self._operational = threading.Event()
        self.failsafe = HostFailsafe(failsafe_timeout_s, self._vent)

    @property
    def operational(self) -> bool:
        """Whether the module is in NMT Operational (acts on PDOs)."""
        return self._operational.is_set()

    def _open(self) -> None:
        self.transport.open()
        self._operational.clear()
        if not self.require_nmt_start:
            self._operational.set()

    def _close(self) -> None:
        self.transport.close()

    def _vent(self) -> None:
        self.raw = self.scaling.pa_to_raw(0.0)
        self.rig.command(0.0)
        # Event-driven TPDO (the output changed); with the bus down it is vented all the same.
        with contextlib.suppress(TransportError):
            self.transport.send(
                canopen_ao.tpdo1_cob_id(self.node_id), canopen_ao.encode_ao_raw(self.raw)
            )

    def _serve(self, timeout_s: float) -> None:
        self._handle(self.failsafe.wait_s(time.monotonic(), timeout_s))
        self.failsafe.check(time.monotonic())

    def _handle(self, timeout_s: float) -> None:
        try:
            frame = self.transport.recv(timeout_s)
        except TransportError:
            self._stop.wait(timeout_s)  # bus down: keep the fail-safe running, do not spin
            return
        if frame is None:
            return
        cob_id, data = frame
        if cob_id == canopen_ao.NMT_COB_ID and len(data) == 2:
            if data[0] == canopen_ao.NMT_START_REMOTE_NODE and data[1] in (0, self.node_id):
                self._operational.set()
            return
        if cob_id != canopen_ao.rpdo1_cob_id(self.node_id) or not self.operational:
            return
        try:
            raw = canopen_ao.decode_ao_raw(data)
        except FrameError:
            self.frames_refused += 1
            return
        fault = self._take_fault()
        if fault == "no_reply":
            return  # a module that has dropped off the bus: nothing applied, nothing sent
        self.raw = raw
        self.rig.command(self.scaling.raw_to_pa(raw))
        self.failsafe.fed(time.monotonic())
        self.rpdos_applied += 1
        tpdo = canopen_ao.tpdo1_cob_id(self.node_id)
        try:
            if fault in ("bad_crc", "garbage"):
                self.transport.send(tpdo, _JUNK_FRAME)
            self.transport.send(tpdo, canopen_ao.encode_ao_raw(raw))
        except TransportError:
            return  # closed under us by stop()
