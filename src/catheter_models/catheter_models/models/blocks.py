"""Physical-effect blocks: the identifiable approximations of the effect catalogue (docs/lab.md).

A grey-box model is a chain: input blocks (pressure to pressure), the thesis's DRDPI
(play, rate dependence, deadband, asymmetry and saturation: the default chain), then output
blocks (bend to bend). Each block here is the *approximation* a person would write down to
identify an effect, not the plant's physics: the simulated plant fills the muscle through an
orifice (a nonlinear flow), the block is a first-order lag; the plant creeps through two
Maxwell branches in the bending stiffness, inside the force balance with the wire's friction,
the block delays a share of the bend itself through two lags. So a diagnosis that finds the
plant's effect with the block is a test of the method, not of code agreeing with itself.

Blocks work on one recording at a time, from rest, in the chain's internal units: input
blocks on pressure in bar, output blocks on bend in degrees; their parameters are SI.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import ClassVar, Final, Literal

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import signal as sps

from catheter_models.errors import ParameterError
from catheter_models.units import pa_to_bar

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

    @abstractmethod
    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The block's output for input ``x`` sampled at ``rate_hz`` with ``values``."""

    @abstractmethod
    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """``apply`` one sample at a time, from rest: ``step(x) -> y``, equal to ``apply``."""

    def excitation_problem(self, inputs: Sequence[FloatArray], rate_hz: float) -> str:
        """Why ``inputs`` (pressure, bar) cannot identify this block ('' if they can)."""
        return ""

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """Why fitted ``values`` are not this effect's physics, though the block fits them.

        A block's fit range is wide so that a search does not end at a wall; the effect it is
        named after only looks one way on a rig. A block that removes error with values the
        effect never has is standing in for something else (the valve's own response, a lag
        on the sensor's side...), and naming the effect would mislead (empty: nothing
        against it).
        """
        return []

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


def _lowpass1(x: FloatArray, rate_hz: float, time_constant_s: float) -> FloatArray:
    """Exact discretisation of a first-order lag, starting at the first sample (rest)."""
    a = math.exp(-1.0 / (rate_hz * time_constant_s))
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
    poles = np.array([math.exp(-1.0 / (rate_hz * tau)) for tau in time_constants_s])
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


@njit(cache=True)
def _fill_vent_kernel(
    x: FloatArray, dt_s: float, fill_s: float, vent_s: float, max_step: float
) -> FloatArray:
    """A first-order lag that vents at its own rate and moves at most ``max_step`` a sample."""
    out = np.empty_like(x)
    p = x[0]
    a_fill = 1.0 - math.exp(-dt_s / fill_s)
    a_vent = 1.0 - math.exp(-dt_s / vent_s)
    for k in range(x.size):
        err = x[k] - p
        dp = err * a_fill if err >= 0.0 else err * a_vent
        dp = min(max(dp, -max_step), max_step)
        p += dp
        out[k] = p
    return out


