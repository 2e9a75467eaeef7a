"""The rig core: the simulated plant stepped in real time, the sensors device emulators read.

:class:`EmulatedRig` owns a :class:`~catheter_driver.sim_hardware.SimHardware` and steps it
at the plant's sample rate (250 Hz) on a deadline loop. Device emulators read its sensors
and feed it valve set-points, each over its own wire protocol. The plant is the shipped
simulator or one of your own (docs/simulated_rig.md, "Your own plant"); one that breaks its
contract while running is stopped, the valve vented, and the rig stops (:attr:`fault`).

It is its own file so the device emulators (``keller``, ``dac_bridge``, ``canopen_ao``,
``laser_adc``) can depend on it without depending on the command-line program
(:mod:`catheter_driver.emulators.rig`), which builds them: the emulators import this core,
the program imports both, and nothing imports back.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any

from catheter_driver.emulators.base import Emulator
from catheter_driver.sim_hardware import SimHardware
from catheter_models.plant import CheckedPlant, PlantConfig, PlantRunError, PlantSample
from catheter_ros.rt_loop import DeadlineLoop, set_process_realtime

SampleListener = Callable[[PlantSample, float], None]
"""Called with each new sample and its instant [monotonic s], in order, on the thread that
took it: the rig's loop, or a device's serving thread that caught the plant up."""


class EmulatedRig:
    """The simulated plant in real time, with the emulators attached to it.

    The plant follows its own clock: sample ``k`` belongs to the instant ``k`` periods after
    the loop started, whoever takes it. The deadline loop takes each on time when it can;
    when it is late (a busy host), a device that reads the plant or sets its valve first
    takes every sample whose instant has passed, so it reads a sample at most one period
    old and its set-point acts from its own instant on, never on samples before it.

    Args:
        config: plant configuration; the thesis rig by default.
        plant: the checked plant (:func:`~catheter_models.plant.make_plant`); the shipped
            plant built from ``config`` by default.
        max_pressure_pa: highest set-point applied, gauge [Pa]; the valve's maximum by default.
        command_timeout_s: vent after this long without a set-point [s]. A real regulator
            holds its last set-point forever (the driver node owns the watchdog), hence inf.
        rt_priority: SCHED_FIFO priority of the plant's loop, its emulators' threads 30 below
            (0: normal scheduling). Real devices have processors of their own; an emulator at
            normal priority shares the host with the graph it serves and, on 2 cores, was late
            on 15-23 % of its ticks. Where the OS refuses, :attr:`realtime` says why.
    """

    def __init__(
        self,
        config: PlantConfig | None = None,
        *,
        plant: CheckedPlant | None = None,
        max_pressure_pa: float | None = None,
        command_timeout_s: float = math.inf,
        rt_priority: int = 0,
    ) -> None:
        self.rt_priority = rt_priority
        self.realtime = "not started"
        """``SCHED_FIFO <priority>`` once the rig runs real time, else why not."""
        config = config if config is not None else PlantConfig.thesis_rig()
        limit_pa = (
            max_pressure_pa if max_pressure_pa is not None else config.rig["valve_max_pressure_pa"]
        )
        self.hw = SimHardware(
            config, max_pressure_pa=limit_pa, command_timeout_s=command_timeout_s, plant=plant
        )
        self.config = config
        self.geometry = self.hw.plant.geometry
        self.ambient_pa = float(config.rig["ambient_pressure_pa"])
        self.sample_rate_hz = self.hw.rate_hz
        self._period_s = 1.0 / self.sample_rate_hz
        self._listeners: list[SampleListener] = []
        self._emulators: list[Emulator] = []
        self._latest: PlantSample | None = None
        self._loop: DeadlineLoop | None = None
        self._lock = threading.Lock()
        self._step_lock = threading.Lock()
        """Held while samples are taken (by the loop or a device), so they come in order."""
        self._origin_s: float | None = None
        """The plant clock: sample k's instant is this + k periods [monotonic s]."""
        self._last_command_s: float | None = None
        self._vented_at_s: float | None = None

    # -- wiring ------------------------------------------------------------------------
    def add_listener(self, listener: SampleListener) -> None:
        """Call ``listener`` with every sample (see :data:`SampleListener`).

        Keep it short, and do not call the rig from it: it runs while samples are taken.
        """
        with self._lock:
            self._listeners.append(listener)

    def remove_listener(self, listener: SampleListener) -> None:
        """Stop calling ``listener`` (no error if it was not added)."""
        with self._lock:
            if listener in self._listeners:
                self._listeners.remove(listener)

    def attach(self, emulator: Emulator) -> Emulator:
        """Have ``emulator`` started and stopped with the rig (started now if running)."""
        self._emulators.append(emulator)
        if self.running:
            emulator.start()
        return emulator

    # -- running -----------------------------------------------------------------------
    def start(self) -> None:
        """Start stepping the plant (checked and warmed up when made), then the emulators."""
        self.hw.reset_ticks()
        self._origin_s = None
        self._loop = DeadlineLoop(
            self.sample_rate_hz, self._tick, name="emulated-rig", rt_priority=self.rt_priority
        )
        self._loop.start()
        for emulator in self._emulators:
            emulator.start()
        if self.rt_priority:
            # The serving threads too (below the plant), or a reply waits behind the host.
            refused = set_process_realtime(self.rt_priority)
            self.realtime = refused or f"SCHED_FIFO {self.rt_priority}"
        else:
            self.realtime = "off (rt_priority 0)"

    def stop(self) -> None:
        """Stop the emulators, then the plant (idempotent)."""
        for emulator in self._emulators:
            emulator.stop()
        loop, self._loop = self._loop, None
        if loop is not None:
            loop.stop()

    @property
    def running(self) -> bool:
        """Whether the plant is being stepped (not once it was stopped: :attr:`fault`)."""
        return self._loop is not None and self._loop.running and not self.hw.fault

    @property
    def fault(self) -> str:
        """Why the plant was stopped and the valve vented ('' while it runs)."""
        return self.hw.fault

    def check_plant(self) -> str:
        """Stop a plant stuck in a step (see :meth:`SimHardware.stuck_reason`); the fault.

        Call it from a thread other than the rig's loop, now and then (the program does,
        twice a second): a step that never returns cannot report itself.
        """
        if not self.hw.fault:
            reason = self.hw.stuck_reason()
            if reason:
                self.hw.stop(reason)
        return self.hw.fault

    def __enter__(self) -> EmulatedRig:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()

    def _tick(self, k: int, deadline_s: float) -> None:
        # The devices sample on their own clocks whether or not this thread ran on time (on a
        # busy host it misses deadlines: 15 % with the whole emulated graph on 2 cores). After
        # an overrun, step through every missed sample, so the laser bridge streams the backlog
        # with consecutive counters as a bridge with a FIFO does, rather than a plant that
        # skips time the sensors never saw. Samples a device has already taken are not taken
        # again (step_through counts them).
        with self._step_lock:
            if self._origin_s is None:
                self._origin_s = deadline_s - k * self._period_s
            self._take_samples(k, deadline_s)
        if self.hw.fault and self._loop is not None:
            self._loop.stop()  # from its own thread: ends after this tick, no join

    def _catch_up(self, now_s: float) -> None:
        """Take every sample whose instant is at or before ``now_s``; hold ``_step_lock``.

        A device calls this (through :meth:`command`, :attr:`measured_pressure_pa`) before it
        acts, so a late loop makes the laser stream late but never feeds a device an old
        sample or applies a set-point to instants before it arrived.
        """
        origin_s = self._origin_s
        if origin_s is None or self._loop is None:
            return  # not started (or stopped): the loop's first tick sets the clock
        k = math.floor((now_s - origin_s) / self._period_s)
        if k > self.hw.ticks_done:
            self._take_samples(k, origin_s + k * self._period_s)

    def _take_samples(self, k: int, deadline_s: float) -> None:
        """Every sample up to ``k`` not taken yet, to :attr:`latest` and the listeners.

        A plant that breaks its contract is stopped here, whoever took the sample: the valve
        is vented (:meth:`SimHardware.stop`), no sample is taken after, and the loop ends.
        """
        if self.hw.fault:
            return
        try:
            for sample_time_s, sample in self.hw.step_through(k, deadline_s, self._period_s):
                with self._lock:
                    self._latest = sample
                    listeners = tuple(self._listeners)
                for listener in listeners:
                    listener(sample, sample_time_s)
        except PlantRunError:
            return  # hw keeps the reason (fault); the loop's tick ends the loop

    # -- what the emulators use --------------------------------------------------------
    def command(self, gauge_pa: float) -> bool:
        """Apply a valve set-point, gauge [Pa] (clamped; refused if not finite)."""
        now_s = time.monotonic()
        with self._step_lock:  # no sample may be taken between the catch-up and the command
            self._catch_up(now_s)
            with self._lock:
                was_pa = self.hw.command_pa
                ok = self.hw.command(gauge_pa, now_s)
                if ok:
                    self._last_command_s = now_s
                    if was_pa > 0.0 and self.hw.command_pa <= 0.0:
                        self._vented_at_s = now_s
        return ok

    def state(self) -> dict[str, Any]:
        """The plant's truth now, as plain values (for the CLI's ``query``).

        Keys: ``t_s`` (monotonic now), ``command_pa`` (valve set-point in force),
        ``muscle_pa`` (pressure in the muscle, noise-free), ``measured_pa`` (what the
        transmitter reads), ``angle_deg`` (true bend), ``distance_m`` (laser),
        ``last_command_s`` (when the latest set-point was applied) and ``vented_at_s``
        (when the set-point last dropped from above 0 to 0), monotonic [s] or None;
        ``plant_steps`` (samples taken since start) and ``steps_caught_up`` (deadlines the
        rig's loop missed because the host was busy: their samples were taken late, by the
        loop or by a device catching the plant up, and streamed as a backlog); ``plant``
        (``"shipped"`` or the plant's spec) and ``fault`` (why the plant was stopped, '').
        A plant of your own gives no truth: ``muscle_pa`` and ``angle_deg`` are then None.
        """
        with self._step_lock:
            self._catch_up(time.monotonic())
        sample = self.latest
        with self._lock:
            last_s, vented_s = self._last_command_s, self._vented_at_s
        loop = self._loop
        stats = loop.stats() if loop is not None else None
        return {
            "plant_steps": self.hw.ticks_done,
            "steps_caught_up": None if stats is None else stats.missed,
            "t_s": time.monotonic(),
            "command_pa": self.hw.command_pa,
            "muscle_pa": _known(None if sample is None else sample.muscle_pressure_pa),
            "measured_pa": self.measured_pressure_pa,
            "angle_deg": _known(None if sample is None else math.degrees(sample.true_angle_rad)),
            "distance_m": None if sample is None else sample.distance_m,
            "last_command_s": last_s,
            "vented_at_s": vented_s,
            "plant": "shipped" if self.hw.plant.shipped else self.hw.plant.name,
            "fault": self.hw.fault,
        }

    @property
    def latest(self) -> PlantSample | None:
        """The newest sample; None before the first step."""
        with self._lock:
            return self._latest

    @property
    def measured_pressure_pa(self) -> float:
        """What the transmitter reads now, gauge [Pa] (0 before the first step: vented)."""
        with self._step_lock:
            self._catch_up(time.monotonic())
        sample = self.latest
        return 0.0 if sample is None else sample.pressure_measured_pa


def _known(value: float | None) -> float | None:
    """None for a value the plant does not give (NaN: no truth from a plant of your own)."""
    return None if value is None or math.isnan(value) else value
