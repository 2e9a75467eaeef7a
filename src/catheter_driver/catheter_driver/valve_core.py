"""The valve driver without ROS: command intake, limits, watchdog, venting, reconnect.

Two duties run at their own pace. The control tick (``tick_setpoint``, 250 Hz) decides the
set-point and writes it: it must never wait on the transmitter, whose RS485 round trip can
take longer than a period. The transmitter poll (``poll_pressure``) reads the line pressure
as fast as the bus allows. Both survive a lost link: the error is counted and reported, the
valve is treated as vented, and the link is re-opened every ``reconnect_period_s``.
"""

from __future__ import annotations

import contextlib
import math
import threading
from dataclasses import dataclass
from typing import Generic, TypeVar

from catheter_driver.command_order import CommandOrder
from catheter_driver.devices.base import Device, PressureTransmitter, ValveSetpoint
from catheter_driver.errors import DeviceError, DeviceTimeout

MAX_CONSECUTIVE_TIMEOUTS = 5
"""A missed reply is counted; this many in a row mean the device is gone."""


@dataclass(frozen=True)
class SetpointTick:
    """What one control tick did.

    Attributes:
        setpoint_pa: set-point written (or that would have been, if the link is down), gauge.
        state: ``ok``, ``disabled``, ``vented``, ``watchdog`` (commands stopped) or
            ``link_down``.
        reason: why the valve is not following commands, for a person ('' when ok).
    """

    setpoint_pa: float
    state: str
    reason: str


DeviceT = TypeVar("DeviceT", bound=Device)


def _named(device: Device, exc: DeviceError) -> str:
    """``<device>: <error>``, naming the device once (most device errors already name it)."""
    name, text = device.describe(), str(exc)
    return text if text.startswith(name) else f"{name}: {text}"


class _Link(Generic[DeviceT]):
    """One device with its open/closed state and a reconnect schedule."""

    def __init__(self, device: DeviceT, period_s: float) -> None:
        self.device = device
        self.period_s = period_s
        self.up = False
        self.next_try_s = 0.0
        self.error = ""
        self.consecutive_timeouts = 0
        self.lock = threading.Lock()

    def ensure(self, now_s: float) -> bool:
        """Open the link if it is down and a retry is due; True if it is up."""
        if self.up:
            return True
        if now_s < self.next_try_s:
            return False
        self.next_try_s = now_s + self.period_s
        try:
            self.device.close()
            self.device.open()
        except DeviceError as exc:
            self.error = _named(self.device, exc)
            return False
        # The device counts the re-open in counters.reconnects itself.
        self.up = True
        self.error = ""
        return True

    def failed(self, exc: DeviceError, now_s: float) -> None:
        """A request failed: a lone timeout is tolerated, anything else drops the link."""
        self.device.counters.last_error = str(exc)
        if isinstance(exc, DeviceTimeout):
            self.consecutive_timeouts += 1
            if self.consecutive_timeouts < MAX_CONSECUTIVE_TIMEOUTS:
                return
        self.lost(exc, now_s)

    def succeeded(self) -> None:
        self.consecutive_timeouts = 0

    def lost(self, exc: DeviceError, now_s: float) -> None:
        self.up = False
        self.consecutive_timeouts = 0
        self.error = _named(self.device, exc)
        self.device.counters.last_error = str(exc)
        self.next_try_s = now_s + self.period_s


