"""What every effect block is (:class:`Block`, :class:`BlockParam`), and the filters blocks share.

The chain's units and the bounds that decide when a fitted block is its effect's physics
(a tube's shortest lag, a tip's largest damping) are here too; see
:mod:`catheter_models.models.blocks` for the chain and the catalogue.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Final, Literal

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import signal as sps

from catheter_models.errors import ParameterError

FloatArray = npt.NDArray[np.float64]
Side = Literal["input", "output"]
Step = Callable[[float], float]
"""One sample in, one out: a block streamed (:meth:`Block.streamer`)."""

SHORTEST_TUBE_S: Final = 0.010
"""Shortest lag or dead time a tube and muscle give [s]. Rigs show 20-120 ms lags and 20-60 ms
delays (docs/lab.md); a proportional valve's own response is a few ms, and the core's
rate-dependent thresholds take that up. Half the rigs' lowest keeps real effects named."""

MOST_TIP_DAMPING: Final = 0.5
"""Largest damping ratio, with the tip straight, that still shows as a tip's ringing. Rigs show
0.05-0.15; above 0.5 a step overshoots by under 16 %, below what the laser's noise and the
hysteresis hide, and a second-order fit there is a smooth lag in disguise."""

PLAIN_LAG_RATE_BAR_PER_S: Final = 1e3
"""A pressure slew no valve command on a 0-3 bar muscle needs limiting at (a full step in
3 ms): the pneumatic lag's flow limit at or above it is no limit."""

DEFAULT_CHAIN_EFFECTS: Final = ("play", "rate_dependence", "deadband", "asymmetry", "saturation")
"""The effects the thesis's DRDPI already carries (the default chain)."""


@dataclass(frozen=True)
class BlockParam:
    """A named, bounded block parameter in SI, with how a person reads it."""

    name: str
    unit: str
    low: float
    high: float
    initial: float
    doc: str
    display_scale: float = 1.0
    display_unit: str = ""
    grid_points: int = 0
    """Points of the identification's search grid over the range (0: the grey box's default
    for a block of this many parameters)."""
    absent: float | None = None
    """The value a model saved before this parameter existed is loaded with (the block's
    earlier form); ``None``: a saved model must hold it."""
    searched: bool = True
    """Whether the identification's grid covers it; ``False``: held at ``absent`` there and
    moved by the polish only (a refinement of a form the grid has found, whose own grid
    would multiply every search's cost)."""
    plain_ends: bool = False
    """Both ends of the range are physical answers, not a sign that the block stands in for
    something else (a share between two laws that are each a real form)."""

    def display(self, value: float) -> str:
        """The value as a person reads it (e.g. ms, Hz, deg/min)."""
        unit = self.display_unit or self.unit
        return f"{value * self.display_scale:.4g} {unit}"


