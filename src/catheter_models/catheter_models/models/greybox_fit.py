"""How a grey-box chain is identified: new blocks searched over their ranges, then a polish.

A core linear in its weights (``free_pi``) is solved again at every grid point of a block's
search (variable projection), in a reduced basis of its play combinations, so an effect the
core could mimic is still found where it belongs; any other core is held while the blocks are
searched, then polished with them. :class:`~catheter_models.models.greybox.GreyBox` picks the
fitter for its core.
"""

from __future__ import annotations

import itertools
import math
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt
from scipy import optimize

import catheter_models.models.cores.base as core_base
from catheter_models.models.base import (
    FloatArray,
)
from catheter_models.models.blocks import FORMS, BlockParam
from catheter_models.models.cores import Core, FreePI
from catheter_models.models.cores.base import _BytesLRU

if TYPE_CHECKING:
    from catheter_models.models.greybox import GreyBox

REDUCED_COLUMNS: Final = 32
"""Play combinations a linear core's block search works in (then every play again)."""

STARTS: Final = 2
"""Grid points that start a joint polish (multi-start)."""

REFINE_GAIN: Final = 0.05
"""Share of the training loss a block's refinement must remove to be kept (refine_forms):
freed parameters always fit a little better, standing in for whatever else the chain
misses (on the simulated rig's 0.2 s lag behind a DRDPI core, 1 %); the Maxwell-slip
catheter's orifice fill, which they describe, gives far more."""

REFINE_EVALS: Final = 12
"""Scalar search steps of a new input block's parameter at each rate factor (refine)."""

GRID_POINTS: Final = {1: 12, 2: 6, 3: 4}
"""Grid points per block parameter, by the number of the block's parameters."""


def _grid(p: BlockParam, n_params: int) -> FloatArray:
    """The search grid of one block parameter: log-spaced over a positive range.

    A parameter's ``absent`` value (the block's earlier, simpler form: one creep lag, a lag
    without a flow limit) is always on it, so the search meets the simpler form too. A
    parameter that is not ``searched`` has that value alone (the polish moves it).
    """
    if not p.searched and p.absent is not None:
        return np.array([p.absent])
    n = p.grid_points or GRID_POINTS.get(n_params, 3)
    if p.low >= 0.0 and p.high > 0.0:
        low = p.low if p.low > 0.0 else 1e-2 * p.high
        points = np.geomspace(low, p.high, n)
        if p.low == 0.0:
            points = np.concatenate([[0.0], points])
    else:
        points = np.linspace(p.low, p.high, n + 1 - n % 2)  # odd: 0 is on the grid
    if p.absent is not None and p.low <= p.absent <= p.high:
        near = np.isclose(points, p.absent, rtol=1e-9, atol=0.0)
        points = np.where(near, p.absent, points) if near.any() else np.sort([*points, p.absent])
    return np.asarray(points, dtype=float)


class _Unit:
    """Maps bounded parameters to [1, 2] (log for ranges over a decade) for the polish.

    Not [0, 1]: the polish's finite differences take a step relative to the value
    (``diff_step`` times it), so a parameter at the bottom of its range (started there, as
    bounded least squares puts it, at 1e-10) got a step of 1e-13 and barely moved: a
    viscous_pi core started with no viscosity on a law with 3 ms of it stopped at 0.17 ms
    (tests/catheter_models/models/test_viscous_pi.py). On [1, 2] every parameter takes a
    step of 0.1-0.2 % of its range.
    """

    LOW: Final = 1.0
    HIGH: Final = 2.0

    def __init__(self, low: FloatArray, high: FloatArray) -> None:
        self.low, self.high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        self.log = (self.low > 0.0) & (self.high / np.where(self.low > 0, self.low, 1) > 10.0)

    def to_unit(self, v: FloatArray) -> FloatArray:
        v = np.clip(v, self.low, self.high)
        out = (v - self.low) / (self.high - self.low)
        lg = self.log
        out[lg] = np.log(v[lg] / self.low[lg]) / np.log(self.high[lg] / self.low[lg])
        clipped: FloatArray = self.LOW + np.clip(out, 0.0, 1.0)
        return clipped

    def from_unit(self, u: FloatArray) -> FloatArray:
        u = np.clip(np.asarray(u, dtype=float) - self.LOW, 0.0, 1.0)
        out = self.low + u * (self.high - self.low)
        lg = self.log
        out[lg] = self.low[lg] * np.exp(u[lg] * np.log(self.high[lg] / self.low[lg]))
        result: FloatArray = np.asarray(out, dtype=float)
        return result


