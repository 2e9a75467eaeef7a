"""What every hysteresis core is, and the helpers cores share.

The :class:`Core` contract, the rate filter, BLAS on one thread, and a thesis model's
parameter table as a core (:class:`_ThesisCore`).
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Final, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt
from threadpoolctl import threadpool_limits

from catheter_models.errors import ParameterError
from catheter_models.models.base import ModelError, Recording
from catheter_models.units import bar_to_pa, deg_to_rad

FloatArray = npt.NDArray[np.float64]
Step = Callable[[float], float]
StateStep = Callable[[float, FloatArray], float]
"""Advance a core's state one sample in place: ``(pressure [bar], state) -> bend [deg]``."""

RATE_FILTER_S: Final = 0.02
"""Low-pass time constant of the rate estimate that rate-dependent thresholds use [s]."""

TENSION_REF_BAR: Final = 1.5
"""Pressure at which ``free_pi``'s play thresholds are their nominal ``r_i`` [bar] (mid-range)."""

TENSION_SCALE_MAX: Final = 2.0
"""Cap of the thresholds' growth with pressure (at twice the reference pressure)."""


P = ParamSpec("P")
R = TypeVar("R")


def one_blas_thread(func: Callable[P, R]) -> Callable[P, R]:
    """Run ``func`` with BLAS on one thread.

    The lab's matrices (tens of thousands of rows, tens to a hundred columns) gain little
    from a second BLAS thread, and OpenBLAS's threads spin while they wait: on a 2-core lab
    PC with anything else running, a free_pi fit took 58 s with two BLAS threads against
    3.4 s with one (measured beside another identification).
    """

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        with threadpool_limits(limits=1, user_api="blas"):
            return func(*args, **kwargs)

    return wrapper


POLISH_CACHE_BYTES: Final = 96 * 2**20
"""What a joint polish may keep of outputs it will ask for again [bytes]: the point being
differenced must outlive the coordinates differenced before the ones that reuse it (a
Bouc-Wen core's five shape values before its five weights: six sets of columns; 3 MB a set
for 5 minutes at 250 Hz). 0 keeps nothing: the polish as it was, for comparison
(bench/bench_polish_cache.py)."""


class _BytesLRU:
    """Arrays by key, the least recently used dropped beyond a budget of bytes."""

    def __init__(self, budget_bytes: int) -> None:
        self.budget_bytes = budget_bytes
        self._items: OrderedDict[Any, FloatArray] = OrderedDict()
        self._bytes = 0

    def get(self, key: Any) -> FloatArray | None:
        """The array kept for ``key`` (now the most recent), or None."""
        hit = self._items.get(key)
        if hit is not None:
            self._items.move_to_end(key)
        return hit

    def put(self, key: Any, value: FloatArray) -> None:
        """Keep ``value`` (read-only from now on: callers share it); with no budget, nothing.

        Beyond the budget the least recent go, but never the one just kept: a polish on hours
        of data still reuses the point it differences.
        """
        if self.budget_bytes <= 0:
            return
        value.flags.writeable = False
        old = self._items.pop(key, None)
        if old is not None:
            self._bytes -= old.nbytes
        self._items[key] = value
        self._bytes += value.nbytes
        while self._bytes > self.budget_bytes and len(self._items) > 1:
            _, dropped = self._items.popitem(last=False)
            self._bytes -= dropped.nbytes


def _alpha(rate_hz: float, tau_s: float = RATE_FILTER_S) -> float:
    return 1.0 - math.exp(-1.0 / (rate_hz * tau_s))


