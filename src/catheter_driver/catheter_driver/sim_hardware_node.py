"""``sim_hardware``: the simulated rig as a ROS 2 lifecycle node.

Subscribes ``pressure/command``; publishes ``pressure/measured``, ``tip/distance`` and
``tip/angle`` at the plant's sample rate (250 Hz), stamped on the plant's clock, and its health
on ``/diagnostics``. Parameters ``effects.<name>.enabled`` and ``effects.<name>.<param>``
switch and size every effect of docs/simulated_rig.md; ``rig.<param>`` sets the rig.
``plant:=module:factory`` (or ``path/to/file.py:factory``) puts a plant of your own behind the
rig instead of the shipped one (docs/simulated_rig.md, "Your own plant"); the node then runs
at that plant's ``rate_hz``.

Lifecycle: *configure* builds the plant (the "device"), checks it and warms it up; a plant
that cannot be loaded or breaks its contract fails the transition with the reason (on
/diagnostics and in the log). *activate* starts the sample loop (publishing, taking commands);
*deactivate* stops it, so nothing is published or applied; *cleanup*/*shutdown* drop the
plant. A plant that breaks its contract while running (raises, returns a non-finite value,
cannot keep its rate) is stopped, the valve vented, /diagnostics says ERROR with the reason,
and the node deactivates itself; it activates again only after cleanup and configure.
Commands that arrive while inactive are counted away, never applied. ``autostart:=true``
configures and activates at start-up for a node run alone.
"""

from __future__ import annotations

import time

from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import FluidPressure, JointState, Range

from catheter_driver.sim_hardware import SimHardware
from catheter_models.contract import (
    COMMAND_TIMEOUT_S,
    MAX_PRESSURE_PA,
    PRESSURE_LIMIT_HARD_PA,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
)
from catheter_models.errors import CatheterError
from catheter_models.limits import BoundedParam
from catheter_models.plant import PlantRunError, make_plant
from catheter_models.plant.config import EFFECTS, RIG_PARAMS, PlantConfig
from catheter_ros import diagnostics, messages, qos
from catheter_ros.loop_node import LifecycleLoopNode
from catheter_ros.node_main import run_node_as_main
from catheter_ros.params import declare_float, declare_int, declare_plain
from catheter_ros.polled import PressureCommands
from catheter_ros.rt_loop import LatencyWindow

_MAX_PRESSURE = BoundedParam(
    "max_pressure_pa",
    MAX_PRESSURE_PA,
    0.0,
    PRESSURE_LIMIT_HARD_PA,
    "safety limit: commands above clamp here, gauge [Pa]",
)
_TIMEOUT = BoundedParam(
    "command_timeout_s",
    COMMAND_TIMEOUT_S,
    0.01,
    5.0,
    "vent when commands stop for longer than this [s]",
)
_PLANT_WATCH_PERIOD_S = 0.2
"""How often the executor looks for a stopped or stuck plant, to report it and deactivate."""


