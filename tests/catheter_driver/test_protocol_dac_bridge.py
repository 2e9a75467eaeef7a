"""DAC bridge codec against hand-worked bytes, and its stream parser under fuzzing."""

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

from catheter_driver.protocols import FrameError, dac_bridge
from catheter_driver.protocols.crc import crc8_07
from catheter_models.errors import ParameterError


def test_crc8_check_value() -> None:
    # CRC-8 (poly 0x07, init 0, no reflection, no xorout): check value of "123456789" is 0xF4.
    assert crc8_07(b"123456789") == 0xF4


def test_get_request_bytes() -> None:
    # CRC-8 over 02 00 by hand: 0x02 shifted 8 times -> 04 08 10 20 40 80 (80<<1)^07=07 0E;
    # then ^00, 8 shifts of 0E -> 1C 38 70 E0 C7 89 15 2A. Frame: A5 02 00 2A.
    assert dac_bridge.encode_get() == bytes.fromhex("A5 02 00 2A")


def test_set_request_and_replies() -> None:
    # 5000 mV = 0x1388, big-endian 13 88; CRC-8 over 01 02 13 88 = 0x19.
    assert dac_bridge.encode_set(5000) == bytes.fromhex("A5 01 02 13 88 19")
    assert dac_bridge.encode_reply(dac_bridge.CMD_SET, 5000) == bytes.fromhex("A5 81 02 13 88 28")
    assert dac_bridge.encode_error(3) == bytes.fromhex("A5 FF 01 03 37")
    frame = dac_bridge.decode_frame(bytes.fromhex("A5 81 02 13 88 28"))
    assert (frame.cmd, frame.millivolts) == (0x81, 5000)


@pytest.mark.parametrize(
    ("frame", "what"),
    [
        (bytes.fromhex("A5 81 02 13 88 29"), "CRC"),
        (bytes.fromhex("A4 81 02 13 88 28"), "start"),
        (bytes.fromhex("A5 81 03 13 88 28"), "length"),
        (bytes.fromhex("A5 07 02 13 88 28"), "command"),
    ],
)
def test_decode_refuses_bad_frames(frame: bytes, what: str) -> None:
    with pytest.raises(FrameError, match=what):
        dac_bridge.decode_frame(frame)


def test_scaling_default_10v_is_6bar() -> None:
    s = dac_bridge.DacScaling()
    assert s.pa_to_mv(6.0e5) == 10_000
    assert s.pa_to_mv(1.5e5) == 2500
    assert s.mv_to_pa(2500) == 1.5e5
    with pytest.raises(ParameterError, match="DAC range"):
        s.pa_to_mv(7.0e5)
    with pytest.raises(ParameterError, match="uint16"):
        dac_bridge.encode_set(70_000)


# -- fuzzing --------------------------------------------------------------------------
mv = st.integers(0, 0xFFFF)
frames = st.one_of(
    st.builds(dac_bridge.encode_set, mv),
    st.just(dac_bridge.encode_get()),
    st.builds(dac_bridge.encode_reply, st.sampled_from([1, 2]), mv),
    st.builds(dac_bridge.encode_error, st.integers(0, 255)),
)
clean_garbage = garbage_without({dac_bridge.SYNC})


@given(st.binary(max_size=300), CUTS)
def test_parser_never_raises_on_garbage(data: bytes, cuts: list[int]) -> None:
    parser = dac_bridge.DacFrameParser()
    out = feed_in_chunks(parser, data, cuts)
    assert parser.counters.frames_ok == len(out)


@given(st.lists(frames, min_size=1, max_size=5), st.lists(clean_garbage, max_size=6), CUTS)
def test_parser_recovers_frames_from_garbage(
    sent: list[bytes], garbage: list[bytes], cuts: list[int]
) -> None:
    parser = dac_bridge.DacFrameParser()
    out = feed_in_chunks(parser, interleave(garbage, sent), cuts)
    assert out == [dac_bridge.decode_frame(f) for f in sent]
    # Every garbage byte is dropped (counted) or, at the very end, still held.
    n_garbage = len(interleave(garbage, sent)) - sum(map(len, sent))
    assert parser.counters.bytes_dropped + parser.buffered == n_garbage
    assert parser.counters.frame_errors >= (1 if parser.counters.bytes_dropped else 0)


@given(frames, frames, st.integers(1, 5), CUTS)
def test_parser_drops_truncated_frame(
    broken: bytes, good: bytes, keep: int, cuts: list[int]
) -> None:
    parser = dac_bridge.DacFrameParser()
    data = broken[: min(keep, len(broken) - 1)] + good
    assume(not spurious_frame_before(dac_bridge.decode_frame, data, len(data) - len(good)))
    out = feed_in_chunks(parser, data, cuts)
    assert out == [dac_bridge.decode_frame(good)]


@given(frames, frames, st.integers(1, 255), CUTS)
def test_parser_counts_bad_crc(bad: bytes, good: bytes, flip: int, cuts: list[int]) -> None:
    parser = dac_bridge.DacFrameParser()
    data = bad[:-1] + bytes((bad[-1] ^ flip,)) + good
    assume(not spurious_frame_before(dac_bridge.decode_frame, data, len(bad)))
    out = feed_in_chunks(parser, data, cuts)
    assert out == [dac_bridge.decode_frame(good)]
    # The corrupted frame counts, and so may a sync byte its bytes happen to hold that starts
    # another candidate failing its CRC (as the laser ADC's parser showed); never more.
    syncs = sum(b == dac_bridge.SYNC for b in data[: len(bad)])
    assert 1 <= parser.counters.crc_failures <= syncs
    if syncs == 1:
        assert parser.counters.crc_failures == 1
