"""The laser ADC bridge on a CAN bus (frames: protocols/laser_adc.py)."""

from __future__ import annotations

from typing import cast

from catheter_driver.devices.threaded_adc import ThreadedLaserAdc
from catheter_driver.protocols import FrameError
from catheter_driver.protocols.laser_adc import DEFAULT_CAN_ID, AdcFrame, decode_can
from catheter_driver.transports import FrameTransport, make_transport

_MAX_BATCH = 64
"""Most frames taken per poll after the first, so samples reach readers promptly."""


class CanLaserAdc(ThreadedLaserAdc):
    """Laser samples sent by the bridge as CAN frames.

    Args:
        transport: the CAN bus (opened and closed by this device).
        arbitration_id: the bridge's frame id; other ids are ignored.
        max_samples: see :class:`ThreadedLaserAdc`.
    """

    def __init__(
        self,
        transport: FrameTransport,
        arbitration_id: int = DEFAULT_CAN_ID,
        max_samples: int = 10_000,
    ) -> None:
        super().__init__(max_samples)
        self.transport = transport
        self.arbitration_id = arbitration_id

    @classmethod
    def from_params(
        cls,
        *,
        interface: str = "socketcan",
        channel: str = "can0",
        bitrate: int | None = None,
        arbitration_id: int = DEFAULT_CAN_ID,
    ) -> CanLaserAdc:
        """Build over a python-can bus from plain parameters.

        Args:
            interface: python-can interface, e.g. "socketcan" or "virtual".
            channel: interface channel, e.g. "can0".
            bitrate: bus rate [bit/s]; None keeps the interface's setting.
            arbitration_id: the bridge's frame id.
        """
        transport = make_transport("can", interface=interface, channel=channel, bitrate=bitrate)
        return cls(cast(FrameTransport, transport), arbitration_id=arbitration_id)

    def describe(self) -> str:
        """E.g. ``laser adc id 0x300 on can socketcan:can0``."""
        return f"laser adc id 0x{self.arbitration_id:03X} on {self.transport.describe()}"

    def _open_link(self) -> None:
        self.transport.open()

    def _close_link(self) -> None:
        self.transport.close()

    def _link_open(self) -> bool:
        return self.transport.is_open

    def _poll(self, timeout_s: float) -> list[AdcFrame]:
        frames: list[AdcFrame] = []
        received = self.transport.recv(timeout_s)
        while received is not None:
            arbitration_id, data = received
            if arbitration_id == self.arbitration_id:
                try:
                    frames.append(decode_can(data))
                    self.counters.frames_ok += 1
                except FrameError as exc:
                    self.counters.frame_errors += 1
                    self.counters.last_error = str(exc)
            if len(frames) >= _MAX_BATCH:
                break
            received = self.transport.recv(0.0)
        return frames
