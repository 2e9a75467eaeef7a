"""A grey-box model: a readable chain of physical-effect blocks around a hysteresis core.

    GreyBox()                                   # the default chain: the thesis's DRDPI
    GreyBox(core="free_pi")                     # another hysteresis law (models.cores)
    GreyBox(effects=("pneumatic_lag",))         # adding an effect is one line...
    model.with_effect("creep").fit(train)       # ...or one call, warm-started from model
    model.with_core("boucwen").fit(train)       # a core change keeps the blocks

In the model file (``greybox.json``) the chain is the list ``"effects"`` and the core's name;
editing them and refitting (``catheter-lab train greybox --set 'effects=["creep"]' ...``) is
the same thing.

Identification. The core is identified on its own first (or warm-started from the model a
block is added to). Each new block's parameters are then searched over their whole range on
a grid (log-spaced for time constants), so that a block is found even where the core had
mimicked part of it:

* a core whose output is linear in its weights (``free_pi``) is solved again, exactly, at
  every grid point with the block in the chain (variable projection): the core cannot keep
  what it absorbed;
* any other core is held at each grid point.

The best few grid points start a joint least-squares polish (multi-start): of the blocks'
parameters with the linear core's weights solved inside, or of the core's and the blocks'
parameters together. The best polish is kept.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections import OrderedDict
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Final

import numpy as np
import numpy.typing as npt
from scipy import optimize

from catheter_models.errors import ParameterError
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
from catheter_models.models.blocks import FORMS, Block, BlockParam, block, ordered
from catheter_models.models.cores import CORES, Core, DRDPICore, FreePI, make_core, one_blas_thread
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.units import deg_to_rad, pa_to_bar, rad_to_deg

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

GREYBOX_FILE = "greybox.json"
GREYBOX_FORMAT = 2
"""2: the core is named with its settings and values; 1 (read too): the DRDPI only."""

_DRDPI_KEYS: Final = ("n_play", "n_deadband", "rate_filter_s", "budget")
"""Constructor arguments that shape the DRDPI core (kept for format-1 files and callers)."""

REDUCED_COLUMNS: Final = 32
"""Play combinations a linear core's block search works in (then every play again)."""

STARTS: Final = 2
"""Grid points that start a joint polish (multi-start)."""

GRID_POINTS: Final = {1: 12, 2: 6, 3: 4}
"""Grid points per block parameter, by the number of the block's parameters."""


def _grid(p: BlockParam, n_params: int) -> FloatArray:
    """The search grid of one block parameter: log-spaced over a positive range.

    A parameter's ``absent`` value (the block's earlier, simpler form: one creep lag, a lag
    without a flow limit) is always on it, so the search meets the simpler form too.
    """
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
    """Maps bounded parameters to [0, 1] (log for ranges over a decade) for the polish."""

    def __init__(self, low: FloatArray, high: FloatArray) -> None:
        self.low, self.high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        self.log = (self.low > 0.0) & (self.high / np.where(self.low > 0, self.low, 1) > 10.0)

    def to_unit(self, v: FloatArray) -> FloatArray:
        v = np.clip(v, self.low, self.high)
        out = (v - self.low) / (self.high - self.low)
        lg = self.log
        out[lg] = np.log(v[lg] / self.low[lg]) / np.log(self.high[lg] / self.low[lg])
        clipped: FloatArray = np.clip(out, 0.0, 1.0)
        return clipped

    def from_unit(self, u: FloatArray) -> FloatArray:
        u = np.clip(u, 0.0, 1.0)
        out = self.low + u * (self.high - self.low)
        lg = self.log
        out[lg] = self.low[lg] * np.exp(u[lg] * np.log(self.high[lg] / self.low[lg]))
        result: FloatArray = np.asarray(out, dtype=float)
        return result


