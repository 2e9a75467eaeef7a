"""load_bag: round trips, alignment, bags from other writers, and every refusal."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from catheter_models.bag import BagRecorder, load_bag, write_bag_from_arrays
from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr, kilted_typestore
from catheter_models.contract import PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE
from catheter_models.errors import BagError, MissingTopicError, ParameterError
from catheter_models.units import AMBIENT_PRESSURE_PA

EPOCH_NS = 1_700_000_000_000_000_000
STEP_NS = 4_000_000  # 250 Hz


def _arrays(n: int = 500) -> dict[str, np.ndarray]:
    t = np.arange(n) / 250.0
    return {
        "t_s": t,
        "pressure_command_pa_gauge": 2.0e5 * np.sin(2 * t) ** 2,
        "pressure_measured_pa_gauge": 1.9e5 * np.sin(2 * t - 0.1) ** 2,
        "angle_rad": 0.6 * np.sin(2 * t - 0.2),
        "distance_m": 0.05 + 0.01 * np.sin(2 * t),
        "angle_desired_rad": 0.6 * np.sin(2 * t),
    }


def _write(path: Path, **overrides: Any) -> Path:
    data: dict[str, Any] = {**_arrays(), **overrides}
    return write_bag_from_arrays(
        path,
        data.pop("t_s"),
        data.pop("pressure_command_pa_gauge"),
        data.pop("pressure_measured_pa_gauge"),
        data.pop("angle_rad"),
        start_time_ns=EPOCH_NS,
        custom_data={"signal": "sine", "plant": "sim"},
        **data,
    )


def test_round_trip_values_stamps_and_custom_data(tmp_path: Path) -> None:
    expected = _arrays()
    data = load_bag(_write(tmp_path / "rt"))
    assert data.start_time_ns == EPOCH_NS
    assert dict(data.custom_data) == {"signal": "sine", "plant": "sim"}
    pairs = {
        "pressure/command": "pressure_command_pa_gauge",
        "pressure/measured": "pressure_measured_pa_gauge",
        "tip/angle": "angle_rad",
        "angle/desired": "angle_desired_rad",
    }
    for name, key in pairs.items():
        series = data.series[name]
        np.testing.assert_allclose(series.t_s, expected["t_s"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(series.values, expected[key], rtol=0, atol=1e-9)
        assert series.topic == f"/catheter/{name}"
    assert data.tip_distance is not None
    # Range carries float32.
    np.testing.assert_allclose(data.tip_distance.values, expected["distance_m"], rtol=1e-6)
    assert data.pressure_command.unit == "Pa (gauge)"
    assert all(v == 0 for v in data.dropped.values())
    with pytest.raises(ValueError, match="read-only"):
        data.tip_angle.values[0] = 1.0


def test_direct_mcap_path_and_lone_mcap(tmp_path: Path) -> None:
    bag = _write(tmp_path / "d")
    via_file = load_bag(bag / "d_0.mcap")
    assert dict(via_file.custom_data) == {"signal": "sine", "plant": "sim"}
    np.testing.assert_array_equal(via_file.tip_angle.values, load_bag(bag).tip_angle.values)
    # Copied out of its directory, the file still carries custom_data in its own metadata record.
    lone = tmp_path / "elsewhere.mcap"
    shutil.copy(bag / "d_0.mcap", lone)
    assert dict(load_bag(lone).custom_data) == {"signal": "sine", "plant": "sim"}


def test_directory_without_metadata_yaml(tmp_path: Path) -> None:
    """`ros2 bag record` writes metadata.yaml only when it stops; the .mcap alone suffices."""
    bag = _write(tmp_path / "nometa")
    (bag / "metadata.yaml").unlink()
    data = load_bag(bag)
    assert len(data.tip_angle) == _arrays()["t_s"].size
    assert dict(data.custom_data) == {"signal": "sine", "plant": "sim"}


def test_required_topic_without_messages(tmp_path: Path) -> None:
    with BagRecorder(tmp_path / "quiet") as rec:
        for spec in (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE):
            rec.add_topic(f"/catheter/{spec.name}", spec.msgtype)
        rec.write("/catheter/tip/angle", joint_state_cdr(EPOCH_NS, 0.1), EPOCH_NS, EPOCH_NS)
    with pytest.raises(
        MissingTopicError,
        match=r"/catheter/pressure/command, /catheter/pressure/measured but no messages",
    ):
        load_bag(tmp_path / "quiet")


def test_aligned_on_reference_stamps(tmp_path: Path) -> None:
    expected = _arrays()
    aligned = load_bag(_write(tmp_path / "a")).aligned()
    np.testing.assert_allclose(aligned.t_s, expected["t_s"], atol=1e-12)
    np.testing.assert_allclose(aligned.angle_rad, expected["angle_rad"], atol=1e-12)
    np.testing.assert_allclose(
        aligned.pressure_command_pa, expected["pressure_command_pa_gauge"], atol=1e-9
    )
    assert aligned.distance_m is not None
    assert aligned.angle_desired_rad is not None
    assert len(aligned) == expected["t_s"].size


def _staggered_bag(path: Path) -> Path:
    """Commands at 50 Hz (steps 0, 1, 2, ... bar), measurement and angle at 250 Hz, offset 1 ms."""
    with BagRecorder(path, flush_period_s=None) as rec:
        cmd, meas, ang = (
            f"/catheter/{s.name}" for s in (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE)
        )
        rec.add_topic(cmd, PRESSURE_COMMAND.msgtype)
        rec.add_topic(meas, PRESSURE_MEASURED.msgtype)
        rec.add_topic(ang, TIP_ANGLE.msgtype)
        for k in range(10):
            stamp = EPOCH_NS + k * 5 * STEP_NS
            rec.write(
                cmd,
                fluid_pressure_cdr(stamp, k * 1e5, ambient_pa=AMBIENT_PRESSURE_PA),
                stamp,
                stamp,
            )
        for i in range(50):
            stamp = EPOCH_NS + 1_000_000 + i * STEP_NS
            t_s = (stamp - EPOCH_NS) / 1e9
            rec.write(
                meas,
                fluid_pressure_cdr(stamp, 1e6 * t_s, ambient_pa=AMBIENT_PRESSURE_PA),
                stamp,
                stamp,
            )
            rec.write(ang, joint_state_cdr(stamp, 10.0 * t_s), stamp, stamp)
    return path


def test_zero_order_hold_for_commands_linear_for_measurements(tmp_path: Path) -> None:
    data = load_bag(_staggered_bag(tmp_path / "s"))
    aligned = data.aligned()
    # Angle stamps: 1 ms + i * 4 ms, within [first common stamp, last common stamp].
    assert aligned.t_s[0] == pytest.approx(0.001)
    # The command is the last set-point at or before each stamp: step k lasts 20 ms.
    np.testing.assert_allclose(aligned.pressure_command_pa, np.floor(aligned.t_s / 0.02) * 1e5)
    np.testing.assert_allclose(aligned.angle_rad, 10.0 * aligned.t_s, rtol=1e-12)

    gridded = data.aligned(rate_hz=1000.0)
    assert gridded.t_s[0] == pytest.approx(0.001)
    np.testing.assert_allclose(np.diff(gridded.t_s), 1e-3, rtol=1e-9)
    assert gridded.t_s[-1] <= data.tip_angle.t_s[-1] + 1e-12
    # Linear data stays linear between samples; held data stays a staircase.
    np.testing.assert_allclose(gridded.pressure_measured_pa, 1e6 * gridded.t_s, rtol=1e-9)
    np.testing.assert_allclose(
        gridded.pressure_command_pa, np.floor(gridded.t_s / 0.02 + 1e-9) * 1e5
    )
    assert gridded.distance_m is None and gridded.angle_desired_rad is None
    with pytest.raises(ParameterError, match="rate_hz"):
        data.aligned(rate_hz=0.0)
    with pytest.raises(BagError, match="reference 'tip/distance' was not loaded"):
        data.aligned(reference="tip/distance")


def _rosbags_bag(
    path: Path, topics: dict[str, str], make: Callable[[str, str, int], Any] | None = None
) -> Path:
    """A bag written by rosbags' own Writer (MCAP, version 9), one message per 4 ms."""
    store = kilted_typestore()
    time_cls = store.types["builtin_interfaces/msg/Time"]
    header_cls = store.types["std_msgs/msg/Header"]

    def default(topic: str, msgtype: str, stamp: int) -> Any:
        header = header_cls(stamp=time_cls(sec=stamp // 10**9, nanosec=stamp % 10**9), frame_id="")
        if msgtype == "sensor_msgs/msg/FluidPressure":
            return store.types[msgtype](
                header=header, fluid_pressure=AMBIENT_PRESSURE_PA + 5e4, variance=0.0
            )
        if msgtype == "sensor_msgs/msg/JointState":
            empty = np.zeros(0)
            return store.types[msgtype](
                header=header, name=["bend"], position=np.array([0.3]), velocity=empty, effort=empty
            )
        return store.types[msgtype](data=1.0)

    make = make or default
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {t: writer.add_connection(t, ty, typestore=store) for t, ty in topics.items()}
        for i in range(20):
            stamp = EPOCH_NS + i * STEP_NS
            for topic, msgtype in topics.items():
                msg = make(topic, msgtype, stamp)
                writer.write(conns[topic], stamp, store.serialize_cdr(msg, msgtype))
    return path


ROOT_TOPICS = {
    "/pressure/command": "sensor_msgs/msg/FluidPressure",
    "/pressure/measured": "sensor_msgs/msg/FluidPressure",
    "/tip/angle": "sensor_msgs/msg/JointState",
}


def test_rosbags_writer_bag_in_root_namespace(tmp_path: Path) -> None:
    data = load_bag(_rosbags_bag(tmp_path / "root", ROOT_TOPICS))
    assert data.pressure_command.topic == "/pressure/command"
    np.testing.assert_allclose(data.pressure_measured.values, 5e4)
    np.testing.assert_allclose(data.tip_angle.values, 0.3)
    assert len(data.tip_angle) == 20
    assert data.tip_distance is None
    assert dict(data.custom_data) == {}
    assert len(data.aligned()) == 20


def test_other_namespace_and_ambiguity(tmp_path: Path) -> None:
    other = {f"/rig2{t}": ty for t, ty in ROOT_TOPICS.items()}
    assert load_bag(_rosbags_bag(tmp_path / "other", other)).tip_angle.topic == "/rig2/tip/angle"
    both = {**other, **{f"/rig3{t}": ty for t, ty in ROOT_TOPICS.items()}}
    bag = _rosbags_bag(tmp_path / "both", both)
    with pytest.raises(BagError, match=r"/rig2/pressure/command and /rig3/pressure/command"):
        load_bag(bag)
    assert load_bag(bag, namespace="/rig3").pressure_command.topic == "/rig3/pressure/command"


def test_missing_topic_named_with_bag_topics(tmp_path: Path) -> None:
    topics = {t: ty for t, ty in ROOT_TOPICS.items() if t != "/pressure/measured"}
    with pytest.raises(MissingTopicError) as info:
        load_bag(_rosbags_bag(tmp_path / "m", topics))
    text = str(info.value)
    assert "/catheter/pressure/measured" in text
    assert "/pressure/command (sensor_msgs/msg/FluidPressure)" in text
    assert "/tip/angle (sensor_msgs/msg/JointState)" in text


def test_requested_optional_topic_must_exist(tmp_path: Path) -> None:
    bag = _rosbags_bag(tmp_path / "o", ROOT_TOPICS)
    with pytest.raises(MissingTopicError, match="tip/distance"):
        load_bag(bag, topics=["tip/distance"])
    only = load_bag(bag, topics=["tip/angle"])
    assert list(only.series) == ["tip/angle"]
    with pytest.raises(BagError, match="pressure/command was not loaded"):
        only.aligned()
    with pytest.raises(ParameterError, match="trajectory"):
        load_bag(bag, topics=["trajectory"])


def test_wrong_type_named(tmp_path: Path) -> None:
    topics = {**ROOT_TOPICS, "/tip/angle": "std_msgs/msg/Float64"}
    with pytest.raises(
        BagError,
        match=(
            r"topic /tip/angle has type std_msgs/msg/Float64; "
            r"the contract expects sensor_msgs/msg/JointState"
        ),
    ):
        load_bag(_rosbags_bag(tmp_path / "w", topics))


def test_joint_state_without_bend(tmp_path: Path) -> None:
    store = kilted_typestore()

    def make(topic: str, msgtype: str, stamp: int) -> Any:
        header = store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](
                sec=stamp // 10**9, nanosec=stamp % 10**9
            ),
            frame_id="",
        )
        if msgtype == "sensor_msgs/msg/JointState":
            empty = np.zeros(0)
            return store.types[msgtype](
                header=header,
                name=["yaw", "pitch"],
                position=np.array([0.1, 0.2]),
                velocity=empty,
                effort=empty,
            )
        return store.types[msgtype](header=header, fluid_pressure=AMBIENT_PRESSURE_PA, variance=0.0)

    with pytest.raises(BagError, match=r"has joints \['yaw', 'pitch'\]; expected one named 'bend'"):
        load_bag(_rosbags_bag(tmp_path / "j", ROOT_TOPICS, make))


