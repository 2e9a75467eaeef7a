"""``follow_joint_trajectory``: the compensator's trajectories as a ROS action.

``control_msgs/action/FollowJointTrajectory`` beside the ``trajectory`` topic, in the graph's
namespace (not ``<controller>/follow_joint_trajectory``: the graph has one controller, and
the topic beside it is not under the node's name either). Both front ends hand the
compensator the same message and get the same checks (:meth:`TrajectoryRunner.submit_trajectory`).

* **Goals.** The trajectory must name exactly the one joint :data:`BEND_JOINT`. A goal is
  accepted, then checked; a refused one is aborted at once with ``INVALID_JOINTS`` or
  ``INVALID_GOAL`` and the compensator's reason in ``error_string`` (a ROS 2 rejection carries
  no reason; the result's codes exist for this). A new accepted goal, or a trajectory on the
  topic, pre-empts the running goal (the catheter moves on from where it is, as with the
  topic); the old goal is aborted with ``INVALID_GOAL`` and "pre-empted".
* **Feedback** at ``feedback_rate_hz`` (20 Hz): desired, measured (``tip/angle``; left empty
  without a fresh sample) and error (desired - measured) of the bend, and the goal point in
  force. Its header stamp and ``time_from_start`` are read at one instant and stamped as
  the compensator stamps ``angle/desired``, so stamp minus ``time_from_start`` is the stamp
  of the plan's first set-point: a client tells the plan's set-points from a hold's before
  it (``trajectory_client`` does).
* **Tolerances.** ``path_tolerance`` and ``goal_tolerance`` positions for ``bend`` are
  checked against ``tip/angle`` (a goal that sets one is refused when no tip angle arrives).
  The path is checked at the feedback rate; a violation stops the run (the pressure ramps
  down) and aborts with ``PATH_TOLERANCE_VIOLATED``. The goal tolerance must hold at some
  ``tip/angle`` sample within ``goal_time_tolerance`` after the plan's last point (with 0,
  the first sample after it), else ``GOAL_TOLERANCE_VIOLATED``; meanwhile the compensator
  holds the last point, so a goal whose ``goal_time_tolerance`` is longer than the
  compensator's ``hold_timeout_s`` is refused. Velocity and acceleration tolerances are
  refused: the catheter's bend rate is not measured. 0 and -1 mean "none".
* **Hold.** After the last point the compensator holds it (as ros2_controllers' trajectory
  controller does), through the goal time and on after the result, until a new trajectory
  replaces the hold, ``~/stop`` releases it, or its ``hold_timeout_s`` passes.
* **Result.** ``SUCCESSFUL`` when the plan ran to its end (and met the goal tolerance). A run
  cut short by the compensator (stale sensor, model failure, ``~/stop``, deactivation, and
  during the goal time also a hold that ended) aborts with ``INVALID_GOAL`` and the reason,
  as ros2_controllers' trajectory controller does for an abort that is not a tolerance.
* **Record.** An accepted goal's trajectory is published on ``trajectory`` (transient local,
  as a client of the topic would), so bags and live views show what ran whichever way it
  came; the compensator skips this echo by its publisher (:meth:`TrajectoryActionServer.is_echo`).
* **Cancel** ramps the pressure down at the slew limit (the compensator's ``~/stop``): a
  catheter left pressurised with no plan would stay bent in the patient. The goal ends
  ``CANCELED`` once the pressure command has reached zero. This holds during the goal time
  too (the hold is the goal's own); once the goal has its result it can no longer be
  cancelled, and ``~/stop`` releases the hold.

The server talks to the compensator through :class:`TrajectoryRunner` only, so it is tested
with a fake (tests/catheter_control/test_trajectory_action.py); the node gives it
:meth:`CompensatorNode.trajectory_progress`.
"""

from __future__ import annotations

import bisect
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from builtin_interfaces.msg import Duration
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from rclpy.action.server import ActionServer, CancelResponse, GoalResponse, ServerGoalHandle
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.task import Future
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from catheter_control.trajectory import TrajectoryPlan
from catheter_models.contract import (
    BEND_JOINT,
    MAX_TRAJECTORY_DURATION_S,
    MAX_TRAJECTORY_POINTS,
    TIP_ANGLE,
    TRAJECTORY,
)
from catheter_models.units import rad_to_deg
from catheter_ros import messages, qos
from catheter_ros.polled import PolledTopics
from catheter_ros.rt_loop import MonotonicStamper

