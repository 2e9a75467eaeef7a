"""The simulated rig behind the hardware topics, without ROS.

It takes the place of the valve, the laser and both drivers (docs/simulated_rig.md), so it
keeps the drivers' safety duties too: commands are checked and clamped, and a watchdog vents
the muscle when commands stop arriving. The plant behind it is the shipped simulator or one
of your own (``catheter_models.plant.interface``); a plant that breaks its contract while
running is stopped and the valve vented, as the watchdog does.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator
from dataclasses import dataclass

from catheter_driver.command_order import CommandOrder
from catheter_models.contract import COMMAND_TIMEOUT_S, MAX_PRESSURE_PA
from catheter_models.plant import CheckedPlant, PlantConfig, PlantRunError, PlantSample, make_plant


@dataclass(frozen=True)
class CommandCounters:
    """What happened to incoming commands since start.

    Attributes:
        received: commands seen.
        refused_nonfinite: NaN/inf commands refused (the last good command stays in force).
        clamped: commands outside [0, max_pressure_pa] applied at the limit.
        watchdog_vents: times the watchdog vented after commands stopped.
        refused_out_of_order: commands stamped before the last one applied (reordered or
            late), refused; the newer command stays in force.
    """

    received: int
    refused_nonfinite: int
    clamped: int
    watchdog_vents: int
    refused_out_of_order: int = 0


class SimHardware:
    """Plant + driver safety: command intake, clamping, watchdog, stepping.

    Args:
        config: plant configuration (the shipped plant's; a plant of your own takes only
            the rig's ambient pressure and straight-tip distance from it).
        max_pressure_pa: highest gauge pressure ever applied [Pa]; higher commands clamp.
        command_timeout_s: vent when no command has arrived for this long [s].
        plant: the checked plant to step (:func:`~catheter_models.plant.make_plant`); the
            shipped plant built from ``config`` by default.
    """

    def __init__(
        self,
        config: PlantConfig,
        max_pressure_pa: float = MAX_PRESSURE_PA,
        command_timeout_s: float = COMMAND_TIMEOUT_S,
        plant: CheckedPlant | None = None,
    ) -> None:
        self.plant = plant if plant is not None else make_plant("", config)
        self.rate_hz = self.plant.rate_hz
        """The sample rate the rig runs at: the plant's [Hz]."""
        self.fault = ""
        """Why the plant was stopped ('' while it runs): see :meth:`stop`."""
        self.max_pressure_pa = max_pressure_pa
        self.command_timeout_s = command_timeout_s
        self._lock = threading.Lock()
        self._command_pa = 0.0
        self._last_command_s: float | None = None
        self._venting = True  # at rest until the first command arrives
        self._received = 0
        self._refused = 0
        self._clamped = 0
        self._vents = 0
        self._order = CommandOrder()
        self._ticks_done = 0
        self.last_refusal: str = ""

    def command(self, gauge_pa: float, now_s: float, stamp_ns: int | None = None) -> bool:
        """Take a valve set-point (gauge [Pa]) received at monotonic time ``now_s``.

        ``stamp_ns`` is the command's intended application time: one stamped before the last
        command applied is refused (:class:`~catheter_driver.command_order.CommandOrder`);
        the watchdog's vent forgets the last stamp.

        Returns:
            False if the command was refused (non-finite, or out of order); the previous
            one stays in force.
        """
        with self._lock:
            self._received += 1
            if self.fault:
                self.last_refusal = f"refused: the plant was stopped ({self.fault})"
                return False
            if not math.isfinite(gauge_pa):
                self._refused += 1
                self.last_refusal = f"refused non-finite pressure command {gauge_pa!r}"
                return False
            refusal = self._order.admit(stamp_ns)
            if refusal:
                self.last_refusal = refusal
                return False
            clamped = min(max(gauge_pa, 0.0), self.max_pressure_pa)
            if clamped != gauge_pa:
                self._clamped += 1
            self._command_pa = clamped
            self._last_command_s = now_s
            self._venting = False
            return True

    def step(self, now_s: float) -> PlantSample:
        """Advance the plant one sample with the command in force at monotonic ``now_s``.

        Raises:
            PlantRunError: the plant broke its contract on this step, or was stopped before
                (:attr:`fault`); it is stopped and the valve vented (:meth:`stop`).
        """
        with self._lock:
            if self.fault:
                raise PlantRunError(self.fault)
            stale = (
                self._last_command_s is None
                or now_s - self._last_command_s > self.command_timeout_s
            )
            if stale and not self._venting:
                self._venting = True
                self._vents += 1
            if stale:
                self._order.forget()
            command = 0.0 if self._venting else self._command_pa
        try:
            sample = self.plant.step_sample(command)
        except PlantRunError as exc:
            self.stop(str(exc))
            raise
        if self.fault:  # stopped from another thread while this step ran (stuck_reason)
            raise PlantRunError(self.fault)
        return sample

    def stop(self, reason: str) -> None:
        """Stop the plant for good and vent: command 0, every later command refused.

        For a plant that broke its contract (:class:`PlantRunError`) or one stuck in a step
        (:meth:`CheckedPlant.stuck_reason`). The first reason is kept in :attr:`fault`.
        """
        with self._lock:
            if not self.fault:
                self.fault = reason
            self._venting = True
            self._command_pa = 0.0
            self._order.forget()

    def stuck_reason(self) -> str:
        """Why the plant counts as too slow while a step runs ('' if not).

        See :meth:`CheckedPlant.stuck_reason`; called from another thread than the stepping one.
        """
        return self.plant.stuck_reason()

    def step_through(
        self, k: int, deadline_s: float, period_s: float
    ) -> Iterator[tuple[float, PlantSample]]:
        """Every sample up to tick ``k`` not taken yet: (its instant [monotonic s], sample).

        The rig samples whether or not the host ran on time: after an overrun, the caller
        gets the backlog, each sample at its true instant, as a sensor driver drains its
        buffer (``sim_hardware`` publishes them; the emulated rig's devices stream them).
        """
        while self._ticks_done < k:
            self._ticks_done += 1
            sample_time_s = deadline_s - (k - self._ticks_done) * period_s
            yield sample_time_s, self.step(sample_time_s)

    @property
    def ticks_done(self) -> int:
        """Samples taken through :meth:`step_through` since the last :meth:`reset_ticks`."""
        return self._ticks_done

    def reset_ticks(self) -> None:
        """A new loop starts counting its ticks from 1."""
        self._ticks_done = 0

    @property
    def venting(self) -> bool:
        """Whether the valve is held vented (no recent command, or the plant was stopped)."""
        return self._venting

    @property
    def command_pa(self) -> float:
        """The set-point in force, gauge [Pa] (0 while venting)."""
        return 0.0 if self._venting else self._command_pa

    def counters(self) -> CommandCounters:
        """Command counters since start."""
        with self._lock:
            return CommandCounters(
                self._received, self._refused, self._clamped, self._vents, self._order.refused
            )
