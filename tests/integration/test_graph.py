"""The simulated graph as separate processes over DDS: follow a trajectory, record it, refuse
what is unsafe (NaN commands, out-of-range parameters, invalid trajectories)."""

from __future__ import annotations

import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from graph_utils import (
    Children,
    Probe,
    diagnostic_values,
    node_argv,
    recorder_values,
    statuses,
    trajectory_msg,
    wait_for_recorder,
)
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from sensor_msgs.msg import FluidPressure, JointState
from trajectory_msgs.msg import JointTrajectory

from catheter_control.bringup import sim_graph_specs
from catheter_models.bag import load_bag
from catheter_models.contract import (
    ANGLE_DESIRED,
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
    TRAJECTORY,
    qualify,
)
from catheter_models.units import AMBIENT_PRESSURE_PA
from catheter_ros import messages, qos
from catheter_ros.qos import RECORD, STREAM

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

RATE_HZ = 250.0
PERIOD_NS = 4_000_000
CONTRACT_TOPICS = {
    qualify(spec): spec.msgtype
    for spec in (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_DISTANCE, TIP_ANGLE, ANGLE_DESIRED)
} | {qualify(TRAJECTORY): TRAJECTORY.msgtype}
SENSOR_TOPICS = [qualify(s) for s in (PRESSURE_MEASURED, TIP_DISTANCE, TIP_ANGLE)]
STREAMS = [t for t in CONTRACT_TOPICS if t != qualify(TRAJECTORY)]
CMD = qualify(PRESSURE_COMMAND)
# Pressure transmitter noise is 300 Pa std (rig.pressure_noise_pa): 2000 Pa is > 6 sigma.
NOISE_MARGIN_PA = 2000.0


def _stamp_ns(msg: object) -> int | None:
    header = getattr(msg, "header", None)
    if header is None:
        return None
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def _read_rosbags(bag: Path) -> tuple[dict[str, str], dict[str, list[object]]]:
    """Types and decoded messages per topic (in log-time order) with rosbags' AnyReader."""
    types: dict[str, str] = {}
    messages: dict[str, list[object]] = defaultdict(list)
    with AnyReader([bag]) as reader:
        for conn in reader.connections:
            types[conn.topic] = conn.msgtype
        for conn, _t, raw in reader.messages():
            messages[conn.topic].append(reader.deserialize(raw, conn.msgtype))
    return types, messages


