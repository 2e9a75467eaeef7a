"""The compensator's tick, without ROS: trajectory in, safe pressure command out.

Every tick takes the desired bend at the current time, asks the streaming compensator for a
pressure, adds the feedback on the measured bend when there is one
(:class:`~catheter_models.feedback.PIDFeedback`), then clamps it to the configured range and
limits its slew (:func:`~catheter_models.feedback.limit_window`, the one rule for both).
Once the plan has run out it holds the plan's last point: the same compensator and
feedback go on commanding that bend, as ros2_controllers' trajectory controller holds its
last point, until a new plan replaces the hold or ``hold_timeout_s`` has passed. A plan that
ends at rest (straight) is not held: zero pressure is the rest, so it ramps down as before.
When a hold times out, a stop is asked for or a required sensor goes stale, it ramps the
pressure down to zero at the slew limit and goes idle: the valve driver's watchdog does the
rest.

A model fitted at one sample rate is stepped at that rate whatever the loop's rate: it reads
the plan at its own sample instants (the plan is known ahead, so it can step one sample early)
and the loop interpolates between its outputs. A 250 Hz c-LSTM in a 1 kHz loop thus sees
exactly the inputs it was trained on, and the valve gets a smooth command every millisecond
with no added lag.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from catheter_control.trajectory import TrajectoryPlan
from catheter_models.feedback import PIDFeedback
from catheter_models.limits import limit_window
from catheter_models.static_map import StaticMap


class StreamingCompensator(Protocol):
    """A feedforward compensator that carries its state from tick to tick.

    ``preview_s`` is how far ahead of now it reads the plan [s]: a model trained to see the
    set-point early covers the valve's and muscle's lag (0 for none). ``sample_period_s`` is
    the period it must be stepped at (the rate it was fitted at), or None for a stateless map
    that may be evaluated at any instant.
    """

    preview_s: float
    sample_period_s: float | None

    def reset(self) -> None:
        """Forget all state (a new run starts from rest)."""

    def step(self, angle_desired_rad: float) -> float:
        """Pressure command (gauge [Pa]) for the desired bend at this tick."""


class StaticInverseCompensator:
    """No hysteresis compensation: the inverse of the quasi-static curve (the baseline)."""

    preview_s = 0.0
    sample_period_s: float | None = None

    def __init__(self, static_map: StaticMap) -> None:
        self.static_map = static_map

    def reset(self) -> None:
        """Stateless: nothing to forget."""

    def step(self, angle_desired_rad: float) -> float:
        """Pressure on the central curve for ``angle_desired_rad``."""
        return float(self.static_map.pressure(angle_desired_rad))


@dataclass(frozen=True)
class TickOutput:
    """What one tick commands: pressure (gauge [Pa]) and the set-point in force [rad].

    While ramping down no set-point is in force (None): the plan's last point published then
    was scored as missed by whatever the ramp let the bend fall, 5 deg on a trajectory that
    ends bent, and drawn as if the loop had let it go.
    """

    pressure_pa: float
    angle_desired_rad: float | None
    state: str


class ControlCore:
    """Plan following with safety limits around a :class:`StreamingCompensator`.

    Args:
        compensator: the feedforward compensator.
        min_pressure_pa, max_pressure_pa: command range, gauge [Pa]; never left.
        max_slew_pa_per_s: command slew limit [Pa/s].
        feedback: feedback on the measured bend while following a plan or holding its last
            point (None: open loop). It acts only on samples given to :meth:`tick`; a
            ramp-down is never corrected.
        hold_timeout_s: how long the last point of a plan is held before the pressure ramps
            down [s]; 0: no hold, the ramp-down starts at the plan's end.
        rest_angle_rad, rest_band_rad: a plan whose last point is within ``rest_band_rad``
            of ``rest_angle_rad`` (straight) ends at rest: it is not held, the pressure ramps
            down at its end (zero pressure holds a straight catheter, with nothing watched).
    """

    IDLE = "idle"
    FOLLOWING = "following"
    HOLDING = "holding"
    RAMPING_DOWN = "ramping_down"

    _PHASE_TOLERANCE = 1e-6
    """Fraction of a model period below which a tick counts as on a model sample instant
    (absolute deadlines put ticks on the grid to ~1e-12 s; this only absorbs rounding)."""

    def __init__(
        self,
        compensator: StreamingCompensator,
        min_pressure_pa: float,
        max_pressure_pa: float,
        max_slew_pa_per_s: float,
        feedback: PIDFeedback | None = None,
        *,
        hold_timeout_s: float = 0.0,
        rest_angle_rad: float = 0.0,
        rest_band_rad: float = 0.0,
    ) -> None:
        if not (math.isfinite(hold_timeout_s) and hold_timeout_s >= 0.0):
            # A hold that never ends would keep the catheter bent after its client is gone.
            raise ValueError(f"hold_timeout_s must be finite and >= 0 s, got {hold_timeout_s}")
        if not 0.0 <= min_pressure_pa <= max_pressure_pa:
            raise ValueError(
                "need 0 <= min_pressure_pa <= max_pressure_pa, "
                f"got {min_pressure_pa}, {max_pressure_pa}"
            )
        period = compensator.sample_period_s
        if period is not None and not (math.isfinite(period) and period > 0.0):
            raise ValueError(f"compensator sample_period_s must be > 0 s or None, got {period}")
        self.compensator = compensator
        self.feedback = feedback
        self.min_pressure_pa = min_pressure_pa
        self.max_pressure_pa = max_pressure_pa
        self.max_slew_pa_per_s = max_slew_pa_per_s
        self.hold_timeout_s = hold_timeout_s
        self.rest_angle_rad = rest_angle_rad
        self.rest_band_rad = rest_band_rad
        self.plan: TrajectoryPlan | None = None
        self._start_s = 0.0
        self._hold_start_s = 0.0
        self._last_pa = 0.0
        self._last_target_pa = 0.0
        self._last_angle = 0.0
        # Model clock (sampled compensators): outputs at plan instants k and k + 1 periods.
        self._k = 0
        self._y0 = 0.0
        self._y1 = 0.0
        self._primed = False
        self.state = self.IDLE
        self.nonfinite_from_compensator = 0
        self.compensator_error = ""
        self.fault_reason = ""
        """Why the last run was cut short by :meth:`fault` ('' if it was not)."""
        self.model_steps = 0
        """Compensator steps taken (one per model sample, not per tick)."""
        self.ended: tuple[TrajectoryPlan, str] | None = None
        """The newest plan that stopped being followed, and why: '' when it ran to its end
        (and while its last point is held), else the reason it was cut short, or the reason
        its hold ended (timed out, stopped, a sensor went stale, replaced by a new plan). A
        plan pre-empted by :meth:`start` while it is still being followed does not end."""

    def _end(self, why: str) -> None:
        if self.state in (self.FOLLOWING, self.HOLDING) and self.plan is not None:
            self.ended = (self.plan, why)

    def _holds(self, plan: TrajectoryPlan) -> bool:
        """Whether ``plan``'s last point is held after its end (not rest, and a hold is on)."""
        off_rest_rad = abs(float(plan.angle_rad[-1]) - self.rest_angle_rad)
        return self.hold_timeout_s > 0.0 and off_rest_rad > self.rest_band_rad

    @property
    def hold_angle_rad(self) -> float | None:
        """The bend being held after a plan's end [rad], or None when not holding."""
        if self.state != self.HOLDING or self.plan is None:
            return None
        return float(self.plan.angle_rad[-1])

    def held_s(self, now_s: float) -> float:
        """How long the current hold has lasted at ``now_s`` [s] (0 when not holding)."""
        return now_s - self._hold_start_s if self.state == self.HOLDING else 0.0

    def start(self, plan: TrajectoryPlan, now_s: float) -> None:
        """Follow ``plan`` from ``now_s``; pre-empts any plan in progress.

        The compensator is reset only from rest: pre-empting mid-motion or a hold keeps its
        memory of the catheter's current state, which a hysteresis compensator needs. The new
        plan's model clock starts at the command in force, so the switch has no jump but the
        slew. Where the new plan may start is the caller's rule (the node's: at the held bend,
        or from rest once the hold is released).
        """
        if self.state == self.HOLDING:
            self._end("pre-empted by a newer trajectory while its last point was held")
        if self.state == self.IDLE:
            self.compensator.reset()
            if self.feedback is not None:
                self.feedback.reset()
            self._last_pa = 0.0
            self._last_target_pa = 0.0
            self._primed = False
            self.fault_reason = ""
        else:
            # Mid-motion: interpolate from the target in force to the new plan's next sample.
            self._y1 = self._last_target_pa
            self._primed = self.state in (self.FOLLOWING, self.HOLDING)
        self._k = -1 if self._primed else 0
        self.plan = plan
        self._start_s = now_s
        self.state = self.FOLLOWING

    def stop(self, why: str = "stopped on request; pressure ramped down") -> None:
        """Ramp down to zero pressure at the slew limit, then idle (``why`` ends the plan)."""
        self._end(why)
        if self.state != self.IDLE:
            self.state = self.RAMPING_DOWN

    def fault(self, reason: str) -> None:
        """Ramp down because something the run depends on failed (a stale sensor)."""
        self._end(reason)
        if self.state != self.IDLE:
            self.fault_reason = reason
            self.state = self.RAMPING_DOWN

    def elapsed_s(self, now_s: float) -> float:
        """Time since the current plan started [s]."""
        return now_s - self._start_s

    def _model_step(self, plan: TrajectoryPlan, at_s: float) -> float:
        """One compensator step on the plan read ``preview_s`` ahead of ``at_s``."""
        self.model_steps += 1
        return self.compensator.step(plan.desired_at(at_s + self.compensator.preview_s))

    def _target_at(self, plan: TrajectoryPlan, elapsed_s: float) -> float:
        """The compensator's pressure for plan time ``elapsed_s`` (may raise)."""
        period = self.compensator.sample_period_s
        if period is None:
            return self._model_step(plan, elapsed_s)
        if not self._primed:
            self._k = 0
            self._y0 = self._model_step(plan, 0.0)
            self._y1 = self._model_step(plan, period)
            self._primed = True
        # Step the model through every sample instant the loop has reached (several after
        # a missed deadline: the model must see its own rate, not the loop's hiccups).
        while (self._k + 1) * period <= elapsed_s + self._PHASE_TOLERANCE * period:
            self._k += 1
            self._y0 = self._y1
            self._y1 = self._model_step(plan, (self._k + 1) * period)
        phase = (elapsed_s - self._k * period) / period
        if phase <= self._PHASE_TOLERANCE:
            return self._y0
        return self._y0 + min(phase, 1.0) * (self._y1 - self._y0)

    def tick(
        self, now_s: float, dt_s: float, angle_measured_rad: float | None = None
    ) -> TickOutput | None:
        """One control tick at time ``now_s`` (``dt_s`` since the last). None when idle.

        ``angle_measured_rad`` is the newest measured bend for the feedback (None or
        non-finite: the feedback holds; the caller ramps down a stale sensor).
        """
        if self.state == self.IDLE:
            return None
        target = 0.0
        if self.state in (self.FOLLOWING, self.HOLDING) and self.plan is not None:
            elapsed = now_s - self._start_s
            if self.state == self.FOLLOWING and elapsed > self.plan.duration_s:
                self._end("")
                # Past its end the plan reads its last point: following it on is the hold.
                self.state = self.HOLDING if self._holds(self.plan) else self.RAMPING_DOWN
                self._hold_start_s = self._start_s + self.plan.duration_s
            if self.state == self.HOLDING and now_s - self._hold_start_s > self.hold_timeout_s:
                self._end(f"hold released after hold_timeout_s ({self.hold_timeout_s:g} s)")
                self.state = self.RAMPING_DOWN
            if self.state in (self.FOLLOWING, self.HOLDING):
                self._last_angle = self.plan.desired_at(elapsed)
                try:
                    target = self._target_at(self.plan, elapsed)
                except Exception as exc:
                    # A model that raises (ONNX Runtime, a refused sample) is as broken as one
                    # that returns NaN: the valve must not hold the last command.
                    self.compensator_error = f"{type(exc).__name__}: {exc}"
                    target = math.nan
                if not math.isfinite(target):
                    # A broken model must not move the catheter: ramp down and say why.
                    self.nonfinite_from_compensator += 1
                    self._end(
                        f"compensator failed ({self.compensator_error or 'non-finite pressure'})"
                    )
                    self.state = self.RAMPING_DOWN
                else:
                    self._last_target_pa = target
        if self.state == self.RAMPING_DOWN:
            target = 0.0
        floor = 0.0 if self.state == self.RAMPING_DOWN else self.min_pressure_pa
        low, high = limit_window(
            self._last_pa, floor, self.max_pressure_pa, self.max_slew_pa_per_s * dt_s
        )
        if self.state in (self.FOLLOWING, self.HOLDING) and self.feedback is not None:
            command = self.feedback.command(
                self._last_angle,
                angle_measured_rad,
                target,
                dt_s=dt_s,
                low_pa=low,
                high_pa=high,
                floor_pa=floor,
                ceiling_pa=self.max_pressure_pa,
            )
            if self.feedback.authority_fault:
                # The bend does not answer the command: stop trusting the loop.
                self.fault(self.feedback.authority_fault)
        else:
            command = min(max(target, low), high)
        self._last_pa = command
        if self.state == self.RAMPING_DOWN and command <= 0.0:
            self.state = self.IDLE
            self.plan = None
        following = self.state in (self.FOLLOWING, self.HOLDING)
        return TickOutput(command, self._last_angle if following else None, self.state)


