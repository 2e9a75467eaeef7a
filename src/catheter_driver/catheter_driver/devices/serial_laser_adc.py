"""The laser ADC bridge on a serial line (frames: protocols/laser_adc.py)."""

from __future__ import annotations

from typing import cast

from catheter_driver.devices.threaded_adc import ThreadedLaserAdc
from catheter_driver.protocols.laser_adc import AdcFrame, AdcSerialParser
from catheter_driver.transports import ByteTransport, make_transport

_READ_CHUNK = 4096


class SerialLaserAdc(ThreadedLaserAdc):
    """Laser samples streamed by the bridge over a serial line.

    Args:
        transport: the serial line (opened and closed by this device).
        max_samples: see :class:`ThreadedLaserAdc`.
    """

    def __init__(self, transport: ByteTransport, max_samples: int = 10_000) -> None:
        super().__init__(max_samples)
        self.transport = transport
        self._parser = AdcSerialParser()

    @classmethod
    def from_params(cls, *, port: str, baudrate: int = 115200) -> SerialLaserAdc:
        """Build over a serial port from plain parameters.

        Args:
            port: device path or pyserial URL of the bridge.
            baudrate: line rate [bit/s]; 250 frames/s of 7 bytes need >= 19200.
        """
        return cls(cast(ByteTransport, make_transport("serial", url=port, baudrate=baudrate)))

    def describe(self) -> str:
        """E.g. ``laser adc on serial /dev/ttyACM1 115200 8N1``."""
        return f"laser adc on {self.transport.describe()}"

    def _open_link(self) -> None:
        self._parser.reset()
        self.transport.open()

    def _close_link(self) -> None:
        self.transport.close()

    def _link_open(self) -> bool:
        return self.transport.is_open

    def _poll(self, timeout_s: float) -> list[AdcFrame]:
        frames = self._parser.feed(self.transport.read(_READ_CHUNK, timeout_s))
        parsed = self._parser.counters
        self.counters.frames_ok = parsed.frames_ok
        self.counters.frame_errors = parsed.frame_errors
        self.counters.crc_failures = parsed.crc_failures
        return frames
