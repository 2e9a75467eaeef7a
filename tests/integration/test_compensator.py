"""The compensator node in the simulated graph, separate processes over DDS: it follows
thesis trajectories with the shipped c-LSTM, and it stays safe when the laser goes
quiet and when it is sent a trajectory it must refuse (killed: test_faults.py)."""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fault_log import FaultRecord
from graph_utils import (
    COMPENSATOR,
    MAX_PRESSURE_PA,
    NOISE_MARGIN_PA,
    SIM,
    SLACK_SENSOR_TIMEOUT_S,
    Children,
    Probe,
    Stamped,
    diagnostic_values,
    gauge_pa,
    node_argv,
    statuses,
    trajectory_msg,
)
from sensor_msgs.msg import FluidPressure, JointState
from trajectory_msgs.msg import JointTrajectory

from catheter_models.contract import (
    ANGLE_DESIRED,
    DEFAULT_NAMESPACE,
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TRAJECTORY,
)
from catheter_ros import qos
from catheter_ros.qos import RECORD

LASER_BACK_TIMEOUT_S = 15.0
"""How long a resumed stand-in laser may take to publish again (0.04-0.06 s when idle)."""

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

RAW_ANGLE = "tip/angle_raw"
ANGLE_RELAY = Path(__file__).with_name("angle_relay.py")

# Tracking bounds [deg] for the shipped c-LSTM over DDS, per thesis trajectory. The benchmark
# (docs/benchmarks.md) measured, open loop with the plant in the loop, RMSE 0.19 / 0.22 /
# 0.15 / 0.46 deg, and the whole graph over DDS (bench_graph_timing.py) tracks as well as
# that: the real-time graph adds no error of its own beyond a missed tick. The bounds are
# 2.5x those figures, at least 0.5 deg: they tolerate a loaded machine and the sensor noise
# of a single 20 s run, and fail a compensator that stopped compensating (the static
# inverse scores 1.00 / 1.77 / 1.07 / 1.74 deg) or a graph that dropped its timing.
#
# Two of the four run here (40 s of real time): the down-chirp, which starts away from rest
# and needs the lead-in, and the up-chirp. All four are tracked offline with tighter bounds
# (tests/catheter_control/test_shipped_compensators.py) and over DDS by `make demo`.
RMSE_BOUND_DEG = {"traj_down_chirp": 0.55, "traj_up_chirp": 0.5}


def _assert_pressures_in_range(
    commands: list[Stamped], measured: list[Stamped], fault: FaultRecord | None = None
) -> None:
    cmd, meas = gauge_pa(commands), gauge_pa(measured)
    assert meas.size > 0, "no pressure/measured at all"
    ok = (cmd.size == 0 or (cmd.min() >= -1e-6 and cmd.max() <= MAX_PRESSURE_PA + 1e-6)) and (
        meas.max() <= MAX_PRESSURE_PA + NOISE_MARGIN_PA
    )
    detail = (
        f"commands [{cmd.min(initial=0):.0f}, {cmd.max(initial=0):.0f}] Pa, "
        f"measured max {meas.max():.0f} Pa"
    )
    if fault is not None:
        fault.check("range", ok, detail)
    assert ok, detail


def _start_rig_and_compensator(
    children: Children, compensator: dict[str, object], relay_angle: bool = False
) -> None:
    sim = node_argv("catheter_driver.sim_hardware_node")
    if relay_angle:
        # The rig's laser goes to a topic a relay process (a stand-in laser driver) passes on
        # to tip/angle, so the test can stop tip/angle (SIGSTOP, as a hung laser driver would)
        # while the rig runs on.
        sim += ["-r", f"{TIP_ANGLE.name}:={RAW_ANGLE}"]
        children.start(
            "angle_relay",
            [sys.executable, str(ANGLE_RELAY), "--ros-args", "-r", f"__ns:={DEFAULT_NAMESPACE}"],
        )
    children.start("sim_hardware", sim)
    children.start("compensator", node_argv("catheter_control.compensator_node", compensator))