class ValveDriverCore:
    """Set-point safety and device I/O of the valve driver.

    Args:
        valve: the set-point device.
        transmitter: the line pressure transmitter.
        min_pressure_pa, max_pressure_pa: command range, gauge [Pa]; commands clamp here.
        max_slew_pa_per_s: set-point slew limit while following commands [Pa/s]. Venting is
            not slew-limited: it is the safe action.
        watchdog_s: vent when no command has arrived for this long [s].
        reconnect_period_s: how often a lost device is re-opened [s].
    """

    def __init__(
        self,
        valve: ValveSetpoint,
        transmitter: PressureTransmitter,
        *,
        min_pressure_pa: float,
        max_pressure_pa: float,
        max_slew_pa_per_s: float,
        watchdog_s: float,
        reconnect_period_s: float = 1.0,
    ) -> None:
        if not 0.0 <= min_pressure_pa <= max_pressure_pa:
            raise ValueError(
                f"need 0 <= min_pressure_pa <= max_pressure_pa, got "
                f"{min_pressure_pa}, {max_pressure_pa}"
            )
        self.valve = _Link(valve, reconnect_period_s)
        self.transmitter = _Link(transmitter, reconnect_period_s)
        self.min_pressure_pa = min_pressure_pa
        self.max_pressure_pa = max_pressure_pa
        self.max_slew_pa_per_s = max_slew_pa_per_s
        self.watchdog_s = watchdog_s
        self._lock = threading.Lock()
        self._command_pa = 0.0
        self._last_command_s: float | None = None
        self._setpoint_pa = 0.0
        self._enabled = True
        self._vent_requested = False
        self.commands_received = 0
        self.commands_refused = 0
        self.commands_clamped = 0
        self.watchdog_trips = 0
        self.last_refusal = ""
        self._watchdog_tripped = False
        self._order = CommandOrder()

    # -- intake (subscriber thread) ------------------------------------------------------
    def command(self, gauge_pa: float, now_s: float, stamp_ns: int | None = None) -> bool:
        """Take a set-point (gauge [Pa]); False if refused. Clamps to range.

        Refused: non-finite values, and commands stamped (``stamp_ns``, the intended
        application time) before the last one applied
        (:class:`~catheter_driver.command_order.CommandOrder`); venting (watchdog, ~/vent,
        disable) forgets the last stamp.
        """
        with self._lock:
            self.commands_received += 1
            if not math.isfinite(gauge_pa):
                self.commands_refused += 1
                self.last_refusal = f"refused non-finite pressure command {gauge_pa!r}"
                return False
            refusal = self._order.admit(stamp_ns)
            if refusal:
                self.last_refusal = refusal
                return False
            clamped = min(max(gauge_pa, self.min_pressure_pa), self.max_pressure_pa)
            if clamped != gauge_pa:
                self.commands_clamped += 1
            self._command_pa = clamped
            self._last_command_s = now_s
            self._vent_requested = False
            return True

    def vent(self) -> None:
        """Vent now and hold vented until the next command."""
        with self._lock:
            self._vent_requested = True
            self._last_command_s = None
            self._order.forget()

    def set_enabled(self, enabled: bool) -> None:
        """Disabled: vented, commands ignored until enabled again."""
        with self._lock:
            self._enabled = enabled
            if not enabled:
                self._last_command_s = None
                self._order.forget()

    @property
    def enabled(self) -> bool:
        """Whether commands are followed."""
        return self._enabled

    @property
    def commands_out_of_order(self) -> int:
        """Commands refused as stamped before the last one applied."""
        return self._order.refused

    # -- control tick --------------------------------------------------------------------
    def tick_setpoint(self, now_s: float, dt_s: float) -> SetpointTick:
        """Decide and write this period's set-point."""
        with self._lock:
            stale = self._last_command_s is None or now_s - self._last_command_s > self.watchdog_s
            if not self._enabled:
                state, reason, target = "disabled", "disabled by ~/enable", 0.0
            elif self._vent_requested:
                state, reason, target = "vented", "vented by ~/vent", 0.0
            elif stale:
                state, target = "watchdog", 0.0
                self._order.forget()
                reason = (
                    "no pressure command yet"
                    if self._last_command_s is None and not self._watchdog_tripped
                    else f"commands stopped for more than {self.watchdog_s * 1e3:.0f} ms"
                )
                if self._last_command_s is not None and not self._watchdog_tripped:
                    self.watchdog_trips += 1
                    self._watchdog_tripped = True
            else:
                state, reason, target = "ok", "", self._command_pa
                self._watchdog_tripped = False
            if state == "ok":
                step = self.max_slew_pa_per_s * dt_s
                setpoint = min(max(target, self._setpoint_pa - step), self._setpoint_pa + step)
            else:
                setpoint = 0.0  # venting is never slew-limited
            self._setpoint_pa = setpoint
        link = self.valve
        with link.lock:
            if link.ensure(now_s):
                try:
                    link.device.write_setpoint_pa(setpoint)
                    link.succeeded()
                except DeviceError as exc:
                    link.failed(exc, now_s)
            if not link.up:
                # Whatever we meant to command, a valve we cannot reach is not following it.
                return SetpointTick(setpoint, "link_down", link.error)
        return SetpointTick(setpoint, state, reason)

    # -- transmitter poll ------------------------------------------------------------------
    def poll_pressure(self, now_s: float) -> float | None:
        """One transmitter reading, gauge [Pa]; None if the link is down or it timed out."""
        link = self.transmitter
        with link.lock:
            if not link.ensure(now_s):
                return None
            try:
                value = link.device.read_gauge_pa()
            except DeviceError as exc:
                link.failed(exc, now_s)
                return None
            link.succeeded()
            return value

    def read_back_pa(self) -> float | None:
        """The valve's own report of its set-point, where it offers one."""
        link = self.valve
        with link.lock:
            if not link.up:
                return None
            return link.device.read_back_pa()

    @property
    def setpoint_pa(self) -> float:
        """The set-point last decided, gauge [Pa]."""
        return self._setpoint_pa

    def close(self) -> None:
        """Vent (best effort) and close both devices."""
        with self.valve.lock:
            if self.valve.up:
                # If this fails the link is going away anyway; the valve's fail-safe vents.
                with contextlib.suppress(DeviceError):
                    self.valve.device.write_setpoint_pa(0.0)
            self.valve.device.close()
            self.valve.up = False
        with self.transmitter.lock:
            self.transmitter.device.close()
            self.transmitter.up = False