class PneumaticLag(Block):
    """Filling the tube and muscle: a first-order lag on pressure, limited by the valve's flow.

    Air fills the muscle through an orifice: near the set-point the flow is about linear in
    the pressure difference (a first-order lag), far from it the flow chokes and the pressure
    can rise no faster than the valve passes air (a slew limit); venting to the atmosphere
    runs through another pressure difference than filling from the supply, so it has its own
    time. ``vent_ratio`` = 1 and ``max_rate_pa_per_s`` at its top (no limit a step of the
    full range reaches) are the plain lag, the block's earlier form.
    """

    effect = "pneumatic_lag"
    evidence_test = "rate_cross"
    regimes = ("fast_motion", "loading", "unloading")
    plant_effect = "pneumatic_lag"
    side: ClassVar[Side] = "input"
    params = (
        BlockParam(
            "time_constant_s",
            "s",
            0.002,
            0.5,
            0.03,
            "lag of muscle behind valve (filling)",
            1e3,
            "ms",
        ),
        BlockParam(
            "vent_ratio",
            "1",
            1.0 / 3.0,
            3.0,
            1.0,
            "venting time constant over filling's",
            display_unit="x",
            grid_points=3,
            absent=1.0,
        ),
        BlockParam(
            "max_rate_pa_per_s",
            "Pa/s",
            2e5,
            1e8,
            1e8,
            "fastest the valve's flow moves the muscle's pressure (top: no limit)",
            1e-5,
            "bar/s",
            grid_points=4,
            absent=1e8,
        ),
    )
    primary = "time_constant_s"
    needs = "pressure changes of a few hundred ms or faster"
    staged_search = True
    # Before a hysteresis a lag shifts each reversal; after it, it rounds the reversal's
    # corner. Both remove much of the same error, so only the better fit tells the side.
    rival = "output_lag"

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """A lag shorter than :data:`SHORTEST_TUBE_S` both ways is the valve's own response."""
        # Filling or venting slower than a valve is the tube's: the other way may be quick
        # (a supply far above the muscle's pressure fills it fast).
        return _valve_sized(max(values[0], values[0] * values[1]), "lag", "tube and muscle fill")

    @staticmethod
    def _terms(rate_hz: float, values: Sequence[float]) -> tuple[float, float, float, float]:
        """(dt [s], fill and vent time constants [s], largest step a sample [bar])."""
        fill_s, vent_ratio, max_rate_pa_per_s = values
        dt_s = 1.0 / rate_hz
        return dt_s, fill_s, fill_s * vent_ratio, float(pa_to_bar(max_rate_pa_per_s)) * dt_s

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The muscle's pressure [bar]: the valve's through the lag."""
        dt_s, fill_s, vent_s, max_step = self._terms(rate_hz, values)
        if fill_s == vent_s and max_step * rate_hz >= PLAIN_LAG_RATE_BAR_PER_S:
            return _lowpass1(x, rate_hz, fill_s)  # the plain lag: exact and vectorised
        contiguous = np.ascontiguousarray(x, dtype=float)
        return _fill_vent_kernel(contiguous, dt_s, fill_s, vent_s, max_step)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The lag, one sample at a time."""
        dt_s, fill_s, vent_s, max_step = self._terms(rate_hz, values)
        a_fill = 1.0 - math.exp(-dt_s / fill_s)
        a_vent = 1.0 - math.exp(-dt_s / vent_s)
        state: list[float] = []

        def step(x: float) -> float:
            if not state:
                state.append(x)
                return x
            err = x - state[0]
            dp = err * a_fill if err >= 0.0 else err * a_vent
            state[0] += min(max(dp, -max_step), max_step)
            return state[0]

        return step


class TransportDelay(Block):
    """Valve dead time and pressure-wave travel as a pure delay (linear interpolation)."""

    effect = "transport_delay"
    evidence_test = "input_cross"
    regimes = ("fast_motion", "loading", "unloading")
    plant_effect = "transport_delay"
    side: ClassVar[Side] = "input"
    params = (BlockParam("delay_s", "s", 0.0, 0.2, 0.01, "dead time", 1e3, "ms"),)
    primary = "delay_s"
    needs = "pressure changes faster than the delay"
    # A dead time also stands in for a smooth lag after the core (a sensor's filter).
    rival = "output_lag"

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """A delay shorter than :data:`SHORTEST_TUBE_S` is the valve's own response."""
        return _valve_sized(values[0], "delay", "valve-to-tip dead time")

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The pressure ``delay_s`` ago (the first sample before the recording began)."""
        t = np.arange(x.size) / rate_hz
        out: FloatArray = np.interp(t - values[0], t, x, left=x[0])
        return out

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The delay, one sample at a time: the first sample and the last ``delay_s`` kept."""
        lag = values[0] * rate_hz  # in samples, fractional
        recent: deque[float] = deque(maxlen=math.ceil(lag) + 2)
        first: list[float] = []
        count = [0]

        def step(x: float) -> float:
            i = count[0]
            count[0] += 1
            recent.append(x)
            if not first:
                first.append(x)
            position = i - lag
            if position <= 0.0:
                return first[0]  # before the recording began: its first sample
            lo = math.floor(position)
            frac = position - lo
            oldest = i - len(recent) + 1  # sample index of recent[0]
            y = recent[lo - oldest]
            return y if frac == 0.0 else (1.0 - frac) * y + frac * recent[lo + 1 - oldest]

        return step


