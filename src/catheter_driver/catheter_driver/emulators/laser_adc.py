"""The laser ADC bridge, streaming the emulated rig's laser voltage each plant step."""

from __future__ import annotations

import threading
from abc import abstractmethod

from catheter_driver.emulators.base import Emulator
from catheter_driver.emulators.rig_core import EmulatedRig
from catheter_driver.protocols import laser_adc
from catheter_driver.transports.base import ByteTransport, FrameTransport, TransportError
from catheter_models.plant import PlantSample

_GARBAGE = b"\x5a\x00\x5a\xa5\x01"
"""Injected junk with false starts (a lone sync byte, a sync pair without a frame)."""
_JUNK_CAN_DATA = b"\x00\x00\x00"
"""A frame one byte short: what a corrupted or mis-configured bridge frame looks like."""


class _LaserAdcEmulator(Emulator):
    """Shared part: one sample per plant step, sequence counter, faults."""

    def __init__(self, rig: EmulatedRig, name: str) -> None:
        super().__init__(name)
        self.rig = rig
        self.seq = 0
        """Sequence number of the next frame."""
        self.frames_sent = 0
        self._streaming = threading.Event()

    def _on_sample(self, sample: PlantSample, _deadline_s: float) -> None:
        if not self._streaming.is_set():
            return
        voltage_v = float(self.rig.geometry.distance_to_voltage_v(sample.distance_m))
        seq = self.seq
        self.seq = (seq + 1) % laser_adc.SEQ_MODULO
        fault = self._take_fault()
        if fault == "no_reply":
            return  # the sample is lost: the driver sees a seq gap
        try:
            self._emit(seq, laser_adc.volts_to_mv(voltage_v), fault)
        except TransportError:
            return  # closed under us by stop()
        self.frames_sent += 1

    @abstractmethod
    def _emit(self, seq: int, millivolts: int, fault: str) -> None:
        """Send one sample [mV] with ``fault`` applied."""

    def _open(self) -> None:
        self._open_link()
        self._streaming.set()
        self.rig.add_listener(self._on_sample)

    def _close(self) -> None:
        self._streaming.clear()
        self.rig.remove_listener(self._on_sample)
        self._close_link()

    @abstractmethod
    def _open_link(self) -> None:
        """Open the emulator's end of the wire."""

    @abstractmethod
    def _close_link(self) -> None:
        """Close the emulator's end of the wire."""


class LaserAdcSerialEmulator(_LaserAdcEmulator):
    """Streams 7-byte serial frames (protocols/laser_adc.py) at the plant's rate.

    Args:
        rig: the emulated rig.
        endpoint: the emulator's end of the line (e.g. :class:`PtyEndpoint`).
    """

    def __init__(self, rig: EmulatedRig, endpoint: ByteTransport) -> None:
        super().__init__(rig, "laser-adc-serial-emulator")
        self.endpoint = endpoint

    def _open_link(self) -> None:
        self.endpoint.open()

    def _close_link(self) -> None:
        self.endpoint.close()

    def _serve(self, timeout_s: float) -> None:
        # The bridge only talks; whatever the driver sends is read and ignored, so a
        # chatty driver cannot fill the line.
        try:
            self.endpoint.read(256, timeout_s)
        except TransportError:
            self._stop.wait(timeout_s)

    def _emit(self, seq: int, millivolts: int, fault: str) -> None:
        frame = laser_adc.encode_serial(seq, millivolts)
        if fault == "bad_crc":
            frame = frame[:-1] + bytes((frame[-1] ^ 0xFF,))
        elif fault == "garbage":
            frame = _GARBAGE + frame
        self.endpoint.write(frame)


class LaserAdcCanEmulator(_LaserAdcEmulator):
    """Sends one 4-byte CAN frame per plant step.

    Args:
        rig: the emulated rig.
        transport: the emulator's bus.
        arbitration_id: frame id (0x300 by default).
    """

    def __init__(
        self,
        rig: EmulatedRig,
        transport: FrameTransport,
        *,
        arbitration_id: int = laser_adc.DEFAULT_CAN_ID,
    ) -> None:
        super().__init__(rig, "laser-adc-can-emulator")
        self.transport = transport
        self.arbitration_id = arbitration_id

    def _open_link(self) -> None:
        self.transport.open()

    def _close_link(self) -> None:
        self.transport.close()

    def _serve(self, timeout_s: float) -> None:
        try:
            self.transport.recv(timeout_s)  # drain: nothing is addressed to the bridge
        except TransportError:
            self._stop.wait(timeout_s)

    def _emit(self, seq: int, millivolts: int, fault: str) -> None:
        if fault in ("bad_crc", "garbage"):
            self.transport.send(self.arbitration_id, _JUNK_CAN_DATA)
        self.transport.send(self.arbitration_id, laser_adc.encode_can(seq, millivolts))