def test_non_finite_and_out_of_range_counted(tmp_path: Path) -> None:
    arrays = _arrays(100)
    measured = arrays["pressure_measured_pa_gauge"].copy()
    measured[[3, 50]] = np.nan
    angle = arrays["angle_rad"].copy()
    angle[7] = np.inf
    distance = arrays["distance_m"].copy()
    distance[10] = np.inf  # REP 117: nothing detected
    distance[11] = 5.0  # beyond max_range 1 m
    data = load_bag(
        _write(
            tmp_path / "nan",
            **{
                k: v
                for k, v in arrays.items()
                if k not in {"pressure_measured_pa_gauge", "angle_rad", "distance_m"}
            },
            pressure_measured_pa_gauge=measured,
            angle_rad=angle,
            distance_m=distance,
        )
    )
    assert data.dropped["pressure/measured"] == 2
    assert data.dropped["tip/angle"] == 1
    assert data.dropped["tip/distance"] == 1
    assert data.out_of_range["tip/distance"] == 1
    assert data.dropped["pressure/command"] == 0
    assert len(data.pressure_measured) == 98
    assert data.pressure_measured.message_count == 100
    assert np.all(np.isfinite(data.pressure_measured.values))
    assert 3 / 250.0 not in set(data.pressure_measured.t_s)
    assert np.all(np.isfinite(data.aligned().pressure_measured_pa))