def _wait_ready(probe: Probe, pub: object, diags: list[Stamped], children: Children) -> None:
    ready = probe.spin_until(
        lambda: (
            pub.get_subscription_count() > 0  # type: ignore[attr-defined]
            and bool(statuses(diags, COMPENSATOR))
            and bool(statuses(diags, SIM))
        ),
        40.0,
    )
    assert ready, f"graph not up:\n{children.all_logs()}"


@pytest.mark.timeout(900)  # 45-80 s idle; minutes beside two busy loops
def test_follows_the_thesis_trajectories_with_the_shipped_c_lstm(
    children: Children, tmp_path: Path
) -> None:
    _start_rig_and_compensator(children, {"require_tip_angle": True})
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, qos.KEEP_EVERY_SAMPLE)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, qos.KEEP_EVERY_SAMPLE)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        _wait_ready(probe, pub, diags, children)
        probe.node.destroy_publisher(pub)

        results: dict[str, dict[str, float]] = {}
        for name in RMSE_BOUND_DEG:
            run_dir = tmp_path / name
            # Started, not run: the probe keeps spinning meanwhile, so it hears every command.
            proc = children.start(
                f"follow_{name}",
                [
                    sys.executable,
                    "-m",
                    "catheter_control.follow_trajectory",
                    "--preset",
                    name,
                    "--out",
                    str(run_dir),
                    "--no-progress",
                ],
            )
            probe.spin_until(lambda proc=proc: proc.poll() is not None, 120.0)
            log = children.log(f"follow_{name}")
            assert proc.poll() == 0, f"{name}: exit {proc.poll()}\n{log}"
            report = json.loads((run_dir / "report.json").read_text())
            results[name] = {
                "rmse_deg": report["overall"]["rmse_deg"],
                "mae_deg": report["overall"]["mae_deg"],
                "missed_fraction": report["timing"]["missed_fraction"],
            }
            assert (run_dir / "tracking.png").is_file()
            probe.spin_for(0.2)  # drain what the probe heard meanwhile
        print(json.dumps(results, indent=2))
        for name, r in results.items():
            assert r["rmse_deg"] < RMSE_BOUND_DEG[name], (name, r)
        # Trajectory 2 starts at 8 deg: follow_trajectory moved there from rest first.
        assert json.loads((tmp_path / "traj_down_chirp" / "report.json").read_text())[
            "lead_in_s"
        ] == pytest.approx(2.0)
        probe.spin_for(0.5)
        _assert_pressures_in_range(commands, measured)
        assert len(commands) > 40 * 250 * 0.9, len(commands)
        last = diagnostic_values(statuses(diags, COMPENSATOR)[-1])
        assert last["compensator"] == "clstm" and last["model_rate_hz"] == "250", last
        assert int(last["model_steps"]) > 40 * 250, last


def _send(probe: Probe, pub: object, msg: JointTrajectory) -> None:
    pub.publish(msg)  # type: ignore[attr-defined]


