"""CANopen AO codec against hand-worked bytes."""

import pytest
from hypothesis import given
from hypothesis import strategies as st

from catheter_driver.protocols import FrameError, canopen_ao
from catheter_models.errors import ParameterError


def test_default_cob_ids_are_the_predefined_connection_set() -> None:
    assert canopen_ao.rpdo1_cob_id(1) == 0x201
    assert canopen_ao.tpdo1_cob_id(1) == 0x181
    assert canopen_ao.rpdo1_cob_id(127) == 0x27F
    with pytest.raises(ParameterError, match=r"1\.\.127"):
        canopen_ao.rpdo1_cob_id(0)
    with pytest.raises(ParameterError, match=r"1\.\.127"):
        canopen_ao.tpdo1_cob_id(128)


def test_nmt_start() -> None:
    # NMT: COB-ID 0, command specifier 0x01 = start remote node, then the node id.
    assert canopen_ao.encode_nmt_start(5) == (0x000, b"\x01\x05")
    assert canopen_ao.encode_nmt_start(0) == (0x000, b"\x01\x00")  # all nodes


@pytest.mark.parametrize(
    ("raw", "data"),
    [
        (0, b"\x00\x00"),
        (1, b"\x01\x00"),  # little-endian: low byte first
        (0x1234, b"\x34\x12"),
        (32767, b"\xff\x7f"),
        (-1, b"\xff\xff"),  # two's complement
        (-32768, b"\x00\x80"),
    ],
)
def test_ao_raw_int16_little_endian(raw: int, data: bytes) -> None:
    assert canopen_ao.encode_ao_raw(raw) == data
    assert canopen_ao.decode_ao_raw(data) == raw


def test_ao_raw_out_of_int16_refused() -> None:
    for raw in (32768, -32769):
        with pytest.raises(ParameterError, match="int16"):
            canopen_ao.encode_ao_raw(raw)


def test_decode_checks_length_and_channel() -> None:
    with pytest.raises(FrameError, match="1 bytes"):
        canopen_ao.decode_ao_raw(b"\x01")
    assert canopen_ao.decode_ao_raw(b"\x01\x00\x02\x00", channel=1) == 2
    with pytest.raises(FrameError, match="channel 2"):
        canopen_ao.decode_ao_raw(b"\x01\x00\x02\x00", channel=2)


def test_default_scaling_is_10v_module_on_6bar_valve() -> None:
    s = canopen_ao.AoScaling()
    assert s.pa_to_raw(0.0) == 0
    assert s.pa_to_raw(6.0e5) == 32767  # 10 V = 6 bar
    assert s.pa_to_raw(3.0e5) == 16384  # 16383.5 rounds to even -> 16384
    assert s.raw_to_pa(32767) == 6.0e5
    # 1.5 bar = 1.5/6 * 32767 = 8191.75 -> 8192 = 0x2000 -> little-endian 00 20
    assert canopen_ao.encode_ao_raw(s.pa_to_raw(1.5e5)) == b"\x00\x20"


def test_scaling_refuses_what_the_module_cannot_drive() -> None:
    s = canopen_ao.AoScaling(full_scale_pa=3.0e5)
    for bad in (-1.0, 3.0e5 + 1.0, float("nan"), float("inf")):
        with pytest.raises(ParameterError, match="AO range"):
            s.pa_to_raw(bad)
    with pytest.raises(ParameterError, match="int16"):
        canopen_ao.AoScaling(raw_at_full=40000)
    with pytest.raises(ParameterError, match="flat"):
        canopen_ao.AoScaling(raw_at_zero=5, raw_at_full=5)


@given(st.binary(max_size=8), st.integers(0, 3))
def test_decoder_never_fails_other_than_frame_error(data: bytes, channel: int) -> None:
    try:
        raw = canopen_ao.decode_ao_raw(data, channel)
    except FrameError:
        assert len(data) < 2 * (channel + 1)
    else:
        assert -32768 <= raw <= 32767


@given(st.floats(0.0, 6.0e5))
def test_scaling_roundtrip_within_one_step(pa: float) -> None:
    s = canopen_ao.AoScaling()
    assert abs(s.raw_to_pa(s.pa_to_raw(pa)) - pa) <= 0.5 * 6.0e5 / 32767 + 1e-6
