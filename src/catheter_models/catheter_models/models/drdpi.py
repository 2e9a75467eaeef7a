"""The Deadband Rate-Dependent Prandtl-Ishlinskii model (thesis ch. 5), pressure -> bend.

``E(u) = Z(y)``, ``y = a0 u + sum_{i=1..N} a_i Φ_{r_i}[u]`` (eq. 5.1), play operators with
thresholds ``r_i = ζ i + β |u̇|`` (eqs. 5.2, 5.6), weights ``a_i = α0 e^{-β0 i}`` (eq. 5.7), and
the deadband sum ``Z(y) = sum_{j=-k..k} g_j Λ_{d_j}(y)`` (eqs. 5.4, 5.5) with ``d_j = dp j``
(j >= 0), ``d_j = dn j`` (j < 0), ``g_j = -α1 e^{-β1 j}`` (j > 0), ``g_j = -α2 e^{-β2 |j|}``
(j < 0) and g0 (eqs. 5.8-5.11). Its 12 parameters are Table 5.1's, identified by
minimising eq. 5.12 (:mod:`catheter_models.models.identify`).

Units: the model works in the thesis's units so that its parameters read like Table 5.2:
pressure in bar gauge in, bend in degrees out; at the :class:`Model` boundary it speaks SI.

Where the thesis is ambiguous or not well-posed, and what this module does:

* Eq. 5.6 prints ``r_i = ζ i + β |u(t)|`` but names it ``r_i(u̇)``, and the model is
  rate-dependent; the thresholds use ``|u̇|`` [bar/s], estimated causally as a backward
  difference through a first-order low-pass of time constant ``rate_filter_s`` (0 = raw
  difference), inside the kernel's state, so batch and stream compute it identically.
  ζ is in bar, β in seconds.
* Eq. 5.11 ``g_j = -α2 e^{-β2 j}`` for negative j grows with |j| when β2 > 0; we use
  ``e^{-β2 |j|}`` (the printed form with β2 negated), so positive β1, β2 both mean weights
  decaying away from the origin.
* The printed minus signs of eqs. 5.9/5.11 are kept: g_j >= 0 (a deadband that opens up, as
  the rig's) needs α1, α2 <= 0, and the default search box says so. The model is well-posed
  (increasing on every branch, hence invertible by eqs. 9.3-9.11) when a0 > 0, g0 > 0 and
  every partial sum of the PI weights and of the deadband weights from g0 outwards stays
  positive; parameters that break this are refused, naming the sum.
* With pressure >= 0 and non-negative play weights the PI output y is >= 0, so the
  negative-index deadband operators (dn, α2, β2) never act on this rig's data: they are not
  identifiable from it, and harmless.
* The output scale of y is not identifiable either: multiplying a0, α0, dp, dn by λ and g0,
  α1, α2 by 1/λ gives the same E. Products such as ``a0 g0`` and ratios such as ``dp / a0``
  are what data can pin down. The default search box therefore holds dp = 10 (y then reads
  roughly in degrees) and the negative side off; ``bounds`` can free them.
* The search runs over the weights of the first operators (``a1``, ``g1``, ``gm1``) instead
  of α0, α1, α2 (:data:`SEARCH_NAMES`); the saved parameters are Table 5.1's.
* Eq. 5.12 prints ``sum_s sum_i ((y - y_exp) / N_s)^2`` = MSE_s / N_s; the text calls it
  the MSE [deg²]. We minimise ``sum_s MSE_s`` (proportional for equal-length recordings).

On the simulated rig the fit drives β0 and β1 to the top of the box: one play (the wire's
Coulomb friction) and one knee (the muscle's opening pressure) carry nearly all the weight,
and Table 5.1's α0 = a1 e^{β0} then reads large (thousands) while a1 is ~10 deg/bar.
"""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Final

import numpy as np
import numpy.typing as npt