class Creep(Block):
    """Viscoelastic relaxation: a share of each bend change arrives through slow lags.

    A polymer relaxes over a spread of times, not at one: a step's creep is fast at first and
    still going long after. The block's two equal branches, ``spread`` apart around
    ``time_constant_s`` (their geometric mean), are the least form that has such a spread;
    ``spread`` = 1 is one lag, the block's earlier form.
    """

    effect = "creep"
    evidence_test = "autocorrelation"
    regimes = ("plateau",)
    plant_effect = "creep"
    side: ClassVar[Side] = "output"
    params = (
        BlockParam("fraction", "1", 0.0, 0.5, 0.05, "share of a step that creeps", 100.0, "%"),
        BlockParam("time_constant_s", "s", 0.1, 30.0, 1.5, "creep time constant"),
        BlockParam(
            "spread",
            "1",
            1.0,
            30.0,
            1.0,
            "slow branch's time constant over the fast one's",
            display_unit="x",
            absent=1.0,
        ),
    )
    # The share is what data pins down; the time constants are a compromise between the
    # real material's many.
    primary = "fraction"
    needs = "plateaus of at least a second after pressure steps"
    staged_search = True
    rival = "slow_fill"

    @staticmethod
    def _branches(values: Sequence[float]) -> tuple[float, float, float]:
        fraction, tau, spread = values
        root = math.sqrt(spread)
        return fraction, tau / root, tau * root

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The bend [deg] with ``fraction`` of every change delayed by the two slow lags."""
        fraction, fast, slow = self._branches(values)
        return _lagged(x, rate_hz, (fast, slow), fraction)

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """Creep is linear: every column at once."""
        fraction, fast, slow = self._branches(values)
        return _lagged_columns(m, rate_hz, (fast, slow), fraction)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """Creep, one sample at a time."""
        fraction, fast, slow = self._branches(values)
        lag_fast = _Lowpass1Stream(rate_hz, fast).step
        lag_slow = _Lowpass1Stream(rate_hz, slow).step
        return lambda x: (1.0 - fraction) * x + fraction * 0.5 * (lag_fast(x) + lag_slow(x))

    def excitation_problem(self, inputs: Sequence[FloatArray], rate_hz: float) -> str:
        """Creep shows only where the pressure holds still after a change."""
        # A plateau: the pressure holds within 2 % of full scale for 1 s after moving.
        window = max(2, round(rate_hz))
        for x in inputs:
            if x.size <= window:
                continue
            spread = np.lib.stride_tricks.sliding_window_view(x, window)
            flat = (spread.max(axis=1) - spread.min(axis=1)) < 0.06
            if flat.any() and float(np.ptp(x)) > 0.5:
                return ""
        return "no plateau of 1 s or longer after a pressure change: creep cannot show"


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


class Drift(Block):
    """Slow offset drift from each recording's start: a warm-up that slows to a stop.

    The offset's rate falls linearly from ``rate_rad_per_s`` to zero over ``settle_s`` and
    the offset then holds: a catheter warming towards its working temperature drifts fast at
    first and less as it nears it. A straight trend (the form before this one), fitted to
    5-minute warm-ups that settle in minutes, took 42-69 % of the initial rate and missed
    the start of every held-out recording (development plants, docs/lab.md). At the top of
    its range (10 h) this form is that straight trend over any session.
    """

    effect = "drift"
    ends_are_plain = True
    evidence_test = "time_trend"
    regimes = ("vented",)
    """Judged with the muscle vented: an offset drift (thermal, a sensor mount) shows at rest
    as much as anywhere, while a change of gain, which a drift block also half fits, cannot
    show where nothing bends. On the foreign plants at seed 2 the drift block removed 65 % of
    the vented error with an offset drift hidden and added 10-59 % with a gain drift."""
    plant_effect = "drift"
    side: ClassVar[Side] = "output"
    params = (
        BlockParam(
            "rate_rad_per_s",
            "rad/s",
            math.radians(-10.0) / 60.0,
            math.radians(10.0) / 60.0,
            0.0,
            "drift rate at the start",
            math.degrees(1.0) * 60.0,
            "deg/min",
        ),
        BlockParam(
            "settle_s",
            "s",
            60.0,
            36_000.0,
            36_000.0,
            "time the drift takes to stop",
            1.0 / 60.0,
            "min",
            absent=36_000.0,
        ),
    )
    primary = "rate_rad_per_s"
    needs = "recordings of a minute or longer"

    @staticmethod
    def offset_deg(t_s: FloatArray, values: Sequence[float]) -> FloatArray:
        """The drift [deg] at times ``t_s`` from the recording's start."""
        rate_deg_s, settle_s = math.degrees(values[0]), values[1]
        t = np.minimum(t_s, settle_s)
        out: FloatArray = rate_deg_s * (t - t * t / (2.0 * settle_s))
        return out

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The bend [deg] plus the drift from the recording's start."""
        out: FloatArray = x + self.offset_deg(np.arange(x.size) / rate_hz, values)
        return out

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """The drift is an offset: columns unchanged, the drift on the offset column."""
        out = m.copy()
        out[:, -1] += self.offset_deg(np.arange(m.shape[0]) / rate_hz, values)
        return out

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The drift, one sample at a time (counted from the first)."""
        rate_deg_s, settle_s = math.degrees(values[0]), values[1]
        count = [0]

        def step(x: float) -> float:
            t = min(count[0] / rate_hz, settle_s)
            count[0] += 1
            return x + rate_deg_s * (t - t * t / (2.0 * settle_s))

        return step

    def excitation_problem(self, inputs: Sequence[FloatArray], rate_hz: float) -> str:
        """A trend needs time to tell apart from the hysteresis."""
        longest_s = max((x.size / rate_hz for x in inputs), default=0.0)
        if longest_s < 30.0:
            return f"the longest recording lasts {longest_s:.0f} s: drift needs 30 s or more"
        return ""


class OutputLag(Block):
    """A first-order lag on the bend, after the core: not in the catalogue.

    The sensor's own filter, or a bend that follows its muscle slowly, looks like this. The
    diagnosis fits it only as the rival of :class:`PneumaticLag` and :class:`TransportDelay`
    (which side of the hysteresis the lag is on); a person may add it to a chain by hand.
    """

    effect = "output_lag"
    side: ClassVar[Side] = "output"
    stands_for = "the sensor's own filter, or a bend that follows its muscle slowly"
    params = (
        BlockParam("time_constant_s", "s", 0.002, 0.5, 0.03, "lag of bend behind core", 1e3, "ms"),
    )
    primary = "time_constant_s"
    needs = "pressure changes of a few hundred ms or faster"

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The bend [deg] through a first-order lag."""
        return _lowpass1(x, rate_hz, values[0])

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """A lag is linear: every column at once."""
        return _lagged_columns(m, rate_hz, (values[0],), 1.0)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The lag, one sample at a time."""
        return _Lowpass1Stream(rate_hz, values[0]).step


class SlowFill(Block):
    """A share of the pressure through a slow lag, before the core: not in the catalogue.

    A second chamber behind a small orifice, or a leak, fills for seconds after the muscle
    has: the bend keeps moving on a plateau as it does under creep, but the slow share
    passes through the hysteresis (its knee and saturation) rather than following the bend.
    The diagnosis fits it only as the rival of :class:`Creep` (which side of the core the
    slow part is on); a person may add it to a chain by hand.
    """

    effect = "slow_fill"
    side: ClassVar[Side] = "input"
    stands_for = "a second chamber behind a small orifice, or a leak"
    params = (
        BlockParam(
            "fraction", "1", 0.0, 0.5, 0.1, "share of the pressure that fills slowly", 100.0, "%"
        ),
        BlockParam("time_constant_s", "s", 0.1, 30.0, 1.5, "slow share's time constant"),
    )
    primary = "fraction"
    needs = "plateaus of at least a second after pressure steps"

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The pressure [bar] with ``fraction`` of it through the slow lag."""
        fraction, tau = values
        return _lagged(x, rate_hz, (tau,), fraction)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The slow fill, one sample at a time."""
        fraction, tau = values
        lag = _Lowpass1Stream(rate_hz, tau).step
        return lambda x: (1.0 - fraction) * x + fraction * lag(x)


BLOCKS: Final[Mapping[str, type[Block]]] = {
    b.effect: b for b in (TransportDelay, PneumaticLag, Creep, TipDynamics, Drift)
}
"""The catalogue: blocks by effect name, in chain order within each side. A diagnosis tries
and names these."""

CHECKS: Final[Mapping[str, type[Block]]] = {b.effect: b for b in (SlowFill, OutputLag)}
"""Forms outside the catalogue: a diagnosis fits them only as a block's :attr:`Block.rival`,
and never names them."""

FORMS: Final[Mapping[str, type[Block]]] = {**BLOCKS, **CHECKS}
"""Every block a grey-box chain can hold, in chain order within each side."""


def block(effect: str) -> Block:
    """The block of ``effect``; ParameterError names the known ones."""
    if effect in DEFAULT_CHAIN_EFFECTS:
        raise ParameterError(
            f"{effect!r} is part of the default chain (the DRDPI) already; blocks that can be "
            f"added: {', '.join(FORMS)}"
        )
    cls = FORMS.get(effect)
    if cls is None:
        raise ParameterError(
            f"unknown effect {effect!r}; blocks that can be added: {', '.join(FORMS)} "
            f"(the DRDPI carries {', '.join(DEFAULT_CHAIN_EFFECTS)})"
        )
    return cls()


def ordered(effects: Sequence[str]) -> tuple[str, ...]:
    """Effects in chain order (input blocks, then output blocks, catalogue order); checked."""
    for e in effects:
        block(e)
    if len(set(effects)) != len(effects):
        raise ParameterError(f"an effect is listed twice: {list(effects)}")
    return tuple(e for e in FORMS if e in effects)
