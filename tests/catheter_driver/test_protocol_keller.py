"""Keller bus codec against hand-checked bytes, and its stream parsers under fuzzing."""

import struct

import pytest
from hypothesis import assume, given
from hypothesis import strategies as st
from parser_fuzz import (
    CUTS,
    feed_in_chunks,
    garbage_without,
    interleave,
    spurious_frame_before,
)

from catheter_driver.protocols import FrameError, keller
from catheter_driver.protocols.crc import crc16_a001
from catheter_models.errors import ParameterError


def reference_crc16(data: bytes) -> int:
    """CRC-16/MODBUS by polynomial long division on the reflected bit stream (independent
    of the implementation under test): reflect every byte, divide by x^16 + x^15 + x^2 + 1
    (0x8005) with the register preset to 0xFFFF, reflect the remainder."""
    reg = 0xFFFF
    for byte in data:
        rbyte = int(f"{byte:08b}"[::-1], 2)
        for bit in range(7, -1, -1):
            top = (reg >> 15) & 1
            reg = (reg << 1) & 0xFFFF
            if top ^ ((rbyte >> bit) & 1):
                reg ^= 0x8005
    return int(f"{reg:016b}"[::-1], 2)


def test_crc16_check_value_and_reference() -> None:
    # CRC-16/MODBUS check value: crc(b"123456789") = 0x4B37; Keller sends it as 4B 37.
    assert crc16_a001(b"123456789") == 0x4B37 == reference_crc16(b"123456789")
    assert keller.with_crc(b"123456789")[-2:] == b"\x4b\x37"
    for data in (b"\xfa\x30", b"\xfa\x49\x01", b"\x01\x49\x01", bytes(range(40))):
        assert crc16_a001(data) == reference_crc16(data)


def test_init_request_bytes() -> None:
    # Keller's own protocol description gives the F48 example to the transparent address:
    # FA 30 04 43 (CRC 0x0443, high byte first; Modbus RTU would send 43 04).
    assert keller.encode_init_request(250) == bytes.fromhex("FA 30 04 43")
    # Address 1: crc16(01 30) = 0x3400 -> 34 00 (high byte first).
    assert reference_crc16(b"\x01\x30") == 0x3400
    assert keller.encode_init_request(1) == bytes.fromhex("01 30 34 00")


def test_read_request_bytes() -> None:
    # Keller's F73 example, channel 1 (P1) at address 250: FA 49 01 A1 A7.
    assert keller.encode_read_request(250, keller.CHANNEL_P1) == bytes.fromhex("FA 49 01 A1 A7")
    # Address 1, channel 1: crc16(01 49 01) = 0x50D6 -> 50 D6.
    assert reference_crc16(b"\x01\x49\x01") == 0x50D6
    assert keller.encode_read_request(1, 1) == bytes.fromhex("01 49 01 50 D6")


def test_value_reply_decodes_big_endian_float() -> None:
    # 1.5 as IEEE 754 single = 0x3FC00000 (sign 0, exponent 127, mantissa .1b);
    # STAT 00; crc16(01 49 3F C0 00 00 00) = 0x9C2D -> 9C 2D.
    frame = bytes.fromhex("01 49 3F C0 00 00 00 9C 2D")
    assert keller.encode_value_reply(1, 1.5) == frame
    assert keller.decode_reply(frame) == keller.KellerValueReply(1, 1.5, 0)


def test_init_reply_fields() -> None:
    # class 5, group 20, year 24, week 10, buffer 10, state 0; crc16 = 0x90A1.
    frame = bytes.fromhex("01 30 05 14 18 0A 0A 00 90 A1")
    info = keller.KellerInitReply(1, 5, 20, 24, 10, 10, 0)
    assert keller.encode_init_reply(info) == frame
    assert keller.decode_reply(frame) == info


def test_exception_reply() -> None:
    # F73 refused, code 32 (not initialised): 01 C9 20, crc16 = 0x8877.
    frame = bytes.fromhex("01 C9 20 88 77")
    assert keller.encode_exception_reply(1, 73, 32) == frame
    reply = keller.decode_reply(frame)
    assert reply == keller.KellerExceptionReply(1, 73, 32)
    assert isinstance(reply, keller.KellerExceptionReply)
    assert "NOT_INITIALISED" in reply.describe()


@pytest.mark.parametrize(
    ("frame", "what"),
    [
        (bytes.fromhex("01 49 3F C0 00 00 00 9C 2E"), "CRC"),
        (bytes.fromhex("01 49 3F C0 00 00 00 9C"), "bytes"),
        (bytes.fromhex("00 49 3F C0 00 00 00 9C 2D"), "address"),
        (bytes.fromhex("01 4A 3F C0 00 00 00 9C 2D"), "function"),
        (b"\x01", "shortest"),
    ],
)
def test_decode_reply_refuses_bad_frames(frame: bytes, what: str) -> None:
    with pytest.raises(FrameError, match=what):
        keller.decode_reply(frame)