from catheter_models.contract import SENSOR_RATE_HZ
from catheter_models.errors import ParameterError
from catheter_models.hysteresis import operators as op
from catheter_models.hysteresis.inverse import invert_chain, invert_chain_kernel
from catheter_models.hysteresis.population import MONOTONE_PENALTY, drdpi_population_loss
from catheter_models.model_dir import Manifest
from catheter_models.models.base import (
    DataRequirement,
    FitReport,
    FloatArray,
    Model,
    ModelError,
    NotFittedError,
    Recording,
    as_input,
    check_finite_step,
    saved_rate_hz,
)
from catheter_models.models.identify import (
    Budget,
    IdentificationResult,
    ParameterBounds,
    identify,
    stack_recordings,
)
from catheter_models.models.params import ParameterSet, ParamsFile
from catheter_models.units import deg_to_rad, pa_to_bar, rad_to_deg

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

FORWARD_UNITS: Final[Mapping[str, str]] = {
    "alpha0": "deg/bar",
    "alpha1": "1",
    "alpha2": "1",
    "beta0": "1",
    "beta1": "1",
    "beta2": "1",
    "dp": "deg",
    "dn": "deg",
    "zeta": "bar",
    "beta": "s",
    "a0": "deg/bar",
    "g0": "1",
}
"""Units of the parameters of a forward DRDPI (bar in, deg out; y in deg before Z)."""

# What makes a single parameter meaningful at all (monotonicity is checked on the whole set).
_EXPONENT_LIMIT = 10.0
_VALIDITY: Final[Mapping[str, tuple[float, float, bool, str]]] = {
    # name: (low, high, low_is_open, why)
    "alpha0": (-math.inf, math.inf, False, "play weight scale"),
    "alpha1": (-math.inf, math.inf, False, "positive-side deadband weight scale"),
    "alpha2": (-math.inf, math.inf, False, "negative-side deadband weight scale"),
    "beta0": (-_EXPONENT_LIMIT, _EXPONENT_LIMIT, False, "decay of the play weights per index"),
    "beta1": (-_EXPONENT_LIMIT, _EXPONENT_LIMIT, False, "decay of the deadband weights (j > 0)"),
    "beta2": (-_EXPONENT_LIMIT, _EXPONENT_LIMIT, False, "decay of the deadband weights (j < 0)"),
    "dp": (0.0, math.inf, True, "deadband threshold step (j > 0) must be > 0 (eq. 5.8)"),
    "dn": (0.0, math.inf, True, "deadband threshold step (j < 0) must be > 0 (eq. 5.10)"),
    "zeta": (0.0, math.inf, True, "thresholds must ascend strictly, eqs. 5.3, 5.6"),
    "beta": (0.0, math.inf, False, "rate term of the thresholds must be >= 0, eq. 5.6"),
    "a0": (0.0, math.inf, True, "input weight must be > 0 for an inverse, eq. 9.6"),
    "g0": (0.0, math.inf, True, "central deadband weight must be > 0 for an inverse, eq. 9.9"),
}

SEARCH_NAMES: Final = (
    "a1",
    "g1",
    "gm1",
    "beta0",
    "beta1",
    "beta2",
    "dp",
    "dn",
    "zeta",
    "beta",
    "a0",
    "g0",
)
"""The coordinates the identification searches: Table 5.1's, except that the weight scales
α0, α1, α2 are replaced by the weights of the first operators, ``a1 = α0 e^{-β0}``,
``g1 = -α1 e^{-β1}`` and ``gm1 = -α2 e^{-β2}`` (the weight of j = -1).

Why: in Table 5.1's coordinates α0 and β0 are tied along a curved valley (a_1 = α0 e^{-β0}
is what the data pin down, and the fit drives β0 up, concentrating the weight on the first
operator), which made the search several times slower and stopped it on the box's edge."""

