"""Killed recordings: load_bag refuses them with a repair hint; repair_bag recovers every
message from complete chunks into a bag that every reader opens."""

from __future__ import annotations

import hashlib
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from catheter_models.bag import BagRecorder, load_bag, repair_bag, write_bag_from_arrays
from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr
from catheter_models.contract import PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE, TRAJECTORY
from catheter_models.errors import BagError, TruncatedBagError
from catheter_models.units import AMBIENT_PRESSURE_PA

EPOCH_NS = 1_700_000_000_000_000_000
STEP_NS = 4_000_000
TOPICS = {
    f"/catheter/{s.name}": s.msgtype for s in (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE)
}


class FakeClock:
    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


@dataclass
class Recording:
    live: Path  # closed normally at the end
    killed: Path  # copy of the directory taken before close, as a kill -9 leaves it
    flush_points: list[tuple[int, int]]  # (file size [bytes], messages on disk) after flushes


def _record(tmp_path: Path, samples: int = 550) -> Recording:
    """2.2 s at 250 Hz on three topics; the recorder flushes every 0.5 s of log time."""
    rec = BagRecorder(
        tmp_path / "live",
        custom_data={"signal": "chirp", "hardware": "rig-1"},
        flush_period_s=0.5,
        clock=FakeClock(),
    )
    for topic, msgtype in TOPICS.items():
        rec.add_topic(topic, msgtype)
    rec.add_topic("/catheter/trajectory", TRAJECTORY.msgtype)  # never published
    points: list[tuple[int, int]] = []
    size = rec.mcap_path.stat().st_size
    for i in range(samples):
        stamp = EPOCH_NS + i * STEP_NS
        for topic in TOPICS:
            data = (
                joint_state_cdr(stamp, 1e-3 * i)
                if topic.endswith("angle")
                else fluid_pressure_cdr(stamp, 100.0 * i, ambient_pa=AMBIENT_PRESSURE_PA)
            )
            rec.write(topic, data, stamp, stamp)
            # A flush happens inside the write that crosses the period, so look after each one.
            if rec.mcap_path.stat().st_size != size:
                size = rec.mcap_path.stat().st_size
                points.append((size, rec.message_count))
    killed = tmp_path / "killed"
    shutil.copytree(rec.path, killed)
    (killed / "live_0.mcap").rename(killed / "killed_0.mcap")
    meta = (killed / "metadata.yaml").read_text().replace("live_0.mcap", "killed_0.mcap")
    (killed / "metadata.yaml").write_text(meta)
    rec.flush()
    points.append((rec.mcap_path.stat().st_size, rec.message_count))
    rec.close()
    return Recording(tmp_path / "live", killed, points)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _reader_counts(bag: Path) -> tuple[dict[str, int], dict[str, int]]:
    with AnyReader([bag]) as reader:
        rosbags_counts: dict[str, int] = {}
        for conn, _t, _raw in reader.messages():
            rosbags_counts[conn.topic] = rosbags_counts.get(conn.topic, 0) + 1
    mcap_counts: dict[str, int] = {}
    with next(bag.glob("*.mcap")).open("rb") as stream:
        decoded = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _s, channel, _m, _msg in decoded.iter_decoded_messages():
            mcap_counts[channel.topic] = mcap_counts.get(channel.topic, 0) + 1
    return rosbags_counts, mcap_counts


