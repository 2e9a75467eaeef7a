"""``tip_dynamics``: the tip's inertia against its stiffness, a lightly damped bend.

One effect, one file: its form, bounds, evidence, regimes, rival and plant counterpart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import numpy as np
from numba import njit

from catheter_models.models.blocks.base import (
    MOST_TIP_DAMPING,
    Block,
    BlockParam,
    FloatArray,
    Inverse,
    Side,
    Step,
    _band_power_fraction,
)


@njit(cache=True)
def _tip_response(  # noqa: PLR0917 - numba compiles positional scalars only
    x: FloatArray,
    dt_s: float,
    omega: float,
    zeta0: float,
    growth_per_deg: float,
    n_sub: int,
    state: FloatArray,
) -> FloatArray:  # pragma: no cover - compiled; exercised through TipDynamics.apply
    """The tip's bend [deg] pulled towards ``x`` through a mass-spring whose damping grows.

    ``state`` is (bend [deg], rate [deg/s]), read at the start and left at the end, so a
    stream calls this one sample at a time. Semi-implicit Euler with the damping implicit:
    stable for any damping, and accurate while ``omega * dt_s / n_sub`` stays small (<= 0.25
    at 40 Hz with 1 ms sub-steps).
    """
    h = dt_s / n_sub
    y = state[0]
    v = state[1]
    out = np.empty_like(x)
    for i in range(x.size):
        # The bend at the sample instant, then the input held over the sample (zero-order
        # hold): the same convention at every sample rate.
        out[i] = y
        zeta = zeta0 + growth_per_deg * max(x[i], 0.0)
        for _ in range(n_sub):
            v = (v + h * omega * omega * (x[i] - y)) / (1.0 + 2.0 * zeta * omega * h)
            y += h * v
    state[0] = y
    state[1] = v
    return out


@njit(cache=True)
def _tip_columns(  # noqa: PLR0917 - numba compiles positional scalars only
    m: FloatArray, dt_s: float, omega: float, zeta: FloatArray, n_sub: int, out: FloatArray
) -> None:  # pragma: no cover - compiled; exercised through TipDynamics.apply_columns
    """:func:`_tip_response` on every column with a given damping schedule (linear then).

    Row by row, the columns innermost: the memory order of ``m``, so the loop vectorises.
    """
    h = dt_s / n_sub
    k2 = h * omega * omega
    y = m[0].copy()
    v = np.zeros(m.shape[1])
    for i in range(m.shape[0]):
        out[i] = y
        inv = 1.0 / (1.0 + 2.0 * zeta[i] * omega * h)
        row = m[i]
        for _ in range(n_sub):
            for c in range(row.size):
                v[c] = (v[c] + k2 * (row[c] - y[c])) * inv
                y[c] += h * v[c]


class TipDynamics(Block):
    """Tip inertia against bending stiffness, damped more the harder the wire pulls.

    A second-order bend pulled towards the hysteresis's (quasi-static) bend. Its damping
    ratio grows with that bend: the steer wire presses on the tube in proportion to its
    tension, so a bent tip swings against more friction than a straight one, and a tip let
    go towards straight rings freely. A fixed damping ratio cannot be right at both ends:
    fitted to the plant with a 2 Hz tip it removed 40 % of the held-out error, against 54 %
    with the growth. The plant's tip rings against a Dahl friction state whose level follows
    the muscle's pull; the block is a viscous damping that follows the bend: not the same
    form.
    """

    effect = "tip_dynamics"
    scheduled = True
    evidence_test = "abs_rate_e"
    regimes = ("fast_motion", "peak", "valley")
    plant_effect = "tip_dynamics"
    side: ClassVar[Side] = "output"
    params = (
        # A resonance is narrow: the frequency grid must be fine enough to land in its basin.
        BlockParam(
            "natural_frequency_hz",
            "Hz",
            1.0,
            40.0,
            10.0,
            "undamped natural frequency",
            grid_points=12,
        ),
        BlockParam(
            "damping_ratio",
            "1",
            0.02,
            1.5,
            0.5,
            "damping ratio with the tip straight",
            grid_points=3,
        ),
        BlockParam(
            "damping_per_rad",
            "1/rad",
            0.0,
            20.0,
            0.5,
            "growth of the damping ratio per radian of bend (wire friction grows with pull)",
            grid_points=1,
        ),
    )
    primary = "natural_frequency_hz"
    needs = "pressure steps or ramps faster than the tip's period (content above 1 Hz)"

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """A tip that does not ring (damping above :data:`MOST_TIP_DAMPING`) is a lag."""
        if values[1] > MOST_TIP_DAMPING:
            return [
                f"a damping ratio of {values[1]:.2f} does not ring (a tip rings: at most "
                f"{MOST_TIP_DAMPING:g} straight): a smooth lag, on the sensor's side or the bend's"
            ]
        return []

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The bend [deg] through the tip's mass-spring, sub-stepped at 1 ms or finer."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        state = np.array([x[0], 0.0])  # at rest on the first sample
        out: FloatArray = _tip_response(x, *self._settings(rate_hz, values), state)
        return out

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """The tip on every column, its damping scheduled by the bend entering it.

        Exactly :meth:`apply` on ``M w`` when ``reference`` is ``M w``.
        """
        dt, omega, zeta0, growth, n_sub = self._settings(rate_hz, values)
        zeta = zeta0 + growth * np.maximum(np.asarray(reference, dtype=float), 0.0)
        out = np.empty_like(m)
        _tip_columns(np.ascontiguousarray(m), dt, omega, zeta, n_sub, out)
        return out

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The tip, one sample at a time (the same compiled kernel, state carried)."""
        settings = self._settings(rate_hz, values)
        state = np.zeros(2)
        started = [False]
        sample = np.zeros(1)

        def step(x: float) -> float:
            if not started[0]:
                state[0], started[0] = x, True
            sample[0] = x
            return float(_tip_response(sample, *settings, state)[0])

        return step

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The bend to pull the tip towards so that it follows the plan without ringing."""
        return _TipInverse(rate_hz, values, self.streamer(rate_hz, values))

    @staticmethod
    def _settings(
        rate_hz: float, values: Sequence[float]
    ) -> tuple[float, float, float, float, int]:
        """(dt, omega, zeta0, growth per degree, sub-steps): sub-steps of 1 ms or finer."""
        f_hz, zeta0, growth_per_rad = values
        n_sub = max(1, math.ceil(1000.0 / rate_hz))
        return 1.0 / rate_hz, 2.0 * math.pi * f_hz, zeta0, growth_per_rad * math.pi / 180.0, n_sub

    def excitation_problem(self, inputs: Sequence[FloatArray], rate_hz: float) -> str:
        """Tip dynamics show only where the pressure moves faster than about 1 Hz."""
        share = _band_power_fraction(inputs, rate_hz, 1.0)
        if share < 0.02:
            return (
                f"only {100 * share:.1f} % of the pressure rate's power lies above 1 Hz: "
                "tip dynamics need fast steps or ramps"
            )
        return ""


class _TipInverse(Inverse):
    """The tip's mass-spring run backwards on the plan.

    ``x = y + 2 zeta y' / omega + y'' / omega^2``: the bend to pull towards, from the wanted
    bend's own rate and acceleration (the plan's, read two samples ahead), not from the
    tip's state. Inverting the sampled tip sample by sample would cancel its sampling zero
    near -1 and ring at half the sample rate; this form puts into the pull what the tip's
    inertia and damping take out, so a smooth plan excites no ringing. The pull is held
    over a sample (as :func:`_tip_response` holds its input), so it is the inverse at the
    sample's middle. The damping is scheduled by the wanted bend, as the block's by the pull
    (equal at rest). A step in the plan becomes a bounded kick: the pressure bounds cut it.
    """

    preview_s: float

    def __init__(self, rate_hz: float, values: Sequence[float], forward: Step) -> None:
        f_hz, self._zeta0, growth_per_rad = values
        self._omega = 2.0 * math.pi * f_hz
        self._growth_per_deg = growth_per_rad * math.pi / 180.0
        self._dt_s = 1.0 / rate_hz
        self.preview_s = 2.0 / rate_hz
        self._plan: list[float] = []  # the wanted bend at samples i-1 .. i+2
        self._forward = forward

    def want(self, target: float) -> float:
        """The pull for the sample two before ``target`` (the plan's newest)."""
        if not self._plan:
            self._plan = [target] * 4  # at rest before the run
        else:
            self._plan = [*self._plan[1:], target]
        before, now, nxt, after = self._plan
        dt = self._dt_s
        bend = 0.5 * (now + nxt)
        rate = (nxt - now) / dt
        accel = ((after - nxt) - (now - before)) / (2.0 * dt * dt)
        zeta = self._zeta0 + self._growth_per_deg * max(bend, 0.0)
        return bend + 2.0 * zeta * rate / self._omega + accel / (self._omega * self._omega)

    def take(self, value: float) -> float:
        """The tip's bend as the model has it, pulled by ``value``."""
        return self._forward(value)