DEFAULT_BOUNDS: Final[Mapping[str, tuple[float, float]]] = {
    "a1": (0.0, 30.0),
    "g1": (0.0, 5.0),
    "gm1": (0.0, 0.0),
    "beta0": (-0.5, 6.0),
    "beta1": (-0.5, 6.0),
    "beta2": (0.0, 0.0),
    "dp": (10.0, 10.0),
    "dn": (10.0, 10.0),
    "zeta": (0.005, 0.3),
    "beta": (0.0, 0.1),
    "a0": (0.01, 30.0),
    "g0": (1e-4, 2.0),
}
"""Search box of a forward DRDPI, in :data:`SEARCH_NAMES` (bar in, deg out; y in deg).

Every point in it is well-posed: a1 >= 0 (counter-clockwise loops), g1, gm1 >= 0 (the
deadband opens up), a0, g0 > 0. Held fixed (equal bounds), because data cannot pin them:
dp = 10 sets the scale of y (only ratios such as dp / a0 are identifiable), and the negative
side (gm1 = 0, so dn and β2 do nothing) never acts while y >= 0. Pass ``bounds`` to free
them."""


def search_to_params(search: FloatArray) -> FloatArray:
    """Search coordinates (:data:`SEARCH_NAMES`) -> Table 5.1's, row by row.

    Args:
        search: Shape ``(12,)`` or ``(P, 12)``.

    Returns:
        Same shape, in :data:`PARAM_NAMES` order.
    """
    table = np.array(search, dtype=np.float64, copy=True)
    rows = table.reshape(-1, len(SEARCH_NAMES))
    rows[:, 0] = rows[:, 0] * np.exp(rows[:, 3])
    # "+ 0.0" turns the -0.0 of a zero weight into 0.0, so saved parameters read cleanly.
    rows[:, 1] = -rows[:, 1] * np.exp(rows[:, 4]) + 0.0
    rows[:, 2] = -rows[:, 2] * np.exp(rows[:, 5]) + 0.0
    return table


def params_to_search(theta: FloatArray) -> FloatArray:
    """Table 5.1's coordinates -> :data:`SEARCH_NAMES` (inverse of :func:`search_to_params`)."""
    search = np.array(theta, dtype=np.float64, copy=True)
    rows = search.reshape(-1, len(PARAM_NAMES))
    rows[:, 0] = rows[:, 0] * np.exp(-rows[:, 3])
    rows[:, 1] = -rows[:, 1] * np.exp(-rows[:, 4])
    rows[:, 2] = -rows[:, 2] * np.exp(-rows[:, 5])
    return search


PARAMS_FILE: Final = "drdpi_params.json"
PARAMS_FORMAT: Final = "catheter_models.drdpi/1"


@dataclass(frozen=True)
class DRDPIParams(ParameterSet):
    """Table 5.1's 12 parameters of a DRDPI-structure chain.

    Units are those of a forward DRDPI (:data:`FORWARD_UNITS`): bar in, degrees out. An
    IDRDPI of the plain DRDPI structure (angle in, pressure out) reuses the class with the
    units swapped (see ``models.idrdpi``).

    Attributes:
        alpha0: Play weight scale, a_i = alpha0 e^{-beta0 i} (eq. 5.7) [deg/bar].
        alpha1: Deadband weight scale, g_j = -alpha1 e^{-beta1 j}, j > 0 (eq. 5.9) [1].
        alpha2: Deadband weight scale, g_j = -alpha2 e^{-beta2 |j|}, j < 0 (eq. 5.11) [1].
        beta0: Decay of the play weights per index [1].
        beta1: Decay of the deadband weights per index, j > 0 [1].
        beta2: Decay of the deadband weights per index, j < 0 [1].
        dp: Deadband threshold step, d_j = dp j, j > 0 (eq. 5.8) [deg].
        dn: Deadband threshold step, d_j = dn j, j < 0 (eq. 5.10; dn > 0) [deg].
        zeta: Rate-independent threshold step, r_i = zeta i + beta |u̇| (eq. 5.6) [bar].
        beta: Rate coefficient of the thresholds [s] (bar per bar/s).
        a0: Input weight (eq. 5.1) [deg/bar].
        g0: Central deadband weight (eq. 5.4) [1].
    """

    alpha0: float
    alpha1: float
    alpha2: float
    beta0: float
    beta1: float
    beta2: float
    dp: float
    dn: float
    zeta: float
    beta: float
    a0: float
    g0: float

    label = "DRDPI"
    table = "Table 5.1"
    validity = _VALIDITY