class _Fitter:
    """Searches new blocks' parameters and polishes the chain for one kind of core."""

    def __init__(
        self,
        model: GreyBox,
        core: Core,
        xs: Sequence[FloatArray],
        ys: Sequence[FloatArray],
        rate: float,
    ) -> None:
        self.model, self.core, self.xs, self.ys, self.rate = model, core, xs, ys, rate
        self.weights = [1.0 / math.sqrt(x.size) for x in xs]
        self.specs = [(e, p) for e in model.effects for p in FORMS[e].params]
        self.refining: frozenset[str] = frozenset()
        """The blocks whose parameters that are not ``searched`` the polish moves
        (:meth:`refine_forms`); held at their values otherwise."""

    def pack(self, blocks: Mapping[str, Sequence[float]]) -> FloatArray:
        return np.array([v for e in self.model.effects for v in blocks[e]], dtype=float)

    def unpack(self, v: FloatArray) -> dict[str, list[float]]:
        out: dict[str, list[float]] = {e: [] for e in self.model.effects}
        for (e, _), value in zip(self.specs, v, strict=True):
            out[e].append(float(value))
        return out

    def moving(self) -> npt.NDArray[np.bool_]:
        """Which of the blocks' parameters the polish moves."""
        return np.array([p.searched or e in self.refining for e, p in self.specs], dtype=bool)

    def block_bounds(self) -> tuple[FloatArray, FloatArray]:
        """The bounds of the parameters the polish moves."""
        moving = self.moving()
        return (
            np.array([p.low for _, p in self.specs])[moving],
            np.array([p.high for _, p in self.specs])[moving],
        )

    def pack_moving(self, blocks: Mapping[str, Sequence[float]]) -> FloatArray:
        """The values of the parameters the polish moves."""
        return self.pack(blocks)[self.moving()]

    def unpack_moving(
        self, v: FloatArray, held: Mapping[str, Sequence[float]]
    ) -> dict[str, list[float]]:
        """``v`` for the parameters the polish moves, ``held``'s values for the rest."""
        full = self.pack(held)
        full[self.moving()] = v
        return self.unpack(full)

    def loss(self, blocks: Mapping[str, Sequence[float]]) -> float:
        raise NotImplementedError

    @staticmethod
    def _grid_of(effect: str) -> list[list[float]]:
        """The first grid of a new block: every parameter's, or the earlier form's alone."""
        params = FORMS[effect].params
        if not FORMS[effect].staged_search:
            return [
                [float(c) for c in combo]
                for combo in itertools.product(*(_grid(p, len(params)) for p in params))
            ]
        earlier = [p for p in params if p.absent is None]
        grids = [
            _grid(p, len(earlier)) if p.absent is None else np.array([p.absent]) for p in params
        ]
        return [[float(c) for c in combo] for combo in itertools.product(*grids)]

    def prepare(self, blocks: Mapping[str, Sequence[float]], new: Sequence[str]) -> None:
        """Set-up before a search (nothing by default)."""

    def polish(self, blocks: dict[str, list[float]]) -> tuple[dict[str, list[float]], float]:
        raise NotImplementedError

    def refine(
        self, base: Mapping[str, list[float]], effect: str, grid: Sequence[Sequence[float]]
    ) -> list[tuple[float, dict[str, list[float]]]]:
        """Points to score beside the grid of a new block (none by default)."""
        return []

    def search(
        self, blocks: dict[str, list[float]], new: Sequence[str]
    ) -> tuple[dict[str, list[float]], float]:
        """Grid over each new block (the rest held), then polish from the best few points."""
        self.prepare(blocks, new)
        starts = [dict(blocks)]
        for e in new:
            scored: list[tuple[float, dict[str, list[float]]]] = []
            base = starts[0]
            params = FORMS[e].params
            for combo in self._grid_of(e):
                trial = {**base, e: combo}
                scored.append((self.loss(trial), trial))
            scored += self.refine(base, e, [t[1][e] for t in scored])
            earliest: list[dict[str, list[float]]] = []
            if FORMS[e].staged_search:
                # Then the added parameters, around the earlier form's best points; the
                # earlier form's best starts a polish too, so the search does at least
                # what it did before the block grew (a coarse fit of the added parameters
                # can lead the polish to a worse optimum).
                scored.sort(key=lambda t: t[0])
                earliest = [scored[0][1]]
                added = [i for i, p in enumerate(params) if p.absent is not None]
                grids = [_grid(params[i], len(params)) for i in added]
                for _, point in scored[:STARTS]:
                    for combo_added in itertools.product(*grids):
                        values = list(point[e])
                        for i, v in zip(added, combo_added, strict=True):
                            values[i] = float(v)
                        if values == point[e]:
                            continue  # the earlier form's point: scored already
                        trial = {**base, e: values}
                        scored.append((self.loss(trial), trial))
            scored.sort(key=lambda t: t[0])
            starts = [t[1] for t in scored[:STARTS]]
            if earliest and earliest[0] not in starts:
                starts[-1] = earliest[0]
        best: tuple[float, dict[str, list[float]], Core] | None = None
        core0 = self.core
        self.refining = frozenset()
        for start in starts:
            self.core = core0.copy()
            polished, value = self.polish(start)
            if best is None or value < best[0]:
                best = (value, polished, self.core)
        assert best is not None
        self.core = best[2]
        return self.refine_forms(best[1], best[0])

    def refine_forms(
        self, blocks: dict[str, list[float]], loss: float
    ) -> tuple[dict[str, list[float]], float]:
        """A second polish that moves the parameters not ``searched``, where the data show them.

        The first polish held them, so the chain is first at least what the blocks' earlier
        forms reach; only a block whose fitted values show what they refine
        (:meth:`Block.refines`: a lag's flow limit that the fill reaches) opens them, and the
        refined chain is kept only where it removes :data:`REFINE_GAIN` of the training loss.
        """
        opened = [
            e
            for e in self.model.effects
            if any(not p.searched for p in FORMS[e].params)
            and self.model._blocks[e].refines(blocks[e])
        ]
        if not opened:
            return blocks, loss
        core = self.core.copy()
        self.refining = frozenset(opened)
        try:
            refined, value = self.polish({e: list(v) for e, v in blocks.items()})
        finally:
            self.refining = frozenset()
        if value < (1.0 - REFINE_GAIN) * loss:
            return refined, value
        self.core = core
        return blocks, loss


