"""The client side of a ``follow_joint_trajectory`` run: what ``follow_trajectory`` does on ROS.

It waits for the graph (measurements flowing, the compensator's action server listening and,
with a bag, the recorder hearing every stream), sends the trajectory as a
control_msgs/FollowJointTrajectory goal, shows progress from the goal's feedback, takes a
refusal or an early stop from its result, and keeps every set-point, measurement and
diagnostics report it hears in a :class:`~catheter_control.tracking_report.RunRecord` for
the report. The server side is :mod:`catheter_control.trajectory_action`. Scoring and the
report are :mod:`catheter_control.tracking_report`'s; the command line and exit codes are
:mod:`catheter_control.follow_trajectory`'s.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus
from control_msgs.action import FollowJointTrajectory
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.action.client import ActionClient, ClientGoalHandle
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from sensor_msgs.msg import JointState
from trajectory_msgs.msg import JointTrajectoryPoint

from catheter_control.process_graph import ProcessGraph
from catheter_control.progress_bar import ProgressBar
from catheter_control.tracking_report import RunRecord
from catheter_control.trajectory import TrajectoryPlan
from catheter_control.trajectory_action import ACTION_NAME
from catheter_models.contract import (
    ANGLE_DESIRED,
    BEND_JOINT,
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
)
from catheter_models.errors import CatheterError
from catheter_models.units import NS_PER_S, s_to_ns
from catheter_ros import qos
from catheter_ros.dds_profile import use_loopback_profile
from catheter_ros.messages import angle_rad_from, ns_from_time

_START_TIMEOUT_S = 8.0
"""The compensator holds a plan up to 5 s for its valve driver; allow for that and more."""

_RAMP_DOWN_S = 1.0
"""How long after the trajectory's end the run goes on: the compensator's ramp-down."""

_LAST_REPORT_WAIT_S = 2.5
"""How long to wait after the run for one more report from each node (they report at 1 Hz)."""


class GraphNotReadyError(CatheterError):
    """The graph did not come up, or the compensator never started the trajectory."""


_CANCEL_WAIT_S = 3.0
"""How long an interrupted run waits for the compensator to answer its cancel and ramp down
(at the slew limit the highest command takes 0.6 s); the set-points of the ramp are kept."""


class GoalRefusedError(CatheterError):
    """The compensator refused the trajectory (its reason), before a set-point went out."""


class RunInterruptedError(CatheterError):
    """A person interrupted (Ctrl-C) before the trajectory was sent: nothing ran."""


def follow(
    plan: TrajectoryPlan,
    *,
    namespace: str,
    ros_args: Sequence[str],
    timeout_s: float,
    graph: ProcessGraph | None,
    wait_for_recorder: bool,
    show_progress: bool,
    lead_s: float,
    interrupt: threading.Event | None = None,
    watch: Callable[[], str] | None = None,
    record: RunRecord | None = None,
) -> RunRecord:
    """Run ``plan`` on the graph in ``namespace`` and return everything heard.

    Args:
        plan: The validated trajectory.
        namespace: The graph's namespace.
        ros_args: rclpy's arguments (after ``--ros-args``), for this tool's own node.
        timeout_s: How long to wait for the graph.
        graph: The local graph this tool started (its nodes are watched while it comes
            up), or None for a graph that was already running.
        wait_for_recorder: A bag is recorded: wait until the recorder hears every stream.
        show_progress: Show a progress bar (on a terminal).
        lead_s: The unscored lead-in at the start of ``plan`` [s] (0: none).
        interrupt: Set (by the caller's SIGINT handler) when a person interrupts: before the
            goal is sent the run ends with :class:`RunInterruptedError`; after, the goal is
            cancelled (the compensator ramps down), the ramp is recorded and the partial
            record returned with ``interrupted`` saying when.
        watch: Called at every spin of the run; a reason ('' while all is well) stops it as
            the compensator's own stops do: the goal is cancelled (the compensator ramps
            down), the run is scored up to there and ``stopped`` says why (the recorder died
            or cannot write: :class:`catheter_control.recording_watch.RecordingWatch`).
        record: Where to keep what is heard (a watch reads the recorder's reports there);
            None: a new one.

    Raises:
        GraphNotReadyError: the graph did not come up within ``timeout_s``, a started node
            exited, or the compensator sent no set-points.
        GoalRefusedError: the compensator refused the trajectory.
        RunInterruptedError: interrupted before the goal was sent.
    """
    record = RunRecord() if record is None else record
    interrupt = interrupt or threading.Event()
    use_loopback_profile()
    with rclpy.init(
        args=["follow_trajectory", "--ros-args", "-r", f"__ns:={namespace}", *ros_args],
        # The caller's handler turns SIGINT into ``interrupt``: rclpy's would raise
        # KeyboardInterrupt wherever the run was, and the partial run would be lost.
        signal_handler_options=SignalHandlerOptions.NO,
    ):
        client = _Client(Node("follow_trajectory"), record, timeout_s, interrupt)
        client.wait_for_graph(graph)
        if wait_for_recorder:
            client.wait_for_recorder()
        client.run(plan, show_progress=show_progress, lead_s=lead_s, watch=watch)
        if record.stopped and not record.stopped_by_watch:  # the watch said its own
            print(f"follow_trajectory: compensator: {record.stopped}", file=sys.stderr)
        if not record.interrupted:
            client.wait_for_last_reports()
        client.node.destroy_node()
    return record


class _Client:
    """This tool's node: its subscriptions fill ``record``; the action client sends the goal.

    Args:
        node: The tool's own node.
        record: Where what is heard goes.
        timeout_s: How long the graph (and the recorder) may take to be ready; the clock
            starts now.
        interrupt: Set when a person interrupts the run.
    """

    def __init__(
        self, node: Node, record: RunRecord, timeout_s: float, interrupt: threading.Event
    ) -> None:
        self.node = node
        self.record = record
        self.interrupt = interrupt

        def on_desired(msg: JointState) -> None:
            record.desired.append(ns_from_time(msg.header.stamp) * 1e-9, angle_rad_from(msg))

        def on_measured(msg: JointState) -> None:
            record.measured.append(ns_from_time(msg.header.stamp) * 1e-9, angle_rad_from(msg))

        def on_diag(msg: DiagnosticArray) -> None:
            now = time.monotonic()
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name.endswith("compensator"):
                    record.compensator.append((now, values))
                elif status.name.endswith(("sim_hardware", "valve_driver")):
                    record.driver.append((now, values))
                elif status.name.endswith("recorder"):
                    record.recorder = values
                    error = status.level == DiagnosticStatus.ERROR
                    record.recorder_error = status.message if error else ""

        # The stamps stay `ns * 1e-9`, not units.ns_to_s (ns / 1e9): the two differ in the
        # last bit for about half of all stamps, and scores are compared across versions.
        # Our compensator's stream: reliable, so the score misses nothing on a busy host. The
        # sensor may be anyone's driver: best effort matches whatever it offers.
        node.create_subscription(JointState, ANGLE_DESIRED.name, on_desired, qos.RECORD)
        node.create_subscription(JointState, TIP_ANGLE.name, on_measured, qos.KEEP_EVERY_SAMPLE)
        node.create_subscription(DiagnosticArray, DIAGNOSTICS.name, on_diag, 10)
        self.action: ActionClient[Any, Any, Any] = ActionClient(
            node, FollowJointTrajectory, ACTION_NAME
        )
        self.timeout_s = timeout_s
        self.deadline = time.monotonic() + timeout_s

    def wait_for_graph(self, graph: ProcessGraph | None) -> None:
        """Until measurements flow and the compensator listens; a started node must not exit."""
        node, record = self.node, self.record
        while time.monotonic() < self.deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
            self._check_interrupt("while waiting for the graph")
            if graph is not None and (dead := graph.failed()):
                for n in dead:
                    print(f"--- {n} log ---\n{graph.log_tail(n)}", file=sys.stderr)
                raise GraphNotReadyError(f"node(s) exited during start-up: {dead}")
            if record.measured and self.action.server_is_ready():
                return
        missing = []
        if not record.measured:
            missing.append(f"no {node.resolve_topic_name(TIP_ANGLE.name)} samples")
        if not self.action.server_is_ready():
            # Actions resolve like topics: the namespace applies.
            missing.append(f"no action server {node.resolve_topic_name(ACTION_NAME)}")
        raise GraphNotReadyError(
            f"graph not ready after {self.timeout_s:g} s: " + "; ".join(missing)
        )

    def wait_for_recorder(self) -> None:
        """Until the recorder reports a publisher on every stream of the bag.

        Discovery is pairwise: that we see the recorder does not mean it has matched the
        compensator. Without this the bag would miss the start of the run.
        """
        streams = [
            self.node.resolve_topic_name(t.name)
            for t in (PRESSURE_COMMAND, ANGLE_DESIRED, TIP_ANGLE, PRESSURE_MEASURED)
        ]

        def unheard() -> list[str]:
            recorder = self.record.recorder
            return [t for t in streams if int(recorder.get(f"publishers {t}", "0")) < 1]

        while unheard() and time.monotonic() < self.deadline:
            rclpy.spin_once(self.node, timeout_sec=0.05)
            self._check_interrupt("while waiting for the recorder")
        if unheard():
            raise GraphNotReadyError(
                "the recorder hears no publisher on "
                + ", ".join(unheard())
                + f" after {self.timeout_s:g} s"
            )

    def _check_interrupt(self, when: str) -> None:
        if self.interrupt.is_set():
            raise RunInterruptedError(f"interrupted {when}; no trajectory was sent")

    def _cancel(
        self,
        sending: Future[ClientGoalHandle[Any, Any, Any]],
        result_future: Future[Any] | None,
    ) -> str:
        """Cancel the goal (the compensator ramps down) and record the ramp; what happened.

        The spin goes on until the goal's result comes (the ramp is done) or
        :data:`_CANCEL_WAIT_S`; a local graph is ramped down by its stop in any case.
        """
        until = time.monotonic() + _CANCEL_WAIT_S
        while not sending.done() and time.monotonic() < until:
            rclpy.spin_once(self.node, timeout_sec=0.05)
        handle = sending.result() if sending.done() else None
        if handle is None or not handle.accepted:
            return "the goal was not accepted yet, nothing to cancel"
        if result_future is None:
            result_future = handle.get_result_async()
        if not result_future.done():
            handle.cancel_goal_async()
        while not result_future.done() and time.monotonic() < until:
            rclpy.spin_once(self.node, timeout_sec=0.05)
        if result_future.done():
            return "goal cancelled, the compensator ramped down"
        return f"goal cancelled, no result within {_CANCEL_WAIT_S:g} s"

    def run(
        self,
        plan: TrajectoryPlan,
        *,
        show_progress: bool,
        lead_s: float,
        watch: Callable[[], str] | None = None,
    ) -> None:
        """Send the goal and spin through the trajectory and the ramp-down after it."""
        node, record = self.node, self.record
        goal = _goal(plan)
        record.desired.clear()
        plan_time_s = [0.0]  # of the newest feedback: the bar shows the compensator's clock
        plan_started = [False]

        def on_feedback(msg: Any) -> None:
            elapsed = msg.feedback.desired.time_from_start
            plan_time_s[0] = elapsed.sec + elapsed.nanosec * 1e-9
            if not plan_started[0]:
                plan_started[0] = True
                # Set-points heard before the plan's first one are the compensator's hold of
                # an earlier trajectory's last point, not this run's: the feedback's stamp
                # minus its time_from_start is the stamp of the plan's first set-point.
                first_s = (
                    ns_from_time(msg.feedback.header.stamp)
                    - elapsed.sec * NS_PER_S
                    - elapsed.nanosec
                ) * 1e-9
                kept = [
                    (t, v)
                    for t, v in zip(record.desired.t_s, record.desired.values, strict=True)
                    if t >= first_s - 1e-6
                ]
                if len(kept) < len(record.desired.t_s):
                    record.desired.clear()
                    for t, v in kept:
                        record.desired.append(t, v)
                    record.started_at_s = time.monotonic() - plan_time_s[0]

        sending: Future[ClientGoalHandle[Any, Any, Any]] = self.action.send_goal_async(
            goal, feedback_callback=on_feedback
        )
        result_future: Future[Any] | None = None
        finished = False
        refusal = ""
        record.sent_at_s = time.monotonic()
        print(f"follow_trajectory: following {plan.name!r} ({plan.duration_s:.1f} s)")
        if lead_s:
            print(
                f"follow_trajectory: the first {lead_s:g} s move from rest to "
                f"{math.degrees(plan.desired_at(lead_s)):.1f} deg and hold (not scored)"
            )
        bar = ProgressBar(plan.duration_s, show_progress)
        # Run through the trajectory and the ramp-down after it, timed from the first
        # set-point: the compensator starts once its valve driver listens, not on receipt.
        while (
            record.started_at_s is None
            or time.monotonic() - record.started_at_s < plan.duration_s + _RAMP_DOWN_S
        ):
            rclpy.spin_once(node, timeout_sec=0.05)
            now = time.monotonic()
            if record.started_at_s is None and record.desired:
                record.started_at_s = now
            if record.started_at_s is not None:
                bar.show(plan_time_s[0])
            if result_future is None and sending.done():
                handle = sending.result()
                if handle is None or not handle.accepted:
                    refusal = "the goal was rejected"
                else:
                    result_future = handle.get_result_async()
            if result_future is not None and result_future.done() and not finished:
                finished = True
                response = result_future.result()
                status = GoalStatus.STATUS_UNKNOWN if response is None else response.status
                outcome = (response and response.result.error_string) or f"status {status}"
                if status != GoalStatus.STATUS_SUCCEEDED:
                    # Aborted before a set-point went out: refused (the compensator's
                    # reason); after: cut short, and the compensator ramped down.
                    if record.started_at_s is None:
                        refusal = outcome
                    else:
                        record.stopped = f"stopped: {outcome}; ramped down"
            if refusal:
                bar.close()
                raise GoalRefusedError(f"the compensator refused the trajectory: {refusal}")
            if record.stopped:
                break
            reason = watch() if watch is not None and not finished else ""
            if reason:
                bar.close()
                heard = len(record.desired)
                done = self._cancel(sending, result_future)
                record.desired.truncate(heard)  # scored up to the stop, as an interrupt is
                record.stopped = f"stopped {plan_time_s[0]:.1f} s in: {reason}; {done}"
                record.stopped_by_watch = True
                break
            if self.interrupt.is_set():
                bar.close()
                when = (
                    "before the first set-point"
                    if record.started_at_s is None
                    else f"{plan_time_s[0]:.1f} s into the trajectory"
                )
                heard = len(record.desired)
                done = self._cancel(sending, result_future)
                # Scored up to the interrupt: the ramp-down after it is no tracking (it is
                # in the bag).
                record.desired.truncate(heard)
                record.interrupted = f"interrupted (SIGINT) {when}: {done}"
                break
            if record.started_at_s is None and now - record.sent_at_s > _START_TIMEOUT_S:
                bar.close()
                raise GraphNotReadyError(
                    f"the compensator sent no set-points within {_START_TIMEOUT_S:g} s of the "
                    "trajectory"
                )
        bar.close()

    def wait_for_last_reports(self) -> None:
        """One more report from each node after the run, so its counters span all of it."""
        record = self.record
        end_s = time.monotonic()
        until = end_s + _LAST_REPORT_WAIT_S
        while time.monotonic() < until and not (
            record.compensator
            and record.compensator[-1][0] > end_s
            and record.driver
            and record.driver[-1][0] > end_s
        ):
            rclpy.spin_once(self.node, timeout_sec=0.05)


def _goal(plan: TrajectoryPlan) -> Any:
    """The plan's knots as a FollowJointTrajectory goal for the bend joint."""
    goal = FollowJointTrajectory.Goal()
    goal.trajectory.joint_names = [BEND_JOINT]
    for i, (t, a) in enumerate(zip(plan.t_s, plan.angle_rad, strict=True)):
        point = JointTrajectoryPoint()
        point.positions = [float(a)]
        # With them the compensator joins the knots as ros2_controllers would: cubic with
        # velocities, quintic with accelerations too; without, with straight lines.
        if plan.velocity_rad_s is not None:
            point.velocities = [float(plan.velocity_rad_s[i])]
        if plan.accel_rad_s2 is not None:
            point.accelerations = [float(plan.accel_rad_s2[i])]
        # Split the rounded whole: rounding the fraction alone turned a knot within half a
        # nanosecond below a whole second into (that second - 1, 0 ns), a second early.
        sec, nanosec = divmod(s_to_ns(t), NS_PER_S)
        point.time_from_start.sec = sec
        point.time_from_start.nanosec = nanosec
        goal.trajectory.points.append(point)
    return goal