def test_killed_recorder_refused_then_repaired(tmp_path: Path) -> None:
    rec = _record(tmp_path)
    # Flushes at 0.5, 1.0, 1.5, 2.0 s of log time, each inside the write of the first
    # command past the period; the last 0.2 s was still in memory.
    assert [count for _size, count in rec.flush_points[:-1]] == [376, 751, 1126, 1501]
    on_disk = rec.flush_points[-2][1]
    before = _sha256(rec.killed / "killed_0.mcap")

    with pytest.raises(TruncatedBagError) as info:
        load_bag(rec.killed)
    text = str(info.value)
    assert "is truncated" in text
    assert f"{on_disk} complete messages are recoverable" in text
    assert f"catheter-lab bag repair {rec.killed}" in text
    # The provisional metadata.yaml already matched what was on disk.
    meta = yaml.safe_load((rec.killed / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == on_disk

    report = repair_bag(rec.killed)
    assert report.output == tmp_path / "killed_repaired"
    assert not report.was_complete
    assert report.message_count == on_disk
    assert report.bytes_discarded == 0  # the kill came between flushes: nothing half-written
    per_topic = dict(zip(TOPICS, (501, 500, 500), strict=True))
    assert dict(report.messages_per_topic) == {**per_topic, "/catheter/trajectory": 0}
    assert f"recovered {on_disk} messages" in report.describe()
    assert _sha256(rec.killed / "killed_0.mcap") == before

    rosbags_counts, mcap_counts = _reader_counts(report.output)
    assert rosbags_counts == mcap_counts == per_topic
    repaired = load_bag(report.output)
    full = load_bag(rec.live)
    for name in ("pressure/command", "pressure/measured", "tip/angle"):
        n = len(repaired.series[name])
        np.testing.assert_array_equal(repaired.series[name].values, full.series[name].values[:n])
        np.testing.assert_array_equal(repaired.series[name].t_s, full.series[name].t_s[:n])
    custom = dict(repaired.custom_data)
    assert custom["signal"] == "chirp" and custom["hardware"] == "rig-1"
    assert custom["repaired_from"] == str(rec.killed)
    assert custom["repair_recovered_messages"] == str(on_disk)


def test_chopped_at_any_offset_recovers_complete_chunks(tmp_path: Path) -> None:
    rec = _record(tmp_path)
    source = rec.live / "live_0.mcap"
    data = source.read_bytes()
    reference = load_bag(rec.live)
    # Where each chunk ends, from the complete file's own index: chunk k holds the messages
    # of flush k, so a cut keeps exactly the flushes whose chunk lies before it.
    with source.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary is not None
    chunk_ends = sorted(c.chunk_start_offset + c.chunk_length for c in summary.chunk_indexes)
    assert len(chunk_ends) == len(rec.flush_points)
    first_flush, last_flush = rec.flush_points[0][0], rec.flush_points[-1][0]
    cuts = [
        0,
        5,  # inside the magic
        30,  # inside the header
        chunk_ends[0] - 1,  # the first chunk one byte short
        chunk_ends[0],  # first chunk whole, its message index records cut off
        first_flush - 1,  # inside the first chunk's last message index record
        first_flush + 40,  # inside the second chunk
        (chunk_ends[1] + chunk_ends[2]) // 2,
        last_flush,  # every message on disk; metadata, summary and footer missing
        len(data) - 1,  # only the closing magic is short
    ]
    for cut in cuts:
        bag = tmp_path / f"cut{cut}"
        bag.mkdir()
        shutil.copy(rec.live / "metadata.yaml", bag / "metadata.yaml")
        (bag / "live_0.mcap").write_bytes(data[:cut])
        expected = max(
            (
                count
                for end, (_s, count) in zip(chunk_ends, rec.flush_points, strict=True)
                if end <= cut
            ),
            default=0,
        )

        with pytest.raises(
            TruncatedBagError, match=f" {expected} complete messages are recoverable"
        ):
            load_bag(bag)
        if expected == 0:
            # Nothing whole to copy (0 bytes, inside the magic or the header, the first
            # chunk cut): refused, and no empty "repaired" bag is written.
            with pytest.raises(BagError, match="nothing to recover"):
                repair_bag(bag)
            assert not (tmp_path / f"cut{cut}_repaired").exists()
            continue
        report = repair_bag(bag)
        assert report.message_count == expected, cut
        assert 0 <= report.bytes_discarded <= cut
        if cut == last_flush:
            assert report.bytes_discarded == 0
        rosbags_counts, mcap_counts = _reader_counts(report.output)
        assert rosbags_counts == mcap_counts
        assert sum(rosbags_counts.values()) == expected
        repaired = load_bag(report.output)
        n = len(repaired.tip_angle)
        np.testing.assert_array_equal(repaired.tip_angle.values, reference.tip_angle.values[:n])


def test_repair_of_complete_bag_and_refusals(tmp_path: Path) -> None:
    t = np.arange(100) / 250.0
    bag = write_bag_from_arrays(tmp_path / "ok", t, t, t, t, start_time_ns=EPOCH_NS)
    report = repair_bag(bag, tmp_path / "copy")
    assert report.was_complete
    assert report.bytes_discarded == 0
    assert report.message_count == 300
    np.testing.assert_array_equal(load_bag(tmp_path / "copy").tip_angle.values, t)
    with pytest.raises(BagError, match="already exists"):
        repair_bag(bag, tmp_path / "copy")
    # The default output beside a lone .mcap file.
    lone = tmp_path / "lone.mcap"
    shutil.copy(bag / "ok_0.mcap", lone)
    assert repair_bag(lone).output == tmp_path / "lone_repaired"
