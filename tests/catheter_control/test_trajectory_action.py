"""The FollowJointTrajectory server over a fake compensator, client and server in one process.

The fake stands for the compensator's narrow interface (submit, progress, stop) with a plan
clock the test moves by hand, so each outcome a client relies on is reached on purpose:
success, a refusal with the compensator's reason, a path-tolerance abort that stops the
catheter, a cancel that ends only once the pressure is down, pre-emption, and the goal
tolerance judged while the compensator holds the last point.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
import rclpy
from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from rclpy.action.client import ActionClient
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from rclpy.task import Future
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from catheter_control.trajectory import TrajectoryLimits, TrajectoryPlan
from catheter_control.trajectory_action import RunProgress, TrajectoryActionServer
from catheter_models.contract import (
    BEND_JOINT,
    MAX_TRAJECTORY_DURATION_S,
    MAX_TRAJECTORY_POINTS,
    TIP_ANGLE,
)
from catheter_models.errors import CatheterError
from catheter_ros import messages

pytestmark = pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning")

Result = FollowJointTrajectory.Result
TIMEOUT_S = 20.0  # generous: the machine may be busy; every wait ends as soon as it can


class FakeRunner:
    """The compensator as the server sees it; the test moves plan time and ends plans."""

    hold_timeout_s = 60.0

    def __init__(self) -> None:
        self.pending: TrajectoryPlan | None = None
        self.following: TrajectoryPlan | None = None
        self.holding: TrajectoryPlan | None = None
        self.elapsed_s = 0.0
        self.ended: list[tuple[TrajectoryPlan, str]] = []
        self.pressure_down = True
        self.stops = 0

    def submit_trajectory(self, msg: JointTrajectory) -> str | None:
        if BEND_JOINT not in msg.joint_names:
            return f"joint_names {list(msg.joint_names)!r} lack {BEND_JOINT!r}"
        times = [p.time_from_start.sec + p.time_from_start.nanosec * 1e-9 for p in msg.points]
        try:
            self.pending = TrajectoryPlan.from_knots(
                times, [p.positions[0] for p in msg.points], TrajectoryLimits(), 250.0
            )
        except CatheterError as exc:
            return str(exc)
        return None

    def trajectory_progress(self) -> RunProgress:
        return RunProgress(
            pending=self.pending,
            following=self.following,
            elapsed_s=self.elapsed_s,
            ended=tuple(self.ended),
            idle=self.pending is None
            and self.following is None
            and self.holding is None
            and self.pressure_down,
            holding=self.holding,
        )

    def stop_trajectory(self) -> None:
        self.stops += 1
        if self.pending is not None:
            self.ended.append((self.pending, "stopped before it started"))
            self.pending = None
        for plan in (self.following, self.holding):
            if plan is not None:
                self.ended.append((plan, "stopped on request; pressure ramped down"))
                self.pressure_down = False  # the ramp takes a while
        self.following = self.holding = None

    # what the control thread does
    def start(self) -> TrajectoryPlan:
        assert self.pending is not None
        if self.holding is not None:
            self.ended.append(
                (self.holding, "pre-empted by a newer trajectory while its last point was held")
            )
            self.holding = None
        self.following, self.pending, self.elapsed_s = self.pending, None, 0.0
        self.pressure_down = False
        return self.following

    def run_to_end(self, past_s: float = 0.0) -> None:
        """The plan ran to its end ``past_s`` ago; its last point is held since."""
        assert self.following is not None
        self.elapsed_s = self.following.duration_s + past_s
        self.ended.append((self.following, ""))
        self.holding, self.following = self.following, None


@dataclass
class Rig:
    runner: FakeRunner
    node: Node
    client: ActionClient
    executor: SingleThreadedExecutor
    publish_tip: Callable[[float], None]

    def spin_until(self, done: Callable[[], bool]) -> None:
        deadline = self.node.get_clock().now().nanoseconds + int(TIMEOUT_S * 1e9)
        while not done():
            assert self.node.get_clock().now().nanoseconds < deadline, "timed out"
            self.executor.spin_once(timeout_sec=0.05)

    def send(self, goal: FollowJointTrajectory.Goal, feedback: list[Any] | None = None) -> Any:
        """Send ``goal`` and return its accepted handle."""
        future = self.client.send_goal_async(
            goal, feedback_callback=None if feedback is None else feedback.append
        )
        self.spin_until(future.done)
        handle = future.result()
        assert handle is not None and handle.accepted
        return handle

    def result(self, handle: Any) -> Any:
        future: Future[Any] = handle.get_result_async()
        self.spin_until(future.done)
        return future.result()


@pytest.fixture
def rig() -> Iterator[Rig]:
    context = Context()
    # A domain of its own (per process), discovery on this host only.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    rclpy.init(context=context, domain_id=100 + os.getpid() % 100)
    node = Node("trajectory_action_test", context=context)
    runner = FakeRunner()
    server = TrajectoryActionServer(node, runner, feedback_rate_hz=50.0)
    client = ActionClient(node, FollowJointTrajectory, "follow_joint_trajectory")
    tip_pub = node.create_publisher(JointState, TIP_ANGLE.name, qos_profile_sensor_data)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    rig = Rig(
        runner,
        node,
        client,
        executor,
        lambda angle_rad: tip_pub.publish(messages.joint_state(angle_rad, 0)),
    )
    try:
        rig.spin_until(client.server_is_ready)
        yield rig
    finally:
        server.destroy()
        client.destroy()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)


def goal_of(points_deg: list[tuple[float, float]], joint: str = BEND_JOINT) -> Any:
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = [joint]
    for t_s, angle_deg in points_deg:
        goal.trajectory.points.append(
            JointTrajectoryPoint(
                positions=[math.radians(angle_deg)],
                time_from_start=Duration(sec=int(t_s), nanosec=round((t_s % 1.0) * 1e9)),
            )
        )
    return goal


RAMP = [(1.0, 10.0), (2.0, 0.0)]


def test_a_goal_that_runs_to_its_end_succeeds_with_feedback(rig: Rig) -> None:
    feedback: list[Any] = []
    handle = rig.send(goal_of(RAMP), feedback)
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    rig.runner.elapsed_s = 1.0  # at the peak: desired 10 deg
    rig.publish_tip(math.radians(9.0))
    rig.spin_until(lambda: any(f.feedback.actual.positions for f in feedback))
    fb = next(f.feedback for f in feedback if f.feedback.actual.positions)
    assert list(fb.joint_names) == [BEND_JOINT]
    assert fb.desired.positions[0] == pytest.approx(math.radians(10.0))
    assert fb.actual.positions[0] == pytest.approx(math.radians(9.0))
    assert fb.error.positions[0] == pytest.approx(math.radians(1.0))
    assert fb.index == 0  # the goal's first point (t = 1 s) is in force
    rig.runner.run_to_end()
    response = rig.result(handle)
    assert response.status == 4  # GoalStatus.STATUS_SUCCEEDED
    assert response.result.error_code == Result.SUCCESSFUL


@pytest.mark.parametrize(
    ("goal", "code", "reason"),
    [
        (goal_of(RAMP, joint="elbow"), Result.INVALID_JOINTS, "'elbow'"),
        (goal_of([(1.0, 80.0), (2.0, 0.0)]), Result.INVALID_GOAL, "outside the allowed"),
        (
            goal_of([(0.01 * (i + 1), 0.0) for i in range(MAX_TRAJECTORY_POINTS + 1)]),
            Result.INVALID_GOAL,
            f"{MAX_TRAJECTORY_POINTS + 1} points, over the limit of {MAX_TRAJECTORY_POINTS} "
            "(MAX_TRAJECTORY_POINTS)",
        ),
        (
            goal_of([(1.0, 5.0), (MAX_TRAJECTORY_DURATION_S + 1.0, 5.0)]),
            Result.INVALID_GOAL,
            "(MAX_TRAJECTORY_DURATION_S)",
        ),
    ],
    ids=["wrong joint", "beyond the angle limit", "too many points", "too long"],
)
def test_a_refused_goal_ends_with_the_reason_and_nothing_runs(
    rig: Rig, goal: Any, code: int, reason: str
) -> None:
    response = rig.result(rig.send(goal))
    assert response.status == 6  # GoalStatus.STATUS_ABORTED
    assert response.result.error_code == code
    assert reason in response.result.error_string
    assert rig.runner.pending is None


def test_a_velocity_tolerance_is_refused_not_ignored(rig: Rig) -> None:
    goal = goal_of(RAMP)
    goal.path_tolerance = [JointTolerance(name=BEND_JOINT, position=0.0, velocity=0.1)]
    response = rig.result(rig.send(goal))
    assert response.result.error_code == Result.INVALID_GOAL
    assert "velocity" in response.result.error_string
    assert rig.runner.pending is None


def test_leaving_the_path_tolerance_stops_the_catheter(rig: Rig) -> None:
    goal = goal_of(RAMP)
    goal.path_tolerance = [JointTolerance(name=BEND_JOINT, position=math.radians(2.0))]
    rig.publish_tip(0.0)
    rig.spin_until(lambda: rig.node.count_subscribers(TIP_ANGLE.name) > 0)
    # The goal needs a fresh tip angle to be accepted: keep one coming until it is.
    handle_future = rig.client.send_goal_async(goal)
    rig.spin_until(lambda: (rig.publish_tip(0.0), handle_future.done())[1])
    handle = handle_future.result()
    assert handle is not None
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    rig.runner.elapsed_s = 1.0  # desired 10 deg; measured 5 deg is 5 deg off
    result_future = handle.get_result_async()
    rig.spin_until(lambda: (rig.publish_tip(math.radians(5.0)), result_future.done())[1])
    result = result_future.result().result
    assert result.error_code == Result.PATH_TOLERANCE_VIOLATED
    assert "off the path by +5.00 deg" in result.error_string
    assert rig.runner.stops == 1


def test_cancel_ends_only_once_the_pressure_is_down(rig: Rig) -> None:
    handle = rig.send(goal_of(RAMP))
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    cancel = handle.cancel_goal_async()
    rig.spin_until(cancel.done)
    assert rig.runner.stops == 1
    result_future = handle.get_result_async()
    rig.executor.spin_once(timeout_sec=0.2)
    assert not result_future.done(), "canceled while the pressure was still ramping down"
    rig.runner.pressure_down = True
    rig.spin_until(result_future.done)
    assert result_future.result().status == 5  # GoalStatus.STATUS_CANCELED


def test_a_new_goal_preempts_the_running_one(rig: Rig) -> None:
    first = rig.send(goal_of(RAMP))
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    second = rig.send(goal_of([(1.0, 5.0), (2.0, 0.0)]))
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    first_result = rig.result(first)
    assert first_result.status == 6
    assert "pre-empted" in first_result.result.error_string
    rig.runner.run_to_end()
    assert rig.result(second).result.error_code == Result.SUCCESSFUL


def test_follow_trajectory_s_goal_keeps_each_knot_s_time_to_the_nanosecond() -> None:
    import numpy as np

    from catheter_control.trajectory_client import _goal

    # A knot half a nanosecond below a whole second rounds up to it; rounding the fraction
    # alone once sent it as (that second - 1, 0 ns), a whole second early.
    t_s = np.array([0.0, 0.9999999999, 1.5, 2.0000000004, 61.25])
    plan = TrajectoryPlan(t_s=t_s, angle_rad=np.linspace(0.0, 0.2, t_s.size))
    points = _goal(plan).trajectory.points
    sent = [(p.time_from_start.sec, p.time_from_start.nanosec) for p in points]
    assert sent == [(0, 0), (1, 0), (1, 500_000_000), (2, 0), (61, 250_000_000)]
    assert all(0 <= ns < 1_000_000_000 for _, ns in sent)


HOLD_15 = [(1.0, 15.0)]
"""From rest up to 15 deg, which is then held."""


def goal_held_at_15(goal_time_s: float = 1.0) -> Any:
    goal = goal_of(HOLD_15)
    goal.goal_tolerance = [JointTolerance(name=BEND_JOINT, position=math.radians(2.0))]
    goal.goal_time_tolerance = Duration(
        sec=int(goal_time_s), nanosec=round((goal_time_s % 1.0) * 1e9)
    )
    return goal


def start_held_goal(rig: Rig, goal: Any, feedback: list[Any] | None = None) -> Any:
    """Send ``goal`` (a goal tolerance needs a fresh tip angle), start it, run it to its end."""
    rig.publish_tip(0.0)
    rig.spin_until(lambda: rig.node.count_subscribers(TIP_ANGLE.name) > 0)
    future = rig.client.send_goal_async(
        goal, feedback_callback=None if feedback is None else feedback.append
    )
    rig.spin_until(lambda: (rig.publish_tip(0.0), future.done())[1])
    handle = future.result()
    assert handle is not None and handle.accepted
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    rig.runner.run_to_end()
    return handle


def test_the_goal_tolerance_is_judged_on_the_held_last_point(rig: Rig) -> None:
    feedback: list[Any] = []
    handle = start_held_goal(rig, goal_held_at_15(), feedback)
    result_future = handle.get_result_async()
    # Still on its way up, 4 deg short: the goal time has not passed, so no verdict yet;
    # meanwhile the feedback shows the held point as the one desired.
    for _ in range(5):
        rig.publish_tip(math.radians(11.0))
        rig.executor.spin_once(timeout_sec=0.02)
    assert not result_future.done(), "judged before the goal time had passed"
    rig.spin_until(lambda: any(f.feedback.actual.positions for f in feedback))
    held = [f.feedback for f in feedback if f.feedback.actual.positions][-1]
    assert held.desired.positions[0] == pytest.approx(math.radians(15.0))
    assert held.index == 0
    rig.spin_until(lambda: (rig.publish_tip(math.radians(14.0)), result_future.done())[1])
    assert result_future.result().result.error_code == Result.SUCCESSFUL
    # The hold is the compensator's to keep after the result: nothing released it.
    assert rig.runner.stops == 0 and rig.runner.holding is not None


def test_a_held_point_missed_for_the_whole_goal_time_violates_the_goal_tolerance(
    rig: Rig,
) -> None:
    handle = start_held_goal(rig, goal_held_at_15(goal_time_s=0.3))
    result_future = handle.get_result_async()
    rig.spin_until(lambda: (rig.publish_tip(math.radians(10.0)), result_future.done())[1])
    result = result_future.result().result
    assert result.error_code == Result.GOAL_TOLERANCE_VIOLATED
    assert "-5.00 deg off the last point 0.3 s after the end" in result.error_string


def test_the_goal_time_runs_from_the_plan_s_end_not_from_when_it_was_seen(rig: Rig) -> None:
    handle = start_held_goal(rig, goal_held_at_15(goal_time_s=1.0))
    rig.runner.elapsed_s += 5.0  # the timer first looks 5 s after the end
    result_future = handle.get_result_async()
    rig.spin_until(lambda: (rig.publish_tip(math.radians(10.0)), result_future.done())[1])
    assert result_future.result().result.error_code == Result.GOAL_TOLERANCE_VIOLATED


def test_a_hold_that_ends_during_the_goal_time_aborts_with_its_reason(rig: Rig) -> None:
    handle = start_held_goal(rig, goal_held_at_15())
    plan = rig.runner.holding
    assert plan is not None
    rig.runner.holding = None
    rig.runner.ended.append((plan, "tip/angle stale: no sample for 120 ms (limit 100 ms)"))
    result = rig.result(handle).result
    assert result.error_code == Result.INVALID_GOAL
    assert result.error_string.startswith("tip/angle stale")


def test_cancel_during_the_goal_time_releases_the_hold(rig: Rig) -> None:
    handle = start_held_goal(rig, goal_held_at_15())
    cancel = handle.cancel_goal_async()
    rig.spin_until(cancel.done)
    assert rig.runner.stops == 1 and rig.runner.holding is None
    result_future = handle.get_result_async()
    rig.executor.spin_once(timeout_sec=0.2)
    assert not result_future.done(), "canceled while the pressure was still ramping down"
    rig.runner.pressure_down = True
    rig.spin_until(result_future.done)
    assert result_future.result().status == 5  # GoalStatus.STATUS_CANCELED


def test_a_new_goal_during_the_goal_time_pre_empts_the_held_one(rig: Rig) -> None:
    first = start_held_goal(rig, goal_held_at_15())
    second = rig.send(goal_of([(0.0, 15.0), (1.0, 10.0)]))
    rig.spin_until(lambda: rig.runner.pending is not None)
    rig.runner.start()
    first_result = rig.result(first).result
    assert first_result.error_code == Result.INVALID_GOAL
    assert "pre-empted" in first_result.error_string
    rig.runner.run_to_end()
    assert rig.result(second).result.error_code == Result.SUCCESSFUL


def test_a_goal_time_longer_than_the_hold_is_refused(rig: Rig) -> None:
    rig.runner.hold_timeout_s = 0.5
    rig.publish_tip(0.0)
    rig.spin_until(lambda: rig.node.count_subscribers(TIP_ANGLE.name) > 0)
    future = rig.client.send_goal_async(goal_held_at_15(goal_time_s=1.0))
    rig.spin_until(lambda: (rig.publish_tip(0.0), future.done())[1])
    handle = future.result()
    assert handle is not None
    result = rig.result(handle).result
    assert result.error_code == Result.INVALID_GOAL
    assert "hold_timeout_s 0.5 s" in result.error_string
    assert rig.runner.pending is None