class GreyBox(Model):
    """A chain of effect blocks around a hysteresis core: pressure [Pa] in, bend [rad] out.

    Input blocks -> core (play, rate dependence, deadband, asymmetry, saturation) -> output
    blocks.

    Args:
        effects: Blocks to add to the core (:data:`~.blocks.FORMS`: the catalogue's and
            its checks'); their order in the chain is fixed by physics (input side, then
            output side).
        core: The hysteresis law (:data:`~.cores.CORES`): ``drdpi`` (the thesis's, default),
            ``free_pi``, ``boucwen``.
        core_settings: The core's structure (see its class), e.g. ``{"n_offsets": 10}``.
        n_play, n_deadband, rate_filter_s, budget: The DRDPI core's structure and search
            effort (the same as ``core_settings`` for ``core="drdpi"``).
        polish_evals: Least-squares evaluations of each joint polish at most.
        seed: Seed of the core's search.
    """

    kind: ClassVar[str] = "greybox"
    direction = "forward"
    requirement: ClassVar[DataRequirement] = DRDPI.requirement

    core_: Core
    blocks_: dict[str, list[float]]

    def __init__(
        self,
        *,
        effects: Sequence[str] = (),
        core: str = "drdpi",
        core_settings: Mapping[str, Any] | None = None,
        n_play: int | None = None,
        n_deadband: int | None = None,
        rate_filter_s: float | None = None,
        budget: Mapping[str, Any] | None = None,
        polish_evals: int = 300,
        seed: int = 0,
    ) -> None:
        if isinstance(effects, str):
            raise ParameterError(f"effects must be a list of names, got the string {effects!r}")
        self.effects = ordered(list(effects))
        # Built once: the polish runs the chain hundreds of times.
        self._blocks: dict[str, Block] = {e: block(e) for e in self.effects}
        settings = dict(core_settings or {})
        legacy = {
            k: v
            for k, v in zip(_DRDPI_KEYS, (n_play, n_deadband, rate_filter_s, budget), strict=True)
            if v is not None
        }
        if legacy and core != "drdpi":
            raise ParameterError(
                f"{', '.join(legacy)} shape the drdpi core; core {core!r} takes core_settings"
            )
        if core == "drdpi":
            settings.setdefault("seed", seed)
        self.core_name = core
        self.core_settings = {**settings, **legacy}
        self._template = make_core(core, self.core_settings)  # checks name and settings now
        if not (isinstance(polish_evals, int) and polish_evals >= 0):
            raise ParameterError(f"polish_evals = {polish_evals!r} must be an integer >= 0")
        self.polish_evals = polish_evals
        self.seed = int(seed)
        self._warm: tuple[Core, dict[str, list[float]]] | None = None
        self._start_blocks: dict[str, list[float]] = {}
        """Block values a core change starts its polish from (no grid: they are known)."""

    # -- the chain ---------------------------------------------------------------------------
    @property
    def chain(self) -> tuple[str, ...]:
        """The chain as a person reads it, input to output."""
        inputs = [e for e in self.effects if FORMS[e].side == "input"]
        outputs = [e for e in self.effects if FORMS[e].side == "output"]
        return (*inputs, self.core_name, *outputs)

    def _fitted_now(self) -> bool:
        return getattr(self, "core_", None) is not None

    def with_effect(self, effect: str) -> GreyBox:
        """This chain plus ``effect``, unfitted, warm-started from this model if fitted."""
        if effect in self.effects:
            raise ParameterError(f"the model has {effect!r} already: {' -> '.join(self.chain)}")
        new = GreyBox(
            effects=(*self.effects, effect),
            core=self.core_name,
            core_settings=self.core_settings,
            polish_evals=self.polish_evals,
            seed=self.seed,
        )
        if self._fitted_now():
            new._warm = (self.core_.copy(), {k: list(v) for k, v in self.blocks_.items()})
        return new

    def with_core(self, core: str, core_settings: Mapping[str, Any] | None = None) -> GreyBox:
        """The same blocks around another core, unfitted; the blocks' values start the search."""
        if core not in CORES:
            raise ParameterError(f"unknown core {core!r}; known cores: {', '.join(CORES)}")
        new = GreyBox(
            effects=self.effects,
            core=core,
            core_settings=core_settings,
            polish_evals=self.polish_evals,
            seed=self.seed,
        )
        if self._fitted_now():
            new._start_blocks = {k: list(v) for k, v in self.blocks_.items()}
        return new

    @classmethod
    def from_drdpi(cls, model: DRDPI) -> GreyBox:
        """The default chain with a fitted DRDPI's parameters (what a diagnosis starts from)."""
        gb = cls(
            n_play=model.n_play, n_deadband=model.n_deadband, rate_filter_s=model.rate_filter_s
        )
        core = gb._template
        assert isinstance(core, DRDPICore)
        core.set_params(model.params_)
        gb._set(core, {}, model.fitted_rate_hz)
        return gb

    @classmethod
    def chain_of(cls, model: Model) -> GreyBox | None:
        """``model`` as the chain the lab edits (None for a black box: no chain to edit).

        A grey box as it is, a fitted DRDPI as the DRDPI core with no blocks. The one place
        a thesis model becomes a chain; the CLI and the diagnosis ask here.
        """
        if isinstance(model, GreyBox):
            return model
        if isinstance(model, DRDPI):
            return cls.from_drdpi(model)
        return None

    def _set(self, core: Core, blocks: Mapping[str, Sequence[float]], rate_hz: float) -> None:
        self.core_ = core
        self.blocks_ = {e: [float(v) for v in blocks[e]] for e in self.effects}
        self.rate_hz_ = float(rate_hz)

    def block_values(self) -> dict[str, dict[str, float]]:
        """Each block's identified parameters by name (SI)."""
        self._fitted()
        return {
            e: {p.name: v for p, v in zip(FORMS[e].params, self.blocks_[e], strict=True)}
            for e in self.effects
        }

    # -- simulation (internal units: bar in, deg out) ----------------------------------------
    def _inputs(
        self, x_bar: FloatArray, rate_hz: float, blocks: Mapping[str, Sequence[float]]
    ) -> FloatArray:
        for e in self.effects:
            if FORMS[e].side == "input":
                x_bar = self._blocks[e].apply(x_bar, rate_hz, blocks[e])
        return x_bar

    def _outputs(
        self, y: FloatArray, rate_hz: float, blocks: Mapping[str, Sequence[float]]
    ) -> FloatArray:
        for e in self.effects:
            if FORMS[e].side == "output":
                y = self._blocks[e].apply(y, rate_hz, blocks[e])
        return y

    def _run(
        self,
        x_bar: FloatArray,
        rate_hz: float,
        core: Callable[[FloatArray], FloatArray],
        blocks: Mapping[str, Sequence[float]],
    ) -> FloatArray:
        return self._outputs(core(self._inputs(x_bar, rate_hz, blocks)), rate_hz, blocks)

    def _fitted(self) -> None:
        if not self._fitted_now():
            raise NotFittedError("greybox model is not fitted: call fit() or load() first")

    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Bend [rad] for a valve pressure signal [Pa gauge], from rest."""
        self._fitted()
        x = pa_to_bar(as_input(input_si, "pressure_pa"))
        core = self.core_
        y = self._run(x, self.rate_hz_, lambda v: core.run(v, self.rate_hz_), self.blocks_)
        out: FloatArray = deg_to_rad(y)
        return out

    def stream(self) -> _GreyBoxStream:
        """Sample by sample, equal to :meth:`predict` (each block streams its own state)."""
        self._fitted()
        return _GreyBoxStream(self)

    # -- identification ------------------------------------------------------------------------
    @one_blas_thread
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Identify the core (unless warm-started) and every block, then polish jointly."""
        t0 = time.perf_counter()
        rate = self._prepare(train, validation)
        xs = [pa_to_bar(r.pressure_pa) for r in train]
        ys = [rad_to_deg(r.angle_rad) for r in train]
        for e in self.effects:
            problem = self._blocks[e].excitation_problem(xs, rate)
            if problem:
                raise ParameterError(f"too little excitation to identify {e}: {problem}")
        start_blocks = dict(self._start_blocks)
        if self._warm is not None:
            core, blocks = self._warm[0].copy(), dict(self._warm[1])
        else:
            core = make_core(self.core_name, self.core_settings)
            core.fit(xs, ys, rate, progress=progress)
            blocks = {}
        new = [e for e in self.effects if e not in blocks and e not in start_blocks]
        blocks.update(start_blocks)
        for e in self.effects:
            blocks.setdefault(e, self._blocks[e].defaults())
        if isinstance(core, FreePI):
            fitter: _Fitter = _LinearFitter(self, core, xs, ys, rate)
        else:
            fitter = _NonlinearFitter(self, core, xs, ys, rate)
        blocks, loss = fitter.search(blocks, new)
        self._set(fitter.core, blocks, rate)
        extra: dict[str, Any] = {
            "chain": list(self.chain),
            "core": {"name": self.core_name, **self.core_.values()},
            "blocks": self.block_values(),
            "train_loss_deg2": loss,
        }
        if validation:
            extra["validation_rmse_deg"] = {
                r.name: float(rad_to_deg(pooled_rmse(self, [r]))) for r in validation
            }
        self.fit_report_ = FitReport(
            duration_s=time.perf_counter() - t0, train_loss=[loss], extra=extra
        )
        return self

    # -- persistence ---------------------------------------------------------------------------
    def _settings(self) -> dict[str, Any]:
        return {
            "effects": list(self.effects),
            "core": self.core_name,
            "core_settings": self.core_settings,
            "polish_evals": self.polish_evals,
            "seed": self.seed,
        }

    def _payload(self) -> dict[str, bytes]:
        self._fitted()
        doc = {
            "format": GREYBOX_FORMAT,
            "effects": list(self.effects),
            "chain": list(self.chain),
            "core": {
                "name": self.core_name,
                "settings": self.core_.settings(),
                "values": self.core_.values(),
            },
            "blocks": self.block_values(),
            "units": {e: {p.name: p.unit for p in FORMS[e].params} for e in self.effects},
        }
        return {GREYBOX_FILE: (json.dumps(doc, indent=2) + "\n").encode()}

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        try:
            doc = json.loads(payload[GREYBOX_FILE])
            effects = doc["effects"]
            raw_blocks = doc["blocks"]
            if doc.get("format", 1) == 1:  # the DRDPI core, its parameters flat
                name, settings, values = "drdpi", dict(doc.get("structure", {})), doc["core"]
            else:
                name = doc["core"]["name"]
                settings, values = dict(doc["core"]["settings"]), doc["core"]["values"]
        except (KeyError, ValueError, TypeError) as exc:
            raise ModelError(f"{GREYBOX_FILE} is malformed: {exc}") from None
        model = cls(effects=effects, core=name, core_settings=settings)
        missing = [e for e in model.effects if e not in raw_blocks]
        if missing:
            raise ModelError(
                f"{GREYBOX_FILE} lists {missing} in 'effects' without identified parameters: "
                "refit it (catheter-lab add / train greybox)"
            )
        blocks = {e: block(e).check(raw_blocks[e]) for e in model.effects}
        rate_hz = saved_rate_hz(manifest, "greybox")
        core = make_core(name, settings)
        core.load_values(values)
        model._set(core, blocks, rate_hz)
        return model


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

    def pack(self, blocks: Mapping[str, Sequence[float]]) -> FloatArray:
        return np.array([v for e in self.model.effects for v in blocks[e]], dtype=float)

    def unpack(self, v: FloatArray) -> dict[str, list[float]]:
        out: dict[str, list[float]] = {e: [] for e in self.model.effects}
        for (e, _), value in zip(self.specs, v, strict=True):
            out[e].append(float(value))
        return out

    def block_bounds(self) -> tuple[FloatArray, FloatArray]:
        return (
            np.array([p.low for _, p in self.specs]),
            np.array([p.high for _, p in self.specs]),
        )

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
        for start in starts:
            self.core = core0.copy()
            polished, value = self.polish(start)
            if best is None or value < best[0]:
                best = (value, polished, self.core)
        assert best is not None
        self.core = best[2]
        return best[1], best[0]


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
        # Blocks' parameters move in [0, 1] (log over ranges wider than a decade): a flow
        # limit of 1e8 Pa/s and a share of 0.2 then take like steps, which a raw vector's
        # relative finite differences and the Jacobian's scaling do not give.
        unit = _Unit(lo_b, hi_b)
        lo = np.concatenate([lo_c, np.zeros(lo_b.size)])
        hi = np.concatenate([hi_c, np.ones(hi_b.size)])
        v0 = np.clip(np.concatenate([core.vector(), unit.to_unit(self.pack(blocks))]), lo, hi)
        n_total = sum(x.size for x in self.xs)

        def residuals(v: FloatArray) -> FloatArray:
            run = core.runner(v[:n_core], self.rate)
            if run is None:
                return np.full(n_total, 1e3)
            bl = self.unpack(unit.from_unit(v[n_core:]))
            return np.concatenate(
                [
                    (self.model._run(x, self.rate, run, bl) - y) * w
                    for x, y, w in zip(self.xs, self.ys, self.weights, strict=True)
                ]
            )

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
        return self.unpack(unit.from_unit(v_best[n_core:])), float(np.sum(residuals(v_best) ** 2))