def _read_mcap(bag: Path) -> tuple[dict[str, str], dict[str, list[object]]]:
    """Types and decoded messages per topic with the mcap reader and its ROS 2 decoder."""
    types: dict[str, str] = {}
    messages: dict[str, list[object]] = defaultdict(list)
    files = sorted(bag.glob("*.mcap"))
    assert files, f"no .mcap file in {bag}: {sorted(p.name for p in bag.iterdir())}"
    for path in files:
        with path.open("rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for schema, channel, _message, decoded in reader.iter_decoded_messages():
                types[channel.topic] = schema.name
                messages[channel.topic].append(decoded)
    return types, messages


def test_follow_trajectory_end_to_end(children: Children, tmp_path: Path) -> None:
    # 0 -> 15 -> 0 deg over 5 s: 6 deg/s and a 12 deg/s corner (1200 deg/s^2 at the 10 ms
    # check resolution), well inside the default limits (35 deg, 200 deg/s, 5000 deg/s^2).
    csv = tmp_path / "triangle.csv"
    csv.write_text("t_s,angle_deg\n0,0\n2.5,15\n5,0\n")
    duration_s = 5.0
    bag = tmp_path / "bag"
    run_dir = tmp_path / "run"
    graph = children.graph(sim_graph_specs(bag, {"source": "test_follow_trajectory"}))
    # The recorder must have matched the rig's and the compensator's publishers before the
    # run starts (follow_trajectory only checks the graph from its own side).
    with Probe(children.domain_id) as probe:
        probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        wait_for_recorder(probe, STREAMS, timeout_s=30.0)

    run = children.run(
        "follow_trajectory",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--file",
            str(csv),
            "--out",
            str(run_dir),
            "--no-progress",
            "--timeout-s",
            "40",
        ],
        timeout_s=90.0,
    )
    assert run.returncode == 0, f"exit {run.returncode}\n{run.stdout}\n{run.stderr}"
    assert not graph.failed(), f"graph nodes exited during the run: {graph.failed()}"
    for label in ("RMSE", "MAE", "NRMSE"):
        assert any(line.strip().startswith(label) for line in run.stdout.splitlines()), (
            f"no {label} line in:\n{run.stdout}"
        )
    assert (run_dir / "tracking.png").is_file()
    report = json.loads((run_dir / "report.json").read_text())

    codes = graph.stop(timeout_s=15.0)
    assert codes == {"compensator": 0, "sim_hardware": 0, "recorder": 0}, codes

    rb_types, rb_msgs = _read_rosbags(bag)
    mc_types, mc_msgs = _read_mcap(bag)
    for reader, types in (("rosbags", rb_types), ("mcap", mc_types)):
        for topic, msgtype in CONTRACT_TOPICS.items():
            assert types.get(topic) == msgtype, f"{reader}: {topic} is {types.get(topic)}"
    counts = {t: len(m) for t, m in rb_msgs.items()}
    assert counts == {t: len(m) for t, m in mc_msgs.items()}, "the two readers disagree"
    for topic in CONTRACT_TOPICS:
        stamps = [_stamp_ns(m) for m in rb_msgs[topic]]
        assert stamps == [_stamp_ns(m) for m in mc_msgs[topic]], topic

    # The trajectory is recorded once (transient-local, one publication), as sent.
    assert counts[qualify(TRAJECTORY)] == 1
    for msgs in (rb_msgs, mc_msgs):
        traj = msgs[qualify(TRAJECTORY)][0]
        assert list(traj.joint_names) == ["bend"]
        t_s = [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in traj.points]
        assert np.allclose(t_s, [0.0, 2.5, 5.0])
        assert np.allclose(np.degrees([p.positions[0] for p in traj.points]), [0, 15, 0])

    # Sensor streams: one sample every 4 ms, stamped at the sampling instant. The rig
    # publishes every sample (a late tick publishes its backlog with the true stamps) and
    # offers reliable delivery, which the recorder asks for: every sample is in the bag.
    lost = json.loads(load_bag(bag).custom_data["samples_lost"])
    for topic in SENSOR_TOPICS:
        stamps = np.array([_stamp_ns(m) for m in rb_msgs[topic]], dtype=np.int64)
        periods = np.diff(stamps)
        assert np.all(periods > 0), f"{topic}: stamps not strictly increasing"
        assert abs(np.median(periods) - PERIOD_NS) <= 0.01 * PERIOD_NS, topic
        # +1 us: stamps are rounded to the nanosecond from monotonic seconds.
        assert periods.max() <= PERIOD_NS + 1_000, f"{topic}: gap {periods.max()} ns"
        expected = round((stamps[-1] - stamps[0]) * 1e-9 * RATE_HZ) + 1
        assert stamps.size == expected, f"{topic}: {stamps.size} of {expected}"
        assert lost[topic] == 0, (topic, lost)
        # Recorded from before the trajectory was sent until after it ended.
        assert (stamps[-1] - stamps[0]) * 1e-9 > duration_s

    # Commands: 250 Hz from the moment the trajectory arrives to its end, then the ramp
    # down to zero at the slew limit (at most max_pressure / slew = 3 bar / 20 bar/s = 0.15 s).
    # Stamps are the loop's deadlines, so every interval is a whole number of periods. The
    # loop skips a deadline it missed rather than bursting: on this 2-core machine with a
    # second graph running (load ~4) it skipped up to 7 % of them (1 % when quiet), so the
    # count bound is 90 %, which still fails a bag that lost part of the run.
    cmd = np.array([_stamp_ns(m) for m in rb_msgs[CMD]], dtype=np.int64)
    cmd_span_s = (cmd[-1] - cmd[0]) * 1e-9
    assert duration_s - 0.01 <= cmd_span_s <= duration_s + 0.15 + 0.01, cmd_span_s
    in_periods = np.diff(cmd) / PERIOD_NS
    assert np.all(in_periods >= 1) and np.allclose(in_periods, np.round(in_periods), atol=1e-3)
    assert 0.90 * (cmd_span_s * RATE_HZ + 1) <= cmd.size <= cmd_span_s * RATE_HZ + 1
    # A skipped tick is a command that never existed, and the bag says how many.
    assert lost[CMD] == round(cmd_span_s * RATE_HZ) + 1 - cmd.size, (lost, cmd.size)
    # Published together at each tick while the plan runs; none during the ramp down at its
    # end (no set-point is in force then), so the commands without one are that ramp.
    desired = np.array([_stamp_ns(m) for m in rb_msgs[qualify(ANGLE_DESIRED)]], dtype=np.int64)
    assert np.isin(desired, cmd).all()
    ramp = cmd[~np.isin(cmd, desired)]
    assert ramp.size < cmd.size // 10 and np.all(ramp > desired.max()), (ramp.size, cmd.size)

    # FluidPressure is absolute: ambient plus a gauge pressure in [0, 3 bar] (+ sensor noise).
    for msgs in (rb_msgs, mc_msgs):
        p_abs = np.array([m.fluid_pressure for m in msgs[qualify(PRESSURE_MEASURED)]])
        assert p_abs.min() > 9.0e4, p_abs.min()
        assert p_abs.max() < AMBIENT_PRESSURE_PA + 3.0e5 + NOISE_MARGIN_PA, p_abs.max()
        c_abs = np.array([m.fluid_pressure for m in msgs[CMD]])
        assert c_abs.min() >= AMBIENT_PRESSURE_PA - 1e-6
        assert c_abs.max() <= AMBIENT_PRESSURE_PA + 3.0e5 + 1e-6

    # Tracking, from the bag with our own loader (stamps aligned, not receive times).
    # The compensator is the static inverse of the rig's quasi-static curve: it does not
    # compensate hysteresis, so the bend lags the set-point by about the rig's play (1.5 deg
    # friction + 0.6 deg presliding) after each reversal and in the 0.85 bar deadband near
    # 0 deg. Measured here over several runs: RMSE 1.1 to 1.6 deg (the maximum error, 2 to 5 deg,
    # depends on single transients, so it is not bounded). A rig that did not follow at all
    # would score the RMS of the triangle itself, 15 / sqrt(3) = 8.7 deg. The bound of 3 deg
    # leaves about 2x margin over what this triangle gives and fails on a real loss of tracking.
    aligned = load_bag(bag).aligned()
    assert aligned.angle_desired_rad is not None
    err_deg = np.degrees(aligned.angle_rad - aligned.angle_desired_rad)
    rmse_deg = float(np.sqrt(np.mean(err_deg**2)))
    print(f"tracking from the bag: RMSE {rmse_deg:.2f} deg, max {np.abs(err_deg).max():.2f} deg")
    assert aligned.t_s[-1] - aligned.t_s[0] >= duration_s - 0.05
    assert rmse_deg < 3.0, f"RMSE {rmse_deg:.2f} deg"
    # follow_trajectory scored the same run live from its subscriptions; they agree.
    assert abs(report["overall"]["rmse_deg"] - rmse_deg) < 0.3, (report, rmse_deg)


