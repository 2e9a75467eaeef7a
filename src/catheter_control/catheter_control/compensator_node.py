"""``compensator``: turn a desired-angle trajectory into pressure commands on a real-time loop.

Subscribes ``trajectory`` (validated whole before a single command goes out), publishes
``pressure/command`` and ``angle/desired`` at ``control_rate_hz`` (250 Hz by default; 1 kHz
works) from its own thread against absolute monotonic deadlines, and its timing, refusals
and faults on ``/diagnostics``. Service ``~/stop`` (std_srvs/Trigger) ramps the pressure down.

With ``require_pressure_measured`` (default on) or ``require_tip_angle`` (default off: a
patient has no tip sensor), a run does not start without that stream, and ramps down when it
has been silent for ``sensor_timeout_s``.

With ``feedback:=pi`` the command also corrects on the measured bend (``tip/angle``), with
the gains of ``feedback_gains`` (a ``feedback.json`` written by ``catheter-lab tune``; ''
takes the one in ``model_dir``, or the shipped one tuned on the simulated rig). The tip
angle is then required whatever ``require_tip_angle`` says: feedback never runs on a stale
stream, and a non-finite sample holds it (counted on ``/diagnostics``).
"""

from __future__ import annotations

import math
import threading
import time

from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import FluidPressure, JointState
from std_srvs.srv import Trigger
from trajectory_msgs.msg import JointTrajectory

from catheter_control import qos
from catheter_control.control_core import ControlCore, SensorWatch
from catheter_control.models import (
    COMPENSATORS,
    DEFAULT_COMPENSATOR,
    FEEDBACKS,
    load_compensator,
    load_feedback,
)
from catheter_control.trajectory import TrajectoryLimits, TrajectoryPlan
from catheter_driver import diagnostics, messages
from catheter_driver.loop_node import LoopNode
from catheter_driver.node_main import run_node
from catheter_driver.params import declare_float, declare_plain
from catheter_driver.polled import PolledTopics
from catheter_models.contract import (
    ANGLE_DESIRED,
    BEND_JOINT,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TRAJECTORY,
)
from catheter_models.errors import CatheterError, ParameterError
from catheter_models.plant.config import ParamSpec
from catheter_models.units import AMBIENT_PRESSURE_PA, deg_to_rad

_RATE = ParamSpec("control_rate_hz", 250.0, 10.0, 2000.0, "control loop rate [Hz]")
_PMIN = ParamSpec("min_pressure_pa", 0.0, 0.0, 6.0e5, "lowest command, gauge [Pa]")
_PMAX = ParamSpec("max_pressure_pa", 3.0e5, 0.0, 6.0e5, "highest command, gauge [Pa]")
_SLEW = ParamSpec("max_slew_pa_per_s", 20.0e5, 1.0e3, 1.0e8, "command slew limit [Pa/s]")
_AMAX = ParamSpec("max_angle_rad", deg_to_rad(35.0), 0.0, 1.18, "highest desired bend [rad]")
_VMAX = ParamSpec(
    "max_rate_rad_s", deg_to_rad(200.0), 0.0, 100.0, "fastest desired bend rate [rad/s]"
)
_ACC = ParamSpec(
    "max_accel_rad_s2", deg_to_rad(5000.0), 0.0, 1e4, "highest desired accel [rad/s^2]"
)
_WAIT = ParamSpec(
    "driver_wait_s", 5.0, 0.0, 60.0, "hold a plan this long for a valve driver to listen [s]"
)
_STALE = ParamSpec(
    "sensor_timeout_s", 0.1, 0.01, 5.0, "ramp down when a required sensor is silent this long [s]"
)
_AMB = ParamSpec("ambient_pressure_pa", AMBIENT_PRESSURE_PA, 5.0e4, 1.2e5, "ambient pressure [Pa]")


