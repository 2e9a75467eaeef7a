"""Keller bus (RS485) as used by Keller series 21Y/30 transmitters: functions 48 and 73.

Frames (every byte after the address counts in the CRC; CRC over all bytes before it):

=========== ======================================================================
F48 request ``addr, 48, CRC_H, CRC_L``
F48 reply   ``addr, 48, class, group, year, week, buffer, state, CRC_H, CRC_L``
F73 request ``addr, 73, channel, CRC_H, CRC_L``
F73 reply   ``addr, 73, B3, B2, B1, B0, STAT, CRC_H, CRC_L`` (IEEE 754 float, big-endian)
exception   ``addr, function | 0x80, code, CRC_H, CRC_L``
=========== ======================================================================

CRC-16 is the Modbus register (reflected polynomial 0xA001, init 0xFFFF), but Keller sends
the **high byte first**: the opposite order to Modbus RTU. A device must be initialised
with F48 after power-up; until then it answers F73 with exception 32. Address 250 is the
transparent address: whatever device is on the line answers with its own address.

This is KELLER's own published bus protocol (of which only F48 and F73 are implemented):
the transmitters speak it as delivered, so nothing needs flashing, only the address and
baud rate set (docs/protocols/keller.md).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from enum import IntEnum
from typing import Final, Literal

from catheter_driver.protocols import FrameError
from catheter_driver.protocols.crc import crc16_a001
from catheter_driver.protocols.stream import NEED_MORE, NOT_A_FRAME, StreamParser
from catheter_models.errors import ParameterError

FN_INIT: Final = 48
FN_READ_FLOAT: Final = 73
EXCEPTION_FLAG: Final = 0x80
TRANSPARENT_ADDRESS: Final = 250
MIN_ADDRESS: Final = 1
MAX_DEVICE_ADDRESS: Final = 249
PA_PER_BAR: Final = 1.0e5

CHANNEL_CH0: Final = 0
CHANNEL_P1: Final = 1
CHANNEL_P2: Final = 2
CHANNEL_T: Final = 3
CHANNEL_TOB1: Final = 4
CHANNEL_TOB2: Final = 5

_INIT_REQUEST_LEN: Final = 4
_READ_REQUEST_LEN: Final = 5
_INIT_REPLY_LEN: Final = 10
_READ_REPLY_LEN: Final = 9
_EXCEPTION_LEN: Final = 5
_MAX_REQUEST_LEN: Final = 12
"""Longest request this module will search for when a function's length is unknown."""

Reference = Literal["gauge", "absolute"]


class KellerErrorCode(IntEnum):
    """Exception codes of the Keller bus."""

    NON_IMPLEMENTED_FUNCTION = 1
    INCORRECT_PARAMETER = 2
    ERRONEOUS_DATA = 3
    NOT_INITIALISED = 32


@dataclass(frozen=True)
class KellerInitReply:
    """Reply to F48: the device's identity.

    Attributes:
        address: the replying device's address.
        device_class, group, year, week: firmware identification.
        buffer: receive buffer size of the device [bytes].
        state: 0 after power-up initialisation, 1 if it was initialised before.
    """

    address: int
    device_class: int
    group: int
    year: int
    week: int
    buffer: int
    state: int


@dataclass(frozen=True)
class KellerValueReply:
    """Reply to F73: one channel's value (bar for pressure channels, degC for temperatures).

    Attributes:
        address: the replying device's address.
        value: the channel's value in the device's unit.
        status: the STAT byte, passed through unchanged.
    """

    address: int
    value: float
    status: int


@dataclass(frozen=True)
class KellerExceptionReply:
    """An exception reply: the device refused ``function`` with ``code``."""

    address: int
    function: int
    code: int

    def describe(self) -> str:
        """E.g. ``device 1 refused function 73: NOT_INITIALISED (32)``."""
        try:
            name = KellerErrorCode(self.code).name
        except ValueError:
            name = "unknown code"
        return f"device {self.address} refused function {self.function}: {name} ({self.code})"


KellerReply = KellerInitReply | KellerValueReply | KellerExceptionReply


@dataclass(frozen=True)
class KellerRequest:
    """A request as the device sees it (for emulators): function and its payload bytes."""

    address: int
    function: int
    payload: bytes