def test_ambient_pressure_parameter(tmp_path: Path) -> None:
    bag = _write(tmp_path / "amb")
    shifted = load_bag(bag, ambient_pa=AMBIENT_PRESSURE_PA - 1000.0)
    np.testing.assert_allclose(
        shifted.pressure_command.values, _arrays()["pressure_command_pa_gauge"] + 1000.0, atol=1e-9
    )


def test_unstamped_messages_refused(tmp_path: Path) -> None:
    store = kilted_typestore()

    def make(topic: str, msgtype: str, stamp: int) -> Any:
        zero = store.types["std_msgs/msg/Header"](
            stamp=store.types["builtin_interfaces/msg/Time"](sec=0, nanosec=0), frame_id=""
        )
        if msgtype == "sensor_msgs/msg/JointState":
            empty = np.zeros(0)
            return store.types[msgtype](
                header=zero, name=["bend"], position=np.array([0.1]), velocity=empty, effort=empty
            )
        return store.types[msgtype](header=zero, fluid_pressure=AMBIENT_PRESSURE_PA, variance=0.0)

    with pytest.raises(
        BagError, match=r"20 of 20 messages on /pressure/command have header.stamp = 0"
    ):
        load_bag(_rosbags_bag(tmp_path / "u", ROOT_TOPICS, make))