def test_encoders_refuse_out_of_range() -> None:
    with pytest.raises(ParameterError, match=r"1\.\.250"):
        keller.encode_read_request(0, 1)
    with pytest.raises(ParameterError, match=r"1\.\.250"):
        keller.encode_init_request(251)
    with pytest.raises(ParameterError, match="one byte"):
        keller.encode_read_request(1, 256)
    with pytest.raises(ParameterError, match=r"1\.\.249"):
        keller.encode_value_reply(250, 1.0)  # a device never answers as 250


def test_transparent_address_accepts_any_device() -> None:
    assert keller.reply_address_matches(250, 17)
    assert keller.reply_address_matches(3, 3)
    assert not keller.reply_address_matches(3, 4)


def test_gauge_and_absolute_references() -> None:
    assert keller.bar_to_gauge_pa(1.5, "gauge", 101325.0) == 1.5e5
    assert keller.bar_to_gauge_pa(2.51325, "absolute", 101325.0) == pytest.approx(1.5e5)
    assert keller.gauge_pa_to_bar(1.5e5, "absolute", 101325.0) == pytest.approx(2.51325)
    with pytest.raises(ParameterError, match="'gauge'"):
        keller.check_reference("relative")


def test_request_parser_finds_unknown_function_by_crc() -> None:
    # F30 (not implemented here) with two payload bytes: length found by the CRC.
    frame = keller.with_crc(bytes((1, 30, 7, 8)))
    (request,) = keller.KellerRequestParser().feed(b"\x00" + frame)
    assert request == keller.KellerRequest(1, 30, b"\x07\x08")


# -- fuzzing --------------------------------------------------------------------------
addresses = st.integers(min_value=1, max_value=249)
f32 = st.floats(width=32, allow_nan=False)
replies = st.one_of(
    st.builds(keller.encode_value_reply, addresses, f32, st.integers(0, 255)),
    st.builds(
        lambda a, f: keller.encode_init_reply(keller.KellerInitReply(a, *f)),
        addresses,
        st.tuples(*[st.integers(0, 255)] * 6),
    ),
    st.builds(
        keller.encode_exception_reply, addresses, st.sampled_from([48, 73]), st.integers(0, 255)
    ),
)
# Without the function bytes (and their exception forms) no reply header can form in garbage.
clean_garbage = garbage_without({48, 73, 48 | 0x80, 73 | 0x80})


@given(st.binary(max_size=300), CUTS)
def test_reply_parser_never_raises_on_garbage(data: bytes, cuts: list[int]) -> None:
    parser = keller.KellerReplyParser()
    out = feed_in_chunks(parser, data, cuts)
    assert parser.counters.frames_ok == len(out)
    assert parser.counters.bytes_dropped + parser.buffered <= len(data)


@given(st.lists(replies, min_size=1, max_size=5), st.lists(clean_garbage, max_size=6), CUTS)
def test_reply_parser_recovers_frames_from_garbage(
    frames: list[bytes], garbage: list[bytes], cuts: list[int]
) -> None:
    parser = keller.KellerReplyParser()
    out = feed_in_chunks(parser, interleave(garbage, frames), cuts)
    assert out == [keller.decode_reply(f) for f in frames]
    # Every garbage byte is dropped (counted) or, at the very end, still held.
    n_garbage = len(interleave(garbage, frames)) - sum(map(len, frames))
    assert parser.counters.bytes_dropped + parser.buffered == n_garbage
    assert parser.counters.frame_errors >= (1 if parser.counters.bytes_dropped else 0)


@given(replies, replies, st.integers(1, 8), CUTS)
def test_reply_parser_drops_truncated_frame(
    broken: bytes, good: bytes, keep: int, cuts: list[int]
) -> None:
    parser = keller.KellerReplyParser()
    data = broken[: min(keep, len(broken) - 1)] + good
    assume(not spurious_frame_before(keller.decode_reply, data, len(data) - len(good)))
    out = feed_in_chunks(parser, data, cuts)
    assert out == [keller.decode_reply(good)]


@given(replies, replies, st.integers(1, 255), CUTS)
def test_reply_parser_counts_bad_crc_and_accepts_next(
    bad: bytes, good: bytes, flip: int, cuts: list[int]
) -> None:
    parser = keller.KellerReplyParser()
    data = bad[:-1] + bytes((bad[-1] ^ flip,)) + good
    assume(not spurious_frame_before(keller.decode_reply, data, len(bad)))
    out = feed_in_chunks(parser, data, cuts)
    assert out == [keller.decode_reply(good)]
    assert parser.counters.crc_failures >= 1


@given(st.binary(max_size=300), CUTS)
def test_request_parser_never_raises(data: bytes, cuts: list[int]) -> None:
    parser = keller.KellerRequestParser()
    out = feed_in_chunks(parser, data, cuts)
    assert parser.counters.frames_ok == len(out)


def test_value_roundtrip_is_float32() -> None:
    value = 1.2345678
    (expected,) = struct.unpack(">f", struct.pack(">f", value))
    reply = keller.decode_reply(keller.encode_value_reply(9, value))
    assert isinstance(reply, keller.KellerValueReply)
    assert reply.value == expected