def _check_address(address: int, *, allow_transparent: bool) -> None:
    top = TRANSPARENT_ADDRESS if allow_transparent else MAX_DEVICE_ADDRESS
    if not MIN_ADDRESS <= address <= top:
        raise ParameterError(f"Keller address must be {MIN_ADDRESS}..{top}, got {address!r}")


def _check_byte(value: int, name: str) -> None:
    if not 0 <= value <= 0xFF:
        raise ParameterError(f"{name} must fit in one byte (0..255), got {value!r}")


def with_crc(body: bytes) -> bytes:
    """``body`` followed by its CRC-16, high byte first (Keller's order)."""
    return body + crc16_a001(body).to_bytes(2, "big")


def crc_ok(frame: bytes) -> bool:
    """Whether the last two bytes are the Keller CRC (high first) of the rest."""
    return len(frame) >= 3 and crc16_a001(frame[:-2]) == int.from_bytes(frame[-2:], "big")


def encode_init_request(address: int) -> bytes:
    """F48 request. ``address`` 1..250 (250: whoever is on the line)."""
    _check_address(address, allow_transparent=True)
    return with_crc(bytes((address, FN_INIT)))


def encode_read_request(address: int, channel: int) -> bytes:
    """F73 request for ``channel`` (1 = P1 pressure, 4 = TOB1 temperature, ...)."""
    _check_address(address, allow_transparent=True)
    _check_byte(channel, "Keller channel")
    return with_crc(bytes((address, FN_READ_FLOAT, channel)))


def encode_init_reply(reply: KellerInitReply) -> bytes:
    """F48 reply (what a device sends; for emulators and tests)."""
    _check_address(reply.address, allow_transparent=False)
    fields = (reply.device_class, reply.group, reply.year, reply.week, reply.buffer, reply.state)
    for name, value in zip(
        ("class", "group", "year", "week", "buffer", "state"), fields, strict=True
    ):
        _check_byte(value, f"F48 {name}")
    return with_crc(bytes((reply.address, FN_INIT, *fields)))


def encode_value_reply(address: int, value: float, status: int = 0) -> bytes:
    """F73 reply carrying ``value`` as a big-endian IEEE 754 single."""
    _check_address(address, allow_transparent=False)
    _check_byte(status, "F73 STAT")
    return with_crc(bytes((address, FN_READ_FLOAT)) + struct.pack(">f", value) + bytes((status,)))


def encode_exception_reply(address: int, function: int, code: int) -> bytes:
    """Exception reply: ``function | 0x80`` and the error code."""
    _check_address(address, allow_transparent=False)
    _check_byte(function, "function")
    _check_byte(code, "exception code")
    return with_crc(bytes((address, (function | EXCEPTION_FLAG) & 0xFF, code)))


def decode_reply(frame: bytes) -> KellerReply:
    """Decode one complete reply frame (F48, F73 or exception).

    Raises:
        FrameError: wrong length, unknown function, address out of range or bad CRC.
    """
    if len(frame) < _EXCEPTION_LEN:
        raise FrameError(f"Keller reply is {len(frame)} bytes; the shortest is {_EXCEPTION_LEN}")
    expected = _reply_length(frame[0], frame[1])
    if expected == NOT_A_FRAME:
        raise FrameError(
            f"Keller reply header {frame[0]:#04x} {frame[1]:#04x} is not address 1..250 and "
            f"function 48, 73 or an exception of them"
        )
    if len(frame) != expected:
        raise FrameError(
            f"Keller reply to function {frame[1] & 0x7F} is {len(frame)} bytes, expected {expected}"
        )
    if not crc_ok(frame):
        raise FrameError(
            f"Keller reply CRC {frame[-2:].hex(' ')} does not match "
            f"{crc16_a001(frame[:-2]).to_bytes(2, 'big').hex(' ')}"
        )
    return _decode_checked(frame)


def _decode_checked(frame: bytes) -> KellerReply:
    address, function = frame[0], frame[1]
    if function & EXCEPTION_FLAG:
        return KellerExceptionReply(address, function & 0x7F, frame[2])
    if function == FN_INIT:
        return KellerInitReply(address, *frame[2:8])
    (value,) = struct.unpack(">f", frame[2:6])
    return KellerValueReply(address, float(value), frame[6])


