"""``follow_joint_trajectory`` over DDS: the simulated rig and the compensator in their own
processes (started and activated as bringup does), a client in the test process.

One graph for the whole story a client lives through, to keep the suite short: goals the
compensator must refuse come back with its reason and move nothing, a goal with path and goal
tolerances runs to its end on the rig and succeeds (its trajectory republished on the topic
for the record, without the compensator running it twice), and a cancel mid-run ends with the
pressure command at zero. A second graph, with feedback, lives through the hold of a goal's
last point: the bend stays there after the result, the next goal goes on from it or (one
that starts from rest, as a lead-in does) has it released first, and ``~/stop`` releases it.
A third holds a trajectory sent on the topic and loses its laser during the hold.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from graph_utils import (
    SLACK_SENSOR_TIMEOUT_S,
    Children,
    Probe,
    diagnostic_values,
    gauge_pa,
    node_argv,
    statuses,
    trajectory_msg,
)
from rclpy.action.client import ActionClient
from sensor_msgs.msg import FluidPressure, JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from catheter_control.bringup import sim_graph_specs
from catheter_control.trajectory import with_lead_in
from catheter_control.trajectory_action import ACTION_NAME
from catheter_models.contract import (
    ANGLE_DESIRED,
    BEND_JOINT,
    DEFAULT_NAMESPACE,
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    TIP_ANGLE,
    TRAJECTORY,
)
from catheter_ros import qos
from catheter_ros.messages import angle_rad_from, ns_from_time

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

Result = FollowJointTrajectory.Result
RAMP_STEP_PA = 1000.0
"""A fall of the command larger than this is the stop's ramp: the ramp falls 8,000 Pa a tick
(the 20 bar/s slew limit at 250 Hz), the feedback moves a hold by tens of Pa."""


def _goal(points_deg: list[tuple[float, float]], joint: str = BEND_JOINT) -> Any:
    goal = FollowJointTrajectory.Goal()
    goal.trajectory = trajectory_msg(points_deg)
    goal.trajectory.joint_names = [joint]
    return goal


def _send(probe: Probe, client: ActionClient, goal: Any, feedback: list[Any]) -> Any:
    future = client.send_goal_async(goal, feedback_callback=feedback.append)
    assert probe.spin_until(future.done, 20.0), "no answer to the goal"
    handle = future.result()
    assert handle is not None and handle.accepted
    return handle


def _result(probe: Probe, handle: Any, timeout_s: float) -> Any:
    future = handle.get_result_async()
    assert probe.spin_until(future.done, timeout_s), f"no result within {timeout_s:g} s"
    return future.result()


def test_refusals_success_and_cancel_over_dds(children: Children) -> None:
    # About the action's answers, not the sensor timeout: a CI run beside a benchmark saw
    # pressure/measured quiet for 100 ms and the goal aborted.
    slack = {"sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S}
    children.graph(sim_graph_specs(None, compensator_params={"require_tip_angle": True, **slack}))
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, qos.KEEP_EVERY_SAMPLE)
        recorded = probe.subscribe(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        client = ActionClient(probe.node, FollowJointTrajectory, ACTION_NAME)
        assert probe.spin_until(client.server_is_ready, 40.0), (
            f"no {ACTION_NAME} server:\n{children.all_logs()}"
        )

        # Refused: the compensator's reason comes back, and nothing moves.
        for goal, code, reason in (
            (_goal([(2.0, 10.0), (4.0, 0.0)], joint="elbow"), Result.INVALID_JOINTS, "'elbow'"),
            (_goal([(2.0, 50.0), (4.0, 0.0)]), Result.INVALID_GOAL, "outside the allowed"),
        ):
            response = _result(probe, _send(probe, client, goal, []), 20.0)
            assert response.status == GoalStatus.STATUS_ABORTED
            assert response.result.error_code == code
            assert reason in response.result.error_string, response.result.error_string
        probe.spin_for(0.5)
        assert not commands, "a refused goal sent pressure commands"
        assert not recorded, "a refused goal's trajectory was republished"

        # Accepted, followed on the rig within its tolerances, succeeded. The c-LSTM tracks
        # to ~0.5 deg at worst (docs/benchmarks.md); feedback compares the newest sample with
        # the set-point now, which adds up to ~0.5 deg of lag at this slope: 3 deg is loose.
        goal = _goal([(2.0, 15.0), (4.0, 0.0)])
        goal.path_tolerance = [JointTolerance(name=BEND_JOINT, position=math.radians(3.0))]
        goal.goal_tolerance = [JointTolerance(name=BEND_JOINT, position=math.radians(2.0))]
        goal.goal_time_tolerance = Duration(sec=1)
        feedback: list[Any] = []
        response = _result(probe, _send(probe, client, goal, feedback), 30.0)
        assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.error_string
        assert response.result.error_code == Result.SUCCESSFUL
        measured = [f.feedback for f in feedback if f.feedback.actual.positions]
        assert len(measured) >= 20, f"{len(measured)} feedback messages with a measured bend"
        peak_desired_deg = max(math.degrees(f.desired.positions[0]) for f in measured)
        assert peak_desired_deg > 13.0, "feedback never showed the trajectory's peak"
        assert all(list(f.joint_names) == [BEND_JOINT] for f in measured)
        # Republished once, as sent; had the compensator taken it as a new trajectory, the
        # goal would have been pre-empted by its own echo and not succeeded above.
        assert [r.msg.points[-1].time_from_start.sec for r in recorded] == [4]

        # Cancelled mid-run: the goal ends CANCELED, and only once the command is at zero,
        # long before the plan would have ended.
        probe.spin_for(1.5)  # the previous run's ramp-down is over (it ended at rest: no hold)
        commands.clear()
        feedback = []
        handle = _send(probe, client, _goal([(2.0, 15.0), (10.0, 15.0), (12.0, 0.0)]), feedback)
        assert probe.spin_until(
            lambda: any(math.degrees(f.feedback.desired.positions[0]) > 10.0 for f in feedback),
            20.0,
        ), "the held trajectory never got under way"
        canceled_at = time.monotonic()
        cancel = handle.cancel_goal_async()
        assert probe.spin_until(cancel.done, 10.0)
        response = _result(probe, handle, 15.0)
        assert response.status == GoalStatus.STATUS_CANCELED
        assert time.monotonic() - canceled_at < 8.0, "the plan ran on after the cancel"
        probe.spin_for(0.3)
        gauge = gauge_pa(commands)
        assert gauge.max() > 1.0e5, "the catheter was never pressurised before the cancel"
        assert gauge[-1] == pytest.approx(0.0, abs=1.0), f"last command {gauge[-1]:.0f} Pa"


def _held_goal(points_deg: list[tuple[float, float]]) -> Any:
    """A goal whose last point must be reached within 2 deg within 1 s of its end."""
    goal = _goal(points_deg)
    goal.goal_tolerance = [JointTolerance(name=BEND_JOINT, position=math.radians(2.0))]
    goal.goal_time_tolerance = Duration(sec=1)
    return goal


def _since(stamped: list[Any], t0_s: float) -> list[Any]:
    return [m for m in stamped if m.mono_s >= t0_s]


def test_the_last_point_is_held_until_a_new_goal_or_stop(children: Children) -> None:
    # Feedback on the laser's bend (docs/closed_loop.md) holds the bend where it was asked.
    # About the hold, not the sensor timeout: a CI run beside a benchmark saw tip/angle quiet
    # for 100 ms 0.25 s into the hold, and the node ramped down.
    slack = {"sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S}
    children.graph(sim_graph_specs(None, compensator_params={"feedback": "pi", **slack}))
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, qos.KEEP_EVERY_SAMPLE)
        tips = probe.subscribe(JointState, TIP_ANGLE.name, qos.KEEP_EVERY_SAMPLE)
        desired = probe.subscribe(JointState, ANGLE_DESIRED.name, qos.RECORD)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 50)
        client = ActionClient(probe.node, FollowJointTrajectory, ACTION_NAME)
        stop = probe.node.create_client(Trigger, "compensator/stop")
        assert probe.spin_until(lambda: client.server_is_ready() and bool(tips), 40.0), (
            f"no {ACTION_NAME} server or no tip angle:\n{children.all_logs()}"
        )

        def bends_deg(since_s: float) -> Any:
            return [math.degrees(angle_rad_from(m.msg)) for m in _since(tips, since_s)]

        # Up to 15 deg and held: the goal tolerance is met on the hold (before the hold, the
        # pressure ramped down at the end and this ended GOAL_TOLERANCE_VIOLATED 15 deg off).
        response = _result(probe, _send(probe, client, _held_goal([(2.0, 15.0)]), []), 30.0)
        assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.error_string
        held_from = time.monotonic()
        # Judged by when the laser sensed each bend, not when the probe heard it: on a busy
        # machine the probe hears the result before a backlog of samples sensed on the way
        # up. The goal succeeded within its 2 deg; the hold keeps it there and settles.
        held_from_ns = probe.node.get_clock().now().nanoseconds
        probe.spin_for(3.0)
        sensed = [
            (ns_from_time(m.msg.header.stamp) - held_from_ns, math.degrees(angle_rad_from(m.msg)))
            for m in tips
        ]
        held = [b for ns, b in sensed if 0 <= ns <= 2_500_000_000]
        settled = [b for ns, b in sensed if 500_000_000 <= ns <= 2_500_000_000]
        assert len(held) > 200, f"{len(held)} tip samples sensed in 2.5 s of the hold"
        assert max(abs(b - 15.0) for b in held) < 2.0, (min(held), max(held))
        assert max(abs(b - 15.0) for b in settled) < 1.0, (min(settled), max(settled))
        holding = [
            s.message
            for s in statuses(_since(diags, held_from), "catheter/compensator")
            if diagnostic_values(s)["state"] == "holding"
        ]
        assert holding and holding[-1].startswith("holding 15.00 deg for "), holding

        # A goal that starts at the held bend goes on from it: the pressure never lets go.
        sent = time.monotonic()
        goal = _held_goal([(0.0, 15.0), (1.5, 10.0)])
        response = _result(probe, _send(probe, client, goal, []), 30.0)
        assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.error_string
        gauge = gauge_pa(_since(commands, held_from))
        assert gauge.min() > 0.5e5, f"the hold let go before the next goal: {gauge.min():.0f} Pa"
        assert min(bends_deg(sent)) > 8.0, "the bend fell on the way from 15 to 10 deg"

        # A goal that starts from rest, as follow_trajectory's and commission's lead-in does
        # (rest up to 8 deg, then the trajectory from there): the hold at 10 deg is released
        # at the slew limit and the goal starts from rest, with no step of the set-point.
        probe.spin_for(0.5)
        t_s, angle_rad, _ = with_lead_in(
            [0.0, 1.0], [math.radians(8.0), math.radians(12.0)], approach_s=1.0, settle_s=1.0
        )
        goal = _held_goal([(t, math.degrees(a)) for t, a in zip(t_s, angle_rad, strict=True)])
        assert goal.trajectory.points[0].positions[0] == 0.0
        sent = time.monotonic()
        feedback: list[Any] = []
        response = _result(probe, _send(probe, client, goal, feedback), 30.0)
        assert response.status == GoalStatus.STATUS_SUCCEEDED, response.result.error_string
        gauge = gauge_pa(_since(commands, sent))
        assert gauge.min() == pytest.approx(0.0, abs=1.0), "the hold was not released first"
        assert "released the hold at 10.00 deg" in children.all_logs(tail_lines=200)
        # A client tells the plan's set-points from the hold's by the feedback: its stamp
        # minus time_from_start is the stamp of the plan's first set-point (at rest), and
        # the one before it is still the released hold's 10 deg.
        fb = feedback[0].feedback
        first_ns = (
            ns_from_time(fb.header.stamp)
            - fb.desired.time_from_start.sec * 1_000_000_000
            - fb.desired.time_from_start.nanosec
        )
        stamps = np.array([ns_from_time(m.msg.header.stamp) for m in desired])
        k = int(np.argmin(np.abs(stamps - first_ns)))
        assert abs(stamps[k] - first_ns) < 1_000, f"{stamps[k] - first_ns} ns off a set-point"
        assert angle_rad_from(desired[k].msg) == pytest.approx(0.0, abs=1e-6)
        assert math.degrees(angle_rad_from(desired[k - 1].msg)) == pytest.approx(10.0)

        # ~/stop releases the hold: the pressure ramps down to zero and the catheter goes
        # back towards straight.
        probe.spin_for(1.0)
        assert min(bends_deg(time.monotonic() - 0.8)) > 10.0, "12 deg was not held"
        assert probe.spin_until(stop.service_is_ready, 10.0)
        stopped = stop.call_async(Trigger.Request())
        assert probe.spin_until(stopped.done, 10.0)
        stopped_at = time.monotonic()
        probe.spin_for(1.5)
        gauge = gauge_pa(_since(commands, stopped_at))
        assert gauge[-1] == pytest.approx(0.0, abs=1.0), f"last command {gauge[-1]:.0f} Pa"
        # Heard after the answer, some commands were sent before it: the hold's, which the
        # feedback moves by tens of Pa either way (so the highest of them is no mark of the
        # ramp's start; a CI run saw the hold rise by 47 Pa after its highest). The ramp starts
        # with the first fall larger than the feedback ever moves the hold, and from there the
        # pressure only goes down.
        falls = np.flatnonzero(np.diff(gauge) < -RAMP_STEP_PA)
        assert falls.size > 5, f"no ramp down after ~/stop: {gauge.round()}"
        ramp = gauge[falls[0] :]
        assert np.all(np.diff(ramp) <= 0.0), f"a stop only lowers the pressure: {ramp.round()}"
        hold = gauge[: falls[0] + 1]
        assert np.ptp(hold) < RAMP_STEP_PA, f"the hold jumped before the ramp: {hold.round()}"
        assert max(bends_deg(time.monotonic() - 0.3)) < 2.0, "the bend stayed up after ~/stop"


def test_a_laser_gone_quiet_during_the_hold_ramps_it_down_and_says_why(
    children: Children,
) -> None:
    # The rig's laser goes through a relay process (a stand-in laser driver) that the test
    # stops with SIGSTOP, as a hung driver would, while the rig runs on.
    relay = children.start(
        "angle_relay",
        [
            sys.executable,
            str(Path(__file__).with_name("angle_relay.py")),
            "--ros-args",
            "-r",
            f"__ns:={DEFAULT_NAMESPACE}",
        ],
    )
    sim = node_argv("catheter_driver.sim_hardware_node")
    children.start("sim_hardware", [*sim, "-r", f"{TIP_ANGLE.name}:=tip/angle_raw"])
    children.start(
        "compensator",
        node_argv(
            "catheter_control.compensator_node",
            # 0.5 s, not the default 0.1 s: the relay and the rig are two more processes
            # on a busy 2-core CI machine, and one 104 ms hiccup of theirs stopped the hold
            # before the fault was injected. The default's own staleness stop is test_faults'
            # (the laser stalls mid-trajectory).
            {
                "compensator": "none",
                "require_tip_angle": True,
                "sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S,
            },
        ),
    )
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, qos.KEEP_EVERY_SAMPLE)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 50)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        assert probe.spin_until(
            lambda: (
                pub.get_subscription_count() > 0
                and bool(statuses(diags, "catheter/compensator"))
                and bool(statuses(diags, "catheter/sim_hardware"))
            ),
            40.0,
        ), f"graph not up:\n{children.all_logs()}"

        # On the topic, not the action: the hold is the compensator's, whichever way it came.
        pub.publish(trajectory_msg([(0.0, 0.0), (1.5, 15.0)]))

        def holding() -> bool:
            last = statuses(diags, "catheter/compensator")[-1]
            return diagnostic_values(last)["state"] == "holding"

        assert probe.spin_until(holding, 10.0), children.all_logs()
        assert gauge_pa(commands[-25:]).min() > 1.0e5, "not holding 15 deg"

        n_diag = len(diags)
        relay.send_signal(signal.SIGSTOP)
        try:
            t_fault = time.monotonic()
            found = probe.spin_until(
                lambda: any(
                    s.level == DiagnosticStatus.ERROR
                    for s in statuses(diags[n_diag:], "catheter/compensator")
                ),
                5.0,
            )
            probe.spin_for(0.5)
        finally:
            relay.send_signal(signal.SIGCONT)
        assert found, [s.message for s in statuses(diags, "catheter/compensator")[-3:]]
        status = next(
            s
            for s in statuses(diags[n_diag:], "catheter/compensator")
            if s.level == DiagnosticStatus.ERROR
        )
        assert status.message.startswith("stopped: tip/angle stale: no sample for"), status.message
        assert status.message.endswith("ramped down"), status.message
        ramp = gauge_pa([m for m in commands if m.mono_s > t_fault])
        assert ramp.size > 0 and ramp[-1] == 0.0, ramp[-5:]
        down = ramp[int(np.argmax(ramp)) :]
        assert np.all(np.diff(down) <= 1e-6), "the ramp-down went up"
