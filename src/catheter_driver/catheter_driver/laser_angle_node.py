"""``laser_angle``: the laser distance sensor, through its ADC bridge, as bend angle.

Lifecycle-managed like ``valve_driver`` (*configure* opens the ADC bridge from the ``adc.*``
parameters and loads the calibration, *activate* starts reading and publishing, *deactivate*
stops, *cleanup*/*shutdown* close the bridge; ``autostart:=true`` for a node run alone).
Publishes ``tip/distance`` (sensor_msgs/Range) and ``tip/angle`` (sensor_msgs/JointState,
joint ``bend``) for every sample, stamped at its sampling instant (rebuilt from the bridge's
counter). The angle needs eq. 3.2's straight-tip reference: ``~/zero`` (std_srvs/Trigger)
measures it with the muscle vented and stores it in ``calibration_file``, which is loaded at
configure. Until then only the distance is published.
Parameters ``laser.m_per_v``, ``laser.offset_m`` (eq. 3.1) and ``laser.length_m``,
``laser.height_m`` (eq. 3.3) default to the thesis's constants.
"""

from __future__ import annotations

import time
from pathlib import Path

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import FluidPressure, JointState, Range
from std_srvs.srv import Trigger

from catheter_driver.devices.factory import make_laser_adc
from catheter_driver.laser_core import LaserAngleCore, ZeroingError
from catheter_models.contract import (
    PRESSURE_MEASURED,
    SENSOR_RATE_HZ,
    TIP_ANGLE,
    TIP_DISTANCE,
)
from catheter_models.errors import CatheterError
from catheter_models.geometry import Calibration, LaserGeometry
from catheter_models.limits import BoundedParam
from catheter_models.units import AMBIENT_PRESSURE_PA
from catheter_ros import diagnostics, messages, qos
from catheter_ros.lifecycle_node import (
    declare_autostart,
    declare_device_options,
    device_options,
)
from catheter_ros.loop_node import declare_rt_priority, make_process_realtime
from catheter_ros.node_main import run_node_as_main
from catheter_ros.params import declare_float, declare_plain
from catheter_ros.rt_loop import DeadlineLoop, MonotonicStamper

_RATE = BoundedParam("rate_hz", SENSOR_RATE_HZ, 10.0, 5000.0, "the ADC bridge's sample rate [Hz]")
# The thesis's geometry is LaserGeometry's defaults; the parameters start from them.
_THESIS = LaserGeometry()
_M = BoundedParam("laser.m_per_v", _THESIS.m_per_v, 1e-4, 0.1, "eq. 3.1 slope m [m/V]")
_N = BoundedParam("laser.offset_m", _THESIS.offset_m, 0.0, 1.0, "eq. 3.1 offset n [m]")
_L = BoundedParam("laser.length_m", _THESIS.length_m, 1e-3, 1.0, "eq. 3.3 bending length L [m]")
_H = BoundedParam("laser.height_m", _THESIS.height_m, 1e-3, 1.0, "eq. 3.3 sensor height H [m]")
_ZERO_S = BoundedParam("zero_duration_s", 1.0, 0.1, 30.0, "how long ~/zero averages [s]")
_ZERO_PA = BoundedParam(
    "zero_max_pressure_pa", 0.05e5, 0.0, 1.0e5, "~/zero refuses above this line pressure [Pa]"
)
_AMB = BoundedParam(
    "ambient_pressure_pa", AMBIENT_PRESSURE_PA, 5.0e4, 1.2e5, "ambient pressure [Pa]"
)
_PRESSURE_FRESH_S = 1.0
"""A pressure reading older than this cannot vouch that the muscle is vented."""