ACTION_NAME = "follow_joint_trajectory"
"""In the graph's namespace, beside the ``trajectory`` topic."""

Result = FollowJointTrajectory.Result
_Handle = ServerGoalHandle[
    FollowJointTrajectory.Goal, FollowJointTrajectory.Result, FollowJointTrajectory.Feedback
]

_NEWEST_SAMPLE = QoSProfile(
    history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT
)
"""Matches any tip/angle publisher (best effort takes reliable and best-effort offers)."""

_TIP_FRESH_S = 0.5
"""A tip/angle sample older than this is not "the measured bend" any more [s]."""


@dataclass(frozen=True)
class RunProgress:
    """What the compensator is doing with the plans it accepted (a snapshot).

    Plans are told apart by identity: the one a submission queued is ``pending`` (or already
    ``following``) right after :meth:`TrajectoryRunner.submit_trajectory` returns.
    """

    pending: TrajectoryPlan | None
    """Accepted, waiting to start (for a valve driver to listen)."""
    following: TrajectoryPlan | None
    """The plan being followed now."""
    elapsed_s: float
    """Plan time of ``following``, or of ``holding`` (past its end) [s] (0 when none)."""
    ended: tuple[tuple[TrajectoryPlan, str], ...]
    """Plans that ended lately and why, oldest first: '' ran to the end (its last point may
    be held), else why they were cut short (including a pending plan dropped before it
    started) or why the hold of their last point ended."""
    idle: bool
    """No plan pending or followed and the pressure command is down to zero."""
    holding: TrajectoryPlan | None = None
    """The plan whose last point is being held now (it ran to its end)."""
    at_s: float | None = None
    """The monotonic instant ``elapsed_s`` was read at [s] (None: just now)."""


class TrajectoryRunner(Protocol):
    """The narrow interface the action server needs from the compensator."""

    hold_timeout_s: float
    """How long the last point of a plan is held after its end [s]."""

    def submit_trajectory(self, msg: JointTrajectory) -> str | None:
        """Queue ``msg`` to run, or refuse it: the reason, or None when accepted."""

    def trajectory_progress(self) -> RunProgress:
        """A snapshot of the accepted plans."""

    def stop_trajectory(self) -> None:
        """Drop a pending plan and ramp the pressure down at the slew limit."""


def _seconds(d: Duration) -> float:
    return float(d.sec + d.nanosec * 1e-9)


def _tolerance_rad(entries: list[JointTolerance], what: str) -> tuple[float | None, str]:
    """The bend's position tolerance [rad] (None: none), or why the entries are refused."""
    position: float | None = None
    for tol in entries:
        if tol.name != BEND_JOINT:
            return None, (
                f"{what} names joint {tol.name!r}; this controller moves only {BEND_JOINT!r}"
            )
        for field in ("velocity", "acceleration"):
            value = getattr(tol, field)
            if value not in (0.0, -1.0):
                return None, (
                    f"{what} sets a {field} tolerance ({value:g}) for {BEND_JOINT!r}: the "
                    "bend's rate is not measured, so it cannot be checked (use 0 or -1)"
                )
        if tol.position > 0.0:
            position = float(tol.position)
        elif tol.position == -1.0:
            position = None
        elif tol.position != 0.0:
            return None, f"{what} position {tol.position:g} is invalid (> 0, 0 or -1)"
    return position, ""


@dataclass
class _Goal:
    handle: _Handle
    plan: TrajectoryPlan
    point_times_s: list[float]
    path_tol_rad: float | None
    goal_tol_rad: float | None
    goal_time_tol_s: float
    done: Future[FollowJointTrajectory.Result]
    end_seen_s: float | None = None
    canceling: bool = False