PARAM_NAMES: Final = DRDPIParams.names()
"""Table 5.1's parameters, in its order (the order of every parameter vector here); the
dataclass's fields are the one place the order is written."""

DRDPI_PARAMS_FILE: Final = ParamsFile(PARAMS_FILE, PARAMS_FORMAT, DRDPIParams)
"""The parameters file of every DRDPI-structure model (the DRDPI's and the IDRDPI's)."""


def rate_alpha(rate_filter_s: float, rate_hz: float) -> float:
    """Low-pass factor of the rate estimate: ``1 - exp(-1 / (rate_hz tau))``, 1 for tau = 0."""
    if not (math.isfinite(rate_filter_s) and rate_filter_s >= 0.0):
        raise ParameterError(f"rate_filter_s = {rate_filter_s!r} must be >= 0 [s]")
    if rate_filter_s == 0.0:
        return 1.0
    return 1.0 - math.exp(-1.0 / (rate_hz * rate_filter_s))


def check_monotone(params: DRDPIParams, n_play: int, n_deadband: int) -> None:
    """Refuse parameters whose chain is not increasing (hence has no inverse), naming the sum.

    Raises:
        ParameterError: A partial sum of the PI weights (eq. 9.6's denominators) or of the
            deadband weights from g0 outwards (eqs. 9.9, 9.11) is <= 0.
    """
    p = params
    idx = np.arange(1, n_play + 1, dtype=np.float64)
    pi_sums = p.a0 + np.cumsum(p.alpha0 * np.exp(-p.beta0 * idx))
    j = np.arange(1, n_deadband + 1, dtype=np.float64)
    up = p.g0 + np.cumsum(-p.alpha1 * np.exp(-p.beta1 * j))
    down = p.g0 + np.cumsum(-p.alpha2 * np.exp(-p.beta2 * j))
    for label, sums in (
        ("a0 + a_1 + ... + a_{i}", pi_sums),
        ("g0 + g_1 + ... + g_{i}", up),
        ("g0 + g_-1 + ... + g_-{i}", down),
    ):
        bad = np.flatnonzero(~(sums > 0.0))
        if bad.size:
            i = int(bad[0]) + 1
            raise ParameterError(
                f"DRDPI parameters are not well-posed: {label.replace('{i}', str(i))} = "
                f"{sums[bad[0]]:.6g} must be > 0, or the model folds back and has no "
                "inverse (eqs. 9.6, 9.9, 9.11)"
            )


def chain_coefficients(
    params: DRDPIParams,
    *,
    n_play: int,
    n_deadband: int,
    rate_hz: float,
    rate_filter_s: float,
    inverse: bool = False,
) -> FloatArray:
    """The operator chain of a DRDPI (``inverse=False``) or of its analytic inverse.

    Args:
        params: The 12 parameters (checked for well-posedness here).
        n_play: N, number of play operators.
        n_deadband: k; 2k + 1 deadband operators.
        rate_hz: Sample rate the chain runs at [Hz].
        rate_filter_s: Time constant of the rate estimate's low-pass [s]; 0 for none.
        inverse: Return E⁻¹ (eqs. 9.2-9.11, :func:`inverse.invert_chain`) instead of E.

    Returns:
        Coefficient vector for :func:`operators.chain_run`.
    """
    check_monotone(params, n_play, n_deadband)
    coef: FloatArray = op.drdpi_coefficients(
        params.as_array(), n_play, n_deadband, float(rate_hz), rate_alpha(rate_filter_s, rate_hz)
    )
    return invert_chain(coef) if inverse else coef


def run_chain(coef: FloatArray, x: FloatArray) -> FloatArray:
    """Run a chain over a whole signal from rest (internal units in and out)."""
    out = np.empty(x.size)
    op.chain_run(
        np.ascontiguousarray(x, dtype=np.float64), coef, np.zeros(op.chain_state_size(coef)), out
    )
    return out


