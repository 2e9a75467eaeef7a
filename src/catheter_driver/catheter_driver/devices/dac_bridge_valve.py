"""The valve set-point through a serial DAC bridge (protocol: protocols/dac_bridge.py)."""

from __future__ import annotations

import math
import time
from typing import cast

from catheter_driver.devices.base import ValveSetpoint
from catheter_driver.errors import DeviceError, DeviceTimeout
from catheter_driver.protocols import dac_bridge
from catheter_driver.transports import ByteTransport, make_transport
from catheter_models.errors import ParameterError

_READ_CHUNK = 64


class DacBridgeValve(ValveSetpoint):
    """Valve behind a DAC bridge: SET on every command, GET for read-back.

    Args:
        transport: the serial line (opened and closed by this device).
        scaling: output voltage <-> gauge pressure.
        timeout_s: longest wait for a reply [s].
    """

    def __init__(
        self,
        transport: ByteTransport,
        *,
        scaling: dac_bridge.DacScaling | None = None,
        timeout_s: float = 0.05,
    ) -> None:
        super().__init__()
        if not (math.isfinite(timeout_s) and timeout_s > 0.0):
            raise ParameterError(f"timeout_s must be finite and > 0 s, got {timeout_s!r}")
        self.transport = transport
        self.scaling = scaling if scaling is not None else dac_bridge.DacScaling()
        self.timeout_s = timeout_s
        self.applied_mv: int | None = None
        """Output the bridge last confirmed [mV]."""
        self._parser = dac_bridge.DacFrameParser()

    @classmethod
    def from_params(
        cls,
        *,
        port: str,
        baudrate: int = 115200,
        full_scale_mv: int = 10_000,
        full_scale_pa: float = 6.0e5,
        timeout_s: float = 0.05,
    ) -> DacBridgeValve:
        """Build over a serial port from plain parameters.

        Args:
            port: device path or pyserial URL of the bridge.
            baudrate: line rate [bit/s].
            full_scale_mv: bridge output at the valve's full scale [mV].
            full_scale_pa: valve pressure at that output, gauge [Pa].
            timeout_s: reply timeout [s].
        """
        transport = make_transport("serial", url=port, baudrate=baudrate)
        return cls(
            cast(ByteTransport, transport),
            scaling=dac_bridge.DacScaling(full_scale_mv, full_scale_pa),
            timeout_s=timeout_s,
        )

    def describe(self) -> str:
        """E.g. ``dac bridge 10000 mV = 600000 Pa on serial /dev/ttyACM0 115200 8N1``."""
        s = self.scaling
        return (
            f"dac bridge {s.full_scale_mv} mV = {s.full_scale_pa:g} Pa on "
            f"{self.transport.describe()}"
        )

    def _open(self) -> None:
        """Open the line and ask the bridge for its output (proves it answers)."""
        self.transport.open()
        self._transact(dac_bridge.encode_get(), dac_bridge.CMD_GET_REPLY)

    def close(self) -> None:
        """Close the line."""
        self.transport.close()

    @property
    def is_open(self) -> bool:
        """Whether the line is open."""
        return self.transport.is_open

    def write_setpoint_pa(self, gauge_pa: float) -> None:
        """SET the output; returns when the bridge confirms (see the base class).

        Raises:
            ParameterError: outside 0..full_scale_pa.
            DeviceTimeout: no confirmation in time.
            DeviceError: the line is down or the bridge refused.
        """
        request = dac_bridge.encode_set(self.scaling.pa_to_mv(gauge_pa))
        self._transact(request, dac_bridge.CMD_SET_REPLY)

    def read_back_pa(self) -> float | None:
        """GET the output the bridge applies, gauge [Pa]."""
        self._transact(dac_bridge.encode_get(), dac_bridge.CMD_GET_REPLY)
        return None if self.applied_mv is None else self.scaling.mv_to_pa(self.applied_mv)

    def _transact(self, request: bytes, reply_cmd: int) -> None:
        try:
            self.transport.reset_input()
            self._parser.reset()
            self.transport.write(request)
            deadline_s = time.monotonic() + self.timeout_s
            while True:
                left_s = deadline_s - time.monotonic()
                if left_s <= 0.0:
                    self.counters.timeouts += 1
                    raise DeviceTimeout(
                        f"{self.describe()}: no reply 0x{reply_cmd:02X} within {self.timeout_s:g} s"
                    )
                frames = self._parser.feed(self.transport.read(_READ_CHUNK, left_s))
                self._sync_counters()
                for frame in frames:
                    if frame.cmd == dac_bridge.CMD_ERROR:
                        self.counters.device_errors += 1
                        raise DeviceError(f"{self.describe()}: bridge error {_error_name(frame)}")
                    if frame.cmd == reply_cmd:
                        self.applied_mv = frame.millivolts
                        return
        except DeviceError as exc:
            self.counters.last_error = str(exc)
            raise

    def _sync_counters(self) -> None:
        parsed = self._parser.counters
        self.counters.frames_ok = parsed.frames_ok
        self.counters.frame_errors = parsed.frame_errors
        self.counters.crc_failures = parsed.crc_failures


def _error_name(frame: dac_bridge.DacFrame) -> str:
    code = frame.payload[0]
    try:
        return f"{dac_bridge.DacErrorCode(code).name} ({code})"
    except ValueError:
        return f"unknown code {code}"
