"""``sim_hardware``: the simulated rig as a ROS 2 node.

Subscribes ``pressure/command``; publishes ``pressure/measured``, ``tip/distance`` and
``tip/angle`` at the plant's sample rate (250 Hz), stamped on the plant's clock, and its health
on ``/diagnostics``. Parameters ``effects.<name>.enabled`` and ``effects.<name>.<param>``
switch and size every effect of docs/simulated_rig.md; ``rig.<param>`` sets the rig.
"""

from __future__ import annotations

import time

from sensor_msgs.msg import FluidPressure, JointState, Range

from catheter_driver import diagnostics, messages, qos
from catheter_driver.loop_node import LoopNode
from catheter_driver.node_main import run_node
from catheter_driver.params import declare_float, declare_int, declare_plain
from catheter_driver.polled import PressureCommands
from catheter_driver.rt_loop import LatencyWindow
from catheter_driver.sim_hardware import SimHardware
from catheter_models.contract import PRESSURE_MEASURED, TIP_ANGLE, TIP_DISTANCE
from catheter_models.plant.config import EFFECTS, RIG_PARAMS, ParamSpec, PlantConfig

_MAX_PRESSURE = ParamSpec(
    "max_pressure_pa", 3.0e5, 0.0, 6.0e5, "safety limit: commands above clamp here, gauge [Pa]"
)
_TIMEOUT = ParamSpec(
    "command_timeout_s", 0.1, 0.01, 5.0, "vent when commands stop for longer than this [s]"
)


class SimHardwareNode(LoopNode):
    """Thin ROS shell over :class:`SimHardware`."""

    def __init__(self) -> None:
        super().__init__("sim_hardware")
        seed = declare_int(
            self, "seed", 0, low=0, high=2**31 - 1, doc="noise seed of the simulated rig"
        )
        config = PlantConfig.thesis_rig(seed=seed)
        rig = {p.name: declare_float(self, f"rig.{p.name}", p) for p in RIG_PARAMS}
        config = config.with_rig(**rig)
        for name, spec in EFFECTS.items():
            enabled = bool(
                declare_plain(self, f"effects.{name}.enabled", config.enabled(name), spec.physics)
            )
            values = {
                p.name: declare_float(self, f"effects.{name}.{p.name}", p) for p in spec.params
            }
            config = config.with_effect(name, enabled=enabled, **values)
        self.ambient_pa = rig["ambient_pressure_pa"]
        self.hw = SimHardware(
            config,
            max_pressure_pa=declare_float(self, "max_pressure_pa", _MAX_PRESSURE),
            command_timeout_s=declare_float(self, "command_timeout_s", _TIMEOUT),
        )
        self.config = config
        geom = self.hw.plant.geometry
        self._range_limits_m = (
            float(geom.voltage_to_distance_m(0.0)),
            float(geom.voltage_to_distance_m(10.0)),
        )

        self._pub_pressure = self.create_publisher(
            FluidPressure, PRESSURE_MEASURED.name, qos.STREAM
        )
        self._pub_distance = self.create_publisher(Range, TIP_DISTANCE.name, qos.STREAM)
        self._pub_angle = self.create_publisher(JointState, TIP_ANGLE.name, qos.STREAM)
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self._commands = PressureCommands(self)  # taken by the loop, see PressureCommands
        self.hw.plant.warm_up()
        self._latency = LatencyWindow()
        self.create_loop(rig["sample_rate_hz"], self._tick)
        self.create_timer(1.0, self._publish_diagnostics)
        on = [n for n in EFFECTS if config.enabled(n)]
        self.get_logger().info(
            f"simulated rig at {rig['sample_rate_hz']:g} Hz, effects on: {', '.join(on) or 'none'}"
        )

    def _on_command(self, msg: FluidPressure, now_s: float) -> None:
        self._latency.add((self.stamp_ns(now_s) - messages.ns_from_time(msg.header.stamp)) * 1e-9)
        gauge_pa = messages.gauge_pa_from(msg, self.ambient_pa)
        if not self.hw.command(gauge_pa, now_s, messages.ns_from_time(msg.header.stamp)):
            self.get_logger().warning(self.hw.last_refusal, throttle_duration_sec=1.0)

    def _tick(self, k: int, deadline_s: float) -> None:
        commands = self._commands.take()
        if commands:
            now_s = time.monotonic()
            for msg in commands:
                self._on_command(msg, now_s)
        # The rig samples whether or not this thread ran on time: after an overrun, step
        # through every missed sample and publish the backlog with its true stamps, as a
        # sensor driver drains its buffer. Stamps are the sampling instants (monotonic
        # deadlines mapped to ROS time), so bags align across nodes.
        for sample_time_s, sample in self.hw.step_through(k, deadline_s, self.loop.period_s):
            stamp_ns = self.stamp_ns(sample_time_s)
            self._pub_pressure.publish(
                messages.fluid_pressure(sample.pressure_measured_pa, stamp_ns, "", self.ambient_pa)
            )
            self._pub_distance.publish(
                messages.laser_range(sample.distance_m, stamp_ns, *self._range_limits_m)
            )
            self._pub_angle.publish(messages.joint_state(sample.angle_rad, stamp_ns))

    def destroy_node(self) -> None:
        """Stop the loop (which takes the commands) before their helper node goes."""
        super().destroy_node()
        commands = getattr(self, "_commands", None)
        if commands is not None:
            commands.destroy()

    def _publish_diagnostics(self) -> None:
        counters = self.hw.counters()
        stats = self.loop.stats()
        level = diagnostics.OK
        message = "running"
        if self.loop.error is not None:
            level, message = diagnostics.ERROR, f"sample loop died: {self.loop.error!r}"
        elif self.hw.venting:
            level, message = diagnostics.WARN, "watchdog: no pressure command, valve vented"
        elif counters.refused_nonfinite or counters.refused_out_of_order:
            level, message = diagnostics.WARN, self.hw.last_refusal
        values: dict[str, object] = {
            "commands_received": counters.received,
            "commands_refused_nonfinite": counters.refused_nonfinite,
            "commands_refused_out_of_order": counters.refused_out_of_order,
            "commands_clamped": counters.clamped,
            "watchdog_vents": counters.watchdog_vents,
            "venting": self.hw.venting,
            "command_bar": f"{self.hw.command_pa / 1e5:.4f}",
            "realtime": self.realtime,
            "samples": stats.ticks,
            "missed_deadlines": stats.missed,
            "lateness_p99_ms": f"{stats.lateness_p99_s * 1e3:.3f}",
            "behind_max_ms": f"{self.loop.take_worst_behind_s() * 1e3:.3f}",
            **self._latency.summary_ms(),
        }
        values.update(self.config.describe())
        diagnostics.publish_status(
            self._pub_diag,
            self,
            level=level,
            message=message,
            values=values,
            hardware_id="sim_hardware",
        )


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_driver sim_hardware``."""
    code = run_node(SimHardwareNode, args)
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
