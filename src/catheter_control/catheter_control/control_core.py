"""The compensator's tick, without ROS: trajectory in, safe pressure command out.

Every tick takes the desired bend at the current time, asks the streaming compensator for a
pressure, then clamps it to the configured range and limits its slew. Once the plan has run
out (or a stop was asked for) it ramps the pressure down to zero at the slew limit and goes
idle: the valve driver's watchdog does the rest.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

from catheter_control.trajectory import TrajectoryPlan
from catheter_models.static_map import StaticMap


class StreamingCompensator(Protocol):
    """A feedforward compensator that carries its state from tick to tick.

    ``preview_s`` is how far ahead of now it reads the plan [s]: a model trained to see the
    set-point early covers the valve's and muscle's lag (0 for none).
    """

    preview_s: float

    def reset(self) -> None:
        """Forget all state (a new run starts from rest)."""

    def step(self, angle_desired_rad: float) -> float:
        """Pressure command (gauge [Pa]) for the desired bend at this tick."""


class StaticInverseCompensator:
    """No hysteresis compensation: the inverse of the quasi-static curve (the baseline)."""

    preview_s = 0.0

    def __init__(self, static_map: StaticMap) -> None:
        self.static_map = static_map

    def reset(self) -> None:
        """Stateless: nothing to forget."""

    def step(self, angle_desired_rad: float) -> float:
        """Pressure on the central curve for ``angle_desired_rad``."""
        return float(self.static_map.pressure(angle_desired_rad))


@dataclass(frozen=True)
class TickOutput:
    """What one tick commands: pressure (gauge [Pa]) and the set-point in force [rad]."""

    pressure_pa: float
    angle_desired_rad: float
    state: str


class ControlCore:
    """Plan following with safety limits around a :class:`StreamingCompensator`.

    Args:
        compensator: the feedforward compensator.
        min_pressure_pa, max_pressure_pa: command range, gauge [Pa]; never left.
        max_slew_pa_per_s: command slew limit [Pa/s].
    """

    IDLE = "idle"
    FOLLOWING = "following"
    RAMPING_DOWN = "ramping_down"

    def __init__(
        self,
        compensator: StreamingCompensator,
        min_pressure_pa: float,
        max_pressure_pa: float,
        max_slew_pa_per_s: float,
    ) -> None:
        if not 0.0 <= min_pressure_pa <= max_pressure_pa:
            raise ValueError(
                "need 0 <= min_pressure_pa <= max_pressure_pa, "
                f"got {min_pressure_pa}, {max_pressure_pa}"
            )
        self.compensator = compensator
        self.min_pressure_pa = min_pressure_pa
        self.max_pressure_pa = max_pressure_pa
        self.max_slew_pa_per_s = max_slew_pa_per_s
        self.plan: TrajectoryPlan | None = None
        self._start_s = 0.0
        self._last_pa = 0.0
        self._last_angle = 0.0
        self.state = self.IDLE
        self.nonfinite_from_compensator = 0
        self.compensator_error = ""

    def start(self, plan: TrajectoryPlan, now_s: float) -> None:
        """Follow ``plan`` from ``now_s``; pre-empts any plan in progress.

        The compensator is reset only from rest: pre-empting mid-motion keeps its memory of
        the catheter's current state, which a hysteresis compensator needs.
        """
        if self.state == self.IDLE:
            self.compensator.reset()
            self._last_pa = 0.0
        self.plan = plan
        self._start_s = now_s
        self.state = self.FOLLOWING

    def stop(self) -> None:
        """Ramp down to zero pressure at the slew limit, then idle."""
        if self.state != self.IDLE:
            self.state = self.RAMPING_DOWN

    def elapsed_s(self, now_s: float) -> float:
        """Time since the current plan started [s]."""
        return now_s - self._start_s

    def tick(self, now_s: float, dt_s: float) -> TickOutput | None:
        """One control tick at time ``now_s`` (``dt_s`` since the last). None when idle."""
        if self.state == self.IDLE:
            return None
        target = 0.0
        if self.state == self.FOLLOWING and self.plan is not None:
            elapsed = now_s - self._start_s
            if elapsed > self.plan.duration_s:
                self.state = self.RAMPING_DOWN
            else:
                self._last_angle = self.plan.desired_at(elapsed)
                preview_s = self.compensator.preview_s
                ahead = self.plan.desired_at(elapsed + preview_s) if preview_s else self._last_angle
                try:
                    target = self.compensator.step(ahead)
                except Exception as exc:
                    # A model that raises (ONNX Runtime, a refused sample) is as broken as one
                    # that returns NaN: the valve must not hold the last command.
                    self.compensator_error = f"{type(exc).__name__}: {exc}"
                    target = math.nan
                if not math.isfinite(target):
                    # A broken model must not move the catheter: ramp down and say why.
                    self.nonfinite_from_compensator += 1
                    self.state = self.RAMPING_DOWN
        if self.state == self.RAMPING_DOWN:
            target = 0.0
        floor = 0.0 if self.state == self.RAMPING_DOWN else self.min_pressure_pa
        target = min(max(target, floor), self.max_pressure_pa)
        step = self.max_slew_pa_per_s * dt_s
        command = min(max(target, self._last_pa - step), self._last_pa + step)
        self._last_pa = command
        if self.state == self.RAMPING_DOWN and command <= 0.0:
            self.state = self.IDLE
            self.plan = None
        return TickOutput(command, self._last_angle, self.state)
