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

import json
import time
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, ClassVar, Final

import numpy.typing as npt

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
from catheter_models.models.blocks import FORMS, Block, block, ordered
from catheter_models.models.blocks.base import Inverse
from catheter_models.models.cores import CORES, Core, DRDPICore, FreePI, make_core, one_blas_thread
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.models.greybox_fit import _Fitter, _LinearFitter, _NonlinearFitter
from catheter_models.units import deg_to_rad, pa_to_bar, rad_to_deg

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

GREYBOX_FILE = "greybox.json"
GREYBOX_FORMAT = 2
"""2: the core is named with its settings and values; 1 (read too): the DRDPI only."""

_DRDPI_KEYS: Final = ("n_play", "n_deadband", "rate_filter_s", "budget")
"""Constructor arguments that shape the DRDPI core (kept for format-1 files and callers)."""


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

    @property
    def fitted(self) -> bool:
        """Whether the chain has been identified (or loaded)."""
        return self._fitted_now()

    def inverse_stages(self) -> tuple[list[Inverse], list[Inverse]]:
        """Each block run backwards (:meth:`Block.inverse`), from rest.

        The input side's and the output side's, each in chain order.

        Raises:
            ParameterError: blocks without an inverse, each named.
        """
        self._fitted()
        stages: dict[str, Inverse] = {}
        missing = []
        for e in self.effects:
            try:
                stages[e] = self._blocks[e].inverse(self.rate_hz_, self.blocks_[e])
            except NotImplementedError:
                missing.append(e)
        if missing:
            raise ParameterError(
                f"the chain {' -> '.join(self.chain)} cannot be compensated: "
                f"{', '.join(missing)} has no inverse (Block.inverse); remove it or give it one"
            )
        side = {e: FORMS[e].side for e in self.effects}
        return (
            [stages[e] for e in self.effects if side[e] == "input"],
            [stages[e] for e in self.effects if side[e] == "output"],
        )

    def dead_time_s(self) -> float | None:
        """How far the bend lags the command through the chain's blocks [s], to first order.

        The sum of each block's :attr:`~Block.dead_time_param` (a transport delay's delay, a
        pneumatic lag's time constant); None when no block of the chain delays the bend.
        """
        values = self.block_values()
        found = [
            values[e][FORMS[e].dead_time_param] for e in self.effects if FORMS[e].dead_time_param
        ]
        return float(sum(found)) if found else None

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
        fitter = self._fitter(core, xs, ys, rate)
        blocks, loss = fitter.search(blocks, new)
        if isinstance(fitter, _LinearFitter) and any(FORMS[e].side == "input" for e in new):
            fitter, blocks, loss = self._refit_core(fitter, blocks, loss)
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

    def _fitter(
        self, core: Core, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate: float
    ) -> _Fitter:
        if isinstance(core, FreePI):
            return _LinearFitter(self, core, xs, ys, rate)
        return _NonlinearFitter(self, core, xs, ys, rate)

    def _refit_core(
        self,
        fitter: _Fitter,
        blocks: dict[str, list[float]],
        loss: float,
    ) -> tuple[_Fitter, dict[str, list[float]], float]:
        """The core identified again on what the new input blocks give it, if that fits better.

        The core's structure (a rate factor, a tension share...) was chosen on the valve's
        pressure, where part of it stood in for the lag or delay now found; the search only
        re-solves its weights and polishes a few numbers. On a Bouc-Wen catheter with a 39 ms
        delay the chain found the delay and still held out 0.23 deg; the core identified
        again behind that delay, 0.15 deg. Kept only where its polished training loss is
        lower, so a chain never ends worse than its search did.

        For the core linear in its weights only, whose structure the search holds (its rate
        factor but for the polish, its tension share), and where it was shown to help
        (docs/lab_validation.md): the other cores polish their structure with the blocks.
        """
        xs, ys, rate = fitter.xs, fitter.ys, fitter.rate
        core = make_core(self.core_name, self.core_settings)
        core.fit([self._inputs(x, rate, blocks) for x in xs], ys, rate, progress=False)
        again = self._fitter(core, xs, ys, rate)
        blocks_again, loss_again = again.search({e: list(v) for e, v in blocks.items()}, [])
        if loss_again < loss:
            return again, blocks_again, loss_again
        return fitter, blocks, loss

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
