"""BagRecorder and write_bag_from_arrays: layout, flushing, and what independent readers see."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from catheter_models.bag import (
    LATCHED_QOS,
    SENSOR_DATA_QOS,
    BagRecorder,
    QosProfile,
    write_bag_from_arrays,
)
from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr, kilted_typestore
from catheter_models.contract import PRESSURE_COMMAND, TIP_ANGLE, TRAJECTORY
from catheter_models.errors import BagError, ParameterError
from catheter_models.units import AMBIENT_PRESSURE_PA

EPOCH_NS = 1_700_000_000_000_000_000
CMD = "/catheter/pressure/command"
ANGLE = "/catheter/tip/angle"


class FakeClock:
    """Wall clock the test advances by hand [s]."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def _metadata(bag: Path) -> dict[str, Any]:
    loaded = yaml.safe_load((bag / "metadata.yaml").read_text())
    info: dict[str, Any] = loaded["rosbag2_bagfile_information"]
    return info


def _sample_bag(tmp_path: Path, n: int = 250) -> tuple[Path, np.ndarray]:
    t = np.arange(n) / 250.0
    bag = write_bag_from_arrays(
        tmp_path / "sample",
        t,
        2.0e5 * np.sin(t) ** 2,
        1.8e5 * np.sin(t) ** 2,
        0.5 * np.sin(t),
        distance_m=0.05 + 0.01 * np.sin(t),
        angle_desired_rad=0.5 * np.sin(t + 0.1),
        custom_data={"signal": "sine", "params": json.dumps({"amplitude_bar": 2.0})},
        start_time_ns=EPOCH_NS,
    )
    return bag, t


def test_layout_schema_channel_and_metadata(tmp_path: Path) -> None:
    bag, t = _sample_bag(tmp_path)
    assert sorted(p.name for p in bag.iterdir()) == ["metadata.yaml", "sample_0.mcap"]
    meta = _metadata(bag)
    assert meta["version"] == 9
    assert meta["storage_identifier"] == "mcap"
    assert meta["relative_file_paths"] == ["sample_0.mcap"]
    assert meta["message_count"] == 5 * t.size
    assert meta["starting_time"]["nanoseconds_since_epoch"] == EPOCH_NS
    assert meta["custom_data"]["signal"] == "sine"
    topic = next(
        x["topic_metadata"]
        for x in meta["topics_with_message_count"]
        if x["topic_metadata"]["name"] == CMD
    )
    assert topic["type_description_hash"] == kilted_typestore().hash_rihs01(
        PRESSURE_COMMAND.msgtype
    )
    # Streams offer reliable delivery (docs/interfaces.md), so `ros2 bag play` republishes so.
    assert topic["offered_qos_profiles"][0]["reliability"] == "reliable"

    with (bag / "sample_0.mcap").open("rb") as stream:
        reader = make_reader(stream)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        # One schema per type, one channel per topic.
        assert sorted(s.name for s in summary.schemas.values()) == [
            "sensor_msgs/msg/FluidPressure",
            "sensor_msgs/msg/JointState",
            "sensor_msgs/msg/Range",
        ]
        assert all(s.encoding == "ros2msg" for s in summary.schemas.values())
        assert len(summary.channels) == 5
        for channel in summary.channels.values():
            assert channel.message_encoding == "cdr"
            # The channel's QoS string and metadata.yaml's list describe the same profiles.
            listed = next(
                x["topic_metadata"]["offered_qos_profiles"]
                for x in meta["topics_with_message_count"]
                if x["topic_metadata"]["name"] == channel.topic
            )
            assert yaml.safe_load(channel.metadata["offered_qos_profiles"]) == listed
            assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
        embedded = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        assert (
            yaml.safe_load(embedded[0].metadata["serialized_metadata"])["custom_data"]
            == (meta["custom_data"])
        )


def test_rosbags_and_mcap_ros2_agree(tmp_path: Path) -> None:
    bag, t = _sample_bag(tmp_path)
    via_rosbags: dict[str, list[tuple[int, float]]] = {}
    with AnyReader([bag]) as reader:
        for conn, log_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            via_rosbags.setdefault(conn.topic, []).append((log_ns, _value(msg)))
    via_mcap: dict[str, list[tuple[int, float]]] = {}
    with (bag / "sample_0.mcap").open("rb") as stream:
        reader2 = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, ros_msg in reader2.iter_decoded_messages():
            via_mcap.setdefault(channel.topic, []).append((message.log_time, _value(ros_msg)))
    assert sorted(via_rosbags) == sorted(via_mcap)
    for topic, samples in via_rosbags.items():
        assert len(samples) == t.size
        assert samples == via_mcap[topic]
    expected_abs = 2.0e5 * np.sin(t) ** 2 + AMBIENT_PRESSURE_PA
    np.testing.assert_allclose([v for _, v in via_mcap[CMD]], expected_abs, rtol=0, atol=1e-9)