def _diag_value(status: object, key: str) -> int:
    return int(diagnostic_values(status)[key])


def test_nan_command_refused_and_counted(children: Children) -> None:
    sim = children.start("sim_hardware", node_argv("catheter_driver.sim_hardware_node"))
    with Probe(children.domain_id) as probe:
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(FluidPressure, PRESSURE_COMMAND.name, STREAM)
        ready = probe.spin_until(
            lambda: len(measured) > 25 and pub.get_subscription_count() > 0, 30.0
        )
        assert ready, f"sim_hardware not up: {len(measured)} samples, exit {sim.poll()}"

        sent = {"valid": 0, "nan": 0, "over": 0}

        def send(gauge_pa: float, kind: str) -> None:
            msg = FluidPressure()
            msg.header.stamp = probe.node.get_clock().now().to_msg()
            msg.fluid_pressure = gauge_pa + AMBIENT_PRESSURE_PA
            pub.publish(msg)
            sent[kind] += 1

        # 2 s of 1 bar at 100 Hz, a NaN in place of every 40th command (5 in all), then
        # 1.5 s asking for 5 bar, which the driver must clamp to its 3 bar limit.
        for i in range(200):
            if i % 40 == 20:
                send(float("nan"), "nan")
            else:
                send(1.0e5, "valid")
            probe.spin_for(0.01)
        for _ in range(150):
            send(5.0e5, "over")
            probe.spin_for(0.01)
        n_diag = len(diags)
        total = sum(sent.values())
        probe.spin_until(
            lambda: (
                len(diags) > n_diag
                and any(
                    _diag_value(s, "commands_received") >= total
                    for s in statuses(diags[n_diag:], "catheter/sim_hardware")
                )
            ),
            3.0,
        )
        probe.spin_for(0.1)
    states = statuses(diags, "catheter/sim_hardware")
    assert states, "no /diagnostics from sim_hardware"
    last = states[-1]
    received = _diag_value(last, "commands_received")
    refused = _diag_value(last, "commands_refused_nonfinite")
    total = sum(sent.values())
    # Best effort may drop a command on the way; every one dropped is missing from
    # `received`, so at most that many NaNs can be missing from `refused`.
    dropped = total - received
    assert 0 <= dropped <= 5, (sent, diagnostic_values(last))
    assert max(1, sent["nan"] - dropped) <= refused <= sent["nan"], (sent, diagnostic_values(last))
    if dropped == 0:
        assert refused == sent["nan"]
    # Every 5 bar request was applied at the 3 bar limit (and counted).
    assert _diag_value(last, "commands_clamped") >= sent["over"] - dropped >= 1
    # While commands flowed, the refusal was reported with its reason.
    assert any(s.level == DiagnosticStatus.WARN and "non-finite" in s.message for s in states), [
        (s.level, s.message) for s in states
    ]

    # The line pressure never became NaN, and stayed in [0, 3 bar] gauge (plus sensor
    # noise); it did reach the 3 bar clamp while 5 bar was asked for.
    gauge = np.array([m.msg.fluid_pressure for m in measured]) - AMBIENT_PRESSURE_PA
    assert np.all(np.isfinite(gauge))
    assert gauge.min() >= -NOISE_MARGIN_PA, gauge.min()
    assert gauge.max() <= 3.0e5 + NOISE_MARGIN_PA, gauge.max()
    assert gauge.max() >= 3.0e5 - NOISE_MARGIN_PA, gauge.max()
    assert sim.poll() is None, "sim_hardware exited"


