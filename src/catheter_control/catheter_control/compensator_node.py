"""``compensator``: turn a desired-angle trajectory into pressure commands on a real-time loop.

Subscribes ``trajectory`` (validated whole before a single command goes out; one over the
contract's size limits, ``MAX_TRAJECTORY_MESSAGE_BYTES``, ``MAX_TRAJECTORY_POINTS`` and
``MAX_TRAJECTORY_DURATION_S``, is refused whole, the biggest before it is deserialised), publishes
``pressure/command`` and ``angle/desired`` at ``control_rate_hz`` (250 Hz by default; 1 kHz
works) from its own thread against absolute monotonic deadlines, and its timing, refusals
and faults on ``/diagnostics``. Service ``~/stop`` (std_srvs/Trigger) ramps the pressure down.

After a trajectory's last point the node holds that bend (the same compensator and feedback
go on) until a new trajectory replaces the hold, ``~/stop`` or a cancel releases it, or
``hold_timeout_s`` passes; then it ramps down. A trajectory that ends at rest (straight) is
not held: it ramps down at its end, zero pressure being the rest. A new trajectory goes on
from the hold when it starts at the held bend; any other starts from rest, so the hold is
released first (ramped down at the slew limit) and the trajectory starts once the command
is at zero.

With ``require_pressure_measured`` (default on) or ``require_tip_angle`` (default off: a
patient has no tip sensor), a run does not start without that stream, and ramps down when it
has been silent for ``sensor_timeout_s``.

With ``feedback:=pi`` the command also corrects on the measured bend (``tip/angle``), with
the gains of ``feedback_gains`` (a ``feedback.json`` written by ``catheter-lab tune``; ''
takes the one in ``model_dir``, or the shipped one tuned on the simulated rig). The file is
refused at configure, each problem named, when its seal does not match (edited by hand) or it
has none, when a gain lies outside the range its tuning recorded, or when its authority or
authority timeout is beyond the contract's envelope (``catheter_models.feedback.seal``). The tip
angle is then required whatever ``require_tip_angle`` says: feedback never runs on a stale
stream, and a non-finite sample holds it (counted on ``/diagnostics``).

With ``feedforward_shaping:=zvd`` the compensator's pressure is input-shaped so it does not
ring the tip mode that the same ``feedback.json``'s tuning identified, and the compensator
reads the plan the shaper's delay earlier, so the shaped pressure arrives on time
(``catheter_models.shaping``). A loop with no tip mode is refused at configure.
"""

from __future__ import annotations

import math
import threading
import time

from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import FluidPressure, JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from catheter_control.control_core import ControlCore, SensorWatch
from catheter_control.models import (
    COMPENSATORS,
    DEFAULT_COMPENSATOR,
    FEEDBACKS,
    ShapedCompensator,
    load_compensator,
    load_feedback,
    load_shaping,
    resolve_compensator,
    resolve_feedback,
    resolve_shaping,
)
from catheter_control.trajectory import TrajectoryLimits, TrajectoryPlan
from catheter_control.trajectory_action import RunProgress, TrajectoryActionServer
from catheter_control.trajectory_intake import IntakeError, TrajectoryIntake, oversize_refusal
from catheter_models.contract import (
    ANGLE_DESIRED,
    BEND_JOINT,
    CONTROL_RATE_HZ,
    MAX_PRESSURE_PA,
    MAX_SLEW_PA_PER_S,
    PRESSURE_COMMAND,
    PRESSURE_LIMIT_HARD_PA,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TRAJECTORY,
)
from catheter_models.errors import CatheterError, ParameterError
from catheter_models.limits import BoundedParam
from catheter_models.shaping import SHAPERS
from catheter_models.units import AMBIENT_PRESSURE_PA, deg_to_rad, rad_to_deg
from catheter_ros import diagnostics, messages, qos
from catheter_ros.loop_node import LifecycleLoopNode
from catheter_ros.node_main import run_node_as_main
from catheter_ros.params import declare_float, declare_plain
from catheter_ros.polled import PolledTopics