def _reply_length(address: int, function: int) -> int:
    if not MIN_ADDRESS <= address <= TRANSPARENT_ADDRESS:
        return NOT_A_FRAME
    if function == FN_INIT:
        return _INIT_REPLY_LEN
    if function == FN_READ_FLOAT:
        return _READ_REPLY_LEN
    if function in (FN_INIT | EXCEPTION_FLAG, FN_READ_FLOAT | EXCEPTION_FLAG):
        return _EXCEPTION_LEN
    return NOT_A_FRAME


def reply_address_matches(request_address: int, reply_address: int) -> bool:
    """Whether a reply belongs to a request: same address, or any device after address 250."""
    if request_address == TRANSPARENT_ADDRESS:
        return MIN_ADDRESS <= reply_address <= TRANSPARENT_ADDRESS
    return reply_address == request_address


class KellerReplyParser(StreamParser[KellerReply]):
    """Streaming parser of replies (driver side); resyncs on garbage, counts drops."""

    def _frame_length(self, buf: bytearray, start: int) -> int:
        if len(buf) - start < 2:
            return NEED_MORE if MIN_ADDRESS <= buf[start] <= TRANSPARENT_ADDRESS else NOT_A_FRAME
        return _reply_length(buf[start], buf[start + 1])

    def _crc_ok(self, frame: bytes) -> bool:
        return crc_ok(frame)

    def _decode(self, frame: bytes) -> KellerReply | None:
        return _decode_checked(frame)


class KellerRequestParser(StreamParser[KellerRequest]):
    """Streaming parser of requests (device side, for emulators).

    F48 and F73 have known lengths; for any other function the length is found by the first
    CRC that holds, so an emulator can answer it with "non-implemented function".
    """

    def _frame_length(self, buf: bytearray, start: int) -> int:
        left = len(buf) - start
        if not MIN_ADDRESS <= buf[start] <= TRANSPARENT_ADDRESS:
            return NOT_A_FRAME
        if left < 2:
            return NEED_MORE
        function = buf[start + 1]
        if function & EXCEPTION_FLAG:
            return NOT_A_FRAME
        if function == FN_INIT:
            return _INIT_REQUEST_LEN
        if function == FN_READ_FLOAT:
            return _READ_REQUEST_LEN
        for n in range(_INIT_REQUEST_LEN, min(left, _MAX_REQUEST_LEN) + 1):
            if crc_ok(bytes(buf[start : start + n])):
                return n
        return NEED_MORE if left < _MAX_REQUEST_LEN else NOT_A_FRAME

    def _crc_ok(self, frame: bytes) -> bool:
        return crc_ok(frame)

    def _decode(self, frame: bytes) -> KellerRequest | None:
        return KellerRequest(frame[0], frame[1], frame[2:-2])


def bar_to_gauge_pa(value_bar: float, reference: Reference, ambient_pa: float) -> float:
    """A pressure reading [bar] to gauge [Pa].

    Args:
        value_bar: the device's reading [bar]; gauge for PR types, absolute for PAA types.
        reference: "gauge" or "absolute", the device type's zero.
        ambient_pa: ambient pressure [Pa], subtracted from absolute readings.
    """
    pa = value_bar * PA_PER_BAR
    return pa - ambient_pa if reference == "absolute" else pa


def gauge_pa_to_bar(gauge_pa: float, reference: Reference, ambient_pa: float) -> float:
    """Inverse of :func:`bar_to_gauge_pa` (what a device of that type would read) [bar]."""
    pa = gauge_pa + ambient_pa if reference == "absolute" else gauge_pa
    return pa / PA_PER_BAR


def check_reference(reference: str) -> Reference:
    """``reference`` as the typed literal, or ParameterError naming the valid ones."""
    if reference == "gauge":
        return "gauge"
    if reference == "absolute":
        return "absolute"
    raise ParameterError(
        f"Keller reference must be 'gauge' (PR types) or 'absolute' (PAA types), got {reference!r}"
    )
