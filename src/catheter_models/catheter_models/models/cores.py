"""Hysteresis cores: the law at the middle of a grey-box chain, which the lab can change.

The thesis's DRDPI fixes play, rate dependence, deadband, asymmetry and saturation in one
parametric shape (exponentially decaying play weights on evenly spaced thresholds, a knee
of deadband operators after them). A real catheter's loops need not have that shape, and a
core of the wrong shape absorbs add-on effects (its rate-dependent thresholds make it late as
a lag does) and leaves an error as large as the effect to be found. So the core is a choice:

``drdpi``
    The thesis's DRDPI (ch. 5), identified by its global search: 12 parameters.
``free_pi``
    A Prandtl-Ishlinskii operator with free weights on a grid of play thresholds, applied to
    the pressure shifted by a grid of opening pressures, ``y = c + sum_ij w_ij
    Φ_{r_i g(p) + β|ṡ_j|}[max(p - d_j, 0)]``: the knee, the loop's width and shape at each
    pressure, saturation (negative weights at high d_j) and asymmetry are all learnt, by
    linear least squares for each rate factor β and tension share γ. The thresholds scale
    with the pressure above an onset ``p_0``, ``g(p) = 1 - γ + γ (p - p_0)⁺ / (p_ref - p_0)``:
    the wire's friction in the sheath grows with its tension (the capstan effect), and the
    muscle pulls only above its opening pressure, so a vented muscle lets the tip come home
    while a pulled one holds it. With γ = 0 every loop is as wide at rest as under load,
    and the model keeps a residual bend after vents that depends on the last excursion
    (on two foreign plants that was most of the held-out error with nothing hidden). The
    loop shape is otherwise free; the laws it can form are those with the wiping-out
    property (Preisach-like).
``boucwen``
    A Bouc-Wen differential hysteresis on a smooth-knee pressure, ``dz = ṡ - b|ṡ||z|^(n-1)z -
    g ṡ|z|^n``, ``y = c0 + c1 s + c2 z + c3 s²``: smooth loops whose width saturates, with a
    hysteretic state that a play grid only approximates.

Cores work in the chain's internal units (pressure in bar in, bend in degrees out). A core
whose output is linear in its weights (``free_pi``) is refitted exactly inside every block
search (variable projection): with a block's time constant on a grid, the core is solved
again at each point, so an effect the core could mimic is still found where it belongs.
"""

from __future__ import annotations

import functools
import math
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Final, ParamSpec, TypeVar

import numpy as np
import numpy.typing as npt
from numba import njit
from scipy import optimize
from threadpoolctl import threadpool_limits

from catheter_models.errors import ParameterError
from catheter_models.hysteresis.operators import play_step
from catheter_models.models.base import ModelError

FloatArray = npt.NDArray[np.float64]
Step = Callable[[float], float]

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
    def streamer(self, rate_hz: float) -> Step:
        """``run`` one sample at a time, equal to it."""

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


# ------------------------------------------------------------------------------------------
# free_pi: plays on a grid of thresholds and opening pressures, free weights
# ------------------------------------------------------------------------------------------