_RATE = BoundedParam("control_rate_hz", CONTROL_RATE_HZ, 10.0, 2000.0, "control loop rate [Hz]")
_PMIN = BoundedParam(
    "min_pressure_pa", 0.0, 0.0, PRESSURE_LIMIT_HARD_PA, "lowest command, gauge [Pa]"
)
_PMAX = BoundedParam(
    "max_pressure_pa", MAX_PRESSURE_PA, 0.0, PRESSURE_LIMIT_HARD_PA, "highest command, gauge [Pa]"
)
_SLEW = BoundedParam(
    "max_slew_pa_per_s", MAX_SLEW_PA_PER_S, 1.0e3, 1.0e8, "command slew limit [Pa/s]"
)
_AMAX = BoundedParam("max_angle_rad", deg_to_rad(35.0), 0.0, 1.18, "highest desired bend [rad]")
_VMAX = BoundedParam(
    "max_rate_rad_s", deg_to_rad(200.0), 0.0, 100.0, "fastest desired bend rate [rad/s]"
)
_ACC = BoundedParam(
    "max_accel_rad_s2", deg_to_rad(5000.0), 0.0, 1e4, "highest desired accel [rad/s^2]"
)
_WAIT = BoundedParam(
    "driver_wait_s", 5.0, 0.0, 60.0, "hold a plan this long for a valve driver to listen [s]"
)
_STALE = BoundedParam(
    "sensor_timeout_s", 0.1, 0.01, 5.0, "ramp down when a required sensor is silent this long [s]"
)
_HOLD = BoundedParam(
    "hold_timeout_s",
    60.0,
    0.0,
    3600.0,
    "hold a trajectory's last point this long, then ramp down [s] (0: no hold)",
)
_AMB = BoundedParam(
    "ambient_pressure_pa", AMBIENT_PRESSURE_PA, 5.0e4, 1.2e5, "ambient pressure [Pa]"
)


