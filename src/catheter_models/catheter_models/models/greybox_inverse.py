"""The explained model as a compensator: the lab's chain run backwards, one sample a tick.

A grey box (:mod:`catheter_models.models.greybox`) says how pressure becomes bend:

    pressure -> [transport_delay] -> [pneumatic_lag] -> core -> [creep] -> [tip] -> [drift] -> bend

:class:`GreyBoxInverse` turns a wanted bend into the pressure to command, by running each
stage backwards (:meth:`Block.inverse`, :meth:`Core.inverse`):

* a delay is read ahead: the compensator reads the plan ``preview_s`` ahead of now, the sum
  of what each stage needs (a delay's delay, the tip's two samples of the plan's curvature);
* a lag is undone exactly, its overdrive bounded by the valve's flow limit and the pressure
  range;
* the core is searched, each tick, for the pressure whose bend is the one wanted;
* creep and an output lag are undone exactly (a stable lead), drift is subtracted, and the
  tip is pulled by the plan's own rate and acceleration so it follows without ringing.

Each tick asks every stage for its input from the bend back to the valve, bounds the command
to ``[min_pressure_pa, max_pressure_pa]`` (the node's clamp), then runs the stages forward on
that command so every state is what the plant's will be, as the model sees it. The node's
slew limit is not modelled here: bounding the command by it inside the inverse made the
lag's one-step inverse overshoot and cycle (a ramp-limited deadbeat), and what the chain
needs stays far below it on smooth plans. What the model expects the bend to be is
:attr:`GreyBoxInverse.model_bend_rad` (the feedback's residual is the catheter's departure
from it).

It is a :class:`~catheter_models.models.base.Stream`: ``step(bend_rad) -> pressure_pa``,
``reset()``, stepped at the rate the chain was fitted at. A chain holding a block without an
inverse (a block a user added without one) is refused by name.

**Which cores it inverts.** A sample-by-sample inverse needs the core's next bend to rise
with this sample's pressure. The DRDPI's identification keeps every stage increasing (its
monotone margin) and the GPI's play density is positive, so both invert to within 0.02 deg
where their rate term is moderate (tests/catheter_models/models/test_greybox_inverse.py).
A ``free_pi`` core's weights are free, and a fit may bend *more* at a lower pressure near
a reversal (negative weights on the narrowest plays), and a ``boucwen`` fit may weigh its
hysteretic state against the pressure: their inverse then jumps between branches.
:func:`invertibility_deg` measures this on the core's own response to a smooth probe, and
the constructor refuses a core that misses by more than :data:`MOST_INVERSION_MISS_DEG`,
naming the number, rather than command jumps.

**A strong rate term.** Run backwards, a rate-dependent law can run away: the inverse's
pressure widens the next sample's thresholds, which asks for more pressure
(:data:`~catheter_models.models.cores.base.MOST_RATE_LOOP_GAIN`); the inverse then runs the
law with its rate filter slowed to a stable loop gain, a law a few per cent off the fitted
one, and the probe above measures the miss that costs against the law as fitted.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np
import numpy.typing as npt

from catheter_models.contract import MAX_PRESSURE_PA
from catheter_models.errors import ParameterError
from catheter_models.models.base import check_finite_step
from catheter_models.models.blocks.base import Inverse
from catheter_models.models.cores.base import Core, CoreInverse
from catheter_models.models.greybox import GreyBox
from catheter_models.units import bar_to_pa, deg_to_rad, pa_to_bar, rad_to_deg

MOST_INVERSION_MISS_DEG: Final = 0.3
"""Largest RMS miss of a core's inverse on its own smooth response (:func:`invertibility_deg`)
that the compensator accepts. A core whose inverse jumps between branches misses by a
degree or more (a free-weight PI fitted on two sines of one frequency: 1.1 deg); an
invertible core misses by its search tolerance, plus what its inverse's slower rate filter
changes (a free-weight PI with a strong rate term on a held-out foreign plant: 0.11 deg; the
simulated rig's DRDPI: 0.15 deg), which the feedback corrects."""

PROBE_S: Final = 20.0
"""Length of the smooth probe the invertibility is measured on [s]."""


def probe_pressure_bar(rate_hz: float, low_bar: float, high_bar: float) -> npt.NDArray[np.float64]:
    """A smooth pressure over the range: two sines (0.3 and 0.7 Hz) growing in over 2 s."""
    t = np.arange(round(PROBE_S * rate_hz)) / rate_hz
    mid, span = 0.5 * (low_bar + high_bar), 0.5 * (high_bar - low_bar)
    x = mid + np.minimum(t / 2.0, 1.0) * span * (
        0.7 * np.sin(2 * np.pi * 0.3 * t) + 0.2 * np.sin(2 * np.pi * 0.7 * t + 1.0)
    )
    out: npt.NDArray[np.float64] = np.clip(x, low_bar, high_bar)
    return out


def invertibility_deg(core: Core, rate_hz: float, low_bar: float, high_bar: float) -> float:
    """RMS [deg] by which the core's inverse misses the core's own response to a smooth probe.

    The bends asked for are the core's on :func:`probe_pressure_bar`, so every one is
    reachable; the pressures the inverse gives are run through the core *as fitted*, so
    the miss holds both a search that fails and the inverse's slower rate filter
    (:data:`~catheter_models.models.cores.base.MOST_RATE_LOOP_GAIN`).
    """
    x = probe_pressure_bar(rate_hz, low_bar, high_bar)
    wanted = core.run(x, rate_hz)
    inverse = core.inverse(rate_hz, low_bar, high_bar)
    commands = np.empty_like(wanted)
    for k, target in enumerate(wanted):
        commands[k] = inverse.want(float(target))
        inverse.take(commands[k])
    got = core.run(commands, rate_hz)
    return float(np.sqrt(np.mean((got - wanted) ** 2)))


class GreyBoxInverse:
    """A fitted grey box run backwards: wanted bend [rad] in, pressure [Pa] out (see module).

    Args:
        model: A fitted :class:`GreyBox` (any core, any blocks with an inverse).
        min_pressure_pa, max_pressure_pa: The command's bounds; the core's search and the
            lag's overdrive stay inside them.

    Raises:
        ParameterError: an unfitted model, empty bounds, or a block without an inverse.
    """

    kind: Final = "greybox"

    def __init__(
        self,
        model: GreyBox,
        *,
        min_pressure_pa: float = 0.0,
        max_pressure_pa: float = MAX_PRESSURE_PA,
    ) -> None:
        if not model.fitted:
            raise ParameterError("a grey box must be fitted before it can be inverted")
        if not (
            math.isfinite(min_pressure_pa)
            and math.isfinite(max_pressure_pa)
            and 0.0 <= min_pressure_pa < max_pressure_pa
        ):
            raise ParameterError(
                f"need 0 <= min_pressure_pa < max_pressure_pa, got {min_pressure_pa}, "
                f"{max_pressure_pa}"
            )
        self.model = model
        self.min_pressure_pa = float(min_pressure_pa)
        self.max_pressure_pa = float(max_pressure_pa)
        self.sample_period_s = 1.0 / model.rate_hz_
        self.chain = model.chain
        self.reset()  # a block without an inverse is refused here, by name
        self.inversion_miss_deg = invertibility_deg(
            model.core_, model.rate_hz_, self._low_bar, self._high_bar
        )
        """RMS miss of the core's inverse on its own smooth response [deg] (measured at load)."""
        if not self.inversion_miss_deg <= MOST_INVERSION_MISS_DEG:
            raise ParameterError(
                f"the {model.core_name} core of {' -> '.join(self.chain)} cannot be inverted "
                f"sample by sample: on its own smooth response its inverse misses by "
                f"{self.inversion_miss_deg:.2f} deg RMS (at most {MOST_INVERSION_MISS_DEG} deg): "
                "the fitted law is not increasing in the pressure everywhere, or its rate term is "
                "too strong to run backwards. Refit the chain "
                "with the drdpi or gpi core (catheter-lab core MODEL drdpi), or compensate with "
                "idrdpi or clstm"
            )
        self.preview_s = sum(s.preview_s for s in (*self._inputs, *self._outputs))
        """How far ahead of now the plan must be read [s] (every stage's preview summed)."""

    def reset(self) -> None:
        """Back to rest: every stage's state as at the start of a recording."""
        m = self.model
        rate = m.rate_hz_
        self._inputs: list[Inverse]
        self._outputs: list[Inverse]
        self._inputs, self._outputs = m.inverse_stages()
        self._low_bar = float(pa_to_bar(self.min_pressure_pa))
        self._high_bar = float(pa_to_bar(self.max_pressure_pa))
        # Behind a lag the muscle refills slowly: keep it charged where the plan is out of reach.
        self._core: CoreInverse = m.core_.inverse(
            rate,
            self._low_bar,
            self._high_bar,
            bound_out_of_reach=not any(s.fills for s in self._inputs),
        )
        self.model_bend_rad = 0.0
        """The bend the model expects after the last command, on the plan's clock [rad]."""

    @property
    def core_evaluations(self) -> int:
        """Evaluations of the core's law in the last tick's search."""
        return self._core.evaluations

    def step(self, angle_desired_rad: float) -> float:
        """The pressure [Pa] to command now for the bend wanted ``preview_s`` from now."""
        target = float(rad_to_deg(check_finite_step(angle_desired_rad, "greybox inverse")))
        for stage in reversed(self._outputs):
            target = stage.want(target)
        x = self._core.want(target)
        for stage in reversed(self._inputs):
            x = stage.want(x)
        command = min(max(x, self._low_bar), self._high_bar)
        value = command
        for stage in self._inputs:
            value = stage.take(value)
        bend = self._core.take(value)
        for stage in self._outputs:
            bend = stage.take(bend)
        self.model_bend_rad = float(deg_to_rad(bend))
        return float(bar_to_pa(command))