@njit(cache=True)
def _free_pi_kernel(  # noqa: PLR0917 - numba compiles positional arguments only
    x: FloatArray,
    offsets: FloatArray,
    thresholds: FloatArray,
    beta_s: float,
    alpha: float,
    rate_hz: float,
    tension_share: float,
    tension_onset_bar: float,
    state: FloatArray,
    weights: FloatArray,
    features: FloatArray,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled; exercised through FreePI
    """Plays on ``max(x - d_j, 0)`` with thresholds ``r_i g(x) + beta |rate_j|``.

    ``g(x) = 1 - share + share * min((x - onset)⁺ / (TENSION_REF_BAR - onset), TENSION_SCALE_MAX)``.

    ``state`` = (previous s_j, rate_j, started flag, plays j*I+i); ``features`` (n, J*I) is
    filled when it has rows, ``out`` (n,) with ``weights @ features + weights[-1]`` when
    ``weights`` is non-empty.
    """
    n_off = offsets.size
    n_thr = thresholds.size
    plays = 2 * n_off + 1
    keep = features.shape[0] > 0
    total = weights.size > 0
    for k in range(x.size):
        acc = 0.0
        tension = min(
            max(x[k] - tension_onset_bar, 0.0) / (TENSION_REF_BAR - tension_onset_bar),
            TENSION_SCALE_MAX,
        )
        scale = 1.0 - tension_share + tension_share * tension
        for j in range(n_off):
            s = x[k] - offsets[j]
            s = max(s, 0.0)
            if state[2 * n_off] == 0.0:
                state[j] = s
            rate = state[n_off + j] + alpha * ((s - state[j]) * rate_hz - state[n_off + j])
            state[j] = s
            state[n_off + j] = rate
            speed = abs(rate)
            for i in range(n_thr):
                at = plays + j * n_thr + i
                th = thresholds[i] * scale + beta_s * speed
                v = play_step(s, th, state[at])
                state[at] = v
                if keep:
                    features[k, j * n_thr + i] = v
                if total:
                    acc += weights[j * n_thr + i] * v
        state[2 * n_off] = 1.0
        if total:
            out[k] = acc + weights[n_off * n_thr]


class FreePI(Core):
    """Plays on a grid of thresholds and opening pressures with free weights (see module).

    Args:
        max_pressure_bar: Highest opening pressure of the grid [bar].
        n_offsets: Opening pressures from 0 to ``max_pressure_bar``.
        thresholds_bar: Play thresholds [bar] (0 is the plain shifted ramp).
        betas_s: Rate factors tried [s]; the best on training data is kept.
        tension_shares: Shares γ of the thresholds that grow with the pressure (the
            capstan effect; 0: fixed thresholds).
        tension_onsets_bar: Pressures p_0 above which the thresholds grow [bar] (below
            :data:`TENSION_REF_BAR`); with the shares, searched at the rate factor that is
            best with fixed thresholds, then the rate factor again.
        ridge: Tikhonov weight relative to the design's mean square (keeps weights of
            columns the data barely excites small).
    """

    name = "free_pi"
    summary = (
        "Prandtl-Ishlinskii plays with free weights on a grid of thresholds and opening "
        "pressures (knee, loop shape, saturation and asymmetry learnt; friction that grows "
        "with the wire's tension)"
    )
    linear = True

    def __init__(
        self,
        *,
        max_pressure_bar: float = 2.6,
        n_offsets: int = 14,
        thresholds_bar: Sequence[float] = (0.0, 0.03, 0.07, 0.12, 0.2, 0.3, 0.45, 0.65),
        betas_s: Sequence[float] = (0.0, 0.01, 0.02, 0.035, 0.05, 0.08),
        tension_shares: Sequence[float] = (0.0, 0.5, 0.8, 0.95),
        tension_onsets_bar: Sequence[float] = (0.0, 0.4, 0.8),
        ridge: float = 1e-6,
    ) -> None:
        if not (max_pressure_bar > 0.0 and 2 <= n_offsets <= 60):
            raise ParameterError("free_pi needs max_pressure_bar > 0 and 2-60 offsets")
        if not thresholds_bar or min(thresholds_bar) < 0.0:
            raise ParameterError("free_pi thresholds_bar must be a non-empty list of values >= 0")
        if not betas_s or min(betas_s) < 0.0:
            raise ParameterError("free_pi betas_s must be a non-empty list of values >= 0 [s]")
        if not tension_shares or not all(0.0 <= g <= 1.0 for g in tension_shares):
            raise ParameterError(
                "free_pi tension_shares must be a non-empty list of values in [0, 1]"
            )
        if not tension_onsets_bar or not all(
            0.0 <= p < TENSION_REF_BAR for p in tension_onsets_bar
        ):
            raise ParameterError(
                "free_pi tension_onsets_bar must be a non-empty list of pressures in "
                f"[0, {TENSION_REF_BAR}) bar"
            )
        self.max_pressure_bar = float(max_pressure_bar)
        self.n_offsets = int(n_offsets)
        self.thresholds_bar = tuple(float(r) for r in thresholds_bar)
        self.betas_s = tuple(float(b) for b in betas_s)
        self.tension_shares = tuple(float(g) for g in tension_shares)
        self.tension_onsets_bar = tuple(float(p) for p in tension_onsets_bar)
        self.ridge = float(ridge)
        self._offsets = np.linspace(0.0, self.max_pressure_bar, self.n_offsets)
        self._thresholds = np.asarray(self.thresholds_bar, dtype=float)
        self.beta_s: float | None = None
        self.tension_share = 0.0
        """γ of the fitted core; a design before the fit uses it too (0: fixed thresholds)."""
        self.tension_onset_bar = 0.0
        """p_0 of the fitted core [bar]."""
        self.weights: FloatArray | None = None

    def settings(self) -> dict[str, Any]:
        """The grid, and the rate factors and tension shares tried."""
        return {
            "max_pressure_bar": self.max_pressure_bar,
            "n_offsets": self.n_offsets,
            "thresholds_bar": list(self.thresholds_bar),
            "betas_s": list(self.betas_s),
            "tension_shares": list(self.tension_shares),
            "tension_onsets_bar": list(self.tension_onsets_bar),
            "ridge": self.ridge,
        }

    @property
    def n_columns(self) -> int:
        """Columns of the design: one per play, plus the constant."""
        return self.n_offsets * len(self.thresholds_bar) + 1

    def _state(self) -> FloatArray:
        return np.zeros(2 * self.n_offsets + 1 + self.n_offsets * len(self.thresholds_bar))

    def design(self, x: FloatArray, rate_hz: float, beta_s: float) -> FloatArray:
        """The design matrix (n, columns): every play's output and a constant.

        The plays' thresholds grow with the pressure by the core's :attr:`tension_share`
        above its :attr:`tension_onset_bar`.
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        features = np.empty((x.size, self.n_columns))
        features[:, -1] = 1.0
        _free_pi_kernel(
            x,
            *self._kernel_args(rate_hz, beta_s),
            self._state(),
            np.empty(0),
            features[:, :-1],
            np.empty(0),
        )
        return features

    def _kernel_args(
        self, rate_hz: float, beta_s: float
    ) -> tuple[FloatArray, FloatArray, float, float, float, float, float]:
        """The kernel's structure arguments, between the input and the state."""
        return (
            self._offsets,
            self._thresholds,
            beta_s,
            _alpha(rate_hz),
            rate_hz,
            self.tension_share,
            self.tension_onset_bar,
        )

    @property
    def fitted(self) -> bool:
        """Whether weights have been solved."""
        return self.weights is not None

    def solve(
        self, designs: Sequence[FloatArray], ys: Sequence[FloatArray]
    ) -> tuple[FloatArray, float]:
        """Ridge least squares over recordings (each weighted by 1/sqrt(length)).

        Returns:
            (weights, loss) with loss the sum over recordings of the mean squared error.
        """
        gram = np.zeros((designs[0].shape[1],) * 2)
        rhs = np.zeros(designs[0].shape[1])
        for a, y in zip(designs, ys, strict=True):
            gram += a.T @ a / y.size
            rhs += a.T @ y / y.size
        scale = float(np.trace(gram)) / gram.shape[0]
        gram[np.diag_indices_from(gram)] += self.ridge * scale
        try:
            w = np.asarray(np.linalg.solve(gram, rhs), dtype=np.float64)
        except np.linalg.LinAlgError:
            w = np.asarray(np.linalg.lstsq(gram, rhs, rcond=None)[0], dtype=np.float64)
        loss = float(sum(np.mean((a @ w - y) ** 2) for a, y in zip(designs, ys, strict=True)))
        return w, loss

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """The rate factor, tension share and onset on their grids; weights by least squares.

        A coordinate search (about 20 solves; the full grid takes 60): the rate factor with
        fixed thresholds, then share and onset at that rate factor, then the rate factor
        again at the best share and onset.
        """
        fits: dict[tuple[float, float, float], tuple[float, FloatArray]] = {}

        def score(beta: float, share: float, onset: float) -> float:
            key = (beta, share, onset) if share > 0.0 else (beta, 0.0, 0.0)
            if key not in fits:
                self.tension_share, self.tension_onset_bar = key[1], key[2]
                w, loss = self.solve([self.design(x, rate_hz, beta) for x in xs], ys)
                fits[key] = (loss, w)
            return fits[key][0]

        beta = min(self.betas_s, key=lambda b: score(b, 0.0, 0.0))
        share, onset = min(
            ((g, p) for g in self.tension_shares for p in self.tension_onsets_bar),
            key=lambda gp: score(beta, *gp),
        )
        beta = min(self.betas_s, key=lambda b: score(b, share, onset))
        if share == 0.0:
            onset = 0.0
        self.beta_s, self.tension_share, self.tension_onset_bar = beta, share, onset
        self.weights = fits[(beta, share, onset)][1]

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        if self.weights is None or self.beta_s is None:
            raise ModelError("free_pi core is not fitted")
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty(x.size)
        _free_pi_kernel(
            x,
            *self._kernel_args(rate_hz, self.beta_s),
            self._state(),
            self.weights,
            np.empty((0, 0)),
            out,
        )
        return out

    def streamer(self, rate_hz: float) -> Step:
        """The same kernel one sample at a time, its state carried."""
        if self.weights is None or self.beta_s is None:
            raise ModelError("free_pi core is not fitted")
        state, sample, out = self._state(), np.zeros(1), np.zeros(1)
        args = self._kernel_args(rate_hz, self.beta_s)
        weights, empty = self.weights, np.empty((0, 0))

        def step(x: float) -> float:
            sample[0] = x
            _free_pi_kernel(sample, *args, state, weights, empty, out)
            return float(out[0])

        return step

    def values(self) -> dict[str, Any]:
        """Rate factor, tension share and weights (the last weight is the constant)."""
        if self.weights is None:
            raise ModelError("free_pi core is not fitted")
        return {
            "beta_s": self.beta_s,
            "tension_share": self.tension_share,
            "tension_onset_bar": self.tension_onset_bar,
            "weights": [float(w) for w in self.weights],
        }

    def load_values(self, values: Mapping[str, Any]) -> None:
        """Weights and rate factor from a model file."""
        try:
            weights = np.asarray(values["weights"], dtype=float)
            beta = float(values["beta_s"])
            # Files written before the thresholds could grow with the pressure: fixed ones.
            share = float(values.get("tension_share", 0.0))
            onset = float(values.get("tension_onset_bar", 0.0))
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"free_pi core values are malformed: {exc}") from None
        if weights.shape != (self.n_columns,) or not np.all(np.isfinite(weights)):
            raise ModelError(
                f"free_pi core needs {self.n_columns} finite weights, got {weights.shape}"
            )
        if not (math.isfinite(beta) and beta >= 0.0):
            raise ModelError(f"free_pi beta_s = {beta!r} must be >= 0")
        if not 0.0 <= share <= 1.0:
            raise ModelError(f"free_pi tension_share = {share!r} must be in [0, 1]")
        if not 0.0 <= onset < TENSION_REF_BAR:
            raise ModelError(
                f"free_pi tension_onset_bar = {onset!r} must be in [0, {TENSION_REF_BAR}) bar"
            )
        self.weights, self.beta_s = weights, beta
        self.tension_share, self.tension_onset_bar = share, onset