class _NonlinearFitter(_Fitter):
    """Core held during the grid; polish of core and blocks together."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        rate = self.rate
        self._held = lambda x: self.core.run(x, rate)

    def loss(self, blocks: Mapping[str, Sequence[float]]) -> float:
        return float(
            sum(
                np.mean((self.model._run(x, self.rate, self._held, blocks) - y) ** 2)
                for x, y in zip(self.xs, self.ys, strict=True)
            )
        )

    def polish(self, blocks: dict[str, list[float]]) -> tuple[dict[str, list[float]], float]:
        core = self.core
        lo_c, hi_c = core.bounds()
        lo_b, hi_b = self.block_bounds()
        n_core = lo_c.size
        # Blocks' parameters move in [1, 2] (log over ranges wider than a decade): a flow
        # limit of 1e8 Pa/s and a share of 0.2 then take like steps, which a raw vector's
        # relative finite differences and the Jacobian's scaling do not give.
        unit = _Unit(lo_b, hi_b)
        lo = np.concatenate([lo_c, np.full(lo_b.size, unit.LOW)])
        hi = np.concatenate([hi_c, np.full(hi_b.size, unit.HIGH)])
        v0 = np.clip(
            np.concatenate([core.vector(), unit.to_unit(self.pack_moving(blocks))]), lo, hi
        )
        n_total = sum(x.size for x in self.xs)
        runners = core.polish_runners(self.rate)
        model, rate = self.model, self.rate
        inputs = [e for e in model.effects if FORMS[e].side == "input"]
        # Where the finite differences move an output block's parameter, the core's output
        # is the point's own: kept, not run again (the core is most of a residual's cost);
        # where they move the core's, so are the input blocks' (a lag's fill is the rest).
        core_outputs = _BytesLRU(core_base.POLISH_CACHE_BYTES)
        core_inputs = _BytesLRU(core_base.POLISH_CACHE_BYTES)

        def residuals(v: FloatArray) -> FloatArray:
            bl = self.unpack_moving(unit.from_unit(v[n_core:]), blocks)
            at_core = v[:n_core].tobytes()
            at_inputs = tuple(value for e in inputs for value in bl[e])
            out = []
            run: Callable[[FloatArray], FloatArray] | None = None
            for i, (x, y, w) in enumerate(zip(self.xs, self.ys, self.weights, strict=True)):
                y_core = core_outputs.get((i, at_core, at_inputs))
                if y_core is None:
                    run = run or runners(v[:n_core])
                    if run is None:
                        return np.full(n_total, 1e3)
                    x_core = core_inputs.get((i, at_inputs))
                    if x_core is None:
                        x_core = model._inputs(x, rate, bl)
                        core_inputs.put((i, at_inputs), x_core)
                    y_core = run(x_core)
                    core_outputs.put((i, at_core, at_inputs), y_core)
                out.append((model._outputs(y_core, rate, bl) - y) * w)
            return np.concatenate(out)

        v_best = v0
        if self.model.polish_evals > 0:
            result = optimize.least_squares(
                residuals,
                v0,
                bounds=(lo, hi),
                method="trf",
                max_nfev=self.model.polish_evals,
                x_scale="jac",
                diff_step=1e-3,
            )
            if 2 * result.cost <= float(np.sum(residuals(v0) ** 2)):
                v_best = result.x
        core.set_vector(v_best[:n_core])
        polished = self.unpack_moving(unit.from_unit(v_best[n_core:]), blocks)
        return polished, float(np.sum(residuals(v_best) ** 2))


class _LinearFitter(_Fitter):
    """The core's weights solved exactly for every block setting (variable projection)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._designs: OrderedDict[tuple[float, ...], list[FloatArray]] = OrderedDict()
        self._scores: dict[tuple[float, ...], float] = {}
        self.basis: FloatArray | None = None
        self.betas = {self.free.beta_s or 0.0}

    @property
    def free(self) -> FreePI:
        """The core being fitted (a copy per start of the polish)."""
        assert isinstance(self.core, FreePI)
        return self.core

    def prepare(self, blocks: Mapping[str, Sequence[float]], new: Sequence[str]) -> None:
        """Reduce the design; free the rate factor when an input block is new.

        The core's rate-dependent thresholds may have stood in for a lag or a delay, so a
        search with a new input block also tries the core without them (and :meth:`refine`
        looks between the grid's points at each).
        """
        if any(FORMS[e].side == "input" for e in new):
            self.betas = {self.free.beta_s or 0.0, 0.0}
        self.reduce(blocks)

    def reduce(self, blocks: Mapping[str, Sequence[float]]) -> None:
        """Search in the span of the core's strongest play combinations (and its fit).

        The blocks act on every column of the design; on 20-40 combinations instead of
        every play the search is several times faster, and the final weights are solved
        on the whole design again.
        """
        beta = self.free.beta_s or 0.0
        gram = sum(a.T @ a / a.shape[0] for a in self._design(blocks, beta))
        _, vectors = np.linalg.eigh(np.asarray(gram))
        keep = [vectors[:, ::-1][:, :REDUCED_COLUMNS]]
        if self.free.weights is not None:
            keep.insert(0, self.free.weights[:, None])
        q, _ = np.linalg.qr(np.hstack(keep))
        self.basis = q
        self._designs.clear()
        self._scores.clear()

    def _design(self, blocks: Mapping[str, Sequence[float]], beta: float) -> list[FloatArray]:
        """Per recording: the core's plays on the input blocks' output (a small cache)."""
        model = self.model
        key = (beta, *(v for e in model.effects if FORMS[e].side == "input" for v in blocks[e]))
        if key in self._designs:
            self._designs.move_to_end(key)
            return self._designs[key]
        designs = [
            self.free.design(model._inputs(x, self.rate, blocks), self.rate, beta) for x in self.xs
        ]
        if self.basis is not None:
            designs = [a @ self.basis for a in designs]
        self._designs[key] = designs
        if len(self._designs) > 3:
            self._designs.popitem(last=False)
        return designs

    def _solve(
        self, blocks: Mapping[str, Sequence[float]], beta: float, *, passes: int = 2
    ) -> tuple[FloatArray, list[FloatArray], list[FloatArray]]:
        """Weights, and per recording the design through the output blocks and its offset.

        The tip's damping follows the bend entering it, which the weights make: ``passes``
        solves, each scheduling the tip by the previous weights' bend (the grid takes one).
        """
        model = self.model
        outputs = [e for e in model.effects if FORMS[e].side == "output"]
        w = self.free.weights
        if w is not None and self.basis is not None:
            w = self.basis.T @ w
        designs = self._design(blocks, beta)
        passes = passes if any(FORMS[e].scheduled for e in outputs) else 1
        for _ in range(passes):
            mats, offsets = [], []
            for a in designs:
                m = np.zeros((a.shape[0], a.shape[1] + 1))  # last column: running offset
                m[:, :-1] = a
                for e in outputs:
                    ref = m[:, :-1] @ w + m[:, -1] if w is not None else m[:, :-1].mean(axis=1)
                    m = model._blocks[e].apply_columns(m, self.rate, blocks[e], ref)
                mats.append(m[:, :-1])
                offsets.append(m[:, -1])
            w, _ = self.free.solve(mats, [y - c for y, c in zip(self.ys, offsets, strict=True)])
        assert w is not None
        return w, mats, offsets

    def _residuals(
        self, blocks: Mapping[str, Sequence[float]], beta: float, *, passes: int = 2
    ) -> FloatArray:
        w, mats, offsets = self._solve(blocks, beta, passes=passes)
        return np.concatenate(
            [
                (m @ w + c - y) * k
                for m, c, y, k in zip(mats, offsets, self.ys, self.weights, strict=True)
            ]
        )

    def refine(
        self, base: Mapping[str, list[float]], effect: str, grid: Sequence[Sequence[float]]
    ) -> list[tuple[float, dict[str, list[float]]]]:
        """For a new input block: its best value at each rate factor, between grid points.

        A delay and the core's rate factor trade along a narrow, curved valley: a play whose
        threshold widens by ``beta`` times the speed lags a ramp by ``beta``, so on ramps a
        delay ``d`` and a factor ``beta`` with the same ``d + beta`` are alike, and only the
        steps' onsets and the reversals tell them apart. A grid point a few ms off the
        valley's floor scores worse than a far smaller delay at the core's own factor (a
        rate-independent law behind 40 ms: 37.5 ms on the grid scored 0.0024 without the
        factor, 0 ms with it 0.0020, 40 ms 0.0012), so the polish started beside the core's
        factor and stopped half-way. So where the grid moves one parameter (a delay, the
        earlier form of a lag), each rate factor gets a bounded scalar search of that
        parameter around its best grid point, and those points join the grid's.
        """
        spec = FORMS[effect]
        if spec.side != "input" or len(self.betas) < 2 or len(grid) < 3:
            return []
        moving = [i for i in range(len(grid[0])) if len({g[i] for g in grid}) > 1]
        if len(moving) != 1:
            return []
        i = moving[0]
        values = sorted({float(g[i]) for g in grid})
        template = list(grid[0])
        unit = _Unit(np.array([spec.params[i].low]), np.array([spec.params[i].high]))

        def trial(value: float) -> dict[str, list[float]]:
            return {**base, effect: [*template[:i], value, *template[i + 1 :]]}

        def from_unit(u: float) -> float:
            return float(unit.from_unit(np.array([u]))[0])

        grid_u = [float(unit.to_unit(np.array([v]))[0]) for v in values]
        out: list[tuple[float, dict[str, list[float]]]] = []
        for beta in sorted(self.betas):
            # The grid's own values (scored already at this factor), then between them.
            k = int(np.argmin([self._score(trial(v), beta) for v in values]))
            found = optimize.minimize_scalar(
                lambda u, beta=beta: self._score(trial(from_unit(u)), beta),
                bounds=(grid_u[max(k - 1, 0)], grid_u[min(k + 1, len(grid_u) - 1)]),
                method="bounded",
                options={"xatol": 2e-3, "maxiter": REFINE_EVALS},
            )
            best = trial(from_unit(float(found.x)))
            out.append((self.loss(best), best))
        return out

    def _score(self, blocks: Mapping[str, Sequence[float]], beta: float) -> float:
        """The search's loss at ``blocks`` and rate factor ``beta`` (kept: refine asks again)."""
        key = (beta, *self.pack(blocks))
        if key not in self._scores:
            self._scores[key] = float(np.sum(self._residuals(blocks, beta, passes=1) ** 2))
        return self._scores[key]

    def loss(self, blocks: Mapping[str, Sequence[float]]) -> float:
        # The rate factor is searched with the blocks: the core's own, or none (a lag or a
        # delay may be what the core's rate-dependent thresholds were standing in for).
        return min(self._score(blocks, b) for b in self.betas)

    def polish(self, blocks: dict[str, list[float]]) -> tuple[dict[str, list[float]], float]:
        self._scores.clear()  # a scheduled block's scores follow the weights the polish moves
        lo_b, hi_b = self.block_bounds()
        free, rate = self.free, self.rate
        beta_hi = max(*free.betas_s, 1e-3)
        # The structure number moves in the core's own coordinate, one it acts on from its
        # lower bound (a viscous lag's pole, not its time constant).
        lo = np.concatenate([[free.beta_coordinate(0.0, rate)], lo_b])
        hi = np.concatenate([[free.beta_coordinate(beta_hi, rate)], hi_b])
        # The beta that does best with these blocks starts the polish.
        beta0 = min(self.betas, key=lambda b: float(np.sum(self._residuals(blocks, b) ** 2)))
        unit = _Unit(lo, hi)
        v0 = np.concatenate([[free.beta_coordinate(beta0, rate)], self.pack_moving(blocks)])

        def residuals(u: FloatArray) -> FloatArray:
            v = unit.from_unit(u)
            return self._residuals(
                self.unpack_moving(v[1:], blocks), free.beta_from_coordinate(v[0], rate)
            )

        v_best = v0
        if self.model.polish_evals > 0 and v0.size > 0:
            u0 = unit.to_unit(v0)
            result = optimize.least_squares(
                residuals,
                u0,
                bounds=(unit.LOW, unit.HIGH),
                method="trf",
                max_nfev=max(8, self.model.polish_evals // 30),
                diff_step=1e-3,
            )
            if 2 * result.cost <= float(np.sum(residuals(u0) ** 2)):
                v_best = unit.from_unit(result.x)
        blocks_best = self.unpack_moving(v_best[1:], blocks)
        beta = free.beta_from_coordinate(float(v_best[0]), rate)
        basis, self.basis = self.basis, None  # the final weights on every play
        self._designs.clear()
        w, _, _ = self._solve(blocks_best, beta)
        self.basis = basis
        self._designs.clear()
        self.free.beta_s, self.free.weights = beta, w
        return blocks_best, float(np.sum(self._residuals_full(blocks_best, beta) ** 2))

    def _residuals_full(self, blocks: Mapping[str, Sequence[float]], beta: float) -> FloatArray:
        basis, self.basis = self.basis, None
        self._designs.clear()
        try:
            return self._residuals(blocks, beta)
        finally:
            self.basis = basis
            self._designs.clear()