@pytest.mark.parametrize(
    ("module", "param", "value", "range_text"),
    [
        (
            "catheter_driver.sim_hardware_node",
            "effects.pneumatic_lag.time_constant_s",
            5.0,
            "[0.005, 0.5]",
        ),
        ("catheter_control.compensator_node", "max_pressure_pa", 1.0e7, "[0, 600000]"),
    ],
)
def test_out_of_range_parameter_refused(
    children: Children, module: str, param: str, value: float, range_text: str
) -> None:
    t0 = time.monotonic()
    run = children.run(module, node_argv(module, {param: value}), timeout_s=30.0)
    elapsed = time.monotonic() - t0
    output = run.stdout + run.stderr
    # Exit code 2: a refused parameter (run_node's contract), not a crash.
    assert run.returncode == 2, f"exit {run.returncode}:\n{output}"
    assert elapsed < 15.0, f"took {elapsed:.1f} s to refuse"
    assert param in output and range_text in output, output
    assert "Traceback" not in output, output


def test_invalid_trajectory_refused_before_anything_moves(
    children: Children, tmp_path: Path
) -> None:
    # 1. follow_trajectory checks the whole file before it starts or sends anything: no graph
    # is running on this domain, and it must not need one to refuse.
    csv = tmp_path / "too_far.csv"
    csv.write_text("t_s,angle_deg\n0,0\n2.5,60\n5,0\n")
    run_dir = tmp_path / "run"
    run = children.run(
        "follow_trajectory",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--file",
            str(csv),
            "--out",
            str(run_dir),
            "--no-progress",
        ],
        timeout_s=30.0,
    )
    assert run.returncode == 2, f"exit {run.returncode}\n{run.stdout}\n{run.stderr}"
    assert "trajectory refused" in run.stderr
    # The message names the user's own point (row 2 of the file: index 1, at 2.5 s) and the
    # allowed range, so a person can find and fix it.
    assert "trajectory point 1 (t = 2.5 s) asks for 60 deg" in run.stderr, run.stderr
    assert "outside the allowed [0, 35] deg" in run.stderr, run.stderr
    assert not run_dir.exists(), "follow_trajectory made a run directory for a refused file"

    # 2. The compensator validates a trajectory received on the topic as a whole, refuses it
    # with the reason on /diagnostics and sends nothing.
    # No rig here: the probe stands in for the valve driver, so the compensator must not
    # wait for pressure/measured (it would, by default, before the control run below).
    children.start(
        "compensator",
        node_argv("catheter_control.compensator_node", {"require_pressure_measured": False}),
    )
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        desired = probe.subscribe(JointState, ANGLE_DESIRED.name, RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)

        def compensator() -> list[DiagnosticStatus]:
            return statuses(diags, "catheter/compensator")

        # Matched both ways before anything is sent, or "no command seen" would prove nothing.
        ready = probe.spin_until(
            lambda: (
                pub.get_subscription_count() > 0
                and probe.subscriptions[PRESSURE_COMMAND.name].get_publisher_count() > 0
                and bool(compensator())
            ),
            30.0,
        )
        assert ready, f"compensator not up:\n{children.log('compensator')}"

        invalid = {
            "non-finite": trajectory_msg([(0.0, 0.0), (1.0, float("nan")), (2.0, 0.0)]),
            # 20 deg in 10 ms: 2000 deg/s, ten times the rate limit.
            "step": trajectory_msg([(0.0, 0.0), (0.01, 20.0)]),
        }
        for n, (label, msg) in enumerate(invalid.items(), start=1):
            pub.publish(msg)
            refused = probe.spin_until(
                lambda n=n: any(
                    int(diagnostic_values(s)["trajectories_refused"]) >= n for s in compensator()
                ),
                5.0,
            )
            assert refused, f"{label}: no refusal on /diagnostics: {compensator()[-1:]}"
        probe.spin_for(1.0)
        assert not commands, f"{len(commands)} pressure commands after refused trajectories"
        assert not desired, f"{len(desired)} set-points after refused trajectories"
        last = compensator()[-1]
        values = diagnostic_values(last)
        assert last.level == DiagnosticStatus.WARN
        assert last.message.startswith("trajectory refused"), last.message
        assert "rate" in values["last_refusal"], values
        assert values["trajectories_accepted"] == "0" and values["state"] == "idle", values
        assert any(
            s.message.startswith("trajectory refused") and "finite" in s.message
            for s in compensator()
        ), [s.message for s in compensator()]

        # Control: a valid trajectory on the same topic does move it, so silence above meant
        # refusal and not a deaf subscription.
        pub.publish(trajectory_msg([(0.0, 0.0), (0.5, 3.0), (1.0, 0.0)]))
        assert probe.spin_until(lambda: len(commands) > 10, 5.0), "valid trajectory not followed"


