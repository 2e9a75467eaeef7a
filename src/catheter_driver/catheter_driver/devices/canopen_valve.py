"""The valve set-point through a CANopen analog-output module (RPDO out, TPDO back)."""

from __future__ import annotations

import time
from typing import cast

from catheter_driver.devices.base import ValveSetpoint
from catheter_driver.errors import DeviceError
from catheter_driver.protocols import FrameError, canopen_ao
from catheter_driver.transports import FrameTransport, make_transport

_MAX_DRAIN = 256
"""Most frames taken off the bus per call: a flooded bus must not stall the caller."""


class CanopenValve(ValveSetpoint):
    """Valve behind a CANopen AO module.

    Args:
        transport: the CAN bus (opened and closed by this device).
        node_id: the module's node id, 1..127.
        scaling: raw value <-> gauge pressure.
        rpdo_cob_id: COB-ID of the set-point PDO; default 0x200 + node id.
        tpdo_cob_id: COB-ID of the read-back PDO; default 0x180 + node id.
        channel: AO channel within the PDOs (0-based; two bytes each).
        nmt_start: send NMT "start remote node" at open (a module ignores PDOs until started).
    """

    def __init__(
        self,
        transport: FrameTransport,
        *,
        node_id: int = 1,
        scaling: canopen_ao.AoScaling | None = None,
        rpdo_cob_id: int | None = None,
        tpdo_cob_id: int | None = None,
        channel: int = 0,
        nmt_start: bool = True,
    ) -> None:
        super().__init__()
        self.transport = transport
        self.node_id = canopen_ao.check_node_id(node_id)
        self.scaling = scaling if scaling is not None else canopen_ao.AoScaling()
        self.rpdo_cob_id = (
            rpdo_cob_id if rpdo_cob_id is not None else canopen_ao.rpdo1_cob_id(node_id)
        )
        self.tpdo_cob_id = (
            tpdo_cob_id if tpdo_cob_id is not None else canopen_ao.tpdo1_cob_id(node_id)
        )
        self.channel = channel
        self.nmt_start = nmt_start
        self.last_read_back_raw: int | None = None
        """Raw value of the latest TPDO seen; None until one arrives."""
        self.last_read_back_s: float | None = None
        """Monotonic time the latest TPDO was taken off the bus [s]."""

    @classmethod
    def from_params(
        cls,
        *,
        interface: str = "socketcan",
        channel: str = "can0",
        bitrate: int | None = None,
        node_id: int = 1,
        raw_at_zero: int = 0,
        raw_at_full: int = canopen_ao.INT16_MAX,
        full_scale_pa: float = 6.0e5,
        rpdo_cob_id: int | None = None,
        tpdo_cob_id: int | None = None,
        ao_channel: int = 0,
        nmt_start: bool = True,
    ) -> CanopenValve:
        """Build over a python-can bus from plain parameters.

        Args:
            interface: python-can interface, e.g. "socketcan" or "virtual".
            channel: interface channel, e.g. "can0".
            bitrate: bus rate [bit/s]; None keeps the interface's setting.
            node_id: the AO module's node id.
            raw_at_zero: raw value at 0 Pa gauge.
            raw_at_full: raw value at ``full_scale_pa``.
            full_scale_pa: valve pressure at full output, gauge [Pa].
            rpdo_cob_id: set-point COB-ID (0 or None: 0x200 + node id).
            tpdo_cob_id: read-back COB-ID (0 or None: 0x180 + node id).
            ao_channel: AO channel within the PDO.
            nmt_start: whether to start the node at open.
        """
        transport = make_transport("can", interface=interface, channel=channel, bitrate=bitrate)
        return cls(
            cast(FrameTransport, transport),
            node_id=node_id,
            scaling=canopen_ao.AoScaling(raw_at_zero, raw_at_full, full_scale_pa),
            rpdo_cob_id=rpdo_cob_id or None,
            tpdo_cob_id=tpdo_cob_id or None,
            channel=ao_channel,
            nmt_start=nmt_start,
        )

    def describe(self) -> str:
        """E.g. ``canopen AO node 1 (RPDO 0x201, TPDO 0x181) on can socketcan:can0``."""
        return (
            f"canopen AO node {self.node_id} (RPDO 0x{self.rpdo_cob_id:03X}, TPDO "
            f"0x{self.tpdo_cob_id:03X}) on {self.transport.describe()}"
        )

    def _open(self) -> None:
        """Open the bus and start the node (NMT), if configured."""
        self.transport.open()
        if self.nmt_start:
            self.transport.send(*canopen_ao.encode_nmt_start(self.node_id))
        self.last_read_back_raw = None
        self.last_read_back_s = None

    def close(self) -> None:
        """Shut the bus down."""
        self.transport.close()

    @property
    def is_open(self) -> bool:
        """Whether the bus is open."""
        return self.transport.is_open

    def write_setpoint_pa(self, gauge_pa: float) -> None:
        """Send the set-point as RPDO (see the base class).

        Raises:
            ParameterError: outside the scaling's 0..full_scale_pa.
            DeviceError: the bus is down.
        """
        data = canopen_ao.encode_ao_raw(self.scaling.pa_to_raw(gauge_pa))
        try:
            self.transport.send(self.rpdo_cob_id, data)
            self._drain()
        except DeviceError as exc:
            self.counters.last_error = str(exc)
            raise

    def read_back_pa(self) -> float | None:
        """The output the module last reported by TPDO, gauge [Pa]; None before any."""
        try:
            self._drain()
        except DeviceError as exc:
            self.counters.last_error = str(exc)
            raise
        if self.last_read_back_raw is None:
            return None
        return self.scaling.raw_to_pa(self.last_read_back_raw)

    def _drain(self) -> None:
        """Take every waiting frame off the bus, keeping the latest read-back."""
        for _ in range(_MAX_DRAIN):
            frame = self.transport.recv(0.0)
            if frame is None:
                return
            cob_id, data = frame
            if cob_id != self.tpdo_cob_id:
                continue  # other nodes' traffic
            try:
                self.last_read_back_raw = canopen_ao.decode_ao_raw(data, self.channel)
            except FrameError as exc:
                self.counters.frame_errors += 1
                self.counters.last_error = str(exc)
                continue
            self.last_read_back_s = time.monotonic()
            self.counters.frames_ok += 1