@pytest.mark.fault(
    "tip/angle stream stalls mid-trajectory (the laser goes quiet)",
    safe="compensator stopped, command ramped to 0 at the slew limit",
)
def test_tip_angle_stopping_ramps_the_pressure_down_and_says_why(
    children: Children, fault: FaultRecord
) -> None:
    # Not the node's 0.1 s default: beside two busy loops the relay process went quiet for
    # 104 ms before the laser was stopped on purpose, and the run under test ended early (and
    # for 304 ms, against 0.3 s, in a clean-clone CI run beside the lab's benchmark grid).
    timeout_s = SLACK_SENSOR_TIMEOUT_S
    _start_rig_and_compensator(
        children, {"require_tip_angle": True, "sensor_timeout_s": timeout_s}, relay_angle=True
    )
    with Probe(children.domain_id) as probe:
        relay = children.procs["angle_relay"]
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        desired = probe.subscribe(JointState, ANGLE_DESIRED.name, RECORD)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        angles = probe.subscribe(JointState, TIP_ANGLE.name, RECORD)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        _wait_ready(probe, pub, diags, children)

        # Up to 20 deg and hold: a run that would last 12 s.
        _send(probe, pub, trajectory_msg([(0.0, 0.0), (2.0, 20.0), (12.0, 20.0)]))
        assert probe.spin_until(lambda: len(commands) > 250, 10.0), children.all_logs()
        probe.spin_for(2.5)

        # An invalid trajectory mid-run is refused, and the run in progress goes on.
        n_diag = len(diags)
        _send(probe, pub, trajectory_msg([(0.0, 0.0), (1.0, float("nan")), (2.0, 0.0)]))
        refused = probe.spin_until(
            lambda: any(
                diagnostic_values(s)["trajectories_refused"] == "1"
                for s in statuses(diags[n_diag:], COMPENSATOR)
            ),
            3.0,
        )
        assert refused, statuses(diags, COMPENSATOR)[-1:]
        status = next(
            s
            for s in statuses(diags[n_diag:], COMPENSATOR)
            if diagnostic_values(s)["trajectories_refused"] == "1"
        )
        assert diagnostic_values(status)["state"] == "following", diagnostic_values(status)
        assert "finite" in diagnostic_values(status)["last_refusal"]
        held = gauge_pa(commands[-25:])
        assert held.min() > 1.0e5, held  # still holding 20 deg

        # The laser goes quiet.
        n_diag = len(diags)
        relay.send_signal(signal.SIGSTOP)
        t_fault = time.monotonic()
        status_found = probe.spin_until(
            lambda: any(
                s.level == DiagnosticStatus.ERROR for s in statuses(diags[n_diag:], COMPENSATOR)
            ),
            3.0,
        )
        assert status_found, [s.message for s in statuses(diags, COMPENSATOR)[-3:]]
        status = next(
            s for s in statuses(diags[n_diag:], COMPENSATOR) if s.level == DiagnosticStatus.ERROR
        )
        assert status.message.startswith("stopped: tip/angle stale: no sample for"), status.message
        assert f"(limit {timeout_s * 1e3:.0f} ms); ramped down" in status.message, status.message
        probe.spin_for(1.0)
        after = [m for m in commands if m.mono_s > t_fault]
        ramp = gauge_pa(after)
        # Ramped to zero at the slew limit (20 bar/s: <= 0.15 s from 3 bar, after the
        # timeout), monotonically, then the compensator went quiet (the driver's watchdog
        # holds the valve vented).
        assert ramp.size > 0 and ramp[-1] == 0.0, ramp[-5:]
        steps = np.diff(ramp)
        falling = int(np.flatnonzero(steps < -1.0e3)[0])
        # Until the timeout the compensator still holds 20 deg; from then on, down at the
        # slew limit (8000 Pa per 4 ms tick) and never up.
        assert np.all(np.abs(ramp[: falling + 1] - ramp[0]) < 1.0e3), ramp[: falling + 1]
        assert np.all((steps[falling:] <= 1e-6) & (steps[falling:] >= -8.0e3 - 1e-6)), steps
        assert after[-1].mono_s - t_fault < timeout_s + 0.4, after[-1].mono_s - t_fault
        fault.safe_after(after[-1].mono_s - t_fault)
        fault.check("reported", status.message.startswith("stopped: tip/angle stale"))
        assert diagnostic_values(status)["state"] in {"ramping_down", "idle"}
        _assert_pressures_in_range(commands, measured, fault)
        n_cmd = len(commands)
        probe.spin_for(0.5)
        assert len(commands) == n_cmd, "commands after the ramp-down"

        # A run cannot start while the laser is silent: refused with the reason.
        n_diag = len(diags)
        _send(probe, pub, trajectory_msg([(0.0, 0.0), (2.0, 10.0)]))
        refused = probe.spin_until(
            lambda: any(
                diagnostic_values(s)["last_refusal"].startswith("tip/angle stale")
                for s in statuses(diags[n_diag:], COMPENSATOR)
            ),
            10.0,
        )
        assert refused, [diagnostic_values(s) for s in statuses(diags, COMPENSATOR)[-1:]]
        assert len(commands) == n_cmd, "commands without the laser"

        # The laser is back: the next trajectory runs, from a clean compensator state. Back
        # means its angles reach the graph again (the probe sees them), not a fixed time after
        # SIGCONT: a resumed process first works through what queued while it was stopped.
        relay.send_signal(signal.SIGCONT)
        t_resumed = time.monotonic()
        back = probe.spin_until(
            lambda: sum(m.mono_s > t_resumed for m in angles) >= 25, LASER_BACK_TIMEOUT_S
        )
        assert back, (
            f"the stand-in laser (angle_relay) published nothing for {LASER_BACK_TIMEOUT_S} s "
            "after SIGCONT: the relay, not the compensator, failed",
            children.all_logs(),
        )
        n_diag = len(diags)
        _send(probe, pub, trajectory_msg([(0.0, 0.0), (1.0, 5.0), (2.0, 0.0)]))
        assert probe.spin_until(lambda: len(commands) > n_cmd + 250, 5.0)
        probe.spin_for(2.0)
        status = statuses(diags, COMPENSATOR)[-1]
        assert status.level == DiagnosticStatus.OK, status.message
        assert diagnostic_values(status)["fault"] == ""

        # A set-point for every command while a plan is followed; none while ramping down
        # (the fault's ramp, and each trajectory's end at rest): each command without one is
        # on the way down.
        def stamp(m: Any) -> int:
            return int(m.msg.header.stamp.sec) * 10**9 + int(m.msg.header.stamp.nanosec)

        desired_stamps = {stamp(m) for m in desired}
        command_stamps = [stamp(m) for m in commands]
        assert desired_stamps <= set(command_stamps)
        sent = gauge_pa(commands)
        unset = [i for i, t in enumerate(command_stamps) if t not in desired_stamps]
        assert unset, "no ramp-down was seen"
        assert all(i == 0 or sent[i] <= sent[i - 1] + 1e-6 for i in unset), sent[unset]


