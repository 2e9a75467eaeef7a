"""Bounded identification of a model's parameters: eq. 5.12 by differential evolution + polish.

The thesis minimised eq. 5.12 with MATLAB's genetic algorithm for 3.5 h. Here the same kind
of global, derivative-free search (scipy's differential evolution, seeded, in a box) scores
a whole generation at once through the problem's population loss, which runs the numba
operators over every recording with one thread per candidate, so both cores work. A local
least-squares polish (or L-BFGS-B) then finishes from the best candidate. A wall-time budget
bounds the whole: the search stops in time to leave the polish its share, and the polish
stops at the deadline with the best point it has seen.

A problem only has to say how to score a population (:class:`Problem`); the DRDPI, the
IDRDPI and the GPI each supply one (``models.drdpi``, ``models.gpi``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Literal, Protocol

import numpy as np
import numpy.typing as npt
import scipy
from scipy.optimize import OptimizeResult, differential_evolution, least_squares, minimize
from tqdm import tqdm

from catheter_models.errors import ParameterError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
_DE_CALLBACK_TAKES_RESULT = tuple(int(part) for part in scipy.__version__.split(".")[:2]) >= (1, 12)
"""differential_evolution passes ``intermediate_result`` to a callback from SciPy 1.12 on."""
PolishMethod = Literal["least_squares", "L-BFGS-B", "none"]
POLISH_METHODS: tuple[PolishMethod, ...] = ("least_squares", "L-BFGS-B", "none")


class Problem(Protocol):
    """What :func:`identify` needs from a model: its loss, for many candidates at once."""

    def population_loss(self, thetas: FloatArray) -> FloatArray:
        """Loss (eq. 5.12) of each row of ``thetas`` (shape ``(P, n_params)``)."""

    def residuals(self, theta: FloatArray) -> FloatArray:
        """Residual vector whose sum of squares is the loss of ``theta`` (for the polish)."""


@dataclass(frozen=True)
class ParameterBounds:
    """A box for the search: one closed interval per parameter, by name.

    A parameter whose interval has ``lower == upper`` is held at that value.

    Attributes:
        names: Parameter names, in the problem's order.
        lower: Lower bounds, same order.
        upper: Upper bounds, same order.
    """

    names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def __post_init__(self) -> None:
        if not (len(self.names) == len(self.lower) == len(self.upper)):
            raise ParameterError(
                f"bounds: {len(self.names)} names, {len(self.lower)} lower and "
                f"{len(self.upper)} upper bounds; they must match"
            )
        for name, lo, hi in zip(self.names, self.lower, self.upper, strict=True):
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise ParameterError(
                    f"bounds of {name!r} are [{lo!r}, {hi!r}]; they must be finite with "
                    "lower <= upper"
                )

    @classmethod
    def from_mapping(
        cls, names: Sequence[str], bounds: Mapping[str, Sequence[float]]
    ) -> ParameterBounds:
        """Bounds for ``names`` from ``{name: (lower, upper)}``; every name needed, no other.

        Raises:
            ParameterError: A name missing or unknown, or an interval malformed.
        """
        unknown = sorted(set(bounds) - set(names))
        missing = [n for n in names if n not in bounds]
        if unknown or missing:
            raise ParameterError(
                f"bounds: unknown parameter(s) {unknown}, missing {missing}; "
                f"expected exactly {list(names)}"
            )
        lower, upper = [], []
        for name in names:
            pair = tuple(bounds[name])
            if len(pair) != 2:
                raise ParameterError(f"bounds of {name!r} must be (lower, upper), got {pair!r}")
            lower.append(float(pair[0]))
            upper.append(float(pair[1]))
        return cls(tuple(names), tuple(lower), tuple(upper))

    def to_mapping(self) -> dict[str, list[float]]:
        """JSON-able ``{name: [lower, upper]}``."""
        return {n: [lo, hi] for n, lo, hi in zip(self.names, self.lower, self.upper, strict=True)}

    def check(self, theta: npt.ArrayLike, owner: str = "parameters") -> None:
        """Refuse a vector that is non-finite or outside the box, naming the bound."""
        values = np.asarray(theta, dtype=np.float64)
        if values.shape != (len(self.names),):
            raise ParameterError(
                f"{owner}: expected {len(self.names)} values {list(self.names)}, "
                f"got shape {values.shape}"
            )
        for name, v, lo, hi in zip(self.names, values, self.lower, self.upper, strict=True):
            if not (math.isfinite(v) and lo <= v <= hi):
                raise ParameterError(f"{owner}: {name} = {v!r} is outside its bounds [{lo}, {hi}]")

    @property
    def free(self) -> npt.NDArray[np.bool_]:
        """Mask of the parameters the search moves (``lower < upper``)."""
        return np.asarray(self.lower) < np.asarray(self.upper)


@dataclass(frozen=True)
class Budget:
    """How much effort an identification may spend.

    Attributes:
        max_generations: Differential-evolution generations at most.
        popsize: Population size as a multiple of the number of free parameters (scipy's
            convention).
        wall_time_s: Wall-clock budget for search and polish together [s].
        tol: Relative spread of the population's losses at which the search has converged
            (scipy's ``tol``).
        polish: Local method after the search: ``least_squares`` (trust-region reflective
            on the residuals), ``L-BFGS-B`` (on the loss), or ``none``.
        polish_max_evals: Evaluations the polish may use at most (for ``least_squares``,
            residual evaluations besides those of its finite-difference Jacobian).
        polish_share: Share of ``wall_time_s`` kept for the polish.

    The defaults let the global search find the basin and leave the last digits to the
    polish: on the thesis-size DRDPI problem (26,800 samples) they reach the loss of a run
    with 10x the generations and 4x the population in about a tenth of a minute on two cores
    (``bench/bench_drdpi_identification.py``); the wall time is the ceiling, not the plan.
    """

    max_generations: int = 100
    popsize: int = 8
    wall_time_s: float = 60.0
    tol: float = 1e-6
    polish: PolishMethod = "least_squares"
    polish_max_evals: int = 600
    polish_share: float = 0.25

    def __post_init__(self) -> None:
        checks: list[tuple[str, bool, str]] = [
            ("max_generations", self.max_generations >= 1, ">= 1"),
            ("popsize", self.popsize >= 2, ">= 2"),
            ("wall_time_s", math.isfinite(self.wall_time_s) and self.wall_time_s > 0.0, "> 0"),
            ("tol", math.isfinite(self.tol) and self.tol >= 0.0, ">= 0"),
            ("polish", self.polish in POLISH_METHODS, f"one of {POLISH_METHODS}"),
            ("polish_max_evals", self.polish_max_evals >= 1, ">= 1"),
            ("polish_share", 0.0 <= self.polish_share < 1.0, "in [0, 1)"),
        ]
        for name, ok, rule in checks:
            if not ok:
                raise ParameterError(f"budget.{name} = {getattr(self, name)!r} must be {rule}")

    @classmethod
    def coerce(cls, value: Budget | Mapping[str, Any] | None) -> Budget:
        """A Budget from itself, a settings mapping (as saved in a manifest), or defaults."""
        if value is None:
            return cls()
        if isinstance(value, Budget):
            return value
        known = set(cls.__dataclass_fields__)
        unknown = sorted(set(value) - known)
        if unknown:
            raise ParameterError(f"budget: unknown setting(s) {unknown}; known: {sorted(known)}")
        return cls(**dict(value))

    def to_dict(self) -> dict[str, Any]:
        """JSON-able settings."""
        return asdict(self)


@dataclass(frozen=True)
class IdentificationResult:
    """What one identification found and spent.

    Attributes:
        theta: Best parameter vector (all parameters, the problem's order).
        loss: Its loss (eq. 5.12, the problem's unit squared).
        search_loss: Best loss when the global search ended, before the polish.
        generations: Generations the search ran.
        evaluations: Candidates scored by the search plus polish evaluations.
        duration_s: Wall time of search and polish [s].
        search_s: Wall time of the search [s].
        stopped_by: Why the search ended: ``converged``, ``max_generations`` or ``wall_time``.
        history: Best loss after each generation.
    """

    theta: FloatArray
    loss: float
    search_loss: float
    generations: int
    evaluations: int
    duration_s: float
    search_s: float
    stopped_by: str
    history: tuple[float, ...] = field(default_factory=tuple)

    def summary(self) -> dict[str, Any]:
        """JSON-able summary for a FitReport (history left out: it goes to ``train_loss``)."""
        return {
            "loss": self.loss,
            "search_loss": self.search_loss,
            "generations": self.generations,
            "evaluations": self.evaluations,
            "duration_s": self.duration_s,
            "search_s": self.search_s,
            "stopped_by": self.stopped_by,
        }


class _OutOfTimeError(Exception):
    """Raised inside the polish's objective at the deadline, to stop scipy at once."""


def stack_recordings(
    inputs: Sequence[FloatArray], outputs: Sequence[FloatArray]
) -> tuple[FloatArray, FloatArray, IntArray]:
    """Recordings back to back, as the population-loss kernels take them.

    Returns:
        ``(x, y, starts)``: inputs and outputs concatenated, and each recording's first
        index followed by the total length.
    """
    lengths = [len(a) for a in inputs]
    starts = np.zeros(len(lengths) + 1, dtype=np.int64)
    starts[1:] = np.cumsum(lengths)
    x = np.ascontiguousarray(np.concatenate(inputs), dtype=np.float64)
    y = np.ascontiguousarray(np.concatenate(outputs), dtype=np.float64)
    return x, y, starts


def identify(
    problem: Problem,
    bounds: ParameterBounds,
    *,
    budget: Budget | None = None,
    seed: int = 0,
    progress: bool = True,
    label: str = "identify",
    x0: npt.ArrayLike | None = None,
) -> IdentificationResult:
    """Minimise ``problem``'s loss in ``bounds``: differential evolution, then a polish.

    Args:
        problem: Population loss and residuals of the model being identified.
        bounds: The search box; equal bounds hold a parameter fixed.
        budget: Generations, population, wall time, polish; defaults if ``None``.
        seed: Seed of the search (same seed, same data, same budget: same result, unless
            the wall-time budget cuts the search at a different generation).
        progress: Show a tqdm progress bar over the generations.
        label: Progress bar title.
        x0: Optional candidate placed in the initial population (inside ``bounds``).

    Returns:
        The best parameters found and what the search spent.
    """
    budget = budget or Budget()
    lower = np.asarray(bounds.lower, dtype=np.float64)
    upper = np.asarray(bounds.upper, dtype=np.float64)
    free = bounds.free
    fixed_theta = lower.copy()
    n_free = int(free.sum())

    def expand(free_values: FloatArray) -> FloatArray:
        """(S, n_free) candidates -> (S, n_params) with the fixed parameters filled in."""
        full = np.repeat(fixed_theta[None, :], free_values.shape[0], axis=0)
        full[:, free] = free_values
        return full

    if n_free:
        # Compile the problem's kernels (numba compiles on first call, or loads its cache)
        # before the clock starts: on a fresh checkout compiling took a large, machine-
        # dependent share of a 20 s budget, and a search cut short by it gives another
        # result on another machine for the same data, seed and budget.
        middle = expand(((lower + upper) / 2.0)[free][None, :])
        problem.population_loss(middle)
        if budget.polish == "least_squares":
            problem.residuals(middle[0])
    t0 = time.perf_counter()
    history: list[float] = []
    evaluations = 0
    search_deadline = t0 + budget.wall_time_s * (1.0 - budget.polish_share)
    deadline = t0 + budget.wall_time_s
    stopped_by = "max_generations"

    if n_free == 0:
        theta = fixed_theta
        loss = float(problem.population_loss(theta[None, :])[0])
        return IdentificationResult(theta, loss, loss, 0, 1, 0.0, 0.0, "converged", (loss,))

    def vectorized_loss(xt: FloatArray) -> FloatArray:
        nonlocal evaluations
        candidates = np.ascontiguousarray(np.atleast_2d(xt.T))
        evaluations += candidates.shape[0]
        return problem.population_loss(expand(candidates))

    bar = tqdm(total=budget.max_generations, desc=label, unit="gen", disable=not progress)

    def on_generation(best_loss: float) -> bool:
        nonlocal stopped_by
        history.append(best_loss)
        bar.update(1)
        bar.set_postfix_str(f"loss {best_loss:.5g}")
        if time.perf_counter() > search_deadline:
            stopped_by = "wall_time"
            return True
        return False

    callback: Callable[..., bool]
    if _DE_CALLBACK_TAKES_RESULT:

        def callback(intermediate_result: OptimizeResult) -> bool:
            return on_generation(float(intermediate_result.fun))

    else:
        # SciPy < 1.12 (Ubuntu 24.04's 1.11) hands the callback only the best member, not its
        # loss: one more evaluation per generation gives the same history.
        def callback(xk: FloatArray, convergence: float = 0.0) -> bool:
            return on_generation(float(vectorized_loss(xk)[0]))

    start = None
    if x0 is not None:
        start_full = np.asarray(x0, dtype=np.float64)
        bounds.check(start_full, owner=f"{label} x0")
        start = start_full[free]
    try:
        result = differential_evolution(
            vectorized_loss,
            list(zip(lower[free], upper[free], strict=True)),
            maxiter=budget.max_generations,
            popsize=budget.popsize,
            tol=budget.tol,
            # seed=, not rng= (SciPy >= 1.15): Ubuntu 24.04 ships SciPy 1.11. Both take the
            # Generator as is and draw the same numbers.
            seed=np.random.default_rng(seed),
            callback=callback,
            polish=False,
            init="latinhypercube",
            updating="deferred",
            vectorized=True,
            x0=start,
        )
    finally:
        bar.close()
    if stopped_by != "wall_time" and len(history) < budget.max_generations:
        stopped_by = "converged"
    search_s = time.perf_counter() - t0
    best_free = np.asarray(result.x, dtype=np.float64)
    search_loss = float(result.fun)
    best_loss = search_loss
    if budget.polish != "none" and time.perf_counter() < deadline:
        best_free, best_loss, used = _polish(
            problem,
            expand,
            best_free,
            best_loss,
            bounds=(lower[free], upper[free]),
            budget=budget,
            deadline=deadline,
        )
        evaluations += used
    theta = expand(best_free[None, :])[0]
    return IdentificationResult(
        theta=theta,
        loss=best_loss,
        search_loss=search_loss,
        generations=len(history),
        evaluations=evaluations,
        duration_s=time.perf_counter() - t0,
        search_s=search_s,
        stopped_by=stopped_by,
        history=tuple(history),
    )


def _polish(
    problem: Problem,
    expand: Callable[[FloatArray], FloatArray],
    start: FloatArray,
    start_loss: float,
    *,
    bounds: tuple[FloatArray, FloatArray],
    budget: Budget,
    deadline: float,
) -> tuple[FloatArray, float, int]:
    """Local refinement from ``start``; returns the best point seen, its loss, evaluations."""
    lower, upper = bounds
    best_x = start.copy()
    best_loss = start_loss
    used = 0

    def keep_best(free_values: FloatArray, value: float) -> None:
        nonlocal best_x, best_loss, used
        used += 1
        if value < best_loss:
            best_x, best_loss = free_values.copy(), value

    def loss_of(free_values: FloatArray) -> float:
        if time.perf_counter() > deadline:
            raise _OutOfTimeError
        value = float(problem.population_loss(expand(free_values[None, :]))[0])
        keep_best(free_values, value)
        return value

    def residuals_of(free_values: FloatArray) -> FloatArray:
        if time.perf_counter() > deadline:
            raise _OutOfTimeError
        res = problem.residuals(expand(free_values[None, :])[0])
        keep_best(free_values, float(res @ res))
        return res

    try:
        if budget.polish == "least_squares":
            least_squares(
                residuals_of,
                np.clip(start, lower, upper),
                bounds=(lower, upper),
                method="trf",
                x_scale="jac",
                max_nfev=budget.polish_max_evals,
            )
        else:
            minimize(
                loss_of,
                start,
                method="L-BFGS-B",
                bounds=list(zip(lower, upper, strict=True)),
                options={"maxfun": budget.polish_max_evals},
            )
    except _OutOfTimeError:
        pass  # the deadline came: keep the best point seen so far
    return best_x, best_loss, used