# ------------------------------------------------------------------------------------------
# boucwen: a Bouc-Wen hysteretic state on a smooth-knee pressure
# ------------------------------------------------------------------------------------------

_BW_NAMES: Final = ("opening_bar", "knee_bar", "b", "g_over_b", "n")
_BW_LOW: Final = np.array([0.0, 0.02, 0.01, -0.9, 0.5])
_BW_HIGH: Final = np.array([2.0, 1.0, 60.0, 1.0, 3.0])


@njit(cache=True)
def _boucwen_kernel(  # noqa: PLR0917
    x: FloatArray,
    theta: FloatArray,
    rate_hz: float,
    alpha: float,
    n_sub: int,
    state: FloatArray,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled; exercised through BoucWen
    """Columns (s, z, s², rate) for each sample; ``state`` = (s_prev, z, rate, started).

    ``s = k softplus((x - d) / k)`` is the pressure above a smooth knee; ``z`` follows
    ``dz/ds = 1 - b |z|^(n-1) z sign(ds) - g |z|^n`` (Bouc-Wen with unit A), sub-stepped; the
    rate column lets the output carry a viscous term ``c4 * ds/dt``.
    """
    # g = (g/b) b with g/b > -1: the hysteretic state stays bounded (|z| < (b+g)^(-1/n)).
    d, k, b, n = theta[0], theta[1], theta[2], theta[4]
    g = theta[3] * b
    for i in range(x.size):
        u = (x[i] - d) / k
        s = k * (u + math.log1p(math.exp(-u))) if u > 0.0 else k * math.log1p(math.exp(u))
        if state[3] == 0.0:
            state[0] = s
            state[3] = 1.0
        ds = (s - state[0]) / n_sub
        z = state[1]
        for _ in range(n_sub):
            az = abs(z)
            pw = az**n if az > 0.0 else 0.0
            sgn = 1.0 if ds >= 0.0 else -1.0
            # |z|^(n-1) z = pw * sign(z)
            zs = pw if z >= 0.0 else -pw
            z += ds * (1.0 - b * sgn * zs - g * pw)
        state[1] = z
        rate = state[2] + alpha * ((s - state[0]) * rate_hz - state[2])
        state[2] = rate
        state[0] = s
        out[i, 0] = s
        out[i, 1] = z
        out[i, 2] = s * s
        out[i, 3] = rate


class BoucWen(Core):
    """Bouc-Wen hysteresis on a smooth-knee pressure (see module).

    Weights by least squares, shape by multi-start nonlinear least squares (variable
    projection).
    """

    name = "boucwen"
    summary = "Bouc-Wen differential hysteresis on a smooth-knee pressure (smooth loops)"

    def __init__(self, *, n_sub: int = 2, starts: int = 4) -> None:
        self.n_sub = int(n_sub)
        self.starts = int(starts)
        self.theta: FloatArray | None = None
        self.weights: FloatArray | None = None

    def settings(self) -> dict[str, Any]:
        """Sub-steps of the hysteretic state and starts of its search."""
        return {"n_sub": self.n_sub, "starts": self.starts}

    @property
    def fitted(self) -> bool:
        """Whether shape and weights are set."""
        return self.theta is not None and self.weights is not None

    def columns(self, x: FloatArray, rate_hz: float, theta: FloatArray) -> FloatArray:
        """(n, 5): s, z, s², rate, constant."""
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty((x.size, 5))
        out[:, 4] = 1.0
        _boucwen_kernel(x, theta, rate_hz, _alpha(rate_hz), self.n_sub, np.zeros(4), out[:, :4])
        return out

    @staticmethod
    def _solve(designs: Sequence[FloatArray], ys: Sequence[FloatArray]) -> FloatArray:
        gram = sum(a.T @ a / a.shape[0] for a in designs)
        rhs = sum(a.T @ y / y.size for a, y in zip(designs, ys, strict=True))
        gram = np.asarray(gram) + 1e-9 * np.eye(5) * float(np.trace(np.asarray(gram)))
        w: FloatArray = np.linalg.lstsq(gram, np.asarray(rhs), rcond=None)[0]
        return w

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """Multi-start least squares over the shape; weights solved inside."""
        weights = [1.0 / math.sqrt(x.size) for x in xs]

        def residuals(theta: FloatArray) -> FloatArray:
            designs = [self.columns(x, rate_hz, theta) for x in xs]
            if not all(np.all(np.isfinite(a)) for a in designs):
                return np.full(sum(x.size for x in xs), 1e3)
            w = self._solve(designs, ys)
            return np.concatenate(
                [(a @ w - y) * c for a, y, c in zip(designs, ys, weights, strict=True)]
            )

        rng = np.random.default_rng(0)
        starts = [np.array([0.8, 0.15, 5.0, 0.0, 1.0])]
        starts += [rng.uniform(_BW_LOW, _BW_HIGH) for _ in range(self.starts - 1)]
        best: tuple[float, FloatArray] | None = None
        for theta0 in starts:
            result = optimize.least_squares(
                residuals,
                np.clip(theta0, _BW_LOW, _BW_HIGH),
                bounds=(_BW_LOW, _BW_HIGH),
                max_nfev=60,
                diff_step=1e-3,
                x_scale="jac",
            )
            if best is None or result.cost < best[0]:
                best = (float(result.cost), result.x)
        assert best is not None
        self.theta = best[1]
        self.weights = self._solve([self.columns(x, rate_hz, self.theta) for x in xs], ys)

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        if self.theta is None or self.weights is None:
            raise ModelError("boucwen core is not fitted")
        out: FloatArray = self.columns(x, rate_hz, self.theta) @ self.weights
        return out

    def streamer(self, rate_hz: float) -> Step:
        """The same kernel one sample at a time."""
        if self.theta is None or self.weights is None:
            raise ModelError("boucwen core is not fitted")
        state, sample, cols = np.zeros(4), np.zeros(1), np.zeros((1, 4))
        theta, weights, alpha = self.theta, self.weights, _alpha(rate_hz)

        def step(x: float) -> float:
            sample[0] = x
            _boucwen_kernel(sample, theta, rate_hz, alpha, self.n_sub, state, cols)
            return float(cols[0] @ weights[:4] + weights[4])

        return step

    def vector(self) -> FloatArray:
        """Shape and weights together."""
        assert self.theta is not None and self.weights is not None
        return np.concatenate([self.theta, self.weights])

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """The shape's box; weights free."""
        inf = np.full(5, np.inf)
        return np.concatenate([_BW_LOW, -inf]), np.concatenate([_BW_HIGH, inf])

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """Run with shape and weights from ``v``."""
        theta, w = v[:5], v[5:]
        return lambda x: self.columns(x, rate_hz, theta) @ w

    def set_vector(self, v: FloatArray) -> None:
        """Adopt ``v``."""
        self.theta, self.weights = np.array(v[:5]), np.array(v[5:])

    def values(self) -> dict[str, Any]:
        """Named shape and the output weights."""
        if self.theta is None or self.weights is None:
            raise ModelError("boucwen core is not fitted")
        return {
            "shape": dict(zip(_BW_NAMES, (float(t) for t in self.theta), strict=True)),
            "weights": [float(w) for w in self.weights],
        }

    def load_values(self, values: Mapping[str, Any]) -> None:
        """Shape and weights from a model file."""
        try:
            theta = np.array([float(values["shape"][n]) for n in _BW_NAMES])
            weights = np.asarray(values["weights"], dtype=float)
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"boucwen core values are malformed: {exc}") from None
        if weights.shape != (5,) or not np.all(np.isfinite(np.concatenate([theta, weights]))):
            raise ModelError("boucwen core needs 5 finite shape values and 5 weights")
        self.theta, self.weights = theta, weights