class Core(ABC):
    """A hysteresis law from pressure [bar] to bend [deg], fitted from data."""

    name: ClassVar[str]
    summary: ClassVar[str]
    linear: ClassVar[bool] = False
    """True when the output is linear in the weights for fixed structure parameters: the
    grey box then refits it exactly by least squares inside every block search."""

    @abstractmethod
    def settings(self) -> dict[str, Any]:
        """The structure (not the fitted values), as the model file stores it."""

    @abstractmethod
    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """Identify from scratch on pressure [bar] and bend [deg] recordings."""

    @abstractmethod
    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] for pressure ``x`` [bar] from rest."""

    @abstractmethod
    def stepper(
        self, rate_hz: float, *, lagged_rate: bool = False, rate_alpha: float | None = None
    ) -> tuple[FloatArray, StateStep]:
        """A state at rest, and the step that advances any such state by one sample.

        The state is a plain array, so a copy of it is a snapshot: the compensator tries
        pressures on copies (:class:`CoreInverse`) and advances the real one once.

        ``lagged_rate``: the law's rate term (rate-dependent thresholds, a viscous term) reads
        the pressure's filtered rate as it was before this sample, the state still learning
        this sample's rate. The law is then the same but for one sample (4 ms at 250 Hz) of
        its rate filter's 20 ms, and this sample's bend rises with this sample's pressure.
        With the rate read now, a threshold that widens faster with the pressure than the
        pressure itself moves (rate factor above the filter's time constant, as fitted on
        the foreign plants) makes the bend *fall* as this sample's pressure rises: a zero in
        the right half-plane, which no stable inverse can cancel (the IDRDPI's answer, eq.
        9.19, is the same: thresholds on a rate known before the sample).

        ``rate_alpha``: the rate filter's factor per sample instead of the law's own (the
        inverse's, :meth:`inverse`).
        """

    def rate_term(self, rate_hz: float) -> tuple[float, float]:
        """(How much the law's output leans on the pressure's rate [s], its filter's factor).

        The rate gain is the rate-dependent thresholds' factor (seconds of rate per bar of
        threshold), or a viscous term over the static slope; 0 for a rate-independent law.
        """
        return 0.0, 1.0

    def streamer(self, rate_hz: float) -> Step:
        """``run`` one sample at a time, equal to it."""
        state, advance = self.stepper(rate_hz)
        return lambda x: advance(x, state)

    def inverse(
        self, rate_hz: float, low_bar: float, high_bar: float, *, bound_out_of_reach: bool = True
    ) -> CoreInverse:
        """The law run backwards, one sample a tick: the pressure for the bend wanted.

        ``bound_out_of_reach``: see :class:`CoreInverse`.
        """
        gain_s, alpha = self.rate_term(rate_hz)
        loop_gain = gain_s * alpha * rate_hz
        slower = None
        if loop_gain > MOST_RATE_LOOP_GAIN:
            slower = MOST_RATE_LOOP_GAIN / (gain_s * rate_hz)
        state, advance = self.stepper(rate_hz, lagged_rate=True, rate_alpha=slower)
        return CoreInverse(state, advance, low_bar, high_bar, bound_out_of_reach=bound_out_of_reach)

    @abstractmethod
    def values(self) -> dict[str, Any]:
        """The fitted values, JSON-ready."""

    @abstractmethod
    def load_values(self, values: Mapping[str, Any]) -> None:
        """Set fitted values read from a model file (ModelError if malformed)."""

    @property
    @abstractmethod
    def fitted(self) -> bool:
        """Whether the core has values."""

    def copy(self) -> Core:
        """An independent copy with the same structure and values."""
        new = type(self)(**self.settings())
        if self.fitted:
            new.load_values(self.values())
        return new

    # Nonlinear cores are polished jointly with the blocks over a bounded vector.
    def vector(self) -> FloatArray:
        """The values as a vector for a joint least-squares polish."""
        raise NotImplementedError

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Lower and upper bounds of :meth:`vector`."""
        raise NotImplementedError

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """A function running the core with vector ``v`` (None if ``v`` is not admissible)."""
        raise NotImplementedError

    def set_vector(self, v: FloatArray) -> None:
        """Adopt the polished vector ``v``."""
        raise NotImplementedError

    def polish_runners(
        self, rate_hz: float
    ) -> Callable[[FloatArray], Callable[[FloatArray], FloatArray] | None]:
        """:meth:`runner` for the many nearby vectors of one joint polish.

        A polish's finite differences move one coordinate at a time; a core may keep, for
        the polish's duration, what does not depend on the coordinate moved (the Bouc-Wen
        state does not depend on the output weights). Outputs must equal :meth:`runner`'s.
        """
        return lambda v: self.runner(v, rate_hz)


CHARGE_SLACK_DEG: Final = 0.01
"""How far above the least bend the law gives a muscle kept charged may hold it [deg]
(:meth:`CoreInverse._charged`): a fifth of the quietest laser's noise, and enough to find
the top of a flat stretch in a few evaluations."""
CHARGE_GRID: Final = 13
"""Pressures across the range on which :meth:`CoreInverse._charged` looks for the least bend
(0.25 bar apart on a 3 bar range)."""

MOST_RATE_LOOP_GAIN: Final = 0.7
"""Largest ``gain * alpha * rate`` of a law's rate term that its inverse runs as fitted.

Run backwards, a rate term reads this sample's pressure in the next sample's thresholds; a
pressure that must rise widens them, so the next must rise more. The pressure's deviations
then follow ``z^2 - c z + c`` (``c`` this loop gain): they decay for ``c < 1`` and grow
beyond it. A free-weight PI fitted on a held-out foreign plant had ``c = 1.47`` and its inverse
ran away on the first slow rise out of the deadband (5-6 deg RMSE against its own model on
the thesis trajectories); with the inverse's rate filter slowed to ``c = 0.7``, 0.04-0.43 deg.
Above it, the inverse's rate filter is slowed to this gain (``|z| = 0.84``), a law 5 % off
the fitted one on the DRDPI of the simulated rig (``c = 0.68``: unchanged)."""


class CoreInverse:
    """A hysteresis core run backwards: each tick, the pressure whose next bend is the one wanted.

    One law for every core, exact for the law as fitted but for its rate term read one sample
    late (:meth:`Core.stepper`, ``lagged_rate``; a tension-grown friction, a Bouc-Wen state
    as they are): a bounded search over this sample's pressure
    on a copy of the core's state, then the real state advanced once on the pressure the
    valve will get (:meth:`take`). A hysteresis law's next output does not fall as its input
    rises (from the same state), so the pressure is bracketed from the last one outwards and
    found by the Illinois method (regula falsi that halves a stale end: it converges
    superlinearly and never leaves the bracket). A bend the law cannot reach within
    ``[low_bar, high_bar]`` gets the nearer bound (below every bend the law gives, the
    lowest pressure; above, the highest), unless ``bound_out_of_reach`` is off; then a bend
    below the law's reach keeps the muscle charged (:meth:`_charged`): the highest
    pressure whose bend is within :data:`CHARGE_SLACK_DEG` of the least the law gives,
    held while it stays within twice the slack. Where a
    fit is flat at the vented end, the two differ: that pressure is the top of the flat
    stretch, where the muscle is charged for the next rise at no cost to the bend, as the
    model sees it. On a catheter
    whose unloading goes on below where the fit flattens, that held it 0.2 deg above its
    vented rest through every valley of a plan below the rest (the ``maxwell_slip_delay``
    plant of tests/support: 0.58 bar, where it rests at 0.97 deg, vented at 0.81): there
    the bound is right, since a muscle never bends less for less pressure. Behind a
    pneumatic lag the charge is worth keeping: venting it costs the refill through the
    lag when the plan rises again (the greybox bench's Maxwell-slip case with a lag, seed 1:
    0.32 -> 0.72 deg on the up chirp vented), so the grey box's inverse turns the bound off
    where its chain fills through a lag
    (:attr:`~catheter_models.models.blocks.base.Inverse.fills`).
    Where a rate term makes the law not monotone within a sample, the search still returns
    a pressure inside the bracket.

    The analytic inverses (the thesis's inverse PI, eqs. 9.2-9.11) invert a
    rate-independent law, or a rate-dependent one on the bend's rate instead of the
    pressure's; this inverts each core exactly at about 10 evaluations of one sample
    (bench/bench_greybox_compensator.py times it against the c-LSTM's step).
    """

    TOLERANCE_DEG = 1e-4
    """A bend this close to the one wanted is found (far below any laser's resolution)."""
    TOLERANCE_BAR = 1e-6
    """A bracket this narrow is the answer (0.1 Pa)."""
    MAX_EVALUATIONS = 60

    def __init__(
        self,
        state: FloatArray,
        advance: StateStep,
        low_bar: float,
        high_bar: float,
        *,
        bound_out_of_reach: bool = True,
    ) -> None:
        if not (math.isfinite(low_bar) and math.isfinite(high_bar) and low_bar < high_bar):
            raise ParameterError(f"a core's inverse needs low < high, got [{low_bar}, {high_bar}]")
        self._state, self._advance = state, advance
        self._scratch = state.copy()
        self.low_bar, self.high_bar = float(low_bar), float(high_bar)
        self._last = float(low_bar)
        self._closest = (float(low_bar), math.inf)
        self.bound_out_of_reach = bound_out_of_reach
        """A bend out of the law's reach gets the nearer bound (else the closest pressure)."""
        self.evaluations = 0
        """Evaluations of the law by the last :meth:`want` (what a tick costs)."""

    def _bend(self, x: float) -> float:
        np.copyto(self._scratch, self._state)
        self.evaluations += 1
        return self._advance(x, self._scratch)

    def want(self, target_deg: float) -> float:
        """The pressure [bar] within the bounds whose bend is ``target_deg`` (or the bound)."""
        self.evaluations = 0
        lo, hi = self.low_bar, self.high_bar
        x = min(max(self._last, lo), hi)
        bend_x = self._bend(x)
        fx = bend_x - target_deg
        if abs(fx) <= self.TOLERANCE_DEG:
            return x
        # The way the bend must go first; then the other way, for a fitted law that is not
        # monotone (a free-weight PI can bend more at a lower pressure): the crossing
        # nearest the last pressure wins.
        first = 1.0 if fx < 0.0 else -1.0
        best_x, best_f = x, fx
        for direction in (first, -first):
            found = self._bracket(x, fx, direction, target_deg)
            if isinstance(found, float):
                return found
            if found is not None:
                return self._illinois(*found, target_deg)
            if abs(self._closest[1]) < abs(best_f):
                best_x, best_f = self._closest
        # No crossing from here to either bound: every bend seen lies on the side of fx.
        if self.bound_out_of_reach:
            return lo if fx > 0.0 else hi
        if fx > 0.0:
            return self._charged(x, bend_x)
        return best_x

    def _charged(self, last: float, last_bend: float) -> float:
        """The highest pressure [bar] whose bend is within the slack of the least bend.

        ``last`` is the last pressure (within the bounds) and ``last_bend`` its bend from
        this state, as :meth:`want` already found them.

        Not the pressure whose bend came closest during the search: in a flat stretch that
        depends on the search's path and jumped, tick to tick, between the vented end and
        0.7 bar (a free-weight PI fitted behind the ``maxwell_slip_lag`` plant's lag), and
        the lag's inverse turned each jump into a burst of the valve to a bound (344-406
        feedforward steps of over 0.5 bar on a thesis trajectory; 4-41 now). The least
        bend is found on a grid of :data:`CHARGE_GRID` pressures (the law may dip below its
        vented bend near the knee), then the edge above it by the Illinois method; the last
        pressure is kept while its bend stays within twice the slack, since the edge moves a
        little with the core's state every tick.
        """
        lo, hi = self.low_bar, self.high_bar
        grid = [lo + (hi - lo) * i / (CHARGE_GRID - 1) for i in range(CHARGE_GRID)]
        bends = [self._bend(x) for x in grid]
        least = min(range(CHARGE_GRID), key=bends.__getitem__)
        edge = bends[least] + CHARGE_SLACK_DEG
        if last_bend <= edge + CHARGE_SLACK_DEG:
            return last  # held: chasing an edge that moves with the state bursts the valve
        for i in range(least + 1, CHARGE_GRID):
            if bends[i] > edge:
                a, b = grid[i - 1], grid[i]
                return self._illinois(a, bends[i - 1] - edge, b, bends[i] - edge, edge)
        return hi

    def _bracket(
        self, x: float, fx: float, direction: float, target_deg: float
    ) -> float | tuple[float, float, float, float] | None:
        """From ``x`` in ``direction``, in steps growing fourfold, to a sign change.

        A float: a pressure within tolerance; a tuple: the bracket (a, fa, b, fb); None: a
        bound reached without a crossing (the closest point seen is kept in ``_closest``).
        """
        lo, hi = self.low_bar, self.high_bar
        step = 0.02
        a, fa = x, fx
        self._closest = (x, fx)
        while True:
            b = min(a + step, hi) if direction > 0.0 else max(a - step, lo)
            if b == a:
                return None
            fb = self._bend(b) - target_deg
            if abs(fb) <= self.TOLERANCE_DEG:
                return b
            if abs(fb) < abs(self._closest[1]):
                self._closest = (b, fb)
            if (fb > 0.0) != (fa > 0.0):
                return (a, fa, b, fb)
            a, fa, step = b, fb, step * 4.0

    def _illinois(self, a: float, fa: float, b: float, fb: float, target_deg: float) -> float:
        """The crossing within the bracket [a, b] by the Illinois method."""
        while self.evaluations < self.MAX_EVALUATIONS and abs(b - a) > self.TOLERANCE_BAR:
            c = b - fb * (b - a) / (fb - fa)
            fc = self._bend(c) - target_deg
            if abs(fc) <= self.TOLERANCE_DEG:
                return c
            if (fc > 0.0) != (fb > 0.0):
                a, fa = b, fb
            else:
                fa *= 0.5  # Illinois: the end that stays is halved, so it cannot stall
            b, fb = c, fc
        return b

    def take(self, x_bar: float) -> float:
        """The bend [deg] after the pressure ``x_bar``; the core's state advances."""
        self._last = x_bar
        return self._advance(x_bar, self._state)


def _recordings(xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float) -> list[Any]:
    """The chain's bar/deg arrays as SI Recordings, for a thesis model's own identification."""
    return [
        Recording(f"r{i}", rate_hz, bar_to_pa(x), deg_to_rad(y))
        for i, (x, y) in enumerate(zip(xs, ys, strict=True))
    ]


class _ThesisCore(Core):
    """A core whose parameters are a thesis model's parameter table (DRDPI, GPI).

    The table's own ``to_dict``/``from_dict`` are what the model file holds.
    """

    params: Any = None

    @abstractmethod
    def _params_type(self) -> Any:
        """The parameter table's class."""

    @property
    def fitted(self) -> bool:
        """Whether parameters are set."""
        return self.params is not None

    def set_params(self, params: Any) -> None:
        """Adopt a parameter table (e.g. a fitted thesis model's)."""
        self.params = params

    def values(self) -> dict[str, Any]:
        """The table's parameters by name."""
        if self.params is None:
            raise ModelError(f"{self.name} core is not fitted")
        out: dict[str, Any] = self.params.to_dict()
        return out

    def load_values(self, values: Mapping[str, Any]) -> None:
        """The table's parameters from a model file."""
        try:
            self.set_params(self._params_type().from_dict(dict(values)))
        except (KeyError, TypeError, ValueError, ParameterError) as exc:
            raise ModelError(f"{self.name} core values are malformed: {exc}") from None
