"""Probes a person at a rig would run on a foreign plant: holds, ramps, steps and sines, and
the read-outs of their responses (a loop's width, a step's mean time).

Shared by the plant tests that read a bend without noise (``bend_without_noise``).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

RATE_HZ = 250.0
DT_S = 1.0 / RATE_HZ
BAR = 1.0e5


class NoiseFreePlant(Protocol):
    def bend_without_noise(
        self, pressure_command_pa: np.ndarray, rate_hz: float, effects: Sequence[object] = ()
    ) -> np.ndarray: ...


def hold(pressure_pa: float, duration_s: float) -> np.ndarray:
    return np.full(round(duration_s * RATE_HZ), pressure_pa)


def ramp(p0_pa: float, p1_pa: float, duration_s: float) -> np.ndarray:
    return np.linspace(p0_pa, p1_pa, round(duration_s * RATE_HZ), endpoint=False)


def step_command(
    p0_pa: float, p1_pa: float, before_s: float = 1.5, after_s: float = 2.0
) -> tuple[np.ndarray, int]:
    """Approach p0 in the step's direction (no friction reversal at the step), hold, step.

    Returns the command and the index of the first sample at p1.
    """
    overshoot = -0.3 * BAR if p1_pa > p0_pa else 0.3 * BAR
    parts = [
        ramp(0.0, p0_pa + overshoot, 2.0),
        ramp(p0_pa + overshoot, p0_pa, 0.5),
        hold(p0_pa, before_s),
    ]
    k = sum(len(x) for x in parts)
    return np.concatenate([*parts, hold(p1_pa, after_s)]), k


def sine_command(
    f_hz: float, cycles: int, low_pa: float = 0.5 * BAR, high_pa: float = 2.5 * BAR
) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, cycles / f_hz, DT_S)
    mid, amp = 0.5 * (low_pa + high_pa), 0.5 * (high_pa - low_pa)
    return t, mid - amp * np.cos(2.0 * np.pi * f_hz * t)


def loop_width_deg(plant: NoiseFreePlant, f_hz: float, effects: Sequence[object] = ()) -> float:
    """Unloading minus loading bend at mid pressure, on the last of three sine cycles."""
    t, cmd = sine_command(f_hz, 3)
    bend = plant.bend_without_noise(cmd, RATE_HZ, effects)
    last = t >= 2.0 / f_hz
    phase = (t[last] * f_hz) % 1.0
    c, y = cmd[last], bend[last]
    up, down = phase < 0.5, phase >= 0.5
    mid = 1.5 * BAR
    y_up = np.interp(mid, c[up], y[up])
    order = np.argsort(c[down])
    y_down = np.interp(mid, c[down][order], y[down][order])
    return math.degrees(y_down - y_up)


def mean_time_s(bend: np.ndarray, k: int, window_s: float) -> float:
    """Area above the normalised step response from sample k (its mean delay) [s]."""
    before = bend[k - 1]
    seg = bend[k : k + round(window_s * RATE_HZ)]
    final = np.mean(seg[-round(0.1 * RATE_HZ) :])
    r = (seg - before) / (final - before)
    return float(np.sum(1.0 - r) * DT_S)
