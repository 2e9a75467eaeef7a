"""A recorder killed mid-run (kill -9) leaves a bag that is refused with a repair hint, and that
``catheter-lab bag repair`` recovers up to its last flushed chunk."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections import Counter, defaultdict
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from fault_log import FaultRecord
from graph_utils import Children, Probe, node_argv, recorder_values, wait_for_recorder
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader

from catheter_control.bringup import sim_graph_specs
from catheter_models.bag import load_bag
from catheter_models.contract import (
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
    qualify,
)
from catheter_models.errors import TruncatedBagError

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

RATE_HZ = 250.0
FLUSH_PERIOD_S = 0.5
KILL_AFTER_S = 4.0
ANGLE = qualify(TIP_ANGLE)
COMMAND = qualify(PRESSURE_COMMAND)


def _count(values: dict[str, str], topic: str) -> int:
    return int(values.get(f"count {topic}", "0"))


@pytest.mark.fault(
    "kill -9 recorder mid-recording",
    safe="the bag is refused with a repair hint; bag repair recovers it",
)
def test_killed_recorder_leaves_repairable_bag(
    children: Children, tmp_path: Path, fault: FaultRecord
) -> None:
    bag = tmp_path / "bag"
    specs = sim_graph_specs(bag, {"source": "test_recorder_kill"}, with_compensator=False)
    specs[0].params["flush_period_s"] = FLUSH_PERIOD_S
    graph = children.graph(specs)
    recorder = graph.procs["recorder"]
    with Probe(children.domain_id) as probe:
        probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        sensors = [qualify(s) for s in (PRESSURE_MEASURED, TIP_DISTANCE, TIP_ANGLE)]
        wait_for_recorder(probe, sensors, timeout_s=30.0)
        # The recorder hears the rig: tip/angle has been going into the bag since before now.
        t_ready = time.time()
        # train_zero_f0.8: 13.4 s of open-loop pressure; the recorder dies long before it ends.
        children.start(
            "excite",
            node_argv("catheter_control.excite_node", {"signal": "train_zero_f0.8", "tail_s": 0.0}),
        )
        assert probe.spin_until(lambda: _count(recorder_values(probe), COMMAND) > 0, 20.0), (
            f"the recorder hears no excite: {recorder_values(probe)}"
        )
        # Kill ~4 s into the recording, with at least 1 s of commands in the bag.
        t_kill = max(t_ready + KILL_AFTER_S, time.time() + 1.0)
        probe.spin_for(max(0.0, t_kill - time.time()))
        last_report = recorder_values(probe)
    assert recorder.poll() is None, f"recorder exited early:\n{children.log('recorder', 'graph')}"
    t_kill = time.time()
    recorder.send_signal(signal.SIGKILL)
    recorder.wait(10.0)
    assert recorder.returncode == -signal.SIGKILL
    children.close()  # stop excite and the rig; nothing else writes to the bag

    with pytest.raises(TruncatedBagError) as refused:
        load_bag(bag)
    fault.check("reported", "catheter-lab bag repair" in str(refused.value), str(refused.value))

    catheter_lab = Path(sys.executable).with_name("catheter-lab")
    repair = subprocess.run(
        [str(catheter_lab), "bag", "repair", str(bag)],
        capture_output=True,
        text=True,
        timeout=60.0,
        check=False,
    )
    assert repair.returncode == 0, f"{repair.stdout}\n{repair.stderr}"
    repaired = bag.with_name(bag.name + "_repaired")
    assert repaired.is_dir(), f"{repair.stdout}\n{sorted(p.name for p in tmp_path.iterdir())}"

    stamps: dict[str, list[int]] = defaultdict(list)
    with AnyReader([repaired]) as reader:
        for conn, _t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            stamps[conn.topic].append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
    rosbags_counts = Counter({t: len(s) for t, s in stamps.items()})
    mcap_counts: Counter[str] = Counter()
    for path in sorted(repaired.glob("*.mcap")):
        with path.open("rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for _schema, channel, _message, decoded in reader.iter_decoded_messages():
                assert decoded is not None
                mcap_counts[channel.topic] += 1
    assert rosbags_counts == mcap_counts
    data = load_bag(repaired)
    assert len(data.tip_angle) == rosbags_counts[ANGLE]
    assert len(data.pressure_command) > 0

    # Stamps are sampling instants on the system clock, so they place the recording in time:
    # it began before the recorder reported that it heard the rig, and ended by the kill.
    angle_s = np.array(stamps[ANGLE]) * 1e-9
    assert angle_s[0] <= t_ready, (angle_s[0], t_ready)
    assert angle_s[-1] <= t_kill
    recorded_s = t_kill - angle_s[0]
    # The recorder closes and flushes a chunk every 0.5 s, so a kill -9 loses at most the open
    # chunk: the last flush period before the kill, plus a little for callbacks running behind
    # the wire (0.3 s margin). Everything before that is 250 Hz tip/angle, none missing.
    expected = RATE_HZ * (recorded_s - FLUSH_PERIOD_S - 0.3)
    print(
        f"recorded {recorded_s:.2f} s; recovered {dict(rosbags_counts)}; expected >= "
        f"{expected:.0f}; recorder's last report {_count(last_report, ANGLE)}"
    )
    fault.check(
        "bag data up to the last flush (0.5 s before the kill) recovered by bag repair",
        rosbags_counts[ANGLE] >= expected,
        f"{rosbags_counts[ANGLE]} tip/angle recovered, expected >= {expected:.0f}",
    )
    assert rosbags_counts[ANGLE] <= RATE_HZ * recorded_s + 1