class ChainStream:
    """A chain stepped one sample at a time: the same kernel as ``predict``, one-sample chunks.

    Args:
        coef: Chain coefficients.
        to_internal: SI input -> the chain's input unit (e.g. Pa -> bar).
        from_internal: The chain's output unit -> SI (e.g. deg -> rad).
        kind: Model kind, for error messages.
    """

    def __init__(
        self,
        coef: FloatArray,
        to_internal: Callable[[float], float],
        from_internal: Callable[[float], float],
        kind: str,
    ) -> None:
        self._coef = np.ascontiguousarray(coef, dtype=np.float64)
        self._state = np.zeros(op.chain_state_size(self._coef))
        self._x = np.zeros(1)
        self._y = np.zeros(1)
        self._to = to_internal
        self._from = from_internal
        self._kind = kind

    def reset(self) -> None:
        """Back to rest (all plays at 0, rate 0), as at the start of ``predict``."""
        self._state[:] = 0.0

    def step(self, value: float) -> float:
        """One sample: SI in, SI out. SignalError on a non-finite input."""
        self._x[0] = self._to(check_finite_step(value, self._kind))
        op.chain_run(self._x, self._coef, self._state, self._y)
        return float(self._from(float(self._y[0])))


class DRDPIProblem:
    """Eq. 5.12 for DRDPI-structure chains on a set of recordings (internal units).

    Candidates are in the search coordinates (:data:`SEARCH_NAMES`).

    Args:
        inputs: Each recording's input, in the chain's input unit.
        outputs: Each recording's measured output, in the chain's output unit.
        n_play: N.
        n_deadband: k.
        rate_hz: Sample rate [Hz].
        rate_filter_s: Rate low-pass time constant [s].
        inverse: Score E⁻¹ of each candidate (eqs. 9.2-9.11) instead of E.
    """

    def __init__(
        self,
        inputs: Sequence[FloatArray],
        outputs: Sequence[FloatArray],
        *,
        n_play: int,
        n_deadband: int,
        rate_hz: float,
        rate_filter_s: float,
        inverse: bool = False,
    ) -> None:
        self.x, self.y, self.starts = stack_recordings(inputs, outputs)
        self.n_play = n_play
        self.n_deadband = n_deadband
        self.rate_hz = float(rate_hz)
        self.alpha = rate_alpha(rate_filter_s, rate_hz)
        self.inverse = inverse
        self._weights = 1.0 / np.sqrt(np.repeat(np.diff(self.starts), np.diff(self.starts)))

    def population_loss(self, thetas: FloatArray) -> FloatArray:
        """Eq. 5.12 for each row of ``thetas`` (search coordinates; numba, in parallel)."""
        loss: FloatArray = drdpi_population_loss(
            search_to_params(np.atleast_2d(thetas)),
            self.n_play,
            self.n_deadband,
            self.rate_hz,
            self.alpha,
            self.inverse,
            self.x,
            self.y,
            self.starts,
        )
        return loss

    def predict_all(self, theta: FloatArray) -> FloatArray:
        """The chain's output over every recording (each from rest), back to back.

        Args:
            theta: Table 5.1's parameters (not search coordinates).
        """
        coef = op.drdpi_coefficients(theta, self.n_play, self.n_deadband, self.rate_hz, self.alpha)
        if self.inverse:
            coef = invert_chain_kernel(coef)
        out = np.empty(self.x.size)
        state = np.zeros(op.chain_state_size(coef))
        for s in range(self.starts.size - 1):
            lo, hi = int(self.starts[s]), int(self.starts[s + 1])
            state[:] = 0.0
            op.chain_run(self.x[lo:hi], coef, state, out[lo:hi])
        return out

    def residuals(self, search: FloatArray) -> FloatArray:
        """Errors scaled by 1/sqrt(N_s): their sum of squares is eq. 5.12's loss.

        A candidate that is not increasing gets a constant large residual, as in the
        population loss, so the polish steps back.

        Args:
            search: One candidate in search coordinates.
        """
        theta = search_to_params(search)
        margin = float(op.drdpi_monotone_margin(theta, self.n_play, self.n_deadband))
        if not margin > 0.0:
            scale = math.sqrt(MONOTONE_PENALTY * (1.0 - margin) / (self.starts.size - 1))
            penalty: FloatArray = np.full(self.x.size, scale) * self._weights
            return penalty
        res: FloatArray = (self.predict_all(theta) - self.y) * self._weights
        return res


