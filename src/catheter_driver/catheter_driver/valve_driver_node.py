"""``valve_driver``: the proportional valve and the line pressure transmitter on the real rig.

Lifecycle-managed. *configure* opens both devices (backends and options from the
``valve.*`` and ``transmitter.*`` parameters); *activate* starts the control loop (watchdog,
clamp, slew, set-point write, at ``rate_hz``) and the transmitter poll, which publishes
``pressure/measured``; *deactivate*, *cleanup*, *shutdown* and *error* leave the valve vented.
By default it waits, unconfigured, for a lifecycle manager (a launch file, ``bringup``,
``ros2 lifecycle set``); with ``autostart:=true`` (a node run alone) it configures and
activates itself, retrying until the devices answer.

Subscribes ``pressure/command``. Services ``~/vent`` (std_srvs/Trigger) and ``~/enable``
(std_srvs/SetBool). Health, device counters and the reason for any venting on
``/diagnostics``.
"""

from __future__ import annotations

import time

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from sensor_msgs.msg import FluidPressure
from std_srvs.srv import SetBool, Trigger

from catheter_driver.devices.factory import make_transmitter, make_valve
from catheter_driver.valve_core import ValveDriverCore
from catheter_models.contract import (
    COMMAND_TIMEOUT_S,
    CONTROL_RATE_HZ,
    MAX_PRESSURE_PA,
    MAX_SLEW_PA_PER_S,
    PRESSURE_LIMIT_HARD_PA,
    PRESSURE_MEASURED,
)
from catheter_models.errors import CatheterError
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
from catheter_ros.polled import PressureCommands
from catheter_ros.rt_loop import DeadlineLoop, LatencyWindow, MonotonicStamper

_RATE = BoundedParam(
    "rate_hz", CONTROL_RATE_HZ, 10.0, 2000.0, "control loop and transmitter poll rate [Hz]"
)
_PMIN = BoundedParam(
    "min_pressure_pa", 0.0, 0.0, PRESSURE_LIMIT_HARD_PA, "lowest set-point, gauge [Pa]"
)
_PMAX = BoundedParam(
    "max_pressure_pa", MAX_PRESSURE_PA, 0.0, PRESSURE_LIMIT_HARD_PA, "highest set-point, gauge [Pa]"
)
_SLEW = BoundedParam(
    "max_slew_pa_per_s", MAX_SLEW_PA_PER_S, 1.0e3, 1.0e8, "set-point slew limit [Pa/s]"
)
_WATCHDOG = BoundedParam(
    "watchdog_s", COMMAND_TIMEOUT_S, 0.01, 5.0, "vent when commands stop this long [s]"
)
_RECONNECT = BoundedParam(
    "reconnect_period_s", 1.0, 0.05, 60.0, "retry a lost device this often [s]"
)
_AMB = BoundedParam(
    "ambient_pressure_pa", AMBIENT_PRESSURE_PA, 5.0e4, 1.2e5, "ambient pressure [Pa]"
)