class CompensatorNode(LifecycleLoopNode):
    """Thin lifecycle shell over :class:`ControlCore`.

    *configure* checks the parameters together, loads the model (hash-checked) and the
    feedback gains, and subscribes; a failure leaves it unconfigured with the reason logged
    (and on ``/diagnostics``). *activate* starts the control loop: from then on a trajectory
    is accepted. *deactivate* ramps the pressure down at the slew limit, waits for zero, and
    stops the loop. *cleanup* and *shutdown* release the model and subscriptions.
    """

    def __init__(self) -> None:
        super().__init__("compensator")
        self.kind = str(
            declare_plain(
                self, "compensator", DEFAULT_COMPENSATOR, f"one of {', '.join(COMPENSATORS)}"
            )
        )
        self.model_dir = str(declare_plain(self, "model_dir", "", "model directory ('' = shipped)"))
        # Given, the kind must agree with model_dir's manifest; left out (or '', as the launch
        # files pass it by default), the manifest says it.
        given = "compensator" in getattr(self, "_parameter_overrides", {})
        self._kind_asked = self.kind if given and self.kind else None
        feedback = str(
            declare_plain(
                self,
                "feedback",
                "",
                f"feedback on tip/angle: one of {', '.join(FEEDBACKS)} ('' = what a "
                "commissioned model_dir was verified with, else none)",
            )
        )
        self._feedback_asked = feedback or None
        self.feedback_kind = feedback or "none"
        self.gains_path = str(
            declare_plain(
                self,
                "feedback_gains",
                "",
                "feedback.json (or its directory); '' = the one in model_dir, or the shipped one",
            )
        )
        shaping = str(
            declare_plain(
                self,
                "feedforward_shaping",
                "",
                f"input shaping of the feedforward: one of {', '.join(SHAPERS)} (zvd: does not "
                "ring the tip that feedback_gains' tuning identified; '' = what a commissioned "
                "model_dir was verified with, else none)",
            )
        )
        self._shaping_asked = shaping or None
        self.shaping_kind = shaping or "none"
        self.rate_hz = declare_float(self, "control_rate_hz", _RATE)
        self.pmin_pa = declare_float(self, "min_pressure_pa", _PMIN)
        self.pmax_pa = declare_float(self, "max_pressure_pa", _PMAX)
        self.slew_pa_per_s = declare_float(self, "max_slew_pa_per_s", _SLEW)
        self.limits = TrajectoryLimits(
            max_angle_rad=declare_float(self, "max_angle_rad", _AMAX),
            max_rate_rad_s=declare_float(self, "max_rate_rad_s", _VMAX),
            max_accel_rad_s2=declare_float(self, "max_accel_rad_s2", _ACC),
        )
        self.ambient_pa = declare_float(self, "ambient_pressure_pa", _AMB)
        self.driver_wait_s = declare_float(self, "driver_wait_s", _WAIT)
        self._require = {
            spec.name: bool(
                declare_plain(
                    self,
                    f"require_{spec.name.replace('/', '_')}",
                    default,
                    f"stop when {spec.name} ({why}) goes stale",
                )
            )
            for spec, default, why in (
                (PRESSURE_MEASURED, True, "the valve driver's transmitter"),
                (TIP_ANGLE, False, "the laser (a patient has no tip sensor)"),
            )
        }
        self.sensor_timeout_s = declare_float(self, "sensor_timeout_s", _STALE)
        self.hold_timeout_s = declare_float(self, "hold_timeout_s", _HOLD)
        # Security: with this off nothing on the DDS network can make this node move the
        # catheter (it still holds the line at rest, reports, and answers ~/stop).
        self.accept_trajectories = bool(
            declare_plain(
                self,
                "accept_trajectories",
                True,
                "subscribe to trajectory (false: nothing on the network can move the catheter)",
            )
        )
        self.core: ControlCore | None = None
        self.watch = SensorWatch((), self.sensor_timeout_s)
        self.model_rate_hz = 0.0
        # The plan waiting to start, when to give up on it, and whether it waits for rest
        # (a hold it does not go on from is being released).
        self._pending: tuple[TrajectoryPlan, float, bool] | None = None
        self._angle_measured_rad: float | None = None
        self._lock = threading.Lock()
        self._refusals = 0
        self._last_refusal = ""
        # The WARN stands until a trajectory starts: a refusal is news until the next run.
        self._refusal_standing = False
        self._accepted = 0
        self._intake: TrajectoryIntake | None = None
        self._intake_lost = ""
        self._action: TrajectoryActionServer | None = None
        # A plan dropped before it started, and why: the action reports it to its goal.
        self._dropped: tuple[TrajectoryPlan, str] | None = None
        self._sensors: PolledTopics | None = None
        self._angles: PolledTopics | None = None

        # The command stream's QoS is overridable by parameter (REP 2003); angle/desired is
        # a record of intent, not a stream a driver acts on.
        self._pub_cmd = qos.overridable_publisher(
            self, FluidPressure, PRESSURE_COMMAND.name, qos.STREAM
        )
        self._pub_des = self.create_publisher(JointState, ANGLE_DESIRED.name, qos.STREAM)
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self.create_service(Trigger, "~/stop", self._on_stop)
        self.create_timer(1.0, self._publish_diagnostics)

    # -- lifecycle -----------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Check the parameters together, load and verify the model and gains, subscribe."""
        try:
            if self.pmin_pa > self.pmax_pa:
                raise ParameterError(
                    f"min_pressure_pa {self.pmin_pa} exceeds max_pressure_pa {self.pmax_pa}"
                )
            self.feedback_kind = resolve_feedback(self._feedback_asked, self.model_dir)
            feedback = load_feedback(
                self.feedback_kind, self.gains_path, self.model_dir, self.rate_hz
            )
            self.kind = resolve_compensator(self._kind_asked, self.model_dir)
            self.shaping_kind = resolve_shaping(self._shaping_asked, self.model_dir)
            compensator = load_shaping(
                self.shaping_kind,
                load_compensator(self.kind, self.model_dir, max_pressure_pa=self.pmax_pa),
                self.gains_path,
                self.model_dir,
            )
        except CatheterError as exc:
            self.fail_transition("configure", str(exc))
            return TransitionCallbackReturn.FAILURE
        self.transition_failure = ""
        # Feedback acts on the laser's bend: a run must not go on without it.
        required = tuple(
            name
            for name, wanted in self._require.items()
            if wanted or (feedback is not None and name == TIP_ANGLE.name)
        )
        self.watch = SensorWatch(required, self.sensor_timeout_s)
        self.model_rate_hz = (
            0.0 if compensator.sample_period_s is None else 1.0 / compensator.sample_period_s
        )
        with self._lock:
            self.core = ControlCore(
                compensator,
                self.pmin_pa,
                self.pmax_pa,
                self.slew_pa_per_s,
                feedback,
                hold_timeout_s=self.hold_timeout_s,
                rest_angle_rad=self.limits.min_angle_rad,
                rest_band_rad=self._same_place_rad(),
            )
        if self.accept_trajectories:
            # Subscribed from configure, not activate: a trajectory latched (transient local)
            # while the node was not armed is refused once here, never run on activation.
            # In a process of its own, which refuses an oversized message by its length, so
            # that taking it never holds this process's GIL (see trajectory_intake).
            with self._lock:
                self._intake_lost = ""
            try:
                self._intake = TrajectoryIntake(
                    self,
                    self.resolve_topic_name(TRAJECTORY.name),
                    self._on_trajectory,
                    self._refuse,
                    self._on_intake_lost,
                )
            except IntakeError as exc:
                self.fail_transition("configure", str(exc))
                self._release()
                return TransitionCallbackReturn.FAILURE
            self._action = TrajectoryActionServer(self, self, stamp_ns=self.stamp_ns)
        else:
            self.get_logger().warning(
                "accept_trajectories is false: trajectory is not subscribed, the catheter "
                "stays at rest"
            )
        # Polled by the loop, not dispatched by the executor: see catheter_ros.polled.
        self._sensors = PolledTopics(
            self,
            {
                spec.name: msg_type
                for spec, msg_type in ((PRESSURE_MEASURED, FluidPressure), (TIP_ANGLE, JointState))
                if spec.name in required and not (feedback is not None and spec is TIP_ANGLE)
            },
            qos_profile_sensor_data,
        )
        # The feedback reads the bend itself, so its samples are deserialised (the others
        # only need to be seen to arrive).
        self._angles = (
            None
            if feedback is None
            else PolledTopics(
                self,
                {TIP_ANGLE.name: JointState},
                qos_profile_sensor_data,
                raw=False,
                suffix="_angle",
            )
        )
        model_rate = f", model stepped at {self.model_rate_hz:g} Hz" if self.model_rate_hz else ""
        fb_text = (
            ""
            if feedback is None
            else f", feedback {self.feedback_kind} (kp {feedback.gains.kp_pa_per_rad:.4g} Pa/rad, "
            f"ki {feedback.gains.ki_pa_per_rad_s:.4g} Pa/(rad s))"
        )
        if isinstance(compensator, ShapedCompensator):
            fb_text += f", feedforward shaped: {compensator.shaper.describe()}"
        self.get_logger().info(
            f"compensator {self.kind!r} at {self.rate_hz:g} Hz{model_rate}{fb_text}; "
            f"requires {', '.join(required) or 'no sensor stream'}"
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Arm: start the control loop; trajectories are accepted from now on."""
        self.start_loop(self.rate_hz, self._tick)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Disarm: ramp the pressure down at the slew limit, then stop the loop."""
        self._ramp_down_and_stop("deactivated")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Release the model and the subscriptions."""
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Ramp down if armed, then release."""
        self._ramp_down_and_stop("shutting down")
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """A transition raised: ramp down if armed and release, so nothing holds pressure."""
        self._ramp_down_and_stop("error")
        self._release()
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        """Process exit (SIGINT, SIGTERM): ramp down if still armed (idempotent)."""
        self._ramp_down_and_stop("process exiting")

    def _ramp_down_and_stop(self, why: str) -> None:
        loop = self.active_loop
        if loop is None:
            return
        with self._lock:
            self._drop_pending(why)
            core = self.core
            if core is not None:
                core.stop()
        if core is not None and core.state != ControlCore.IDLE:
            self.get_logger().info(f"{why}: ramping the pressure down before the loop stops")
            # The loop thread does the ramp at the slew limit; bounded in case it has died.
            give_up_s = time.monotonic() + self.pmax_pa / self.slew_pa_per_s + 2.0
            while core.state != ControlCore.IDLE and loop.running and time.monotonic() < give_up_s:
                time.sleep(loop.period_s)
            if core.state != ControlCore.IDLE:
                self.get_logger().error(
                    f"{why}: ramp-down did not finish (loop running: {loop.running}); the "
                    "valve driver's watchdog vents when commands stop"
                )
        self.stop_loop()

    def _release(self) -> None:
        self.stop_loop()
        if self._intake is not None:
            self._intake.close()
            self._intake = None
        if self._action is not None:
            self._action.destroy()
            self._action = None
        for polled in (self._sensors, self._angles):
            if polled is not None:
                polled.destroy()
        self._sensors = self._angles = None
        with self._lock:
            self.core = None

    def _refuse(self, reason: str) -> None:
        with self._lock:
            self._refusals += 1
            self._last_refusal = reason
            self._refusal_standing = True
        self.get_logger().error(f"trajectory refused: {reason}")
        self._publish_diagnostics()

    def plan_trajectory(self, msg: JointTrajectory) -> TrajectoryPlan | str:
        """The plan ``msg`` asks for, or why it is refused (nothing is queued or counted).

        Checks the whole trajectory against the limits, and that the node is armed (active).
        """
        if self.active_loop is None or self.core is None:
            return "the compensator is not active (lifecycle: configure, then activate it)"
        too_many = self.limits.size_error(len(msg.points))
        if too_many:
            return too_many  # before the per-point work below
        names = list(msg.joint_names)
        if BEND_JOINT not in names:
            return f"joint_names {names!r} lack {BEND_JOINT!r}"
        j = names.index(BEND_JOINT)
        times, angles = [], []
        for i, point in enumerate(msg.points):
            if len(point.positions) <= j:
                return f"point {i} has no position for {BEND_JOINT!r}"
            times.append(point.time_from_start.sec + point.time_from_start.nanosec * 1e-9)
            angles.append(point.positions[j])
        # Rates and accelerations, as ros2_controllers takes them: on every point or none.
        derivatives: dict[str, list[float] | None] = {}
        for field in ("velocities", "accelerations"):
            given = [len(getattr(point, field)) > j for point in msg.points]
            if any(given) and not all(given):
                first = given.index(not given[0])
                return (
                    f"point {first} {'has' if given[first] else 'lacks'} {field} for "
                    f"{BEND_JOINT!r} that point 0 {'lacks' if given[first] else 'has'}: give "
                    f"{field} on every point or on none"
                )
            derivatives[field] = (
                [float(getattr(point, field)[j]) for point in msg.points]
                if given and all(given)
                else None
            )
        try:
            plan = TrajectoryPlan.from_knots(
                times,
                angles,
                self.limits,
                self.rate_hz,
                velocity_rad_s=derivatives["velocities"],
                accel_rad_s2=derivatives["accelerations"],
            )
        except CatheterError as exc:
            return str(exc)
        preview_s = float(getattr(self.core.compensator, "preview_s", 0.0))
        if plan.duration_s < preview_s:
            # Read that far ahead, a plan this short is its last point from the first tick:
            # the catheter would jump there, one dead time late, not follow it.
            return (
                f"the plan lasts {plan.duration_s:.3f} s, less than the {preview_s:.3f} s the "
                f"{self.kind} compensator reads ahead (the loop's dead time it undoes)"
            )
        return plan

    def submit_trajectory(self, msg: JointTrajectory) -> str | None:
        """Accept ``msg`` for the control thread to run, or refuse it: the reason, or None.

        What the ``trajectory`` topic does with every message; any other front end (an
        action server) calls this too, so the acceptance rules live in one place. A refusal
        is counted, logged and put on ``/diagnostics``.
        """
        plan = self.plan_trajectory(msg)
        if isinstance(plan, str):
            self._refuse(plan)
            return plan
        with self._lock:
            # Start on the control thread once a valve driver listens: commands sent before
            # DDS has matched it would go nowhere while the plan's clock runs on. A hold
            # gets a ramp-down's time more, in case the plan must wait for rest.
            give_up_s = time.monotonic() + self.driver_wait_s + self.pmax_pa / self.slew_pa_per_s
            self._pending = (plan, give_up_s, False)
            self._accepted += 1
            held = None if self.core is None else self.core.hold_angle_rad
        start = ""
        if held is not None:
            start = (
                f"; it goes on from the hold at {rad_to_deg(held):.2f} deg"
                if self._goes_on_from(plan, held)
                else f"; it starts at {rad_to_deg(plan.angle_rad[0]):.2f} deg, not at the held "
                f"{rad_to_deg(held):.2f} deg, so the hold is released and it starts from rest"
            )
        self.get_logger().info(
            f"accepted a {plan.duration_s:.2f} s trajectory ({len(msg.points)} points){start}"
        )
        return None

    def _same_place_rad(self) -> float:
        """How far apart two set-points may be and count as one place [rad].

        No farther than the plan limits let the set-point move in one control tick: going
        from one to the other is no faster than a plan itself may be. Used for "starts at
        the held bend" and "ends at rest".
        """
        return self.limits.max_rate_rad_s / self.rate_hz

    def _goes_on_from(self, plan: TrajectoryPlan, held_rad: float) -> bool:
        """Whether ``plan`` starts at the held bend (see :meth:`_same_place_rad`)."""
        return abs(float(plan.angle_rad[0]) - held_rad) <= self._same_place_rad() + 1e-12

    def _on_intake_lost(self, reason: str) -> None:
        """The intake process stopped on its own: no trajectory can arrive on the topic now."""
        with self._lock:
            self._intake_lost = reason
        self.get_logger().error(
            f"{reason}: trajectories on the topic are no longer taken (the action still is); "
            "cleanup and configure the node to start it again"
        )
        self._publish_diagnostics()

    def _on_trajectory(self, data: bytes, publisher_gid: bytes = b"") -> None:
        """A ``trajectory`` message, serialised, from the intake process.

        Runs on the executor's thread, never the control loop's; what they share is the GIL,
        which rclpy's deserialisation holds while it builds a Python object per point (13 s
        for a 10^6-point message on the test machine, during which the loop missed hundreds of
        deadlines). The intake process refused anything over the byte limit; the length is
        checked again here because this layer deserialises, and must not trust a pipe to
        have bounded that work.
        """
        if self._action is not None and self._action.is_echo(publisher_gid):
            return  # an action goal's trajectory, republished for the record: already running
        refusal = oversize_refusal(len(data))
        if refusal:
            self._refuse(refusal)
            return
        try:
            msg = deserialize_message(data, JointTrajectory)
        except Exception as exc:  # whatever rclpy raises, the message is refused
            self._refuse(f"the message does not deserialise as a JointTrajectory: {exc}")
            return
        self.submit_trajectory(msg)

    def stop_trajectory(self) -> None:
        """Drop a pending plan and ramp the pressure down at the slew limit (``~/stop``)."""
        with self._lock:
            self._drop_pending("stopped before it started")
            if self.core is not None:
                self.core.stop()

    def _drop_pending(self, why: str) -> None:
        """Forget the pending plan, remembering why (the caller holds the lock)."""
        if self._pending is not None:
            self._dropped = (self._pending[0], why)
            self._pending = None

    def trajectory_progress(self) -> RunProgress:
        """What became of the accepted plans, for the trajectory action."""
        now_s = time.monotonic()
        with self._lock:
            core = self.core
            state = ControlCore.IDLE if core is None else core.state
            plan = None if core is None else core.plan
            following = plan if state == ControlCore.FOLLOWING else None
            holding = plan if state == ControlCore.HOLDING else None
            return RunProgress(
                pending=None if self._pending is None else self._pending[0],
                following=following,
                elapsed_s=0.0 if core is None or plan is None else core.elapsed_s(now_s),
                ended=tuple(e for e in (self._dropped, core and core.ended) if e),
                idle=self._pending is None and state == ControlCore.IDLE,
                holding=holding,
                at_s=now_s,
            )

    def _on_stop(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        self.stop_trajectory()
        resp.success = True
        resp.message = "ramping pressure down"
        return resp

    def _tick(self, _k: int, deadline_s: float) -> None:
        core, loop, sensors = self.core, self.active_loop, self._sensors
        if core is None or loop is None or sensors is None:
            return
        refusal = fault = released = ""
        for name in sensors.poll():
            self.watch.seen(name, deadline_s)
        if self._angles is not None:
            samples = self._angles.take(TIP_ANGLE.name)
            if samples:
                self.watch.seen(TIP_ANGLE.name, deadline_s)
                try:
                    self._angle_measured_rad = messages.angle_rad_from(samples[-1])
                except ValueError:
                    # A sample without the bend joint: the feedback holds and counts it.
                    self._angle_measured_rad = math.nan
        with self._lock:
            stale = self.watch.stale(deadline_s)
            if self._pending is not None:
                plan, give_up_s, from_rest = self._pending
                listening = self._pub_cmd.get_subscription_count() > 0
                held = core.hold_angle_rad
                go_on = held is not None and self._goes_on_from(plan, held)
                if listening and not stale and held is not None and not from_rest and not go_on:
                    # It starts elsewhere, as from rest: bring the catheter to rest at the
                    # slew limit, as ~/stop does, rather than step the set-point.
                    released = (
                        f"released the hold at {rad_to_deg(held):.2f} deg: the new "
                        f"trajectory starts at {rad_to_deg(plan.angle_rad[0]):.2f} deg, "
                        "so it starts from rest"
                    )
                    core.stop(released)
                    from_rest = True
                    self._pending = (plan, give_up_s, from_rest)
                if listening and not stale and (not from_rest or core.state == ControlCore.IDLE):
                    core.start(plan, deadline_s)
                    self._pending = None
                    self._refusal_standing = False
                elif deadline_s > give_up_s:
                    refusal = stale or (
                        f"no valve driver subscribes to "
                        f"{self._pub_cmd.topic_name} after {self.driver_wait_s:g} s"
                    )
                    self._drop_pending(refusal)
            if stale and core.state != ControlCore.IDLE and not core.fault_reason:
                core.fault(stale)
                fault = stale
            was = core.state
            out = core.tick(deadline_s, loop.period_s, self._angle_measured_rad)
            now_state, ended = core.state, core.ended
        if released:
            self.get_logger().info(released)
        if now_state != was and ControlCore.HOLDING in (was, now_state):
            # Once per hold, not per tick: where it started, or why it ended.
            if (
                now_state == ControlCore.HOLDING
                and out is not None
                and out.angle_desired_rad is not None
            ):
                self.get_logger().info(
                    f"holding {rad_to_deg(out.angle_desired_rad):.2f} deg after the trajectory's "
                    f"end (released by a new trajectory, ~/stop, a cancel, or after "
                    f"hold_timeout_s {self.hold_timeout_s:g} s)"
                )
            elif now_state == ControlCore.RAMPING_DOWN and ended is not None and ended[1]:
                self.get_logger().info(f"ramping down: {ended[1]}")
        if refusal:
            self._refuse(refusal)
        if fault:
            # Off the hot path in spirit: this happens once per fault, not per tick.
            self.get_logger().error(f"ramping down: {fault}")
        if out is None:
            return
        stamp_ns = self.stamp_ns(deadline_s)
        self._pub_cmd.publish(
            messages.fluid_pressure(out.pressure_pa, stamp_ns, "", self.ambient_pa)
        )
        if out.angle_desired_rad is not None:  # none while ramping down: no set-point
            self._pub_des.publish(messages.joint_state(out.angle_desired_rad, stamp_ns))

    def _publish_diagnostics(self) -> None:
        """One status a second: the lifecycle state, refusals and, while armed, the loop's timing.

        The values are built in one place whatever the state, so an armed and a not-armed
        report share their keys' names and order: state, compensator, (armed: set-up),
        refusals, (armed: timing).
        """
        loop = self.active_loop
        with self._lock:
            refusals, last, accepted = self._refusals, self._last_refusal, self._accepted
            standing = self._refusal_standing
            core = self.core
            intake_lost = self._intake_lost
        intake = self._intake
        setup: dict[str, object] = {}
        timing: dict[str, object] = {}
        if core is None or loop is None:
            state = "inactive" if core is not None else "unconfigured"
            level, message = self._not_armed_level(core is not None)
        else:
            stats = loop.stats()
            with self._lock:
                state, bad_model = core.state, core.nonfinite_from_compensator
                model_error, fault = core.compensator_error, core.fault_reason
                model_steps = core.model_steps
                hold_rad, held_s = core.hold_angle_rad, core.held_s(time.monotonic())
                fb = core.feedback
                fb_values = (
                    {}
                    if fb is None
                    else {
                        "feedback_integral_pa": f"{fb.integral_pa:.0f}",
                        "feedback_untrusted_samples": fb.untrusted_samples,
                        "feedback_saturated_ticks": fb.saturated_ticks,
                    }
                )
            now_s = time.monotonic()
            level, message = diagnostics.OK, state
            if loop.error is not None:
                level, message = diagnostics.ERROR, f"control loop died: {loop.error!r}"
            elif fault:
                level, message = diagnostics.ERROR, f"stopped: {fault}; ramped down"
            elif bad_model:
                level, message = (
                    diagnostics.ERROR,
                    f"compensator failed ({model_error or 'non-finite pressure'}); ramped down",
                )
            elif intake_lost:
                level, message = diagnostics.ERROR, intake_lost
            elif standing:
                level, message = diagnostics.WARN, f"trajectory refused: {last}"
            elif hold_rad is not None:
                message = (
                    f"holding {rad_to_deg(hold_rad):.2f} deg for {held_s:.1f} s (ramps down "
                    f"after hold_timeout_s {self.hold_timeout_s:g} s)"
                )
            setup = {
                "control_rate_hz": f"{self.rate_hz:g}",
                "model_rate_hz": f"{self.model_rate_hz:g}" if self.model_rate_hz else "any",
                "model_steps": model_steps,
                "feedback": self.feedback_kind,
                "feedforward_shaping": self.shaping_kind,
                **fb_values,
                "fault": fault,
                "hold_deg": "" if hold_rad is None else f"{rad_to_deg(hold_rad):.2f}",
                "held_s": "" if hold_rad is None else f"{held_s:.1f}",
                "hold_timeout_s": f"{self.hold_timeout_s:g}",
                "accept_trajectories": str(self.accept_trajectories).lower(),
                "trajectories_accepted": accepted,
                "trajectory_intake_pid": "" if intake is None else intake.pid,
                "trajectory_intake_lost": intake_lost,
            }
            timing = {
                "realtime": loop.realtime,
                "ticks": stats.ticks,
                "missed_deadlines": stats.missed,
                "lateness_p50_ms": f"{stats.lateness_p50_s * 1e3:.3f}",
                "lateness_p99_ms": f"{stats.lateness_p99_s * 1e3:.3f}",
                "behind_max_ms": f"{loop.take_worst_behind_s() * 1e3:.3f}",
                "compute_p50_ms": f"{stats.compute_p50_s * 1e3:.3f}",
                "compute_p99_ms": f"{stats.compute_p99_s * 1e3:.3f}",
                **{
                    f"{name.replace('/', '_')}_age_ms": f"{self.watch.age_s(name, now_s) * 1e3:.0f}"
                    for name in self.watch.required
                },
                **{
                    f"{name.replace('/', '_')}_longest_silence_ms": (
                        f"{self.watch.take_longest_silence_s(name) * 1e3:.0f}"
                    )
                    for name in self.watch.required
                },
            }
        diagnostics.publish_status(
            self._pub_diag,
            self,
            level=level,
            message=message,
            values={
                "state": state,
                "compensator": self.kind,
                **setup,
                "trajectories_refused": refusals,
                "last_refusal": last,
                **timing,
            },
        )

    def _not_armed_level(self, configured: bool) -> tuple[bytes, str]:
        """Not active: say which lifecycle state, and why configure failed if it did."""
        if configured:
            return diagnostics.WARN, "configured, not active: trajectories refused"
        if self.transition_failure:
            return diagnostics.ERROR, self.transition_failure
        return diagnostics.WARN, "not configured: trajectories refused"

    def destroy_node(self) -> None:
        """Stop the loop (which polls the sensors) before their helper node goes."""
        self.stop_loop()
        super().destroy_node()
        for name in ("_sensors", "_angles"):
            polled = getattr(self, name, None)
            if polled is not None:
                polled.destroy()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control compensator``."""
    run_node_as_main(CompensatorNode, args)


if __name__ == "__main__":
    main()