def identify_chain(
    problem: DRDPIProblem,
    bounds: ParameterBounds,
    *,
    budget: Budget,
    seed: int,
    progress: bool,
    label: str,
) -> tuple[DRDPIParams, IdentificationResult]:
    """Identify Table 5.1's parameters of a DRDPI-structure chain on ``problem``."""
    result = identify(problem, bounds, budget=budget, seed=seed, progress=progress, label=label)
    return DRDPIParams.from_array(search_to_params(result.theta)), result


def _rmse_per_recording(
    predicted: FloatArray, measured: FloatArray, starts: npt.NDArray[np.int64]
) -> list[float]:
    err = predicted - measured
    return [
        float(np.sqrt(np.mean(err[int(a) : int(b)] ** 2))) for a, b in itertools.pairwise(starts)
    ]


class DRDPI(Model):
    """The DRDPI (thesis ch. 5): valve pressure -> bend, rate-dependent with deadband.

    Args:
        n_play: N, number of play operators (the thesis does not print it).
        n_deadband: k; the deadband sum has 2k + 1 operators.
        rate_filter_s: Time constant of the low-pass on the input-rate estimate [s]; 0 uses
            the raw backward difference.
        bounds: Search box ``{name: (low, high)}`` over :data:`SEARCH_NAMES`, in the units
            of :data:`FORWARD_UNITS` (a1 like α0, g1 and gm1 like α1); missing names take
            :data:`DEFAULT_BOUNDS`; equal bounds hold a parameter fixed.
        budget: Identification effort (:class:`~catheter_models.models.identify.Budget`, or
            its settings as a mapping).
        seed: Seed of the search.
    """

    kind: ClassVar[str] = "drdpi"
    direction = "forward"
    requirement: ClassVar[DataRequirement] = DataRequirement(
        min_samples=2_500,
        why="The DRDPI's 12 parameters need several hysteresis loops: 10 s at 250 Hz at least.",
    )

    params_: DRDPIParams
    coef_: FloatArray

    def __init__(
        self,
        *,
        n_play: int = 10,
        n_deadband: int = 4,
        rate_filter_s: float = 0.02,
        bounds: Mapping[str, Sequence[float]] | None = None,
        budget: Budget | Mapping[str, Any] | None = None,
        seed: int = 0,
    ) -> None:
        if not (isinstance(n_play, int) and 1 <= n_play <= 200):
            raise ParameterError(f"n_play = {n_play!r} must be an integer in [1, 200]")
        if not (isinstance(n_deadband, int) and 0 <= n_deadband <= 50):
            raise ParameterError(f"n_deadband = {n_deadband!r} must be an integer in [0, 50]")
        rate_alpha(rate_filter_s, SENSOR_RATE_HZ)  # validates
        self.n_play = n_play
        self.n_deadband = n_deadband
        self.rate_filter_s = float(rate_filter_s)
        self.bounds = ParameterBounds.from_mapping(
            SEARCH_NAMES, {**DEFAULT_BOUNDS, **dict(bounds or {})}
        )
        self.budget = Budget.coerce(budget)
        self.seed = int(seed)

    # -- building from known parameters -----------------------------------------------------
    @classmethod
    def from_params(
        cls, params: DRDPIParams, rate_hz: float = SENSOR_RATE_HZ, **settings: Any
    ) -> Self:
        """A fitted DRDPI with given parameters (for simulation, tests, the analytic inverse)."""
        model = cls(**settings)
        model._set_params(params, rate_hz)
        return model

    def _set_params(self, params: DRDPIParams, rate_hz: float) -> None:
        self.coef_ = chain_coefficients(
            params,
            n_play=self.n_play,
            n_deadband=self.n_deadband,
            rate_hz=rate_hz,
            rate_filter_s=self.rate_filter_s,
        )
        self.params_ = params
        self.rate_hz_ = float(rate_hz)

    # -- the contract ------------------------------------------------------------------------
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Identify the 12 parameters on ``train`` (eq. 5.12), score ``validation``."""
        t0 = time.perf_counter()
        rate = self._prepare(train, validation)
        problem = self._problem(train, rate)
        params, result = identify_chain(
            problem,
            self.bounds,
            budget=self.budget,
            seed=self.seed,
            progress=progress,
            label="DRDPI",
        )
        self._set_params(params, rate)
        train_rmse = _rmse_per_recording(
            problem.predict_all(params.as_array()), problem.y, problem.starts
        )
        extra: dict[str, Any] = {
            "identification": result.summary(),
            "train_rmse_deg": dict(zip([r.name for r in train], train_rmse, strict=True)),
            "params": params.to_dict(),
        }
        validation_loss: list[float] = []
        if validation:
            vproblem = self._problem(validation, rate)
            vrmse = _rmse_per_recording(
                vproblem.predict_all(params.as_array()), vproblem.y, vproblem.starts
            )
            validation_loss = [float(sum(v * v for v in vrmse))]
            extra["validation_rmse_deg"] = dict(
                zip([r.name for r in validation], vrmse, strict=True)
            )
        self.fit_report_ = FitReport(
            duration_s=time.perf_counter() - t0,
            train_loss=[*result.history, result.loss],
            validation_loss=validation_loss,
            extra=extra,
        )
        return self

    def _problem(self, recordings: Sequence[Recording], rate_hz: float) -> DRDPIProblem:
        return DRDPIProblem(
            [pa_to_bar(r.pressure_pa) for r in recordings],
            [rad_to_deg(r.angle_rad) for r in recordings],
            n_play=self.n_play,
            n_deadband=self.n_deadband,
            rate_hz=rate_hz,
            rate_filter_s=self.rate_filter_s,
        )

    def _coef(self) -> FloatArray:
        coef: FloatArray | None = getattr(self, "coef_", None)
        if coef is None:
            raise NotFittedError("drdpi model is not fitted: call fit() or load() first")
        return coef

    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Bend [rad] for a valve pressure signal [Pa gauge], from rest."""
        coef = self._coef()
        x = pa_to_bar(as_input(input_si, "pressure_pa"))
        out: FloatArray = deg_to_rad(run_chain(coef, x))
        return out

    def stream(self) -> ChainStream:
        """Stateful stepper: Pa in, rad out, equal to :meth:`predict` sample by sample."""
        return ChainStream(self._coef(), pa_to_bar, deg_to_rad, self.kind)

    # -- persistence -------------------------------------------------------------------------
    def _settings(self) -> dict[str, Any]:
        return {
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
            "bounds": self.bounds.to_mapping(),
            "budget": self.budget.to_dict(),
            "seed": self.seed,
        }

    def _payload(self) -> dict[str, bytes]:
        self._coef()
        return {PARAMS_FILE: DRDPI_PARAMS_FILE.dump(self.params_, FORWARD_UNITS, self._structure())}

    def _structure(self) -> dict[str, Any]:
        return {
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
        }

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        params, structure = DRDPI_PARAMS_FILE.read(payload, kind=cls.kind)
        settings = dict(manifest.metrics.get("settings", {}))
        settings.update(structure)
        try:
            model = cls(**settings)
        except (TypeError, ValueError) as exc:
            raise ModelError(f"{cls.kind} manifest settings are malformed: {exc}") from None
        model._set_params(params, saved_rate_hz(manifest, cls.kind))
        return model


__all__ = [
    "DEFAULT_BOUNDS",
    "DRDPI",
    "DRDPI_PARAMS_FILE",
    "FORWARD_UNITS",
    "PARAM_NAMES",
    "SEARCH_NAMES",
    "ChainStream",
    "DRDPIParams",
    "DRDPIProblem",
    "chain_coefficients",
    "check_monotone",
    "identify_chain",
    "params_to_search",
    "rate_alpha",
    "run_chain",
    "search_to_params",
]