class ValveDriverNode(LifecycleNode):
    """Thin lifecycle shell over :class:`ValveDriverCore`."""

    def __init__(self) -> None:
        super().__init__("valve_driver")
        declare_device_options(self, "valve")
        declare_device_options(self, "transmitter")
        self.rate_hz = declare_float(self, "rate_hz", _RATE)
        self.ambient_pa = declare_float(self, "ambient_pressure_pa", _AMB)
        self.autostart = declare_autostart(self)
        self.allow_enable = bool(
            declare_plain(self, "allow_enable_service", True, "offer ~/enable (it re-arms motion)")
        )
        self.limits = {
            "min_pressure_pa": declare_float(self, "min_pressure_pa", _PMIN),
            "max_pressure_pa": declare_float(self, "max_pressure_pa", _PMAX),
            "max_slew_pa_per_s": declare_float(self, "max_slew_pa_per_s", _SLEW),
            "watchdog_s": declare_float(self, "watchdog_s", _WATCHDOG),
            "reconnect_period_s": declare_float(self, "reconnect_period_s", _RECONNECT),
        }
        self.rt_priority = declare_rt_priority(self)
        self.core: ValveDriverCore | None = None
        self._loops: list[DeadlineLoop] = []
        self._stamper = MonotonicStamper(self.get_clock().now().nanoseconds)
        self._latency = LatencyWindow()
        # The reading's stamp is uncertain by its round trip (below); a busy host stretches it.
        self._round_trip = LatencyWindow(name="transmitter_round_trip")
        self._last_tick_state = "unconfigured"
        self._last_reason = "not configured"
        self._pub_measured = qos.overridable_publisher(
            self, FluidPressure, PRESSURE_MEASURED.name, qos.STREAM
        )
        self._pub_diag = diagnostics.create_diagnostics_publisher(self)
        self._commands = PressureCommands(self)  # taken by the control loop
        self.commands_ignored_inactive = 0
        """Commands that arrived while the driver was not active: never applied."""
        self.create_service(Trigger, "~/vent", self._on_vent)
        if self.allow_enable:
            self.create_service(SetBool, "~/enable", self._on_enable)
        self.create_timer(1.0, self._publish_diagnostics)
        if self.autostart:
            # Keep trying: a driver started before its devices are plugged in comes up when
            # they appear, without a lifecycle manager.
            self._autostart_timer = self.create_timer(
                self.limits["reconnect_period_s"], self._try_autostart
            )
            self._try_autostart()

    def _try_autostart(self) -> None:
        if self.core is None:
            self.trigger_configure()
        if self.core is not None and not self._loops:
            self.trigger_activate()
        if self._loops:
            self._autostart_timer.cancel()

    # -- lifecycle -----------------------------------------------------------------------
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build and open both devices; failure leaves the node unconfigured, with the reason."""
        try:
            valve_backend, valve_opts = device_options(self, "valve")
            tx_backend, tx_opts = device_options(self, "transmitter")
            core = ValveDriverCore(
                make_valve(valve_backend, **valve_opts),
                make_transmitter(tx_backend, **tx_opts),
                **self.limits,
            )
        except (CatheterError, ValueError, TypeError) as exc:
            self._fail(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        now = time.monotonic()
        if not core.valve.ensure(now) or not core.transmitter.ensure(now):
            self._fail(f"configure failed: {core.valve.error or core.transmitter.error}")
            core.close()
            return TransitionCallbackReturn.FAILURE
        self.core = core
        self._last_tick_state, self._last_reason = "inactive", "configured, not active"
        self.get_logger().info(
            f"valve {core.valve.device.describe()}, transmitter "
            f"{core.transmitter.device.describe()}"
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Start the control loop and the transmitter poll."""
        make_process_realtime(self, self.rt_priority)
        # Whatever came while inactive is old news: counted, never applied.
        self.commands_ignored_inactive += len(self._commands.take())
        # The valve's loop outranks the transmitter poll: a slow serial reply must not
        # delay the watchdog or a command.
        self._loops = [
            DeadlineLoop(
                self.rate_hz, self._control_tick, name="valve_control", rt_priority=self.rt_priority
            ),
            DeadlineLoop(
                self.rate_hz,
                self._poll_tick,
                name="transmitter_poll",
                rt_priority=max(0, self.rt_priority - 1),
            ),
        ]
        for loop in self._loops:
            loop.start()
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop the loops and vent."""
        self._stop_loops_and_vent("deactivated")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Vent and close the devices."""
        self._close("cleaned up")
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Vent and close the devices."""
        self._close("shut down")
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Whatever went wrong, leave the valve vented."""
        self._close("error")
        return TransitionCallbackReturn.SUCCESS

    def close(self) -> None:
        """Process exit: vent and close (idempotent)."""
        self._close("process exiting")

    def destroy_node(self) -> None:
        """Stop the loops (which take the commands) before their helper node goes.

        A constructor that refused a parameter has set neither ``_loops`` nor ``_commands``,
        and rclpy still destroys the half-built node when its context shuts down: reading
        them with getattr keeps that refusal an exit 2 with its reason, not an AttributeError.
        """
        for loop in getattr(self, "_loops", []):
            loop.stop()
        super().destroy_node()
        commands = getattr(self, "_commands", None)
        if commands is not None:
            commands.destroy()

    def _stop_loops_and_vent(self, why: str) -> None:
        for loop in self._loops:
            loop.stop()
        self._loops = []
        if self.core is not None:
            self.core.vent()
            self.core.tick_setpoint(time.monotonic(), 0.0)
        self._last_tick_state, self._last_reason = "inactive", f"{why}: valve vented"

    def _close(self, why: str) -> None:
        self._stop_loops_and_vent(why)
        if self.core is not None:
            self.core.close()
            self.core = None

    def _fail(self, reason: str) -> None:
        self._last_tick_state, self._last_reason = "error", reason
        self.get_logger().error(reason, throttle_duration_sec=5.0)

    # -- data path -----------------------------------------------------------------------
    def _on_command(self, core: ValveDriverCore, msg: FluidPressure, now_s: float) -> None:
        self._latency.add(
            (self._stamper.ns(now_s) - messages.ns_from_time(msg.header.stamp)) * 1e-9
        )
        if not core.command(
            messages.gauge_pa_from(msg, self.ambient_pa),
            now_s,
            messages.ns_from_time(msg.header.stamp),
        ):
            self.get_logger().warning(core.last_refusal, throttle_duration_sec=1.0)

    def _control_tick(self, _k: int, deadline_s: float) -> None:
        core = self.core
        if core is None:
            return
        commands = self._commands.take()
        if commands:
            now_s = time.monotonic()
            for msg in commands:
                self._on_command(core, msg, now_s)
        tick = core.tick_setpoint(deadline_s, 1.0 / self.rate_hz)
        if tick.state != self._last_tick_state:
            if tick.state != "ok":
                self.get_logger().warning(f"valve {tick.state}: {tick.reason}")
            self._last_tick_state = tick.state
        self._last_reason = tick.reason

    def _poll_tick(self, _k: int, _deadline_s: float) -> None:
        core = self.core
        if core is None:
            return
        start = time.monotonic()
        gauge_pa = core.poll_pressure(start)
        if gauge_pa is None:
            return
        # The reading is true somewhere within the round trip; its middle is the best guess,
        # off by up to half the round trip (RMS round trip / sqrt(12) if uniform), which
        # /diagnostics reports: on a busy host it, not the transmitter, limits the stamps.
        end = time.monotonic()
        self._round_trip.add(end - start)
        sample_s = 0.5 * (start + end)
        self._pub_measured.publish(
            messages.fluid_pressure(gauge_pa, self._stamper.ns(sample_s), "", self.ambient_pa)
        )

    # -- services ------------------------------------------------------------------------
    def _on_vent(self, _req: Trigger.Request, resp: Trigger.Response) -> Trigger.Response:
        if self.core is not None:
            self.core.vent()
        resp.success = True
        resp.message = "valve vented; the next pressure command resumes control"
        return resp

    def _on_enable(self, req: SetBool.Request, resp: SetBool.Response) -> SetBool.Response:
        if self.core is None:
            resp.success, resp.message = False, "not configured"
            return resp
        self.core.set_enabled(bool(req.data))
        resp.success = True
        resp.message = "enabled" if req.data else "disabled: valve vented, commands ignored"
        return resp

    # -- diagnostics ---------------------------------------------------------------------
    def _publish_diagnostics(self) -> None:
        core = self.core
        values: dict[str, object] = {
            "state": self._last_tick_state,
            "reason": self._last_reason,
            "realtime": self._loops[0].realtime if self._loops else "not active",
            **self._latency.summary_ms(),
            **self._round_trip.summary_ms(),
        }
        level = diagnostics.OK if self._last_tick_state == "ok" else diagnostics.WARN
        if self._last_tick_state in {"link_down", "error"}:
            level = diagnostics.ERROR
        if core is not None:
            values.update(
                {
                    "setpoint_bar": f"{core.setpoint_pa / 1e5:.4f}",
                    "commands_received": core.commands_received,
                    "commands_ignored_inactive": self.commands_ignored_inactive,
                    "commands_refused_nonfinite": core.commands_refused,
                    "commands_refused_out_of_order": core.commands_out_of_order,
                    "commands_clamped": core.commands_clamped,
                    "watchdog_trips": core.watchdog_trips,
                    "valve_link": "up" if core.valve.up else f"down: {core.valve.error}",
                    "transmitter_link": (
                        "up" if core.transmitter.up else f"down: {core.transmitter.error}"
                    ),
                }
            )
            readback = core.read_back_pa()
            if readback is not None:
                values["valve_readback_bar"] = f"{readback / 1e5:.4f}"
            for name, link in (("valve", core.valve), ("transmitter", core.transmitter)):
                values.update({f"{name}.{k}": v for k, v in link.device.counters.as_dict().items()})
        message = self._last_tick_state + (f": {self._last_reason}" if self._last_reason else "")
        if core is not None and not core.transmitter.up:
            # pressure/measured has stopped: not OK, even while the valve follows commands.
            level = diagnostics.ERROR
            message += f"; transmitter link down: {core.transmitter.error}"
        diagnostics.publish_status(
            self._pub_diag,
            self,
            level=level,
            message=message,
            values=values,
            hardware_id="valve_driver",
        )


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_driver valve_driver``."""
    run_node_as_main(ValveDriverNode, args)


if __name__ == "__main__":
    main()