def test_not_a_bag(tmp_path: Path) -> None:
    with pytest.raises(BagError, match="does not exist"):
        load_bag(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(BagError, match=r"holds no \.mcap"):
        load_bag(tmp_path / "empty")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all, just text" * 4)
    with pytest.raises(BagError, match="not an MCAP file"):
        load_bag(junk)


@pytest.mark.parametrize("compression", ["none", "zstd"])
def test_a_bag_damaged_inside_a_chunk_is_refused_as_damaged(
    tmp_path: Path, compression: str
) -> None:
    t = np.arange(5000) / 250.0
    noise = np.random.default_rng(3).normal(size=(3, t.size))  # chunks that do not shrink
    bag = write_bag_from_arrays(
        tmp_path / "bag",
        t,
        1e5 + 1e3 * noise[0],
        1e5 + 1e3 * noise[1],
        0.1 * noise[2],
        compression=compression,
    )
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    third = len(data) // 3
    data[third : third + 64] = bytes(b ^ 0xFF for b in data[third : third + 64])
    mcap.write_bytes(bytes(data))
    # Uncompressed, the chunk's checksum catches it; compressed, the decompressor fails
    # first. Either way a BagError that names the bag, not a decoder's own exception.
    with pytest.raises(BagError, match="is damaged") as info:
        load_bag(bag)
    assert str(bag) in str(info.value)