def test_the_recorder_counts_and_says_what_it_could_not_keep(
    children: Children, tmp_path: Path
) -> None:
    """A stream that reaches the recorder with a hole in it (here: a user's own best-effort
    driver that lost 22 samples in a row) is recorded as it came, and the hole is counted on
    /diagnostics and in the bag's custom_data; the recorder matched the best-effort publisher
    rather than recording nothing."""
    bag = tmp_path / "bag"
    graph = children.graph(sim_graph_specs(bag, {"source": "gap test"})[:1])
    angle_topic = qualify(TIP_ANGLE)
    with Probe(children.domain_id) as probe:
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointState, TIP_ANGLE.name, qos.SENSOR)
        assert probe.spin_until(
            lambda: recorder_values(probe).get(f"publishers {angle_topic}") == "1", 30.0
        ), recorder_values(probe)
        t0_ns = probe.node.get_clock().now().nanoseconds
        sent = 0
        for k in range(600):
            if 300 <= k < 322:
                continue  # lost on the way
            pub.publish(messages.joint_state(0.001 * k, t0_ns + k * PERIOD_NS))
            sent += 1
            if k % 25 == 0:
                probe.spin_for(0.02)
        said = probe.spin_until(
            lambda: recorder_values(probe).get(f"lost {angle_topic}") == "22", 10.0
        )
        assert said, recorder_values(probe)
        # The hole is seen when the first sample after it arrives; the rest of the burst may
        # still be on its way. Stopping before the last sample arrived would lose it unseen (no
        # later stamp reveals it): a race in the test, not a loss (seen once beside busy
        # loops and a live commissioning run: 577 of 578 in the bag, the last one missing).
        took_all = probe.spin_until(
            lambda: recorder_values(probe).get(f"count {angle_topic}") == str(sent), 30.0
        )
        assert took_all, recorder_values(probe)
        status = statuses(diags, "catheter/recorder")[-1]
        assert status.level == DiagnosticStatus.WARN
        assert f"lost 22 of {angle_topic}" in status.message, status.message
        assert recorder_values(probe)["best_effort_topics"] == angle_topic
    assert graph.stop(timeout_s=15.0) == {"recorder": 0}
    data = load_bag(bag, topics=[TIP_ANGLE.name])
    # Best effort on one host: nothing else was lost, and what came is all in the bag.
    assert data.tip_angle.t_s.size == sent
    assert json.loads(data.custom_data["samples_lost"])[angle_topic] == 22
    assert json.loads(data.custom_data["gaps"])[angle_topic] == 1
    assert any("tip/angle lacks 22 samples in 1 gap(s)" in line for line in data.gap_report())


