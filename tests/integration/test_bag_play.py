"""A recorded session played back over DDS into a second recorder comes out the same."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from graph_utils import Children, Probe, recorder_values, wait_for_recorder
from rosbags.highlevel import AnyReader

from catheter_control.bringup import sim_graph_specs
from catheter_models.bag.messages import kilted_typestore
from catheter_models.bag.metadata import bag_custom_data, locate_bag
from catheter_models.contract import DIAGNOSTICS, SENSOR_STREAMS, qualify

pytestmark = [
    pytest.mark.slow,
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

SENSORS = [qualify(s) for s in SENSOR_STREAMS]


def _messages(bag: Path) -> dict[str, list[bytes]]:
    out: dict[str, list[bytes]] = {}
    with AnyReader([bag], default_typestore=kilted_typestore()) as reader:
        for conn, _log_ns, raw in reader.messages():
            out.setdefault(conn.topic, []).append(bytes(raw))
    return out


def test_a_played_bag_records_again_message_for_message(children: Children, tmp_path: Path) -> None:
    # (i) Record 4 s of the simulated rig's sensor streams.
    first = tmp_path / "first"
    graph = children.graph(sim_graph_specs(first, {"source": "play test"}, with_compensator=False))
    with Probe(children.domain_id) as probe:
        probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        wait_for_recorder(probe, SENSORS, timeout_s=30.0)
        probe.spin_for(4.0)
    assert graph.stop(timeout_s=15.0) == {"sim_hardware": 0, "recorder": 0}

    # (ii) Play it, twice as fast, into a second recorder on the same topics.
    second = tmp_path / "second"
    recorder = children.graph(sim_graph_specs(second, {"source": "replayed"})[:1])
    started = time.monotonic()
    play = children.run(
        "bag_play",
        [
            sys.executable,
            "-m",
            "catheter_control.bag_play",
            str(first),
            "--rate",
            "2",
            "--wait-for-subscribers-s",
            "30",
            "--allow-commands",  # a domain of its own: no valve driver listens
            "--no-progress",
        ],
        timeout_s=120.0,
    )
    assert play.returncode == 0, play.stderr
    assert "bag_play: played:" in play.stderr, play.stderr
    with Probe(children.domain_id) as probe:
        probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        assert probe.spin_until(lambda: bool(recorder_values(probe)), 10.0)
    assert recorder.stop(timeout_s=15.0) == {"recorder": 0}
    print(f"played and recorded in {time.monotonic() - started:.1f} s")

    # The same messages, byte for byte (so the same header stamps), in the same order.
    original, replayed = _messages(first), _messages(second)
    for topic in SENSORS:
        assert len(original[topic]) > 500, (topic, len(original[topic]))
        assert replayed.get(topic, []) == original[topic], (
            topic,
            len(original[topic]),
            len(replayed.get(topic, [])),
        )
    lost = json.loads(bag_custom_data(locate_bag(second))["samples_lost"])
    assert all(lost[t] == 0 for t in SENSORS), lost


def test_bag_play_refuses_what_it_cannot_play(children: Children, tmp_path: Path) -> None:
    first = tmp_path / "nothing"
    run = children.run(
        "bag_play",
        [sys.executable, "-m", "catheter_control.bag_play", str(first), "--no-progress"],
        timeout_s=60.0,
    )
    assert run.returncode == 2 and "bag_play:" in run.stderr, run.stderr
    bags = Path(__file__).resolve().parents[2] / "bags" / "training"
    run = children.run(
        "bag_play",
        [sys.executable, "-m", "catheter_control.bag_play", str(bags), "--topics", "tip/nope"],
        timeout_s=60.0,
    )
    assert run.returncode == 2 and "no topic 'tip/nope'" in run.stderr, run.stderr
    run = children.run(
        "bag_play",
        [sys.executable, "-m", "catheter_control.bag_play", str(bags), "--rate", "0"],
        timeout_s=60.0,
    )
    assert run.returncode == 2 and "--rate must be a positive factor" in run.stderr, run.stderr
    # The commands in a bag would move a real catheter: not under their own names by default.
    run = children.run(
        "bag_play",
        [sys.executable, "-m", "catheter_control.bag_play", str(bags), "--no-progress"],
        timeout_s=60.0,
    )
    assert run.returncode == 2, run.stderr
    assert "a valve driver on this ROS domain would move the catheter" in run.stderr, run.stderr
    assert "--remap /catheter/pressure/command:=/replay/catheter/pressure/command" in run.stderr