def test_a_1_khz_loop_follows_like_the_250_hz_one(children: Children, tmp_path: Path) -> None:
    """`follow_trajectory --sim --control-rate-hz 1000`: the whole graph, the c-LSTM at 250 Hz
    inside a 1 kHz loop. Timing targets are the benchmark's business (docs/benchmarks.md);
    this checks that the loop really ran at 1 kHz and tracked as the 250 Hz one does."""
    run_dir = tmp_path / "run"
    run = children.run(
        "follow_trajectory",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--sim",
            "--preset",
            "traj_up_chirp",
            "--control-rate-hz",
            "1000",
            "--out",
            str(run_dir),
            "--no-progress",
        ],
        timeout_s=150.0,
    )
    assert run.returncode == 0, f"exit {run.returncode}\n{run.stdout}\n{run.stderr}"
    report = json.loads((run_dir / "report.json").read_text())
    timing = report["timing"]
    assert timing["control_rate_hz"] == 1000.0, timing
    # 20 s of trajectory plus up to a report period either side: ~20,000 to 22,000 deadlines,
    # of which the loop ran most (the benchmark measured 0.055 % missed; a loaded CI machine
    # may miss more, which is not what this test is about).
    deadlines = timing["ticks"] + timing["missed_deadlines"]
    assert 19_000 <= deadlines <= 23_500, timing
    assert timing["ticks"] >= 0.5 * deadlines, timing
    # Measured 0.147 deg at 1 kHz (0.145 deg offline at 250 Hz): same bound as at 250 Hz.
    assert report["overall"]["rmse_deg"] < RMSE_BOUND_DEG["traj_up_chirp"], report["overall"]
    assert "Control loop at 1000 Hz" in run.stdout, run.stdout