class SimHardwareNode(LifecycleLoopNode):
    """Thin lifecycle shell over :class:`SimHardware`."""

    def __init__(self) -> None:
        super().__init__("sim_hardware")
        self.plant_spec = str(
            declare_plain(
                self,
                "plant",
                "",
                "the plant behind the rig: module:factory or path/to/file.py:factory of a plant "
                "of your own ('' = the shipped simulator; docs/simulated_rig.md)",
            )
        )
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
        self.rate_hz = rig["sample_rate_hz"]
        self._max_pressure_pa = declare_float(self, "max_pressure_pa", _MAX_PRESSURE)
        self._command_timeout_s = declare_float(self, "command_timeout_s", _TIMEOUT)
        self.config = config
        self.hw: SimHardware | None = None
        self._range_limits_m = (0.0, 0.0)

        # Sensor streams: QoS overridable by parameter (REP 2003).
        self._pub_pressure = qos.overridable_publisher(
            self, FluidPressure, PRESSURE_MEASURED.name, qos.STREAM
        )
        self._pub_distance = qos.overridable_publisher(self, Range, TIP_DISTANCE.name, qos.STREAM)
        self._pub_angle = qos.overridable_publisher(self, JointState, TIP_ANGLE.name, qos.STREAM)
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self._commands = PressureCommands(self)  # taken by the loop, see PressureCommands
        self.commands_ignored_inactive = 0
        """Commands that arrived while the rig was not active: never applied."""
        self._latency = LatencyWindow()
        self._fault_reported = False
        self.create_timer(1.0, self._publish_diagnostics)
        self.create_timer(_PLANT_WATCH_PERIOD_S, self._watch_plant)

    # -- lifecycle -----------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the plant, check it at rest and warm it up."""
        try:
            hw = SimHardware(
                self.config,
                max_pressure_pa=self._max_pressure_pa,
                command_timeout_s=self._command_timeout_s,
                plant=make_plant(self.plant_spec, self.config),
            )
        except (CatheterError, ValueError) as exc:
            self.fail_transition("configure", str(exc))
            return TransitionCallbackReturn.FAILURE
        self.transition_failure = ""
        self._fault_reported = False
        self.rate_hz = hw.rate_hz
        geom = hw.plant.geometry
        self._range_limits_m = (
            float(geom.voltage_to_distance_m(0.0)),
            float(geom.voltage_to_distance_m(10.0)),
        )
        self.hw = hw
        if hw.plant.shipped:
            on = [n for n in EFFECTS if self.config.enabled(n)]
            what = f"effects on: {', '.join(on) or 'none'}"
        else:
            what = f"plant {hw.plant.name} (tip/distance derived from its bend)"
        self.get_logger().info(f"simulated rig at {self.rate_hz:g} Hz, {what}")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start sampling, publishing and taking commands."""
        assert self.hw is not None  # the state machine activates configured nodes only
        if self.hw.fault:
            self.fail_transition(
                "activate",
                f"the plant was stopped ({self.hw.fault}); cleanup and configure load it again",
            )
            return TransitionCallbackReturn.FAILURE
        # Whatever came while inactive is old news: counted, never applied.
        self.commands_ignored_inactive += len(self._commands.take())
        self.hw.reset_ticks()
        self.start_loop(self.rate_hz, self._tick)
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop sampling: nothing published, no command applied."""
        self.stop_loop()
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Drop the plant."""
        self.stop_loop()
        self.hw = None
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop and drop the plant."""
        return self.on_cleanup(state)

    def _on_command(self, hw: SimHardware, msg: FluidPressure, now_s: float) -> None:
        self._latency.add((self.stamp_ns(now_s) - messages.ns_from_time(msg.header.stamp)) * 1e-9)
        gauge_pa = messages.gauge_pa_from(msg, self.ambient_pa)
        if not hw.command(gauge_pa, now_s, messages.ns_from_time(msg.header.stamp)):
            self.get_logger().warning(hw.last_refusal, throttle_duration_sec=1.0)

    def _tick(self, k: int, deadline_s: float) -> None:
        hw, loop = self.hw, self.active_loop
        if hw is None or loop is None:
            return
        commands = self._commands.take()
        if commands:
            now_s = time.monotonic()
            for msg in commands:
                self._on_command(hw, msg, now_s)
        # The rig samples whether or not this thread ran on time: after an overrun, step
        # through every missed sample and publish the backlog with its true stamps, as a
        # sensor driver drains its buffer. Stamps are the sampling instants (monotonic
        # deadlines mapped to ROS time), so bags align across nodes.
        try:
            for sample_time_s, sample in hw.step_through(k, deadline_s, loop.period_s):
                stamp_ns = self.stamp_ns(sample_time_s)
                self._pub_pressure.publish(
                    messages.fluid_pressure(
                        sample.pressure_measured_pa, stamp_ns, "", self.ambient_pa
                    )
                )
                self._pub_distance.publish(
                    messages.laser_range(sample.distance_m, stamp_ns, *self._range_limits_m)
                )
                self._pub_angle.publish(messages.joint_state(sample.angle_rad, stamp_ns))
        except PlantRunError:
            # hw has vented and keeps the reason; the loop ends here, and the executor
            # reports it and deactivates the node (_watch_plant): no logging on this thread.
            loop.stop()

    def _watch_plant(self) -> None:
        """Stop a plant stuck in a step; report a stopped one once, and deactivate.

        Runs on the executor (the loop thread does not log or change state): the report is
        the log's error and /diagnostics ERROR with the reason.
        """
        hw = self.hw
        if hw is None:
            return
        if not hw.fault:
            stuck = hw.stuck_reason()
            if not stuck:
                return
            hw.stop(stuck)
        if self._fault_reported:
            return
        self._fault_reported = True
        self.get_logger().error(f"plant stopped, valve vented: {hw.fault}")
        self._publish_diagnostics()
        if self.active_loop is not None:
            self.trigger_deactivate()
            self._publish_diagnostics()

    def destroy_node(self) -> None:
        """Stop the loop (which takes the commands) before their helper node goes."""
        super().destroy_node()
        commands = getattr(self, "_commands", None)
        if commands is not None:
            commands.destroy()

    def _publish_diagnostics(self) -> None:
        hw, loop = self.hw, self.active_loop
        if hw is not None and hw.fault:
            # Stopped by its plant: ERROR while configured, active or not, until cleanup.
            diagnostics.publish_status(
                self._pub_diag,
                self,
                level=diagnostics.ERROR,
                message=f"plant stopped, valve vented: {hw.fault}",
                values={
                    "plant": self.plant_spec or "shipped",
                    "venting": hw.venting,
                    "command_bar": f"{hw.command_pa / 1e5:.4f}",
                    "samples": hw.ticks_done,
                    "commands_ignored_inactive": self.commands_ignored_inactive,
                },
                hardware_id="sim_hardware",
            )
            return
        if hw is None or loop is None:
            diagnostics.publish_status(
                self._pub_diag,
                self,
                level=diagnostics.WARN,
                message=self.transition_failure
                or ("configured, not active" if hw is not None else "not configured"),
                values={"commands_ignored_inactive": self.commands_ignored_inactive},
                hardware_id="sim_hardware",
            )
            return
        counters = hw.counters()
        stats = loop.stats()
        level = diagnostics.OK
        message = "running"
        if loop.error is not None:
            level, message = diagnostics.ERROR, f"sample loop died: {loop.error!r}"
        elif hw.venting:
            level, message = diagnostics.WARN, "watchdog: no pressure command, valve vented"
        elif counters.refused_nonfinite or counters.refused_out_of_order:
            level, message = diagnostics.WARN, hw.last_refusal
        values: dict[str, object] = {
            "commands_received": counters.received,
            "commands_refused_nonfinite": counters.refused_nonfinite,
            "commands_refused_out_of_order": counters.refused_out_of_order,
            "commands_clamped": counters.clamped,
            "watchdog_vents": counters.watchdog_vents,
            "commands_ignored_inactive": self.commands_ignored_inactive,
            "venting": hw.venting,
            "command_bar": f"{hw.command_pa / 1e5:.4f}",
            "realtime": loop.realtime,
            "samples": stats.ticks,
            "missed_deadlines": stats.missed,
            "lateness_p99_ms": f"{stats.lateness_p99_s * 1e3:.3f}",
            "behind_max_ms": f"{loop.take_worst_behind_s() * 1e3:.3f}",
            **self._latency.summary_ms(),
        }
        if hw.plant.shipped:
            values.update(self.config.describe())
        else:
            values["plant"] = self.plant_spec
            values["rate_hz"] = f"{hw.rate_hz:g}"
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
    run_node_as_main(SimHardwareNode, args)


if __name__ == "__main__":
    main()