class TrajectoryActionServer:
    """``FollowJointTrajectory`` over a :class:`TrajectoryRunner`, on ``node``'s executor.

    Nothing here blocks the executor: a goal's execute callback awaits a future that the
    supervising timer completes. ``clock`` is the monotonic clock of ``tip/angle`` receipts
    and of the runner's plan time; ``stamp_ns`` turns its instants into ROS stamps (the
    compensator's ``stamp_ns``).
    """

    def __init__(
        self,
        node: Node,
        runner: TrajectoryRunner,
        *,
        action_name: str = ACTION_NAME,
        feedback_rate_hz: float = 20.0,
        clock: Callable[[], float] = time.monotonic,
        stamp_ns: Callable[[float], int] | None = None,
    ) -> None:
        if not feedback_rate_hz > 0.0:
            raise ValueError(f"feedback_rate_hz must be > 0, got {feedback_rate_hz}")
        self._node = node
        self._runner = runner
        self._clock = clock
        # The compensator's own monotonic-to-ROS mapping when it gives one, so feedback and
        # angle/desired stamps agree to the nanosecond; else one of our own.
        self._stamp_ns = stamp_ns or MonotonicStamper(node.get_clock().now().nanoseconds).ns
        self._goals: list[_Goal] = []
        self._stamp_now_ns = 0
        self._tip: tuple[float, float] | None = None  # (received at [s], bend [rad])
        # Taken at the feedback rate, not dispatched 250 times a second by the executor that
        # the compensator's control thread shares the GIL with (see catheter_ros.polled);
        # only the newest sample matters, so only it is kept.
        self._tips = PolledTopics(
            node, {TIP_ANGLE.name: JointState}, _NEWEST_SAMPLE, raw=False, suffix="_action"
        )
        self._echo = node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        self._server = ActionServer(
            node,
            FollowJointTrajectory,
            action_name,
            execute_callback=self._execute,
            goal_callback=lambda _goal: GoalResponse.ACCEPT,
            cancel_callback=self._on_cancel,
        )
        self._timer = node.create_timer(1.0 / feedback_rate_hz, self.supervise)

    def destroy(self) -> None:
        """Abort what runs (without stopping the catheter: the node does that) and leave."""
        for goal in list(self._goals):
            self._finish(goal, "abort", Result.INVALID_GOAL, "the action server is shutting down")
        self._node.destroy_timer(self._timer)
        self._tips.destroy()
        self._node.destroy_publisher(self._echo)
        self._server.destroy()

    # -- inputs ---------------------------------------------------------------------------
    def measured_rad(self, now_s: float) -> float | None:
        """The newest tip/angle bend, or None when none arrived in the last 0.5 s.

        Samples are taken here (the timer calls this at the feedback rate even with no goal,
        so a sample's receipt time is known to one feedback period).
        """
        for msg in reversed(self._tips.take(TIP_ANGLE.name)):
            try:
                angle = messages.angle_rad_from(msg)
            except ValueError:
                continue  # no bend joint in it: not a measurement of ours
            if math.isfinite(angle):
                self._tip = (now_s, angle)
                break
        if self._tip is None or now_s - self._tip[0] > _TIP_FRESH_S:
            return None
        return self._tip[1]

    def is_echo(self, publisher_gid: bytes) -> bool:
        """Whether a ``trajectory`` message came from this server's own echo publisher."""
        if not publisher_gid:
            return False
        ours = [
            bytes(pub.endpoint_gid)
            for pub in self._node.get_publishers_info_by_topic(self._echo.topic_name)
            if pub.node_name == self._node.get_name()
            and pub.node_namespace == self._node.get_namespace()
        ]
        return publisher_gid in ours

    def _on_cancel(self, goal_handle: _Handle) -> CancelResponse:
        for goal in self._goals:
            if goal.handle is goal_handle:
                goal.canceling = True
                progress = self._runner.trajectory_progress()
                # Only stop the catheter for a run (or hold) that is this goal's own.
                ours = (progress.pending, progress.following, progress.holding)
                if any(goal.plan is plan for plan in ours):
                    self._runner.stop_trajectory()
        return CancelResponse.ACCEPT

    # -- goals ----------------------------------------------------------------------------
    def check_goal(self, goal: FollowJointTrajectory.Goal) -> tuple[int, str]:
        """What the action itself refuses before the compensator sees the trajectory."""
        # Size first: everything below (and the compensator's checks) costs per point.
        n_points = len(goal.trajectory.points)
        if n_points > MAX_TRAJECTORY_POINTS:
            return Result.INVALID_GOAL, (
                f"trajectory has {n_points} points, over the limit of {MAX_TRAJECTORY_POINTS} "
                "(MAX_TRAJECTORY_POINTS): split it, or knot it more sparsely"
            )
        if n_points and _seconds(goal.trajectory.points[-1].time_from_start) > (
            MAX_TRAJECTORY_DURATION_S
        ):
            last_s = _seconds(goal.trajectory.points[-1].time_from_start)
            return Result.INVALID_GOAL, (
                f"trajectory lasts {last_s:g} s, over the limit of {MAX_TRAJECTORY_DURATION_S:g} s "
                "(MAX_TRAJECTORY_DURATION_S)"
            )
        names = list(goal.trajectory.joint_names)
        if names != [BEND_JOINT]:
            return Result.INVALID_JOINTS, (
                f"joint_names {names!r}: this controller moves the one joint {BEND_JOINT!r}"
            )
        if goal.multi_dof_trajectory.points or goal.multi_dof_trajectory.joint_names:
            return Result.INVALID_JOINTS, "multi_dof_trajectory is not empty: no multi-DOF joint"
        if goal.component_path_tolerance or goal.component_goal_tolerance:
            return Result.INVALID_GOAL, "component tolerances are for multi-DOF joints: none here"
        stamp = goal.trajectory.header.stamp
        if stamp.sec or stamp.nanosec:
            start_ns = messages.ns_from_time(stamp)
            ahead_s = (start_ns - self._node.get_clock().now().nanoseconds) * 1e-9
            if ahead_s > 0.1:
                return Result.INVALID_GOAL, (
                    f"header.stamp is {ahead_s:.2f} s in the future: a trajectory starts as "
                    "soon as it is accepted here; leave the stamp zero"
                )
        for entries, what in (
            (goal.path_tolerance, "path_tolerance"),
            (goal.goal_tolerance, "goal_tolerance"),
        ):
            tol, why = _tolerance_rad(list(entries), what)
            if why:
                return Result.INVALID_GOAL, why
            if tol is not None and self.measured_rad(self._clock()) is None:
                return Result.INVALID_GOAL, (
                    f"{what} for {BEND_JOINT!r} needs the measured bend, and no {TIP_ANGLE.name} "
                    f"sample arrived in the last {_TIP_FRESH_S:g} s"
                )
        goal_time_s = _seconds(goal.goal_time_tolerance)
        if goal_time_s < 0.0:
            return Result.INVALID_GOAL, "goal_time_tolerance is negative"
        hold_s = self._runner.hold_timeout_s
        if goal.goal_tolerance and goal_time_s > hold_s:
            return Result.INVALID_GOAL, (
                f"goal_time_tolerance {goal_time_s:g} s is longer than the compensator holds "
                f"the last point (hold_timeout_s {hold_s:g} s): the goal tolerance would be "
                "judged on a catheter ramping down"
            )
        return Result.SUCCESSFUL, ""

    async def _execute(self, handle: _Handle) -> FollowJointTrajectory.Result:
        goal: FollowJointTrajectory.Goal = handle.request
        code, why = self.check_goal(goal)
        if not why:
            refusal = self._runner.submit_trajectory(goal.trajectory)
            if refusal is not None:
                code, why = Result.INVALID_GOAL, refusal
        if why:
            self._node.get_logger().error(f"{ACTION_NAME}: goal refused: {why}")
            handle.abort()
            return Result(error_code=code, error_string=why)
        progress = self._runner.trajectory_progress()
        # The executor runs one callback at a time, so nothing queued a plan since ours.
        plan = progress.pending or progress.following
        if plan is None:
            raise RuntimeError("the runner accepted a trajectory but shows no plan for it")
        self._echo.publish(goal.trajectory)
        path_tol, _ = _tolerance_rad(list(goal.path_tolerance), "path_tolerance")
        goal_tol, _ = _tolerance_rad(list(goal.goal_tolerance), "goal_tolerance")
        running = _Goal(
            handle=handle,
            plan=plan,
            point_times_s=[_seconds(p.time_from_start) for p in goal.trajectory.points],
            path_tol_rad=path_tol,
            goal_tol_rad=goal_tol,
            goal_time_tol_s=_seconds(goal.goal_time_tolerance),
            done=Future(),
        )
        self._goals.append(running)
        self._node.get_logger().info(
            f"{ACTION_NAME}: goal accepted, a {plan.duration_s:.2f} s trajectory"
        )
        result = await running.done
        assert isinstance(result, Result)
        return result

    def _finish(self, goal: _Goal, how: str, code: int, why: str) -> None:
        self._goals.remove(goal)
        if how == "succeed":
            goal.handle.succeed()
        elif how == "canceled":
            goal.handle.canceled()
        else:
            goal.handle.abort()
            self._node.get_logger().error(f"{ACTION_NAME}: goal aborted: {why}")
        goal.done.set_result(Result(error_code=code, error_string=why))

    # -- supervision ----------------------------------------------------------------------
    def supervise(self) -> None:
        """Feedback, tolerances and the end of every running goal (the timer's callback)."""
        now_s = self._clock()
        measured = self.measured_rad(now_s)
        if not self._goals:
            return
        progress = self._runner.trajectory_progress()
        # The instant the plan time was read at: the feedback's stamp and time_from_start
        # go together to the nanosecond.
        at_s = progress.at_s if progress.at_s is not None else self._clock()
        self._stamp_now_ns = self._stamp_ns(at_s)
        for goal in list(self._goals):
            self._supervise(goal, progress, now_s, measured)

    def _supervise(
        self, goal: _Goal, progress: RunProgress, now_s: float, measured: float | None
    ) -> None:
        # The newest word on this plan: one that ran to its end may end again (its hold).
        ended = next((why for plan, why in reversed(progress.ended) if plan is goal.plan), None)
        if goal.canceling:
            if progress.idle or (ended is None and goal.plan is not progress.following):
                self._finish(goal, "canceled", Result.SUCCESSFUL, "canceled; pressure at zero")
            return
        if ended is not None:
            if ended:
                # Cut short, or (during the goal time) its hold ended: there is nothing left
                # to judge the goal tolerance on.
                self._finish(goal, "abort", Result.INVALID_GOAL, ended)
            else:
                self._at_end(goal, progress, now_s, measured)
            return
        if goal.plan is progress.pending:
            return  # not started: nothing to report yet
        if goal.plan is not progress.following:
            self._finish(
                goal,
                "abort",
                Result.INVALID_GOAL,
                "pre-empted by a newer trajectory (an action goal or the trajectory topic)",
            )
            return
        desired = goal.plan.desired_at(progress.elapsed_s)
        self._publish_feedback(goal, progress.elapsed_s, desired, measured)
        if goal.path_tol_rad is None:
            return
        if measured is None:
            why = f"path_tolerance cannot be checked: {TIP_ANGLE.name} went silent"
        elif abs(desired - measured) > goal.path_tol_rad:
            why = (
                f"{BEND_JOINT!r} off the path by {rad_to_deg(desired - measured):+.2f} deg at "
                f"t = {progress.elapsed_s:.2f} s (tolerance {rad_to_deg(goal.path_tol_rad):.2f} "
                "deg); pressure ramped down"
            )
        else:
            return
        self._runner.stop_trajectory()
        self._finish(goal, "abort", Result.PATH_TOLERANCE_VIOLATED, why)

    def _at_end(
        self, goal: _Goal, progress: RunProgress, now_s: float, measured: float | None
    ) -> None:
        if goal.goal_tol_rad is None:
            self._finish(goal, "succeed", Result.SUCCESSFUL, "")
            return
        held = goal.plan is progress.holding
        if goal.end_seen_s is None:
            # The goal time runs from the plan's end on its own clock, not from when this
            # timer first noticed it (up to a feedback period later).
            past_end_s = max(progress.elapsed_s - goal.plan.duration_s, 0.0) if held else 0.0
            goal.end_seen_s = now_s - past_end_s
        final = float(goal.plan.angle_rad[-1])
        if held:
            self._publish_feedback(goal, progress.elapsed_s, final, measured)
        if measured is not None and abs(final - measured) <= goal.goal_tol_rad:
            self._finish(goal, "succeed", Result.SUCCESSFUL, "")
        elif now_s - goal.end_seen_s >= goal.goal_time_tol_s:
            off = (
                "no tip/angle sample"
                if measured is None
                else (f"{rad_to_deg(measured - final):+.2f} deg off the last point")
            )
            self._finish(
                goal,
                "abort",
                Result.GOAL_TOLERANCE_VIOLATED,
                f"{BEND_JOINT!r} {off} {goal.goal_time_tol_s:g} s after the end (tolerance "
                f"{rad_to_deg(goal.goal_tol_rad):.2f} deg)",
            )

    def _publish_feedback(
        self, goal: _Goal, elapsed_s: float, desired: float, measured: float | None
    ) -> None:
        fb = FollowJointTrajectory.Feedback()
        fb.header.stamp = messages.time_from_ns(self._stamp_now_ns)
        fb.joint_names = [BEND_JOINT]
        t = Duration(sec=int(elapsed_s), nanosec=int((elapsed_s % 1.0) * 1e9))
        fb.desired = JointTrajectoryPoint(positions=[desired], time_from_start=t)
        if measured is not None:
            fb.actual = JointTrajectoryPoint(positions=[measured], time_from_start=t)
            fb.error = JointTrajectoryPoint(positions=[desired - measured], time_from_start=t)
        fb.index = max(bisect.bisect_right(goal.point_times_s, elapsed_s) - 1, 0)
        goal.handle.publish_feedback(fb)
