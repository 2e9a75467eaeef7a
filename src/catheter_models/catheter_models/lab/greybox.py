"""A grey-box model: a readable chain of physical-effect blocks around the thesis's DRDPI.

    GreyBox()                                   # the default chain: the DRDPI
    GreyBox(effects=("pneumatic_lag",))         # adding an effect is one line...
    model.with_effect("creep").fit(train)       # ...or one call, warm-started from model

In the model file (``greybox.json``) the chain is the list ``"effects"``; editing it and
refitting (``catheter-lab train greybox --set 'effects=["creep"]' ...``) is the same thing.

Identification: the DRDPI core is identified as the DRDPI is (global search, then polish),
unless the model is warm-started from a fitted one; each block is then initialised by a
coarse grid over its parameters with the rest held, and finally every parameter, core and
blocks together, is polished by least squares on eq. 5.12's residuals. A warm-started refit
(what a diagnosis runs once per candidate effect) takes seconds.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, ClassVar, Self

import numpy as np
import numpy.typing as npt
from scipy import optimize

from catheter_models.errors import ParameterError
from catheter_models.hysteresis import operators as op
from catheter_models.lab.blocks import BLOCKS, Block, block, ordered
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
)
from catheter_models.models.drdpi import (
    DRDPI,
    DRDPIParams,
    params_to_search,
    rate_alpha,
    search_to_params,
)
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.models.identify import Budget
from catheter_models.units import deg_to_rad, pa_to_bar, rad_to_deg

GREYBOX_FILE = "greybox.json"
GREYBOX_FORMAT = 1


class GreyBox(Model):
    """A chain of effect blocks around the DRDPI: valve pressure [Pa] in, bend [rad] out.

    Input blocks -> DRDPI (play, rate dependence, deadband, asymmetry, saturation) -> output
    blocks.

    Args:
        effects: Catalogue effects to add to the default chain (:data:`~.blocks.BLOCKS`);
            their order in the chain is fixed by physics (input side, then output side).
        n_play, n_deadband, rate_filter_s: The DRDPI core's structure (see DRDPI).
        budget: Effort of the core's global search when not warm-started.
        polish_evals: Least-squares evaluations of the joint polish at most.
        seed: Seed of the core's search.
    """

    kind: ClassVar[str] = "greybox"
    direction = "forward"
    requirement: ClassVar[DataRequirement] = DRDPI.requirement

    core_: DRDPIParams
    blocks_: dict[str, list[float]]

    def __init__(
        self,
        *,
        effects: Sequence[str] = (),
        n_play: int = 10,
        n_deadband: int = 4,
        rate_filter_s: float = 0.02,
        budget: Budget | Mapping[str, Any] | None = None,
        polish_evals: int = 300,
        seed: int = 0,
    ) -> None:
        if isinstance(effects, str):
            raise ParameterError(f"effects must be a list of names, got the string {effects!r}")
        self.effects = ordered(list(effects))
        # Built once: the polish runs the chain hundreds of times.
        self._blocks: dict[str, Block] = {e: block(e) for e in self.effects}
        self._core_model = DRDPI(
            n_play=n_play,
            n_deadband=n_deadband,
            rate_filter_s=rate_filter_s,
            budget=budget,
            seed=seed,
        )
        self.n_play, self.n_deadband, self.rate_filter_s = n_play, n_deadband, rate_filter_s
        self.budget = self._core_model.budget
        if not (isinstance(polish_evals, int) and polish_evals >= 0):
            raise ParameterError(f"polish_evals = {polish_evals!r} must be an integer >= 0")
        self.polish_evals = polish_evals
        self.seed = int(seed)
        self._warm: tuple[DRDPIParams, dict[str, list[float]]] | None = None

    # -- the chain ---------------------------------------------------------------------------
    @property
    def chain(self) -> tuple[str, ...]:
        """The chain as a person reads it, input to output."""
        inputs = [e for e in self.effects if BLOCKS[e].side == "input"]
        outputs = [e for e in self.effects if BLOCKS[e].side == "output"]
        return (*inputs, "drdpi", *outputs)

    def with_effect(self, effect: str) -> GreyBox:
        """This chain plus ``effect``, unfitted, warm-started from this model if fitted."""
        if effect in self.effects:
            raise ParameterError(f"the model has {effect!r} already: {' -> '.join(self.chain)}")
        new = GreyBox(effects=(*self.effects, effect), **self._structure(), **self._effort())
        if getattr(self, "core_", None) is not None:
            new._warm = (self.core_, {k: list(v) for k, v in self.blocks_.items()})
        return new

    @classmethod
    def from_drdpi(cls, model: DRDPI) -> GreyBox:
        """The default chain with a fitted DRDPI's parameters (what a diagnosis starts from)."""
        gb = cls(
            n_play=model.n_play, n_deadband=model.n_deadband, rate_filter_s=model.rate_filter_s
        )
        gb._set(model.params_, {}, model.fitted_rate_hz)
        return gb

    def _structure(self) -> dict[str, Any]:
        return {
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
        }

    def _effort(self) -> dict[str, Any]:
        return {
            "budget": self.budget.to_dict(),
            "polish_evals": self.polish_evals,
            "seed": self.seed,
        }

    def _set(
        self, core: DRDPIParams, blocks: Mapping[str, Sequence[float]], rate_hz: float
    ) -> None:
        self.core_ = core
        self.blocks_ = {e: [float(v) for v in blocks[e]] for e in self.effects}
        self.rate_hz_ = float(rate_hz)
        self._coef = op.drdpi_coefficients(
            core.as_array(),
            self.n_play,
            self.n_deadband,
            self.rate_hz_,
            rate_alpha(self.rate_filter_s, self.rate_hz_),
        )

    def block_values(self) -> dict[str, dict[str, float]]:
        """Each block's identified parameters by name (SI)."""
        self._fitted()
        return {
            e: {p.name: v for p, v in zip(BLOCKS[e].params, self.blocks_[e], strict=True)}
            for e in self.effects
        }

    # -- simulation (internal units: bar in, deg out) ----------------------------------------
    def _run(
        self,
        x_bar: FloatArray,
        rate_hz: float,
        coef: FloatArray,
        blocks: Mapping[str, Sequence[float]],
    ) -> FloatArray:
        for e in self.effects:
            if BLOCKS[e].side == "input":
                x_bar = self._blocks[e].apply(x_bar, rate_hz, blocks[e])
        y = np.empty(x_bar.size)
        state = np.zeros(op.chain_state_size(coef))
        op.chain_run(np.ascontiguousarray(x_bar), coef, state, y)
        for e in self.effects:
            if BLOCKS[e].side == "output":
                y = self._blocks[e].apply(y, rate_hz, blocks[e])
        return y

    def _fitted(self) -> None:
        if getattr(self, "core_", None) is None:
            raise NotFittedError("greybox model is not fitted: call fit() or load() first")

    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Bend [rad] for a valve pressure signal [Pa gauge], from rest."""
        self._fitted()
        x = pa_to_bar(as_input(input_si, "pressure_pa"))
        out: FloatArray = deg_to_rad(self._run(x, self.rate_hz_, self._coef, self.blocks_))
        return out

    def stream(self) -> _GreyBoxStream:
        """Sample by sample, equal to :meth:`predict` (each block streams its own state)."""
        self._fitted()
        return _GreyBoxStream(self)

    # -- identification ------------------------------------------------------------------------
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Identify the core (unless warm-started) and every block, then polish all jointly."""
        t0 = time.perf_counter()
        rate = self._prepare(train, validation)
        xs = [pa_to_bar(r.pressure_pa) for r in train]
        ys = [rad_to_deg(r.angle_rad) for r in train]
        for e in self.effects:
            problem = self._blocks[e].excitation_problem(xs, rate)
            if problem:
                raise ParameterError(f"too little excitation to identify {e}: {problem}")
        if self._warm is not None:
            core, blocks = self._warm[0], dict(self._warm[1])
        else:
            core_model = DRDPI(**self._structure(), budget=self.budget, seed=self.seed)
            core = core_model.fit(train, progress=progress).params_
            blocks = {}
        for e in self.effects:
            blocks.setdefault(e, self._blocks[e].defaults())
        alpha = rate_alpha(self.rate_filter_s, rate)

        def coef_of(theta: FloatArray) -> FloatArray:
            c: FloatArray = op.drdpi_coefficients(theta, self.n_play, self.n_deadband, rate, alpha)
            return c

        def loss(coef: FloatArray, bl: Mapping[str, Sequence[float]]) -> float:
            return float(
                sum(
                    np.mean((self._run(x, rate, coef, bl) - y) ** 2)
                    for x, y in zip(xs, ys, strict=True)
                )
            )

        # Blocks new to the chain start from a coarse grid, the core and other blocks held.
        coef0 = coef_of(core.as_array())
        new = [e for e in self.effects if self._warm is None or e not in self._warm[1]]
        for e in new:
            grids = [
                np.geomspace(max(p.low, 1e-3 * p.high), p.high, 9)
                if p.low >= 0
                else np.linspace(p.low, p.high, 9)
                for p in BLOCKS[e].params
            ]
            best = (loss(coef0, blocks), list(blocks[e]))
            for combo in itertools.product(*grids):
                trial = {**blocks, e: list(combo)}
                value = loss(coef0, trial)
                if value < best[0]:
                    best = (value, list(combo))
            blocks[e] = best[1]
        core, blocks, polish_loss = self._polish(
            core=core, blocks=blocks, xs=xs, ys=ys, rate=rate, coef_of=coef_of
        )
        self._set(core, blocks, rate)
        extra: dict[str, Any] = {
            "chain": list(self.chain),
            "core": core.to_dict(),
            "blocks": self.block_values(),
            "train_loss_deg2": polish_loss,
        }
        if validation:
            extra["validation_rmse_deg"] = {
                r.name: float(rad_to_deg(pooled_rmse(self, [r]))) for r in validation
            }
        self.fit_report_ = FitReport(
            duration_s=time.perf_counter() - t0, train_loss=[polish_loss], extra=extra
        )
        return self

    def _polish(
        self,
        *,
        core: DRDPIParams,
        blocks: dict[str, list[float]],
        xs: Sequence[FloatArray],
        ys: Sequence[FloatArray],
        rate: float,
        coef_of: Callable[[FloatArray], FloatArray],
    ) -> tuple[DRDPIParams, dict[str, list[float]], float]:
        """Least squares over the core's free search coordinates and every block parameter."""
        bounds = self._core_model.bounds
        free = bounds.free
        lower_core = np.asarray(bounds.lower)[free]
        upper_core = np.asarray(bounds.upper)[free]
        search0 = params_to_search(core.as_array()[None, :])[0]
        block_specs = [(e, p) for e in self.effects for p in BLOCKS[e].params]
        lo = np.concatenate([lower_core, [p.low for _, p in block_specs]])
        hi = np.concatenate([upper_core, [p.high for _, p in block_specs]])
        v0 = np.concatenate([search0[free], [v for e in self.effects for v in blocks[e]]])
        v0 = np.clip(v0, lo, hi)
        weights = [1.0 / math.sqrt(x.size) for x in xs]

        def unpack(v: FloatArray) -> tuple[FloatArray, dict[str, list[float]]]:
            search = search0.copy()
            search[free] = v[: free.sum()]
            theta = search_to_params(search[None, :])[0]
            out: dict[str, list[float]] = {e: [] for e in self.effects}
            for (e, _), value in zip(block_specs, v[free.sum() :], strict=True):
                out[e].append(float(value))
            return theta, out

        def residuals(v: FloatArray) -> FloatArray:
            theta, bl = unpack(v)
            margin = float(op.drdpi_monotone_margin(theta, self.n_play, self.n_deadband))
            if not margin > 0.0:
                return np.full(sum(x.size for x in xs), 1e3 * (1.0 - margin))
            coef = coef_of(theta)
            return np.concatenate(
                [
                    (self._run(x, rate, coef, bl) - y) * w
                    for x, y, w in zip(xs, ys, weights, strict=True)
                ]
            )

        if self.polish_evals > 0:
            result = optimize.least_squares(
                residuals,
                v0,
                bounds=(lo, hi),
                method="trf",
                max_nfev=self.polish_evals,
                x_scale="jac",
                diff_step=1e-3,
            )
            v_best = result.x if 2 * result.cost <= float(np.sum(residuals(v0) ** 2)) else v0
        else:
            v_best = v0
        theta, bl = unpack(v_best)
        final = float(np.sum(residuals(v_best) ** 2))
        return DRDPIParams.from_array(theta), bl, final

    # -- persistence ---------------------------------------------------------------------------
    def _settings(self) -> dict[str, Any]:
        return {"effects": list(self.effects), **self._structure(), **self._effort()}

    def _payload(self) -> dict[str, bytes]:
        self._fitted()
        doc = {
            "format": GREYBOX_FORMAT,
            "effects": list(self.effects),
            "chain": list(self.chain),
            "structure": self._structure(),
            "core": self.core_.to_dict(),
            "blocks": self.block_values(),
            "units": {e: {p.name: p.unit for p in BLOCKS[e].params} for e in self.effects},
        }
        return {GREYBOX_FILE: (json.dumps(doc, indent=2) + "\n").encode()}

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        try:
            doc = json.loads(payload[GREYBOX_FILE])
            effects = doc["effects"]
            core = DRDPIParams.from_dict(doc["core"])
            raw_blocks = doc["blocks"]
        except (KeyError, ValueError, TypeError) as exc:
            raise ModelError(f"{GREYBOX_FILE} is malformed: {exc}") from None
        model = cls(effects=effects, **doc.get("structure", {}))
        missing = [e for e in model.effects if e not in raw_blocks]
        if missing:
            raise ModelError(
                f"{GREYBOX_FILE} lists {missing} in 'effects' without identified parameters: "
                "refit it (catheter-lab add / train greybox)"
            )
        blocks = {e: block(e).check(raw_blocks[e]) for e in model.effects}
        rate = manifest.metrics.get("rate_hz")
        if not isinstance(rate, (int, float)):
            raise ModelError("greybox manifest metrics lack a valid 'rate_hz'")
        model._set(core, blocks, float(rate))
        return model


class _GreyBoxStream:
    """Sample-by-sample grey box: each block and the DRDPI core carry their own state."""

    def __init__(self, model: GreyBox) -> None:
        self._model = model
        self.reset()

    def reset(self) -> None:
        m = self._model
        rate = m.rate_hz_
        self._inputs = [
            m._blocks[e].streamer(rate, m.blocks_[e])
            for e in m.effects
            if BLOCKS[e].side == "input"
        ]
        self._outputs = [
            m._blocks[e].streamer(rate, m.blocks_[e])
            for e in m.effects
            if BLOCKS[e].side == "output"
        ]
        self._state = np.zeros(op.chain_state_size(m._coef))
        self._x = np.zeros(1)
        self._y = np.zeros(1)

    def step(self, value: float) -> float:
        x = pa_to_bar(check_finite_step(value, "greybox"))
        for block_step in self._inputs:
            x = block_step(x)
        self._x[0] = x
        op.chain_run(self._x, self._model._coef, self._state, self._y)
        y = float(self._y[0])
        for block_step in self._outputs:
            y = block_step(y)
        return float(deg_to_rad(y))