class CompensatorNode(LoopNode):
    """Thin ROS shell over :class:`ControlCore`."""

    def __init__(self) -> None:
        super().__init__("compensator")
        kind = str(
            declare_plain(
                self, "compensator", DEFAULT_COMPENSATOR, f"one of {', '.join(COMPENSATORS)}"
            )
        )
        model_dir = str(declare_plain(self, "model_dir", "", "model directory ('' = shipped)"))
        self.feedback_kind = str(
            declare_plain(
                self, "feedback", "none", f"feedback on tip/angle: one of {', '.join(FEEDBACKS)}"
            )
        )
        gains_path = str(
            declare_plain(
                self,
                "feedback_gains",
                "",
                "feedback.json (or its directory); '' = the one in model_dir, or the shipped one",
            )
        )
        self.rate_hz = declare_float(self, "control_rate_hz", _RATE)
        feedback = load_feedback(self.feedback_kind, gains_path, model_dir, self.rate_hz)
        pmin = declare_float(self, "min_pressure_pa", _PMIN)
        pmax = declare_float(self, "max_pressure_pa", _PMAX)
        if pmin > pmax:
            raise ParameterError(f"min_pressure_pa {pmin} exceeds max_pressure_pa {pmax}")
        self.limits = TrajectoryLimits(
            max_angle_rad=declare_float(self, "max_angle_rad", _AMAX),
            max_rate_rad_s=declare_float(self, "max_rate_rad_s", _VMAX),
            max_accel_rad_s2=declare_float(self, "max_accel_rad_s2", _ACC),
        )
        self.ambient_pa = declare_float(self, "ambient_pressure_pa", _AMB)
        self.driver_wait_s = declare_float(self, "driver_wait_s", _WAIT)
        required = tuple(
            spec.name
            for spec, default, why in (
                (PRESSURE_MEASURED, True, "the valve driver's transmitter"),
                (TIP_ANGLE, False, "the laser (a patient has no tip sensor)"),
            )
            if declare_plain(
                self,
                f"require_{spec.name.replace('/', '_')}",
                default,
                f"stop when {spec.name} ({why}) goes stale",
            )
            # Feedback acts on the laser's bend: a run must not go on without it.
            or (feedback is not None and spec is TIP_ANGLE)
        )
        self.watch = SensorWatch(required, declare_float(self, "sensor_timeout_s", _STALE))
        self._pending: tuple[TrajectoryPlan, float] | None = None
        self.kind = kind
        compensator = load_compensator(kind, model_dir)
        self.model_rate_hz = (
            0.0 if compensator.sample_period_s is None else 1.0 / compensator.sample_period_s
        )
        self.core = ControlCore(
            compensator,
            pmin,
            pmax,
            declare_float(self, "max_slew_pa_per_s", _SLEW),
            feedback,
        )
        self._angle_measured_rad: float | None = None
        self._lock = threading.Lock()
        self._refusals = 0
        self._last_refusal = ""
        # The WARN stands until a trajectory starts: a refusal is news until the next run.
        self._refusal_standing = False
        self._accepted = 0

        self._pub_cmd = self.create_publisher(FluidPressure, PRESSURE_COMMAND.name, qos.STREAM)
        self._pub_des = self.create_publisher(JointState, ANGLE_DESIRED.name, qos.STREAM)
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
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
        if self.accept_trajectories:
            self.create_subscription(
                JointTrajectory, TRAJECTORY.name, self._on_trajectory, qos.TRAJECTORY
            )
        else:
            self.get_logger().warning(
                "accept_trajectories is false: trajectory is not subscribed, the catheter "
                "stays at rest"
            )
        # Polled by the loop, not dispatched by the executor: see catheter_driver.polled.
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
        self.create_service(Trigger, "~/stop", self._on_stop)
        self.create_timer(1.0, self._publish_diagnostics)
        self.create_loop(self.rate_hz, self._tick)
        model_rate = f", model stepped at {self.model_rate_hz:g} Hz" if self.model_rate_hz else ""
        fb_text = (
            ""
            if feedback is None
            else f", feedback {self.feedback_kind} (kp {feedback.gains.kp_pa_per_rad:.4g} Pa/rad, "
            f"ki {feedback.gains.ki_pa_per_rad_s:.4g} Pa/(rad s))"
        )
        self.get_logger().info(
            f"compensator {kind!r} at {self.rate_hz:g} Hz{model_rate}{fb_text}; "
            f"requires {', '.join(required) or 'no sensor stream'}"
        )

    def _refuse(self, reason: str) -> None:
        with self._lock:
            self._refusals += 1
            self._last_refusal = reason
            self._refusal_standing = True
        self.get_logger().error(f"trajectory refused: {reason}")
        self._publish_diagnostics()

    def _on_trajectory(self, msg: JointTrajectory) -> None:
        names = list(msg.joint_names)
        if BEND_JOINT not in names:
            self._refuse(f"joint_names {names!r} lack {BEND_JOINT!r}")
            return
        j = names.index(BEND_JOINT)
        times, angles = [], []
        for i, point in enumerate(msg.points):
            if len(point.positions) <= j:
                self._refuse(f"point {i} has no position for {BEND_JOINT!r}")
                return
            times.append(point.time_from_start.sec + point.time_from_start.nanosec * 1e-9)
            angles.append(point.positions[j])
        try:
            plan = TrajectoryPlan.from_knots(times, angles, self.limits, self.rate_hz)
        except CatheterError as exc:
            self._refuse(str(exc))
            return
        with self._lock:
            # Start on the control thread once a valve driver listens: commands sent before
            # DDS has matched it would go nowhere while the plan's clock runs on.
            self._pending = (plan, time.monotonic() + self.driver_wait_s)
            self._accepted += 1
        self.get_logger().info(
            f"accepted a {plan.duration_s:.2f} s trajectory ({len(msg.points)} points)"
        )

    def _on_stop(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        with self._lock:
            self.core.stop()
        resp.success = True
        resp.message = "ramping pressure down"
        return resp

    def _tick(self, _k: int, deadline_s: float) -> None:
        refusal = fault = ""
        for name in self._sensors.poll():
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
                plan, give_up_s = self._pending
                listening = self._pub_cmd.get_subscription_count() > 0
                if listening and not stale:
                    self.core.start(plan, deadline_s)
                    self._pending = None
                    self._refusal_standing = False
                elif deadline_s > give_up_s:
                    self._pending = None
                    refusal = stale or (
                        f"no valve driver subscribes to "
                        f"{self._pub_cmd.topic_name} after {self.driver_wait_s:g} s"
                    )
            if stale and self.core.state != ControlCore.IDLE and not self.core.fault_reason:
                self.core.fault(stale)
                fault = stale
            out = self.core.tick(deadline_s, self.loop.period_s, self._angle_measured_rad)
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
        self._pub_des.publish(messages.joint_state(out.angle_desired_rad, stamp_ns))

    def _publish_diagnostics(self) -> None:
        stats = self.loop.stats()
        with self._lock:
            refusals, last, accepted = self._refusals, self._last_refusal, self._accepted
            standing = self._refusal_standing
            state, bad_model = self.core.state, self.core.nonfinite_from_compensator
            model_error, fault = self.core.compensator_error, self.core.fault_reason
            model_steps = self.core.model_steps
            fb = self.core.feedback
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
        if self.loop.error is not None:
            level, message = diagnostics.ERROR, f"control loop died: {self.loop.error!r}"
        elif fault:
            level, message = diagnostics.ERROR, f"stopped: {fault}; ramped down"
        elif bad_model:
            level, message = (
                diagnostics.ERROR,
                f"compensator failed ({model_error or 'non-finite pressure'}); ramped down",
            )
        elif standing:
            level, message = diagnostics.WARN, f"trajectory refused: {last}"
        diagnostics.publish_status(
            self._pub_diag,
            self,
            level=level,
            message=message,
            values={
                "state": state,
                "compensator": self.kind,
                "control_rate_hz": f"{self.rate_hz:g}",
                "model_rate_hz": f"{self.model_rate_hz:g}" if self.model_rate_hz else "any",
                "model_steps": model_steps,
                "feedback": self.feedback_kind,
                **fb_values,
                "fault": fault,
                "accept_trajectories": str(self.accept_trajectories).lower(),
                "trajectories_accepted": accepted,
                "trajectories_refused": refusals,
                "last_refusal": last,
                "realtime": self.realtime,
                "ticks": stats.ticks,
                "missed_deadlines": stats.missed,
                "lateness_p50_ms": f"{stats.lateness_p50_s * 1e3:.3f}",
                "lateness_p99_ms": f"{stats.lateness_p99_s * 1e3:.3f}",
                "behind_max_ms": f"{self.loop.take_worst_behind_s() * 1e3:.3f}",
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
            },
        )

    def destroy_node(self) -> None:
        """Stop the loop (which polls the sensors) before their helper node goes."""
        super().destroy_node()
        for name in ("_sensors", "_angles"):
            polled = getattr(self, name, None)
            if polled is not None:
                polled.destroy()


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control compensator``."""
    code = run_node(CompensatorNode, args)
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
