"""``follow_joint_trajectory`` over DDS: the simulated rig and the compensator in their own
processes (started and activated as bringup does), a client in the test process.

One graph for the whole story a client lives through, to keep the suite short: goals the
compensator must refuse come back with its reason and move nothing, a goal with path and goal
tolerances runs to its end on the rig and succeeds (its trajectory republished on the topic
for the record, without the compensator running it twice), and a cancel mid-run ends with the
pressure command at zero.
"""

from __future__ import annotations

import math
import time
from typing import Any

import pytest
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from graph_utils import Children, Probe, gauge_pa, trajectory_msg
from rclpy.action.client import ActionClient
from sensor_msgs.msg import FluidPressure
from trajectory_msgs.msg import JointTrajectory

from catheter_control.bringup import sim_graph_specs
from catheter_control.trajectory_action import ACTION_NAME
from catheter_models.contract import BEND_JOINT, PRESSURE_COMMAND, TRAJECTORY
from catheter_ros import qos

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

Result = FollowJointTrajectory.Result


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
    children.graph(sim_graph_specs(None, compensator_params={"require_tip_angle": True}))
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
        probe.spin_for(1.5)  # the previous run's ramp-down is over
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