class Block(ABC):
    """One effect's identifiable form: ``apply`` maps a recording's signal, from rest."""

    effect: ClassVar[str]
    side: ClassVar[Side]
    params: ClassVar[tuple[BlockParam, ...]]
    primary: ClassVar[str]
    """The parameter the diagnosis reports (a time constant, a delay, a frequency...)."""
    needs: ClassVar[str]
    """What excitation identifies it, for the 'too little excitation' message."""
    staged_search: ClassVar[bool] = False
    """Search the block's earlier form first (its parameters with an ``absent`` value held
    there, on that form's grid), then the added parameters around its best points. For
    parameters that refine a form which already fits (a creep's spread, a lag's venting and
    flow limit): a joint grid as fine as the earlier form's would cost their product, and a
    coarse one misses the earlier form's own optimum. Not where the parameters trade against
    each other (a drift's settle time against its rate)."""
    stands_for: ClassVar[str] = ""
    """For a form outside the catalogue: what physical thing it stands for, in a person's
    words (said where it fits about as well as the catalogue block it rivals)."""
    rival: ClassVar[str] = ""
    """A form outside the catalogue (:data:`CHECKS`) that gives the same signature from the
    core's other side. Where it fits the held-out data clearly better, the effect is not
    where this block puts it, and the diagnosis does not name it ('': no rival)."""
    scheduled: ClassVar[bool] = False
    """Its response depends on the signal entering it (the tip's damping follows the bend), so
    a core linear in its weights and the block are solved in passes, each scheduling the block
    by the previous weights' output."""
    ends_are_plain: ClassVar[bool] = False
    """Either end of a parameter's range is a plain answer (a drift's range is symmetric), so
    a value there does not say the block stands in for something else."""
    evidence_test: ClassVar[str] = ""
    """The residual test whose signature the effect leaves (a name in
    ``residuals.TEST_NAMES``; docs/lab.md, 'where it shows'). Catalogue blocks must have one."""
    regimes: ClassVar[tuple[str, ...]] = ()
    """The regimes where the effect shows (``metrics.REGIMES`` and ``'vented'``): a block must
    help there to earn its place in a diagnosis."""
    plant_effect: ClassVar[str] = ""
    """The simulated plant's effect with the same physics (a key of ``plant.config.EFFECTS``),
    which ``catheter-lab effects`` shows beside it ('' where the plant has none)."""
    dead_time_param: ClassVar[str] = ""
    """The parameter by which the block delays the bend behind the command [s], to first order
    (a delay by its delay, a lag by its time constant); '' for a block that does not. A
    compensator reads the plan that far ahead (:meth:`GreyBox.dead_time_s`)."""

    @abstractmethod
    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The block's output for input ``x`` sampled at ``rate_hz`` with ``values``."""

    @abstractmethod
    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """``apply`` one sample at a time, from rest: ``step(x) -> y``, equal to ``apply``."""

    def excitation_problem(self, inputs: Sequence[FloatArray], rate_hz: float) -> str:
        """Why ``inputs`` (pressure, bar) cannot identify this block ('' if they can)."""
        return ""

    def refines(self, values: Sequence[float]) -> bool:
        """Whether fitted ``values`` show what the parameters that are not ``searched`` refine.

        They are held at their values while the earlier form is polished, then moved by a
        second polish only where this says the data show it (a flow limit the fill reaches,
        before its shape is refined). False by default: nothing to refine.
        """
        return False

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """Why fitted ``values`` are not this effect's physics, though the block fits them.

        A block's fit range is wide so that a search does not end at a wall; the effect it is
        named after only looks one way on a rig. A block that removes error with values the
        effect never has is standing in for something else (the valve's own response, a lag
        on the sensor's side...), and naming the effect would mislead (empty: nothing
        against it).
        """
        return []

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The block run backwards, one sample a tick (:class:`Inverse`), for a compensator.

        A block without one cannot be compensated: the grey box's compensator refuses a
        chain that holds it, naming it (NotImplementedError here).
        """
        raise NotImplementedError(f"{self.effect} has no inverse")

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """An output block on every column of ``m`` (n, k), for a core linear in its weights.

        Every output block is affine in its input for fixed parameters (the tip once its
        damping schedule is fixed by ``reference``, the signal that enters it), so
        ``B(M w) = L(M) w + B(0)``: columns get the linear part ``B(m) - B(0)``, and the
        last column (the chain's running offset) also gets ``B(0)``. The grey box then
        solves a linear core's weights exactly for any block parameters.
        """
        zero = self.apply(np.zeros(m.shape[0]), rate_hz, values)
        out = np.empty_like(m)
        for k in range(m.shape[1]):
            out[:, k] = self.apply(np.ascontiguousarray(m[:, k]), rate_hz, values) - zero
        out[:, -1] += zero
        return out

    @classmethod
    def defaults(cls) -> list[float]:
        """Initial values of the parameters, in order."""
        return [p.initial for p in cls.params]

    @classmethod
    def check(cls, values: Mapping[str, float]) -> list[float]:
        """Values by name, in order, each within its bounds (ParameterError otherwise)."""
        out = []
        for p in cls.params:
            raw = values.get(p.name, p.absent)
            if raw is None:
                raise ParameterError(f"{cls.effect}: parameter {p.name!r} is missing")
            v = float(raw)
            if not (math.isfinite(v) and p.low <= v <= p.high):
                raise ParameterError(
                    f"{cls.effect}.{p.name} = {v!r} is outside [{p.low:g}, {p.high:g}] {p.unit}"
                )
            out.append(v)
        unknown = set(values) - {p.name for p in cls.params}
        if unknown:
            raise ParameterError(f"{cls.effect} has no parameter(s) {sorted(unknown)}")
        return out


class Inverse:
    """One stage of the chain run backwards, one sample a tick.

    The compensator (:class:`~catheter_models.models.greybox_inverse.GreyBoxInverse`) asks
    every stage, from the bend back to the valve, for the input that gives the output it
    wants (:meth:`want`), bounds the valve's command, then runs the stages forward on what
    the valve will really get (:meth:`take`), so each stage's state is the plant's as the
    model sees it, also where a bound held the command back. This base is the identity: a
    stage that only reads the plan ahead (a delay) sets :attr:`preview_s` and nothing else.
    """

    preview_s: float = 0.0
    """How far ahead of the bend this stage reads the plan [s] (a delay's delay; a stage that
    needs the plan's next samples, their time)."""

    fills: bool = False
    """Whether the pressure behind this stage takes time to come back once vented (a lag):
    the core's inverse then keeps the muscle charged where the plan is out of reach
    (:class:`~catheter_models.models.cores.base.CoreInverse`)."""

    def want(self, target: float) -> float:
        """The input that makes this stage's next output ``target``."""
        return target

    def take(self, value: float) -> float:
        """Advance on the input ``value`` really applied; this stage's output."""
        return value


class LagMixInverse(Inverse):
    """The inverse of ``(1 - fraction) x + fraction * mean_k lag_k(x)`` (:func:`_lagged`).

    Each lag's next state is ``a s + (1 - a) x``, affine in this sample's ``x``, so the input
    that gives ``y`` is exact and causal:
    ``x = (y - share * sum a s) / ((1 - fraction) + share * sum (1 - a))``. A mix of lags
    has no zeros outside the unit circle (its inverse is a stable lead): nothing rings.
    """

    fills = True

    def __init__(self, rate_hz: float, time_constants_s: Sequence[float], fraction: float) -> None:
        self._poles = [math.exp(-1.0 / (rate_hz * tau)) for tau in time_constants_s]
        self._share = fraction / len(self._poles)
        self._direct = (1.0 - fraction) + self._share * sum(1.0 - a for a in self._poles)
        self._state: list[float] = []

    def want(self, target: float) -> float:
        """The input that makes the mix ``target`` now (``target`` itself at rest)."""
        if not self._state:
            return target
        held = self._share * sum(a * s for a, s in zip(self._poles, self._state, strict=True))
        return (target - held) / self._direct

    def take(self, value: float) -> float:
        """The lags advanced on ``value``; the mix."""
        if not self._state:
            self._state = [value] * len(self._poles)
            return value
        pairs = zip(self._poles, self._state, strict=True)
        self._state = [a * s + (1.0 - a) * value for a, s in pairs]
        share = (1.0 - self._share * len(self._poles)) * value
        return share + self._share * sum(self._state)


def _pole(rate_hz: float, time_constant_s: float) -> float:
    """The discrete pole of a first-order lag, exactly discretised: ``exp(-1 / (rate * tau))``."""
    return math.exp(-1.0 / (rate_hz * time_constant_s))


def _lowpass1(x: FloatArray, rate_hz: float, time_constant_s: float) -> FloatArray:
    """Exact discretisation of a first-order lag, starting at the first sample (rest)."""
    a = _pole(rate_hz, time_constant_s)
    y, _ = sps.lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])
    out: FloatArray = np.asarray(y, dtype=float)
    return out