class _LinearFitter(_Fitter):
    """The core's weights solved exactly for every block setting (variable projection)."""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        self._designs: OrderedDict[tuple[float, ...], list[FloatArray]] = OrderedDict()
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
        search with a new input block also tries the core without them.
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

    def loss(self, blocks: Mapping[str, Sequence[float]]) -> float:
        # The rate factor is searched with the blocks: the core's own, or none (a lag or a
        # delay may be what the core's rate-dependent thresholds were standing in for).
        return min(float(np.sum(self._residuals(blocks, b, passes=1) ** 2)) for b in self.betas)

    def polish(self, blocks: dict[str, list[float]]) -> tuple[dict[str, list[float]], float]:
        lo_b, hi_b = self.block_bounds()
        betas = self.free.betas_s
        beta_hi = max(*betas, 1e-3)
        lo, hi = np.concatenate([[0.0], lo_b]), np.concatenate([[beta_hi], hi_b])
        # The beta that does best with these blocks starts the polish.
        beta0 = min(self.betas, key=lambda b: float(np.sum(self._residuals(blocks, b) ** 2)))
        unit = _Unit(lo, hi)
        v0 = np.concatenate([[beta0], self.pack(blocks)])

        def residuals(u: FloatArray) -> FloatArray:
            v = unit.from_unit(u)
            return self._residuals(self.unpack(v[1:]), float(v[0]))

        v_best = v0
        if self.model.polish_evals > 0 and v0.size > 0:
            u0 = unit.to_unit(v0)
            result = optimize.least_squares(
                residuals,
                u0,
                bounds=(0.0, 1.0),
                method="trf",
                max_nfev=max(8, self.model.polish_evals // 30),
                diff_step=1e-3,
            )
            if 2 * result.cost <= float(np.sum(residuals(u0) ** 2)):
                v_best = unit.from_unit(result.x)
        blocks_best = self.unpack(v_best[1:])
        beta = float(v_best[0])
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


class _GreyBoxStream:
    """Sample-by-sample grey box: each block and the core carry their own state."""

    def __init__(self, model: GreyBox) -> None:
        self._model = model
        self.reset()

    def reset(self) -> None:
        m = self._model
        rate = m.rate_hz_
        self._inputs = [
            m._blocks[e].streamer(rate, m.blocks_[e]) for e in m.effects if FORMS[e].side == "input"
        ]
        self._outputs = [
            m._blocks[e].streamer(rate, m.blocks_[e])
            for e in m.effects
            if FORMS[e].side == "output"
        ]
        self._core = m.core_.streamer(rate)

    def step(self, value: float) -> float:
        x = pa_to_bar(check_finite_step(value, "greybox"))
        for block_step in self._inputs:
            x = block_step(x)
        y = self._core(x)
        for block_step in self._outputs:
            y = block_step(y)
        return float(deg_to_rad(y))