def _value(msg: object) -> float:
    for field in ("fluid_pressure", "range"):
        if hasattr(msg, field):
            return float(getattr(msg, field))
    return float(msg.position[0])  # type: ignore[attr-defined]


def test_cdr_matches_ros_typesupport(tmp_path: Path) -> None:
    serialization = pytest.importorskip("rclpy.serialization")
    sensor_msgs = pytest.importorskip("sensor_msgs.msg")
    data = joint_state_cdr(EPOCH_NS + 5, 0.25)
    msg = serialization.deserialize_message(data, sensor_msgs.JointState)
    assert list(msg.name) == ["bend"]
    assert list(msg.position) == [0.25]
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (EPOCH_NS // 10**9, 5)
    pressure = serialization.deserialize_message(
        fluid_pressure_cdr(EPOCH_NS, 1.0e5, ambient_pa=AMBIENT_PRESSURE_PA),
        sensor_msgs.FluidPressure,
    )
    assert pressure.fluid_pressure == 1.0e5 + AMBIENT_PRESSURE_PA


@pytest.mark.parametrize("compression", ["lz4", "zstd"])
def test_compressed_bags_read_everywhere(tmp_path: Path, compression: str) -> None:
    t = np.arange(50) / 250.0
    bag = write_bag_from_arrays(
        tmp_path / compression,
        t,
        t,
        t,
        t,
        start_time_ns=EPOCH_NS,
        compression=compression,  # type: ignore[arg-type]
    )
    with AnyReader([bag]) as reader:
        assert reader.message_count == 150
        assert sum(1 for _ in reader.messages()) == 150
    with next(bag.glob("*.mcap")).open("rb") as stream:
        decoded = make_reader(stream, decoder_factories=[DecoderFactory()])
        assert sum(1 for _ in decoded.iter_decoded_messages()) == 150


def test_flush_by_log_time_updates_file_and_metadata(tmp_path: Path) -> None:
    clock = FakeClock()
    rec = BagRecorder(tmp_path / "rec", flush_period_s=0.5, clock=clock)
    meta = _metadata(rec.path)
    # Provisional metadata exists from the start.
    assert meta["message_count"] == 0
    assert meta["relative_file_paths"] == ["rec_0.mcap"]
    rec.add_topic(CMD, PRESSURE_COMMAND.msgtype, offered_qos=[SENSOR_DATA_QOS])
    sizes = []
    for i in range(300):  # 1.2 s of log time at 250 Hz
        stamp = EPOCH_NS + i * 4_000_000
        rec.write(CMD, fluid_pressure_cdr(stamp, i, ambient_pa=0.0), stamp, stamp)
        sizes.append(rec.mcap_path.stat().st_size)
    # Flushes at 0.5 s and 1.0 s of log time: the file grew in exactly two steps.
    assert len(set(sizes)) == 3
    assert sizes[124] == sizes[0] < sizes[125] == sizes[249] < sizes[250] == sizes[-1]
    meta = _metadata(rec.path)
    assert meta["message_count"] == 251  # messages 0..250 were on disk at the 1.0 s flush
    assert meta["topics_with_message_count"][0]["message_count"] == 251
    rec.close()
    assert _metadata(rec.path)["message_count"] == 300


def test_flush_by_wall_time(tmp_path: Path) -> None:
    clock = FakeClock()
    with BagRecorder(tmp_path / "wall", flush_period_s=0.5, clock=clock) as rec:
        rec.add_topic(ANGLE, TIP_ANGLE.msgtype)
        rec.write(ANGLE, joint_state_cdr(EPOCH_NS, 0.1), EPOCH_NS, EPOCH_NS)
        size_before = rec.mcap_path.stat().st_size
        clock.now_s = 0.6  # log time stands still (e.g. sim time paused); wall time moves on
        rec.write(ANGLE, joint_state_cdr(EPOCH_NS, 0.2), EPOCH_NS, EPOCH_NS)
        assert rec.mcap_path.stat().st_size > size_before
        assert _metadata(rec.path)["message_count"] == 2


def test_custom_data_later_and_qos_profiles(tmp_path: Path) -> None:
    with BagRecorder(tmp_path / "cd", custom_data={"plant": "sim"}) as rec:
        rec.add_topic("/catheter/trajectory", TRAJECTORY.msgtype, offered_qos=[LATCHED_QOS])
        rec.set_custom_data("model", "gru_v3")
        rec.flush()
        assert _metadata(rec.path)["custom_data"] == {"plant": "sim", "model": "gru_v3"}
    meta = _metadata(tmp_path / "cd")
    qos = meta["topics_with_message_count"][0]["topic_metadata"]["offered_qos_profiles"][0]
    assert qos["durability"] == "transient_local"
    assert qos["reliability"] == "reliable"
    # A topic with no messages still opens in rosbags.
    with AnyReader([tmp_path / "cd"]) as reader:
        assert [c.topic for c in reader.connections] == ["/catheter/trajectory"]


def test_close_twice_and_use_after_close(tmp_path: Path) -> None:
    rec = BagRecorder(tmp_path / "c2")
    rec.add_topic(ANGLE, TIP_ANGLE.msgtype)
    rec.close()
    rec.close()
    assert rec.closed
    with pytest.raises(BagError, match="closed"):
        rec.write(ANGLE, b"", EPOCH_NS, EPOCH_NS)
    with pytest.raises(BagError, match="closed"):
        rec.set_custom_data("a", "b")


def test_refuses_to_overwrite(tmp_path: Path) -> None:
    existing = tmp_path / "taken"
    existing.mkdir()
    with pytest.raises(BagError, match=str(existing)):
        BagRecorder(existing)
    with pytest.raises(BagError, match="already exists"):
        write_bag_from_arrays(existing, [0.0], [0.0], [0.0], [0.0])
    assert list(existing.iterdir()) == []


def test_topic_and_argument_errors(tmp_path: Path) -> None:
    with BagRecorder(tmp_path / "err") as rec:
        rec.add_topic(ANGLE, TIP_ANGLE.msgtype)
        rec.add_topic(ANGLE, TIP_ANGLE.msgtype)  # same again: fine
        with pytest.raises(BagError, match=r"/catheter/tip/angle is already recorded as"):
            rec.add_topic(ANGLE, PRESSURE_COMMAND.msgtype)
        with pytest.raises(BagError, match="call add_topic first"):
            rec.write("/nope", b"", EPOCH_NS, EPOCH_NS)
        with pytest.raises(BagError, match="not in the ROS 2 Kilted type store"):
            rec.add_topic("/x", "my_msgs/msg/Nothing")
        with pytest.raises(TypeError, match="str -> str"):
            rec.set_custom_data("gain", 2.0)  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="flush_period_s"):
        BagRecorder(tmp_path / "p", flush_period_s=0.0)
    with pytest.raises(ParameterError, match="rmw"):
        QosProfile(reliability="sometimes")
    with pytest.raises(ParameterError, match="strictly increasing"):
        write_bag_from_arrays(tmp_path / "t", [0.0, 0.0], [0, 0], [0, 0], [0, 0])
    with pytest.raises(ParameterError, match=r"angle_rad has shape \(1,\)"):
        write_bag_from_arrays(tmp_path / "s", [0.0, 0.1], [0, 0], [0, 0], [0])


def test_type_hash_matches_installed_ros(tmp_path: Path) -> None:
    """The RIHS01 hash we record equals the one ROS 2 itself ships, where ROS is installed."""
    # ROS installs each type's description (with its hash) under <prefix>/share.
    prefixes = [
        Path(sys.prefix),
        *(Path(p) for p in os.environ.get("AMENT_PREFIX_PATH", "").split(":") if p),
    ]
    candidates = [p / "share/sensor_msgs/msg/FluidPressure.json" for p in prefixes]
    description = next((c for c in candidates if c.is_file()), None)
    if description is None:
        pytest.skip("no ROS 2 sensor_msgs type description installed")
    hashes = json.loads(description.read_text())["type_hashes"]
    expected = next(h["hash_string"] for h in hashes if h["type_name"] == PRESSURE_COMMAND.msgtype)
    assert kilted_typestore().hash_rihs01(PRESSURE_COMMAND.msgtype) == expected
