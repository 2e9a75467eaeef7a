"""Frames of the ADC bridge that samples the laser's analog output at 250 Hz.

This protocol (serial and CAN framing) was designed by this project; no firmware speaks it
yet. A rig that uses the ``adc_serial`` or ``adc_can`` backend needs a microcontroller with
an ADC flashed with firmware that implements it (docs/protocols/laser_adc.md is the
specification to build it from); only the emulator (``emulators/laser_adc.py``) speaks it
today. The Keller bus (:mod:`~catheter_driver.protocols.keller`) and CANopen
(:mod:`~catheter_driver.protocols.canopen_ao`) are, by contrast, protocols that
off-the-shelf devices already speak.

Serial frame, 7 bytes, one sample:

====== ======= ====================================================
offset size    field
====== ======= ====================================================
0      2       sync ``5A A5``
2      2       seq, uint16 little-endian (wraps at 65536)
4      2       voltage, uint16 little-endian [mV] (0..10000 for 0-10 V)
6      1       CRC-8 (poly 0x07, init 0) over bytes 2..5
====== ======= ====================================================

CAN frame: arbitration id 0x300 by default, 4 data bytes: seq uint16 LE, mV uint16 LE.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from catheter_driver.protocols import FrameError
from catheter_driver.protocols.crc import crc8_07
from catheter_driver.protocols.stream import NEED_MORE, NOT_A_FRAME, StreamParser
from catheter_models.errors import ParameterError

SYNC: Final = b"\x5a\xa5"
SERIAL_FRAME_LEN: Final = 7
CAN_DATA_LEN: Final = 4
DEFAULT_CAN_ID: Final = 0x300
SEQ_MODULO: Final = 1 << 16
MV_PER_V: Final = 1000.0
UINT16_MAX: Final = 0xFFFF


@dataclass(frozen=True)
class AdcFrame:
    """One decoded sample: counter and voltage [mV]."""

    seq: int
    millivolts: int

    @property
    def voltage_v(self) -> float:
        """The sample [V]."""
        return self.millivolts / MV_PER_V


def _payload(seq: int, millivolts: int) -> bytes:
    if not 0 <= seq <= UINT16_MAX:
        raise ParameterError(f"ADC seq must be 0..{UINT16_MAX}, got {seq!r}")
    if not 0 <= millivolts <= UINT16_MAX:
        raise ParameterError(f"ADC sample must be 0..{UINT16_MAX} mV (uint16), got {millivolts!r}")
    return seq.to_bytes(2, "little") + millivolts.to_bytes(2, "little")


def volts_to_mv(voltage_v: float) -> int:
    """A voltage [V] as the bridge sends it: rounded, clipped to 0..65535 mV."""
    return min(max(round(voltage_v * MV_PER_V), 0), UINT16_MAX)


def encode_serial(seq: int, millivolts: int) -> bytes:
    """Serial frame for one sample."""
    body = _payload(seq, millivolts)
    return SYNC + body + bytes((crc8_07(body),))


def decode_serial(frame: bytes) -> AdcFrame:
    """Decode one complete serial frame.

    Raises:
        FrameError: wrong length, sync or CRC.
    """
    if len(frame) != SERIAL_FRAME_LEN or frame[:2] != SYNC:
        raise FrameError(
            f"ADC frame must be {SERIAL_FRAME_LEN} bytes starting 5a a5, got {frame.hex(' ')}"
        )
    if crc8_07(frame[2:6]) != frame[6]:
        raise FrameError(f"ADC frame CRC 0x{frame[6]:02X} != 0x{crc8_07(frame[2:6]):02X}")
    return _decode_body(frame[2:6])


def _decode_body(body: bytes) -> AdcFrame:
    return AdcFrame(int.from_bytes(body[0:2], "little"), int.from_bytes(body[2:4], "little"))


def encode_can(seq: int, millivolts: int) -> bytes:
    """CAN data for one sample."""
    return _payload(seq, millivolts)


def decode_can(data: bytes) -> AdcFrame:
    """Decode CAN data of one sample.

    Raises:
        FrameError: the data is not exactly 4 bytes.
    """
    if len(data) != CAN_DATA_LEN:
        raise FrameError(f"ADC CAN frame has {len(data)} data bytes, expected {CAN_DATA_LEN}")
    return _decode_body(data)


def seq_gap(previous: int, current: int) -> int:
    """Samples lost between two consecutive frames (0 if ``current`` follows ``previous``)."""
    return (current - previous - 1) % SEQ_MODULO


class AdcSerialParser(StreamParser[AdcFrame]):
    """Streaming parser of serial ADC frames; resyncs on garbage, counts drops."""

    def _frame_length(self, buf: bytearray, start: int) -> int:
        if buf[start] != SYNC[0]:
            return NOT_A_FRAME
        if len(buf) - start < 2:
            return NEED_MORE
        return SERIAL_FRAME_LEN if buf[start + 1] == SYNC[1] else NOT_A_FRAME

    def _crc_ok(self, frame: bytes) -> bool:
        return crc8_07(frame[2:6]) == frame[6]

    def _decode(self, frame: bytes) -> AdcFrame | None:
        return _decode_body(frame[2:6])