@njit(cache=True)
def _lags_columns(
    m: FloatArray, poles: FloatArray, fraction: float, out: FloatArray
) -> None:  # pragma: no cover - compiled; exercised through Creep and OutputLag
    """``(1 - fraction) * m + fraction * mean_k lag_k(m)``, every column, each lag from rest.

    ``poles`` are the lags' discrete poles, ``exp(-1 / (rate * tau))``. Row by row, the
    columns innermost: the memory order of ``m``. ``lfilter`` along axis 0 of a row-major
    matrix strides through memory, and it took 60 % of a diagnosis step on a creep chain.
    """
    n_lags = poles.size
    state = np.empty((n_lags, m.shape[1]))
    for k in range(n_lags):
        state[k] = m[0]
    share = fraction / n_lags
    for i in range(m.shape[0]):
        row = m[i]
        for c in range(row.size):
            acc = 0.0
            for k in range(n_lags):
                a = poles[k]
                state[k, c] = a * state[k, c] + (1.0 - a) * row[c]
                acc += state[k, c]
            out[i, c] = (1.0 - fraction) * row[c] + share * acc


def _lagged_columns(
    m: FloatArray, rate_hz: float, time_constants_s: Sequence[float], fraction: float
) -> FloatArray:
    """:func:`_lags_columns` for lags given by their time constants [s]."""
    poles = np.array([_pole(rate_hz, tau) for tau in time_constants_s])
    out = np.empty_like(m)
    _lags_columns(np.ascontiguousarray(m, dtype=np.float64), poles, float(fraction), out)
    return out


def _lagged(
    x: FloatArray, rate_hz: float, time_constants_s: Sequence[float], fraction: float
) -> FloatArray:
    """:func:`_lagged_columns` on one signal: the share ``fraction`` through the lags."""
    return _lagged_columns(
        np.asarray(x, dtype=float)[:, None], rate_hz, time_constants_s, fraction
    )[:, 0]


class _Lowpass1Stream:
    """:func:`_lowpass1` one sample at a time (the first sample is the rest it starts from)."""

    def __init__(self, rate_hz: float, time_constant_s: float) -> None:
        self.a = math.exp(-1.0 / (rate_hz * time_constant_s))
        self.y: float | None = None

    def step(self, x: float) -> float:
        self.y = x if self.y is None else self.a * self.y + (1.0 - self.a) * x
        return self.y


def _band_power_fraction(inputs: Sequence[FloatArray], rate_hz: float, above_hz: float) -> float:
    """Share of the inputs' rate-signal power above ``above_hz`` (what fast effects need)."""
    total = high = 0.0
    for x in inputs:
        if x.size < 16:
            continue
        dx = np.diff(x) * rate_hz
        spec = np.abs(np.fft.rfft(dx - dx.mean())) ** 2
        f = np.fft.rfftfreq(dx.size, 1.0 / rate_hz)
        total += float(spec.sum())
        high += float(spec[f >= above_hz].sum())
    return high / total if total > 0.0 else 0.0


def _valve_sized(time_s: float, what: str, of_a_rig: str) -> list[str]:
    """Why a lag or delay of ``time_s`` is the valve's response (empty if it is not)."""
    if time_s < SHORTEST_TUBE_S:
        return [
            f"a {1e3 * time_s:.1f} ms {what} is shorter than any {of_a_rig} "
            f"({1e3 * SHORTEST_TUBE_S:.0f} ms): the valve's own response"
        ]
    return []