def test_a_recorder_whose_writer_falls_behind_drops_counts_and_still_finishes_its_bag(
    children: Children, tmp_path: Path
) -> None:
    """With room for one message between writer passes, a burst overflows the recorder's
    intake: it drops and counts rather than growing without bound, every message it was sent
    is either in the bag or counted, and the bag closes whole (mcap summary readable)."""
    bag = tmp_path / "bag"
    specs = sim_graph_specs(bag, {"source": "queue test"})[:1]
    specs[0].params["max_queue"] = 1
    graph = children.graph(specs)
    angle_topic = qualify(TIP_ANGLE)
    with Probe(children.domain_id) as probe:
        probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)  # read by recorder_values
        pub = probe.node.create_publisher(JointState, TIP_ANGLE.name, STREAM)
        assert probe.spin_until(
            lambda: recorder_values(probe).get(f"publishers {angle_topic}") == "1", 30.0
        ), recorder_values(probe)
        t0_ns = probe.node.get_clock().now().nanoseconds
        sent = 400
        for k in range(sent - 1):  # a burst, far faster than one message per writer pass
            pub.publish(messages.joint_state(0.001 * k, t0_ns + k * PERIOD_NS))
        probe.spin_for(1.0)  # the writer catches up; the last message then surely fits
        pub.publish(messages.joint_state(0.0, t0_ns + (sent - 1) * PERIOD_NS))

        def accounted() -> int:
            # Written or dropped. The last message has no later stamp to reveal it as a gap,
            # so stopping before the recorder took it would lose it unseen: a race in the test
            # (seen once in CI beside busy loops: 5 written + 394 dropped of 400), not a loss.
            values = recorder_values(probe)
            return int(values.get(f"count {angle_topic}", "0")) + int(
                values.get(f"dropped {angle_topic}", "0")
            )

        said = probe.spin_until(lambda: accounted() == sent, 30.0)
        assert said, recorder_values(probe)
    assert graph.stop(timeout_s=15.0) == {"recorder": 0}
    with (bag / "bag_0.mcap").open("rb") as f:
        summary = make_reader(f).get_summary()  # a finished file: summary and footer
    assert summary is not None
    data = load_bag(bag, topics=[TIP_ANGLE.name])
    written = data.tip_angle.t_s.size
    dropped = json.loads(data.custom_data["dropped_by_recorder"])[angle_topic]
    assert dropped > 0 and written + dropped == sent, (written, dropped)
    # A dropped sample is lost to the bag, counted once (its stamp kept it out of the gaps).
    assert json.loads(data.custom_data["samples_lost"])[angle_topic] == dropped