# ------------------------------------------------------------------------------------------
# drdpi: the thesis's law, as the grey box has always had it
# ------------------------------------------------------------------------------------------


def _recordings(xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float) -> list[Any]:
    """The chain's bar/deg arrays as SI Recordings, for a thesis model's own identification."""
    from catheter_models.models.base import Recording
    from catheter_models.units import bar_to_pa, deg_to_rad

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
        """The parameter table's class (imported lazily, as the models are)."""

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


class DRDPICore(_ThesisCore):
    """The thesis's DRDPI (``models.drdpi``) as a core: its global search, its 12 parameters.

    Args:
        n_play, n_deadband, rate_filter_s: The DRDPI's structure.
        budget: Effort of its global search.
        seed: Seed of the search.
    """

    name = "drdpi"
    summary = "the thesis's DRDPI: exponential play weights, rate-dependent thresholds, knee"

    def __init__(
        self,
        *,
        n_play: int = 10,
        n_deadband: int = 4,
        rate_filter_s: float = 0.02,
        budget: Mapping[str, Any] | None = None,
        seed: int = 0,
    ) -> None:
        from catheter_models.models.drdpi import DRDPI

        self._model = DRDPI(
            n_play=n_play,
            n_deadband=n_deadband,
            rate_filter_s=rate_filter_s,
            budget=budget,
            seed=seed,
        )
        self.n_play, self.n_deadband, self.rate_filter_s = n_play, n_deadband, rate_filter_s
        self.seed = int(seed)
        self.params: Any = None  # DRDPIParams once fitted
        self._coef: dict[float, FloatArray] = {}

    def _params_type(self) -> Any:
        from catheter_models.models.drdpi import DRDPIParams

        return DRDPIParams

    def settings(self) -> dict[str, Any]:
        """Structure and search effort."""
        return {
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
            "budget": self._model.budget.to_dict(),
            "seed": self.seed,
        }

    def set_params(self, params: Any) -> None:
        """Adopt DRDPI parameters (e.g. a fitted DRDPI's); the cached coefficients go."""
        self.params = params
        self._coef = {}

    def coefficients(self, theta: FloatArray, rate_hz: float) -> FloatArray:
        """The chain's coefficients for Table 5.1 parameters ``theta``."""
        from catheter_models.hysteresis import operators as op
        from catheter_models.models.drdpi import rate_alpha

        coef: FloatArray = op.drdpi_coefficients(
            theta, self.n_play, self.n_deadband, rate_hz, rate_alpha(self.rate_filter_s, rate_hz)
        )
        return coef

    def _coef_at(self, rate_hz: float) -> FloatArray:
        if self.params is None:
            raise ModelError("drdpi core is not fitted")
        if rate_hz not in self._coef:
            self._coef[rate_hz] = self.coefficients(self.params.as_array(), rate_hz)
        return self._coef[rate_hz]

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """The DRDPI's global search, then its polish."""
        recs = _recordings(xs, ys, rate_hz)
        self.set_params(self._model.fit(recs, progress=bool(kw.get("progress"))).params_)

    @staticmethod
    def _run_coef(coef: FloatArray, x: FloatArray) -> FloatArray:
        from catheter_models.models.drdpi import run_chain  # the DRDPI model's own runner

        return run_chain(coef, x)

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        return self._run_coef(self._coef_at(rate_hz), x)

    def streamer(self, rate_hz: float) -> Step:
        """The chain one sample at a time."""
        from catheter_models.hysteresis import operators as op

        coef = self._coef_at(rate_hz)
        state, sample, out = np.zeros(op.chain_state_size(coef)), np.zeros(1), np.zeros(1)

        def step(x: float) -> float:
            sample[0] = x
            op.chain_run(sample, coef, state, out)
            return float(out[0])

        return step

    def vector(self) -> FloatArray:
        """The free search coordinates of the DRDPI's box."""
        from catheter_models.models.drdpi import params_to_search

        search = params_to_search(self.params.as_array()[None, :])[0]
        return np.asarray(search[self._model.bounds.free], dtype=float)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """The DRDPI's search box on its free coordinates."""
        b = self._model.bounds
        return np.asarray(b.lower)[b.free], np.asarray(b.upper)[b.free]

    def _theta(self, v: FloatArray) -> FloatArray:
        from catheter_models.models.drdpi import params_to_search, search_to_params

        search = params_to_search(self.params.as_array()[None, :])[0]
        search[self._model.bounds.free] = v
        theta: FloatArray = search_to_params(search[None, :])[0]
        return theta

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """The chain with search coordinates ``v``; None where it is not increasing."""
        from catheter_models.hysteresis import operators as op

        theta = self._theta(v)
        if not float(op.drdpi_monotone_margin(theta, self.n_play, self.n_deadband)) > 0.0:
            return None
        coef = self.coefficients(theta, rate_hz)
        return lambda x: self._run_coef(coef, x)

    def set_vector(self, v: FloatArray) -> None:
        """Adopt the polished coordinates."""
        from catheter_models.models.drdpi import DRDPIParams

        self.set_params(DRDPIParams.from_array(self._theta(v)))


