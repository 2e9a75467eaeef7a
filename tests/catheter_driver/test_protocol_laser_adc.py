"""Laser ADC frames against hand-worked bytes, and the serial parser under fuzzing."""

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

from catheter_driver.protocols import FrameError, laser_adc
from catheter_models.errors import ParameterError
from catheter_models.geometry import LaserGeometry


def test_serial_frame_bytes() -> None:
    # seq 1 -> 01 00; 8802 mV = 0x2262 -> 62 22; CRC-8/0x07 over 01 00 62 22 = 0x27.
    frame = bytes.fromhex("5A A5 01 00 62 22 27")
    assert laser_adc.encode_serial(1, 8802) == frame
    assert laser_adc.decode_serial(frame) == laser_adc.AdcFrame(1, 8802)
    assert laser_adc.decode_serial(frame).voltage_v == pytest.approx(8.802)


def test_can_frame_bytes() -> None:
    # seq 0x1234 -> 34 12; 10000 mV = 0x2710 -> 10 27.
    assert laser_adc.encode_can(0x1234, 10_000) == bytes.fromhex("34 12 10 27")
    assert laser_adc.decode_can(bytes.fromhex("34 12 10 27")) == laser_adc.AdcFrame(0x1234, 10_000)


@pytest.mark.parametrize("data", [b"", b"\x00\x00\x00", b"\x00" * 5, b"\x00" * 8])
def test_can_decoder_checks_length(data: bytes) -> None:
    with pytest.raises(FrameError, match="expected 4"):
        laser_adc.decode_can(data)


def test_serial_decoder_refuses_bad_crc_and_sync() -> None:
    with pytest.raises(FrameError, match="CRC"):
        laser_adc.decode_serial(bytes.fromhex("5A A5 01 00 62 22 28"))
    with pytest.raises(FrameError, match="5a a5"):
        laser_adc.decode_serial(bytes.fromhex("5A A4 01 00 62 22 27"))


def test_encoder_ranges_and_rounding() -> None:
    with pytest.raises(ParameterError, match="seq"):
        laser_adc.encode_serial(65536, 0)
    with pytest.raises(ParameterError, match="uint16"):
        laser_adc.encode_can(0, -1)
    assert laser_adc.volts_to_mv(8.8015) == 8802
    assert laser_adc.volts_to_mv(-0.2) == 0


def test_seq_gap_wraps() -> None:
    assert laser_adc.seq_gap(5, 6) == 0
    assert laser_adc.seq_gap(65535, 0) == 0
    assert laser_adc.seq_gap(65534, 1) == 2


def test_voltage_matches_eq_3_1() -> None:
    # Eq. 3.1: s = m U + n with m = 4.05 mm/V, n = 29.36 mm. The thesis rig's straight tip
    # at 65 mm reads U = (65 - 29.36) / 4.05 = 8.8000 V -> 8800 mV.
    u = float(LaserGeometry().distance_to_voltage_v(0.065))
    assert laser_adc.volts_to_mv(u) == 8800


# -- fuzzing --------------------------------------------------------------------------
frames = st.builds(laser_adc.encode_serial, st.integers(0, 0xFFFF), st.integers(0, 0xFFFF))
clean_garbage = garbage_without({0x5A})


@given(st.binary(max_size=300), CUTS)
def test_parser_never_raises_on_garbage(data: bytes, cuts: list[int]) -> None:
    parser = laser_adc.AdcSerialParser()
    out = feed_in_chunks(parser, data, cuts)
    assert parser.counters.frames_ok == len(out)


@given(st.lists(frames, min_size=1, max_size=6), st.lists(clean_garbage, max_size=7), CUTS)
def test_parser_recovers_frames_from_garbage(
    sent: list[bytes], garbage: list[bytes], cuts: list[int]
) -> None:
    parser = laser_adc.AdcSerialParser()
    out = feed_in_chunks(parser, interleave(garbage, sent), cuts)
    assert out == [laser_adc.decode_serial(f) for f in sent]
    # Every garbage byte is dropped (counted) or, at the very end, still held.
    n_garbage = len(interleave(garbage, sent)) - sum(map(len, sent))
    assert parser.counters.bytes_dropped + parser.buffered == n_garbage
    assert parser.counters.frame_errors >= (1 if parser.counters.bytes_dropped else 0)


@given(frames, frames, st.integers(1, 6), CUTS)
def test_parser_drops_truncated_frame(
    broken: bytes, good: bytes, keep: int, cuts: list[int]
) -> None:
    parser = laser_adc.AdcSerialParser()
    data = broken[:keep] + good
    assume(not spurious_frame_before(laser_adc.decode_serial, data, len(data) - len(good)))
    out = feed_in_chunks(parser, data, cuts)
    assert out == [laser_adc.decode_serial(good)]


@given(frames, frames, st.integers(1, 255), CUTS)
def test_parser_counts_bad_crc(bad: bytes, good: bytes, flip: int, cuts: list[int]) -> None:
    parser = laser_adc.AdcSerialParser()
    data = bad[:-1] + bytes((bad[-1] ^ flip,)) + good
    assume(not spurious_frame_before(laser_adc.decode_serial, data, len(bad)))
    out = feed_in_chunks(parser, data, cuts)
    assert out == [laser_adc.decode_serial(good)]
    # Every candidate frame that starts inside the corrupted bytes and fails its CRC counts:
    # the corrupted frame, and any sync pattern its bytes happen to hold (found by
    # hypothesis: 5a a5 57 01 59 5a a5 is a frame with a second sync at its end).
    candidates = sum(data[i : i + 2] == laser_adc.SYNC for i in range(len(bad)))
    assert parser.counters.crc_failures == candidates
