"""``boucwen``: a Bouc-Wen hysteretic state on a smooth-knee pressure.

See :mod:`catheter_models.models.cores` for the law and where it sits in the chain.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Final

import numpy as np
from numba import njit
from scipy import optimize

import catheter_models.models.cores.base as core_base
from catheter_models.models.base import ModelError
from catheter_models.models.cores.base import (
    Core,
    FloatArray,
    StateStep,
    _alpha,
    _BytesLRU,
)

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

    def stepper(
        self, rate_hz: float, *, lagged_rate: bool = False, rate_alpha: float | None = None
    ) -> tuple[FloatArray, StateStep]:
        """The Bouc-Wen state at rest, and the same kernel's one-sample step.

        Lagged (:meth:`Core.stepper`), the viscous term reads the rate held before.
        """
        if self.theta is None or self.weights is None:
            raise ModelError("boucwen core is not fitted")
        sample, cols = np.zeros(1), np.zeros((1, 4))
        theta, weights = self.theta, self.weights
        alpha = _alpha(rate_hz) if rate_alpha is None else rate_alpha
        w_s, w_z, w_s2, w_rate, w_0 = (float(w) for w in weights)

        def advance(x: float, state: FloatArray) -> float:
            sample[0] = x
            _boucwen_kernel(sample, theta, rate_hz, alpha, self.n_sub, state, cols)
            return float(cols[0] @ weights[:4] + weights[4])

        def advance_lagged(x: float, state: FloatArray) -> float:
            rate = state[2]
            sample[0] = x
            _boucwen_kernel(sample, theta, rate_hz, alpha, self.n_sub, state, cols)
            c = cols[0]
            return float(w_s * c[0] + w_z * c[1] + w_s2 * c[2] + w_rate * rate + w_0)

        return np.zeros(4), advance_lagged if lagged_rate else advance

    def rate_term(self, rate_hz: float) -> tuple[float, float]:
        """The viscous weight over the pressure's weight [s], and the rate filter's factor."""
        if self.weights is None:
            raise ModelError("boucwen core is not fitted")
        w_s, w_rate = abs(float(self.weights[0])), abs(float(self.weights[3]))
        return (w_rate / w_s if w_s > 0.0 else 0.0), _alpha(rate_hz)

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

    def polish_runners(
        self, rate_hz: float
    ) -> Callable[[FloatArray], Callable[[FloatArray], FloatArray] | None]:
        """:meth:`runner`, with the Bouc-Wen columns kept for a shape and an input.

        Half of the polished vector is the output weights, and so are half of the finite
        differences: for those (and for an output block's parameters) the shape and the
        input are the ones of the point differenced, and the kernel, nearly all of the cost,
        need not run again. Kept by recency within ``core_base.POLISH_CACHE_BYTES``.
        """
        budget = core_base.POLISH_CACHE_BYTES  # read now: one switch for the whole polish
        if budget <= 0:
            return super().polish_runners(rate_hz)
        cache = _BytesLRU(budget)

        def columns(x: FloatArray, theta: FloatArray) -> FloatArray:
            key = (theta.tobytes(), rate_hz, np.ascontiguousarray(x, dtype=np.float64).tobytes())
            hit = cache.get(key)
            if hit is None:
                hit = self.columns(x, rate_hz, theta)
                cache.put(key, hit)
            return hit

        def make(v: FloatArray) -> Callable[[FloatArray], FloatArray]:
            theta, w = np.array(v[:5]), np.array(v[5:])
            return lambda x: columns(x, theta) @ w

        return make

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