# ------------------------------------------------------------------------------------------
# gpi: the thesis's Generalized Prandtl-Ishlinskii (ch. 9), rate-independent
# ------------------------------------------------------------------------------------------


class GPICore(_ThesisCore):
    """The thesis's GPI (``models.gpi``): a tanh envelope, exponentially weighted plays.

    Rate-independent: the thesis fits one per frequency; as a core it is fitted on all the
    data at once, so it shows how much of the error is the rate dependence it lacks.
    """

    name = "gpi"
    summary = "the thesis's GPI: tanh envelope, exponential play density, rate-independent"

    def __init__(self, *, n_play: int = 10, seed: int = 0) -> None:
        self.n_play, self.seed = int(n_play), int(seed)
        self.params: Any = None

    def _params_type(self) -> Any:
        from catheter_models.models.gpi import GPIParams

        return GPIParams

    def settings(self) -> dict[str, Any]:
        """Structure and seed of the search."""
        return {"n_play": self.n_play, "seed": self.seed}

    def _coef(self, params: Any) -> FloatArray:
        from catheter_models.models.gpi import gpi_coefficients

        coef: FloatArray = gpi_coefficients(params, self.n_play)
        return coef

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """The GPI's own identification on all recordings together."""
        from catheter_models.models.gpi import GPI

        recs = _recordings(xs, ys, rate_hz)
        model = GPI(
            n_play=self.n_play, seed=self.seed, budget={"max_generations": 40, "wall_time_s": 20.0}
        )
        self.params = model.fit(recs, progress=bool(kw.get("progress"))).params_

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        from catheter_models.models.gpi import run_gpi

        if self.params is None:
            raise ModelError("gpi core is not fitted")
        return run_gpi(self._coef(self.params), x)

    def streamer(self, rate_hz: float) -> Step:
        """The GPI one sample at a time."""
        from catheter_models.hysteresis import operators as op

        if self.params is None:
            raise ModelError("gpi core is not fitted")
        coef = self._coef(self.params)
        state, sample, out = op.gpi_rest_state(coef), np.zeros(1), np.zeros(1)

        def step(x: float) -> float:
            sample[0] = x
            op.gpi_run(sample, coef, state, out)
            return float(out[0])

        return step

    def vector(self) -> FloatArray:
        """Table 9.1's parameters."""
        return np.asarray(self.params.as_array(), dtype=float)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Each parameter within a factor of its value's neighbourhood (a local polish)."""
        v = self.vector()
        span = np.maximum(np.abs(v), 0.1)
        low, high = v - 2.0 * span, v + 2.0 * span
        # c0, c1, beta, q stay positive (the GPI's validity).
        for i in (0, 1, 4, 7):
            low[i] = max(low[i], 1e-3)
        low[5] = max(low[5], 0.0)
        return low, high

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """The GPI with parameters ``v``; None if they are not valid."""
        from catheter_models.models.gpi import GPIParams, run_gpi

        try:
            coef = self._coef(GPIParams.from_array(v))
        except (ParameterError, ValueError):
            return None
        return lambda x: run_gpi(coef, x)

    def set_vector(self, v: FloatArray) -> None:
        """Adopt ``v``."""
        from catheter_models.models.gpi import GPIParams

        self.params = GPIParams.from_array(v)


CORES: Final[Mapping[str, type[Core]]] = {c.name: c for c in (DRDPICore, FreePI, BoucWen, GPICore)}
"""Cores by name; the first is the thesis's default."""


def make_core(name: str, settings: Mapping[str, Any] | None = None) -> Core:
    """A core by name with its settings; ParameterError names the known cores."""
    cls = CORES.get(name)
    if cls is None:
        raise ParameterError(f"unknown core {name!r}; known cores: {', '.join(CORES)}")
    try:
        return cls(**dict(settings or {}))
    except TypeError as exc:
        raise ParameterError(f"core {name!r}: {exc}") from None
