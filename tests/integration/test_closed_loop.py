"""Feedback on the measured bend in the real graph (separate processes over DDS): it tracks
better than the feedforward alone, and it stays safe when the laser lies or the gains are
wrong."""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fault_log import FaultRecord
from graph_utils import (
    COMPENSATOR,
    SLACK_SENSOR_TIMEOUT_S,
    Children,
    Probe,
    diagnostic_values,
    gauge_pa,
    node_argv,
    statuses,
    trajectory_msg,
)
from sensor_msgs.msg import FluidPressure, JointState
from test_compensator import (
    _assert_pressures_in_range,
    _send,
    _start_rig_and_compensator,
    _wait_ready,
)
from trajectory_msgs.msg import JointTrajectory

from catheter_control.models import SHIPPED_GAINS, shipped_model_dir
from catheter_models.contract import (
    ANGLE_DESIRED,
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TRAJECTORY,
)
from catheter_models.feedback import GAINS_FILE, FeedbackGains
from catheter_ros import qos
from catheter_ros.qos import RECORD

pytestmark = [
    pytest.mark.slow,
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

# Offline (bench/bench_closed_loop.py, the same plant and shipped gains at 250 Hz), the static
# inverse tracks the down-chirp at 1.77 deg alone and 0.24 deg with the PI. Over DDS at 1 kHz
# the bound is half the feedforward's error: it fails a feedback that does nothing or makes
# things worse, and tolerates a loaded machine.
FEEDBACK_BOUND_DEG = 0.9
SHIPPED = shipped_model_dir(SHIPPED_GAINS)
"""The shipped gains (tuned on the simulated rig), which the nodes here load."""


def test_feedback_in_the_graph_at_1_khz_halves_the_feedforwards_error(
    children: Children, tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    run = children.run(
        "follow_trajectory",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--sim",
            "--compensator",
            "none",
            "--feedback",
            "pi",
            "--preset",
            "traj_down_chirp",
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
    assert report["overall"]["rmse_deg"] < FEEDBACK_BOUND_DEG, report["overall"]
    assert report["timing"]["control_rate_hz"] == 1000.0
    controller = report["controller"]
    assert controller["compensator"] == "none" and controller["feedback"] == "pi", controller
    # The laser's every sample was usable: the feedback never held for a bad one.
    assert controller["feedback_untrusted_samples"] == "0", controller


@pytest.mark.fault(
    "laser freezes at a plausible value while feedback is on",
    safe="feedback held within its authority, then ramped down with the reason",
)
def test_a_frozen_laser_is_caught_by_the_feedbacks_authority(
    children: Children, fault: FaultRecord
) -> None:
    _start_rig_and_compensator(
        children,
        {
            "compensator": "none",
            "feedback": "pi",
            "require_tip_angle": True,
            # A frozen laser still publishes; its staleness is test_compensator's.
            "sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S,
        },
        relay_angle=True,
    )
    gains = FeedbackGains.load(SHIPPED)
    with Probe(children.domain_id) as probe:
        relay = children.procs["angle_relay"]
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        _wait_ready(probe, pub, diags, children)
        # To 5 deg, hold, then on to 20 deg: the laser freezes during the hold.
        _send(probe, pub, trajectory_msg([(0.0, 0.0), (1.0, 5.0), (3.0, 5.0), (6.0, 20.0)]))
        assert probe.spin_until(lambda: len(commands) > 250, 10.0), children.all_logs()
        probe.spin_for(1.5)
        held = gauge_pa(commands[-25:]).mean()
        n_diag = len(diags)
        relay.send_signal(signal.SIGUSR1)
        t_fault = time.monotonic()
        found = probe.spin_until(
            lambda: any(
                s.level == DiagnosticStatus.ERROR for s in statuses(diags[n_diag:], COMPENSATOR)
            ),
            8.0,
        )
        assert found, [s.message for s in statuses(diags, COMPENSATOR)[-3:]]
        status = next(
            s for s in statuses(diags[n_diag:], COMPENSATOR) if s.level == DiagnosticStatus.ERROR
        )
        assert "authority" in status.message and "laser" in status.message, status.message
        probe.spin_for(1.0)
        after = gauge_pa([m for m in commands if m.mono_s > t_fault])
        assert after.size > 0 and after[-1] == 0.0, after[-5:]
        # The static inverse alone asks at most ~2 bar for 20 deg; the frozen laser never
        # pushed the command more than the feedback's authority above what it was asked.
        assert after.max() < 2.2e5 + gains.max_correction_pa, after.max()
        fault.check("reported", "authority" in status.message, status.message)
        fault.safe_after(max(m.mono_s for m in commands if m.mono_s > t_fault) - t_fault)
        _assert_pressures_in_range(commands, measured, fault)
        assert held > 0.5e5


@pytest.mark.fault(
    "feedback gains with a sign error (negative kp) given at start",
    safe="compensator refuses to start and names the gain; nothing moves",
)
def test_gains_with_a_sign_error_are_refused_at_start(
    children: Children, fault: FaultRecord, tmp_path: Path
) -> None:
    raw = json.loads((SHIPPED / GAINS_FILE).read_text())
    raw["kp_pa_per_rad"] = -raw["kp_pa_per_rad"]
    bad = tmp_path / "feedback.json"
    bad.write_text(json.dumps(raw))
    run = children.run(
        "compensator",
        node_argv(
            "catheter_control.compensator_node",
            {"compensator": "none", "feedback": "pi", "feedback_gains": str(bad)},
        ),
        timeout_s=60.0,
    )
    said = run.stdout + run.stderr
    assert run.returncode != 0, said
    assert "kp_pa_per_rad must be >= 0" in said and "sign error" in said, said
    fault.check("reported", "kp_pa_per_rad" in said, said[-300:])
    fault.safe_after(0.0)


def _start(children: Children, sim_params: dict[str, object] | None = None) -> None:
    children.start("sim_hardware", node_argv("catheter_driver.sim_hardware_node", sim_params))
    children.start(
        "compensator",
        node_argv(
            "catheter_control.compensator_node",
            {
                "compensator": "none",
                "feedback": "pi",
                "require_tip_angle": True,
                # Not about a sensor's silence: a busy machine's pauses must not stop these.
                "sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S,
            },
        ),
    )


@pytest.mark.fault(
    "the valve saturates: a set-point beyond what 3 bar can bend, with feedback on",
    safe="command held at the 3 bar clamp; off it within a few ticks once the set-point "
    "is reachable (no wound-up integral)",
)
def test_a_saturated_valve_does_not_wind_the_feedback_up(
    children: Children, fault: FaultRecord
) -> None:
    _start(children)
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        desired = probe.subscribe(JointState, ANGLE_DESIRED.name, RECORD)
        angles = probe.subscribe(JointState, TIP_ANGLE.name, RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        _wait_ready(probe, pub, diags, children)
        # 35 deg is past the rig's ~28 deg at 3 bar: the command pins at the clamp for 3 s.
        _send(
            probe,
            pub,
            trajectory_msg([(0.0, 0.0), (2.0, 35.0), (5.0, 35.0), (7.0, 10.0), (10.0, 10.0)]),
        )
        assert probe.spin_until(lambda: len(commands) > 250, 10.0), children.all_logs()
        probe.spin_for(10.5)
        cmd = gauge_pa(commands)
        t_cmd = np.array([m.mono_s for m in commands])
        set_points = np.degrees([m.msg.position[0] for m in desired])
        t_set = np.array([m.mono_s for m in desired])
        # Pinned at the clamp while the set-point is out of reach ...
        leave = t_set[np.flatnonzero(set_points >= 34.99)[-1]]
        pinned = cmd[(t_cmd > leave - 1.0) & (t_cmd < leave)]
        assert pinned.size and np.all(pinned >= 3.0e5 - 1.0), pinned
        # ... and off it as soon as the falling set-point comes within reach (below the bend
        # the clamp gave). A wound-up integral would hold it there for seconds more.
        reach_deg = max(
            np.degrees(m.msg.position[0]) for m in angles if leave - 1.0 < m.mono_s < leave
        )
        reachable = t_set[(t_set > leave) & (set_points < reach_deg)][0]
        freed = t_cmd[(t_cmd > leave) & (cmd < 3.0e5 - 1.0)]
        assert freed.size and freed[0] - reachable < 0.1, (freed[0] - reachable, reach_deg)
        # And the bend settles on 10 deg, not below it (a wound-up integral overshoots down).
        # The plan holds 10 deg for its last 3 s; the compensator then ramps down (<= 0.1 s
        # from there), still publishing that set-point. Score the hold's last second before it.
        end = t_set[-1]
        bend = np.degrees([m.msg.position[0] for m in angles if end - 1.4 < m.mono_s < end - 0.4])
        assert abs(bend.mean() - 10.0) < 0.3, bend.mean()
        assert bend.min() > 9.0, bend.min()
        fault.check("off the clamp within 0.1 s of the set-point coming within reach", True)
        fault.safe_after(0.0)
        _assert_pressures_in_range(commands, measured, fault)
        last = diagnostic_values(statuses(diags, COMPENSATOR)[-1])
        assert int(last["feedback_saturated_ticks"]) > 0, last


@pytest.mark.fault(
    "a noisy laser (10x its noise) with feedback on",
    safe="the loop stays stable; the noise reaches the command only attenuated",
)
def test_a_noisy_laser_does_not_destabilise_the_feedback(
    children: Children, fault: FaultRecord
) -> None:
    # The rig's laser distance noise is 0.02 mm std (about 0.05 deg); ten times that.
    _start(children, {"rig.laser_noise_m": 0.2e-3})
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        angles = probe.subscribe(JointState, TIP_ANGLE.name, RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        _wait_ready(probe, pub, diags, children)
        _send(probe, pub, trajectory_msg([(0.0, 0.0), (2.0, 12.0), (6.0, 12.0)]))
        assert probe.spin_until(lambda: len(commands) > 250, 10.0), children.all_logs()
        probe.spin_for(6.5)
        t_cmd = np.array([m.mono_s for m in commands])
        end = t_cmd[-1]
        hold = (t_cmd > end - 2.5) & (t_cmd < end - 0.5)
        noise_deg = np.degrees(
            np.std([m.msg.position[0] for m in angles if end - 2.5 < m.mono_s < end - 0.5])
        )
        bend = np.degrees([m.msg.position[0] for m in angles if end - 2.5 < m.mono_s < end - 0.5])
        assert noise_deg > 0.2, noise_deg  # the noise really is there
        # The hold is held: on average at the set-point, and the command quiet (a loop near
        # instability would ring; the laser's noise through kp alone is ~0.03 bar).
        assert abs(bend.mean() - 12.0) < 0.2, bend.mean()
        assert np.std(gauge_pa(commands)[hold]) < 0.1e5, np.std(gauge_pa(commands)[hold])
        fault.check("stable: hold on the set-point, command std < 0.1 bar", True)
        fault.safe_after(0.0)
        _assert_pressures_in_range(commands, measured, fault)