class LaserAngleNode(LifecycleNode):
    """Thin lifecycle shell over :class:`LaserAngleCore`."""

    def __init__(self) -> None:
        super().__init__("laser_angle")
        declare_device_options(self, "adc")
        self.rate_hz = declare_float(self, "rate_hz", _RATE)
        self.geometry = LaserGeometry(
            m_per_v=declare_float(self, "laser.m_per_v", _M),
            offset_m=declare_float(self, "laser.offset_m", _N),
            length_m=declare_float(self, "laser.length_m", _L),
            height_m=declare_float(self, "laser.height_m", _H),
        )
        self.calibration_file = Path(
            str(
                declare_plain(
                    self,
                    "calibration_file",
                    str(Path.home() / ".local/share/catheter/laser_calibration.json"),
                    "where ~/zero stores the straight-tip reference (eq. 3.2)",
                )
            )
        ).expanduser()
        self.zero_s = declare_float(self, "zero_duration_s", _ZERO_S)
        self.zero_max_pa = declare_float(self, "zero_max_pressure_pa", _ZERO_PA)
        self.ambient_pa = declare_float(self, "ambient_pressure_pa", _AMB)
        self.autostart = declare_autostart(self)
        self.rt_priority = declare_rt_priority(self)
        self.core: LaserAngleCore | None = None
        self._loop: DeadlineLoop | None = None
        self._stamper = MonotonicStamper(self.get_clock().now().nanoseconds)
        self._state = "unconfigured"
        self._reason = "not configured"
        self._pressure: tuple[float, float] | None = None  # (gauge Pa, monotonic s)
        self._published = 0
        self._range_m = (
            float(self.geometry.voltage_to_distance_m(0.0)),
            float(self.geometry.voltage_to_distance_m(10.0)),
        )
        self._pub_distance = qos.overridable_publisher(self, Range, TIP_DISTANCE.name, qos.STREAM)
        self._pub_angle = qos.overridable_publisher(self, JointState, TIP_ANGLE.name, qos.STREAM)
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self.create_subscription(
            FluidPressure, PRESSURE_MEASURED.name, self._on_pressure, qos_profile_sensor_data
        )
        self.create_service(Trigger, "~/zero", self._on_zero)
        self.create_timer(1.0, self._publish_diagnostics)
        if self.autostart:
            self._autostart_timer = self.create_timer(1.0, self._try_autostart)
            self._try_autostart()

    def _try_autostart(self) -> None:
        if self.core is None:
            self.trigger_configure()
        if self.core is not None and self._loop is None:
            self.trigger_activate()
        if self._loop is not None:
            self._autostart_timer.cancel()

    # -- lifecycle -----------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Open the ADC bridge and load the stored calibration, if any."""
        try:
            backend, options = device_options(self, "adc")
            adc = make_laser_adc(backend, **options)
            adc.open()
        except (CatheterError, ValueError, TypeError) as exc:
            self._state, self._reason = "error", f"configure failed: {exc}"
            self.get_logger().error(self._reason, throttle_duration_sec=5.0)
            return TransitionCallbackReturn.FAILURE
        calibration = None
        if self.calibration_file.is_file():
            try:
                calibration = Calibration.load(self.calibration_file)
            except CatheterError as exc:
                self.get_logger().error(f"{exc}; zero the laser again (~/zero)")
        self.core = LaserAngleCore(adc, self.geometry, 1.0 / self.rate_hz, calibration)
        self._state = "inactive"
        self._reason = "" if calibration else "not zeroed: call ~/zero with the muscle vented"
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start reading and publishing."""
        make_process_realtime(self, self.rt_priority)
        self._loop = DeadlineLoop(
            self.rate_hz, self._tick, name="laser_poll", rt_priority=self.rt_priority
        )
        self._loop.start()
        self._state = "active"
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop reading."""
        self._stop()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the ADC bridge."""
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the ADC bridge."""
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Close the ADC bridge."""
        self.close()
        return TransitionCallbackReturn.SUCCESS

    def _stop(self) -> None:
        if self._loop is not None:
            self._loop.stop()
            self._loop = None
        self._state = "inactive"

    def close(self) -> None:
        """Stop and close (idempotent)."""
        self._stop()
        if self.core is not None:
            self.core.adc.close()
            self.core = None

    # -- data path -----------------------------------------------------------------------
    def _on_pressure(self, msg: FluidPressure) -> None:
        self._pressure = (messages.gauge_pa_from(msg, self.ambient_pa), time.monotonic())

    def _tick(self, _k: int, _deadline_s: float) -> None:
        core = self.core
        if core is None:
            return
        try:
            readings = core.poll(0.0)
        except CatheterError as exc:
            # The bridge went away: report it, and try to reopen at the next tick.
            self._state, self._reason = "link_down", str(exc)
            core.adc.counters.last_error = str(exc)
            try:
                core.adc.close()
                core.adc.open()  # counts itself in counters.reconnects
                self._state, self._reason = "active", ""
            except CatheterError:
                time.sleep(0.2)  # the loop skips the deadlines it missed; no busy retry
            return
        for r in readings:
            stamp_ns = self._stamper.ns(r.sample_s)
            self._pub_distance.publish(messages.laser_range(r.distance_m, stamp_ns, *self._range_m))
            if r.angle_rad is not None:
                self._pub_angle.publish(messages.joint_state(r.angle_rad, stamp_ns))
        self._published += len(readings)

    # -- zeroing -------------------------------------------------------------------------
    def _on_zero(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        core = self.core
        resp.success = False
        if core is None or self._loop is None:
            resp.message = "refused: the node is not active"
            return resp
        pressure = self._pressure
        if pressure is None or time.monotonic() - pressure[1] > _PRESSURE_FRESH_S:
            resp.message = (
                "refused: no recent pressure/measured, so the muscle cannot be confirmed vented"
            )
            return resp
        if pressure[0] > self.zero_max_pa:
            resp.message = (
                f"refused: line pressure {pressure[0] / 1e5:.3f} bar is above "
                f"{self.zero_max_pa / 1e5:.3f} bar; vent the muscle first"
            )
            return resp
        core.start_zeroing()
        time.sleep(self.zero_s)
        try:
            calibration = core.finish_zeroing(
                min_samples=max(10, int(0.5 * self.zero_s * self.rate_hz))
            )
            calibration.save(self.calibration_file)
        except (ZeroingError, OSError) as exc:
            resp.message = f"refused: {exc}"
            return resp
        core.calibration = calibration
        self._reason = ""
        resp.success = True
        resp.message = (
            f"zeroed: straight-tip distance {calibration.straight_distance_m * 1e3:.3f} mm "
            f"(std {calibration.std_m * 1e6:.1f} um, {calibration.samples} samples), "
            f"stored in {self.calibration_file}"
        )
        self.get_logger().info(resp.message)
        return resp

    # -- diagnostics ---------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        core = self.core
        values: dict[str, object] = {
            "state": self._state,
            "samples_published": self._published,
            "realtime": self._loop.realtime if self._loop is not None else "not active",
        }
        level = diagnostics.OK
        if self._state in {"error", "link_down"}:
            level = diagnostics.ERROR
        elif self._reason or self._state != "active":
            level = diagnostics.WARN
        if core is not None:
            values["samples_lost"] = core.clock.lost
            values["zeroed"] = core.calibration is not None
            if core.calibration is not None:
                values["straight_distance_mm"] = f"{core.calibration.straight_distance_m * 1e3:.3f}"
                values["zeroed_at"] = core.calibration.zeroed_at
            values.update({f"adc.{k}": v for k, v in core.adc.counters.as_dict().items()})
        message = self._state + (f": {self._reason}" if self._reason else "")
        diagnostics.publish_status(
            self._pub_diag,
            self,
            level=level,
            message=message,
            values=values,
            hardware_id="laser_angle",
        )


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_driver laser_angle``."""
    run_node_as_main(LaserAngleNode, args)


if __name__ == "__main__":
    main()