_SILENCE = " stale: no sample for "
"""How :meth:`SensorWatch.stale` words a silence, so :func:`is_sensor_silence` can know it."""


def is_sensor_silence(reason: str) -> bool:
    """Whether a run's stop ``reason`` is a sensor that fell silent mid-run.

    Not a stream that never came (``required but none received``): that is a rig not
    publishing at all, where a second attempt would only wait as long again.
    """
    return _SILENCE in reason


class SensorWatch:
    """Ages of the sensor streams a run depends on; names the first one gone stale.

    Receipt times come from the subscription callbacks, the check from the control thread:
    single float stores, so no lock is needed.

    Args:
        required: stream names that must keep arriving (e.g. ``tip/angle``).
        timeout_s: longest gap between samples before the stream counts as stale [s].
    """

    def __init__(self, required: tuple[str, ...], timeout_s: float) -> None:
        if not timeout_s > 0.0:
            raise ValueError(f"sensor timeout must be > 0 s, got {timeout_s}")
        self.required = required
        self.timeout_s = timeout_s
        self._last_s: dict[str, float | None] = dict.fromkeys(required)
        self._longest_s: dict[str, float] = dict.fromkeys(required, 0.0)

    def seen(self, name: str, now_s: float) -> None:
        """A sample of ``name`` arrived at monotonic ``now_s``."""
        if name in self._last_s:
            last = self._last_s[name]
            if last is not None:
                self._longest_s[name] = max(self._longest_s[name], now_s - last)
            self._last_s[name] = now_s

    def take_longest_silence_s(self, name: str) -> float:
        """The longest wait between two samples of ``name`` since the previous call [s].

        The early warning: a stream that went quiet for 60 ms did not trip a 100 ms timeout,
        but says how close it came (and when, against the producer's own reports).
        """
        longest, self._longest_s[name] = self._longest_s[name], 0.0
        return longest

    def age_s(self, name: str, now_s: float) -> float:
        """Seconds since the last sample of ``name`` (inf if none yet)."""
        last = self._last_s[name]
        return math.inf if last is None else now_s - last

    def stale(self, now_s: float) -> str:
        """Why a required stream is stale, or '' when all are fresh."""
        for name in self.required:
            age = self.age_s(name, now_s)
            if age == math.inf:
                return f"{name} required but none received"
            if age > self.timeout_s:
                return f"{name}{_SILENCE}{age * 1e3:.0f} ms (limit {self.timeout_s * 1e3:.0f} ms)"
        return ""
