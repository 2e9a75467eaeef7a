"""A serial DAC bridge: a microcontroller whose DAC drives the valve's 0-10 V input.

This protocol was designed by this project; no firmware speaks it yet. A rig that uses the
``dac_serial`` backend needs a microcontroller flashed with firmware that implements it,
including the fail-safe (docs/protocols/dac_bridge.md is the specification to build it
from); only the emulator (``emulators/dac_bridge.py``) speaks it today. The Keller bus
(:mod:`~catheter_driver.protocols.keller`) and CANopen
(:mod:`~catheter_driver.protocols.canopen_ao`) are, by contrast, protocols that
off-the-shelf devices already speak.

Frame (both directions): ``0xA5, cmd, len, payload[len], CRC-8`` with the CRC (polynomial
0x07, init 0x00) over ``cmd, len, payload``.

======= ========= =================== =========================================
cmd     direction payload             meaning
======= ========= =================== =========================================
0x01    to bridge uint16 BE [mV]      SET the output
0x81    from      uint16 BE [mV]      the output now applied (after clamping)
0x02    to bridge (none)              GET the output
0x82    from      uint16 BE [mV]      the output now applied
0xFF    from      uint8 code          error (see :class:`DacErrorCode`)
======= ========= =================== =========================================

Default scaling: 10 000 mV = 6 bar gauge (a 0-10 V, 0-6 bar valve).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import Final

from catheter_driver.protocols import FrameError
from catheter_driver.protocols.crc import crc8_07
from catheter_driver.protocols.stream import NEED_MORE, NOT_A_FRAME, StreamParser
from catheter_models.errors import ParameterError

SYNC: Final = 0xA5
CMD_SET: Final = 0x01
CMD_GET: Final = 0x02
REPLY_FLAG: Final = 0x80
CMD_SET_REPLY: Final = CMD_SET | REPLY_FLAG
CMD_GET_REPLY: Final = CMD_GET | REPLY_FLAG
CMD_ERROR: Final = 0xFF
MAX_PAYLOAD: Final = 8
_PAYLOAD_LEN: Final = {CMD_SET: 2, CMD_GET: 0, CMD_SET_REPLY: 2, CMD_GET_REPLY: 2, CMD_ERROR: 1}
"""Payload length of every command; a frame with another length is malformed."""
UINT16_MAX: Final = 0xFFFF


class DacErrorCode(IntEnum):
    """Error codes of the 0xFF reply."""

    UNKNOWN_COMMAND = 1
    BAD_LENGTH = 2
    OUT_OF_RANGE = 3


@dataclass(frozen=True)
class DacFrame:
    """One frame: command byte and payload."""

    cmd: int
    payload: bytes

    @property
    def millivolts(self) -> int:
        """The uint16 BE payload of SET / SET reply / GET reply [mV]."""
        if len(self.payload) != 2:
            raise FrameError(f"DAC frame 0x{self.cmd:02X} carries no millivolt value")
        return int.from_bytes(self.payload, "big")


def encode_frame(cmd: int, payload: bytes = b"") -> bytes:
    """Frame ``cmd`` and ``payload`` with sync byte, length and CRC-8.

    Raises:
        ParameterError: ``cmd`` not one byte, or payload longer than :data:`MAX_PAYLOAD`.
    """
    if not 0 <= cmd <= 0xFF:
        raise ParameterError(f"DAC bridge command must be one byte, got {cmd!r}")
    if len(payload) > MAX_PAYLOAD:
        raise ParameterError(f"DAC bridge payload is {len(payload)} bytes; at most {MAX_PAYLOAD}")
    body = bytes((cmd, len(payload))) + payload
    return bytes((SYNC,)) + body + bytes((crc8_07(body),))


def _mv_payload(millivolts: int) -> bytes:
    if not 0 <= millivolts <= UINT16_MAX:
        raise ParameterError(f"DAC output must be 0..{UINT16_MAX} mV (uint16), got {millivolts!r}")
    return int(millivolts).to_bytes(2, "big")


def encode_set(millivolts: int) -> bytes:
    """SET request."""
    return encode_frame(CMD_SET, _mv_payload(millivolts))


def encode_get() -> bytes:
    """GET request."""
    return encode_frame(CMD_GET)


def encode_reply(cmd: int, millivolts: int) -> bytes:
    """SET or GET reply carrying the applied output (for emulators)."""
    return encode_frame(cmd | REPLY_FLAG, _mv_payload(millivolts))


def encode_error(code: int) -> bytes:
    """Error reply."""
    return encode_frame(CMD_ERROR, bytes((code & 0xFF,)))


def decode_frame(frame: bytes) -> DacFrame:
    """Decode one complete frame.

    Raises:
        FrameError: bad sync, length, command or CRC.
    """
    if len(frame) < 4 or frame[0] != SYNC:
        raise FrameError(
            f"DAC frame must start 0x{SYNC:02X} and be >= 4 bytes, got {frame.hex(' ')}"
        )
    n = _frame_length(frame, 0)
    if n != len(frame):
        raise FrameError(f"DAC frame {frame.hex(' ')} has a bad command or length byte")
    if crc8_07(frame[1:-1]) != frame[-1]:
        raise FrameError(f"DAC frame CRC 0x{frame[-1]:02X} != 0x{crc8_07(frame[1:-1]):02X}")
    return DacFrame(frame[1], frame[3:-1])


def _frame_length(buf: bytes | bytearray, start: int) -> int:
    if buf[start] != SYNC:
        return NOT_A_FRAME
    if len(buf) - start < 3:
        if len(buf) - start == 2 and buf[start + 1] not in _PAYLOAD_LEN:
            return NOT_A_FRAME
        return NEED_MORE
    cmd, length = buf[start + 1], buf[start + 2]
    if _PAYLOAD_LEN.get(cmd) != length:
        return NOT_A_FRAME
    return 4 + length


class DacFrameParser(StreamParser[DacFrame]):
    """Streaming parser of DAC bridge frames (either direction); resyncs and counts."""

    def _frame_length(self, buf: bytearray, start: int) -> int:
        return _frame_length(buf, start)

    def _crc_ok(self, frame: bytes) -> bool:
        return crc8_07(frame[1:-1]) == frame[-1]

    def _decode(self, frame: bytes) -> DacFrame | None:
        return DacFrame(frame[1], frame[3:-1])


@dataclass(frozen=True)
class DacScaling:
    """Linear map between gauge pressure and DAC output.

    Attributes:
        full_scale_mv: output at the valve's full scale [mV] (10 V input).
        full_scale_pa: valve pressure at that output, gauge [Pa] (6 bar by default).
    """

    full_scale_mv: int = 10_000
    full_scale_pa: float = 6.0e5

    def __post_init__(self) -> None:
        if not 0 < self.full_scale_mv <= UINT16_MAX:
            raise ParameterError(
                f"full_scale_mv must be 1..{UINT16_MAX} mV, got {self.full_scale_mv!r}"
            )
        if not (math.isfinite(self.full_scale_pa) and self.full_scale_pa > 0.0):
            raise ParameterError(
                f"full_scale_pa must be finite and > 0 Pa, got {self.full_scale_pa!r}"
            )

    def pa_to_mv(self, gauge_pa: float) -> int:
        """Output for a set-point, gauge [Pa] -> [mV], rounded.

        Raises:
            ParameterError: not finite or outside 0..full_scale_pa.
        """
        if not (math.isfinite(gauge_pa) and 0.0 <= gauge_pa <= self.full_scale_pa):
            raise ParameterError(
                f"valve set-point {gauge_pa!r} Pa is outside the DAC range "
                f"0..{self.full_scale_pa:g} Pa"
            )
        return round(gauge_pa / self.full_scale_pa * self.full_scale_mv)

    def mv_to_pa(self, millivolts: int) -> float:
        """Gauge pressure [Pa] for an output [mV]."""
        return millivolts / self.full_scale_mv * self.full_scale_pa
