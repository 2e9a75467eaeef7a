"""The Generalized Prandtl-Ishlinskii model (thesis eqs. 9.12-9.16) and its inverse (9.17-9.21).

``y = q γ(x) + sum_{i=1..n} p(r_i) F_{r_i}[γ(x)]`` with the envelope
``γ(x) = c0 tanh(c1 x + c2) + c3`` (eq. 9.14), thresholds ``r_i = β i`` (eq. 9.16) and
density ``p(r_i) = ρ e^{-τ r_i}`` (eq. 9.15): 8 parameters (Table 9.1). It is rate-independent,
so the thesis identifies one GPI per excitation frequency and inverts each analytically
(eqs. 9.17-9.21) to make virtual training data for the IDRDPI (``models.idrdpi``).

Units: pressure in bar gauge in, bend in degrees out (SI at the :class:`Model` boundary).
γ's unit is arbitrary: scaling c0, c3 and β by λ and q, ρ by 1/λ and τ by 1/λ gives the
same model, so the default search box holds c0 = 10 (γ then spans c3 ± 10, like Table
9.3's c0 = 7.75) and the rest are identified. Eq. 9.20 prints q' = 1/q'; it means 1/q.

Rest: a PI's plays sit at their input when u = 0; here each play starts at γ(0), and the
inverse's plays at the forward model's output at rest, so inverse(forward(0)) = 0 exactly.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar, Final

import numpy as np
import numpy.typing as npt

from catheter_models.contract import SENSOR_RATE_HZ
from catheter_models.errors import ParameterError
from catheter_models.hysteresis import gpi_kernels
from catheter_models.hysteresis.population import gpi_population_loss
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
from catheter_models.units import bar_to_pa, deg_to_rad, pa_to_bar, rad_to_deg

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

GPI_UNITS: Final[Mapping[str, str]] = {
    "c0": "g",
    "c1": "1/bar",
    "c2": "1",
    "c3": "g",
    "beta": "g",
    "rho": "deg/g",
    "tau": "1/g",
    "q": "deg/g",
}
"""Units; ``g`` is the envelope's own (arbitrary) unit."""

_VALIDITY: Final[Mapping[str, tuple[float, float, bool, str]]] = {
    "c0": (0.0, math.inf, True, "envelope amplitude must be > 0 (eq. 9.14)"),
    "c1": (0.0, math.inf, True, "envelope slope must be > 0 (eq. 9.14)"),
    "c2": (-math.inf, math.inf, False, "envelope offset"),
    "c3": (-math.inf, math.inf, False, "envelope level"),
    "beta": (0.0, math.inf, True, "thresholds r_i = beta i must ascend (eq. 9.16)"),
    "rho": (0.0, math.inf, False, "density scale must be >= 0 for an inverse (eq. 9.20)"),
    "tau": (-50.0, 50.0, False, "density decay (eq. 9.15)"),
    "q": (0.0, math.inf, True, "input weight must be > 0 for an inverse (eq. 9.20)"),
}

GPI_SEARCH_NAMES: Final = ("c0", "c1", "c2", "c3", "beta", "p1", "tau", "q")
"""The coordinates the identification searches: Table 9.1's with ρ replaced by the weight
of the first play, ``p1 = p(r_1) = ρ e^{-τ β}``; as with the DRDPI's weights
(``models.drdpi.SEARCH_NAMES``), ρ and τ are otherwise tied along a curved valley."""

GPI_DEFAULT_BOUNDS: Final[Mapping[str, tuple[float, float]]] = {
    "c0": (10.0, 10.0),
    "c1": (0.05, 5.0),
    "c2": (-5.0, 5.0),
    "c3": (-20.0, 20.0),
    "beta": (0.01, 3.0),
    "p1": (0.0, 10.0),
    "tau": (-1.0, 10.0),
    "q": (0.01, 10.0),
}
"""Search box over :data:`GPI_SEARCH_NAMES` (bar in, deg out); c0 held at 10 (γ's scale)."""


def gpi_search_to_params(search: FloatArray) -> FloatArray:
    """Search coordinates (:data:`GPI_SEARCH_NAMES`) -> Table 9.1's, row by row."""
    table = np.array(search, dtype=np.float64, copy=True)
    rows = table.reshape(-1, len(GPI_SEARCH_NAMES))
    rows[:, 5] = rows[:, 5] * np.exp(rows[:, 6] * rows[:, 4])
    return table


_GPI_BUDGET: Final = Budget(wall_time_s=20.0)
"""A GPI is fitted on one frequency (a quarter of the data, 7 parameters free): 20 s at most."""


GPI_PARAMS_FILE: Final = "gpi_params.json"
GPI_PARAMS_FORMAT: Final = "catheter_models.gpi/1"


@dataclass(frozen=True)
class GPIParams(ParameterSet):
    """Table 9.1's 8 parameters (units in :data:`GPI_UNITS`).

    Attributes:
        c0: Envelope amplitude (eq. 9.14).
        c1: Envelope slope [1/bar].
        c2: Envelope offset [1].
        c3: Envelope level.
        beta: Threshold step, r_i = beta i (eq. 9.16).
        rho: Density scale, p(r) = rho e^{-tau r} (eq. 9.15).
        tau: Density decay.
        q: Input weight (eq. 9.12).
    """

    c0: float
    c1: float
    c2: float
    c3: float
    beta: float
    rho: float
    tau: float
    q: float

    label = "GPI"
    table = "Table 9.1"
    validity = _VALIDITY


GPI_PARAM_NAMES: Final = GPIParams.names()
"""Table 9.1's parameters, in its order (the dataclass's fields)."""

GPI_FILE: Final = ParamsFile(GPI_PARAMS_FILE, GPI_PARAMS_FORMAT, GPIParams)
"""The GPI's parameters file."""


def gpi_coefficients(params: GPIParams, n_play: int) -> FloatArray:
    """Forward coefficients (``gpi_kernels.G_*`` layout) of a GPI with ``n_play`` plays."""
    coef: FloatArray = gpi_kernels.gpi_coefficients(params.as_array(), n_play)
    return coef


def run_gpi(coef: FloatArray, x_bar: FloatArray) -> FloatArray:
    """Forward GPI over a whole signal from rest: bar in, deg out."""
    out = np.empty(x_bar.size)
    gpi_kernels.gpi_run(
        np.ascontiguousarray(x_bar, dtype=np.float64), coef, gpi_kernels.gpi_rest_state(coef), out
    )
    return out


def run_inverse_gpi(coef: FloatArray, inverse: FloatArray, y_deg: FloatArray) -> FloatArray:
    """Inverse GPI (eqs. 9.17-9.21) over a whole signal from rest: deg in, bar out."""
    out = np.empty(y_deg.size)
    state = gpi_kernels.gpi_inverse_rest_state(coef)
    gpi_kernels.gpi_inverse_run(np.ascontiguousarray(y_deg, dtype=np.float64), inverse, state, out)
    return out


class GPIProblem:
    """Eq. 5.12 for the GPI on a set of recordings (bar in, deg out)."""

    def __init__(
        self, inputs: Sequence[FloatArray], outputs: Sequence[FloatArray], *, n_play: int
    ) -> None:
        self.x, self.y, self.starts = stack_recordings(inputs, outputs)
        self.n_play = n_play
        self._weights = 1.0 / np.sqrt(np.repeat(np.diff(self.starts), np.diff(self.starts)))

    def population_loss(self, thetas: FloatArray) -> FloatArray:
        """Eq. 5.12 for each row of ``thetas`` (search coordinates; numba, in parallel)."""
        loss: FloatArray = gpi_population_loss(
            gpi_search_to_params(np.atleast_2d(thetas)),
            self.n_play,
            self.x,
            self.y,
            self.starts,
        )
        return loss

    def predict_all(self, theta: FloatArray) -> FloatArray:
        """The GPI's output over every recording (each from rest), back to back.

        Args:
            theta: Table 9.1's parameters (not search coordinates).
        """
        coef = gpi_kernels.gpi_coefficients(np.asarray(theta, dtype=np.float64), self.n_play)
        out = np.empty(self.x.size)
        for s in range(self.starts.size - 1):
            lo, hi = int(self.starts[s]), int(self.starts[s + 1])
            gpi_kernels.gpi_run(self.x[lo:hi], coef, gpi_kernels.gpi_rest_state(coef), out[lo:hi])
        return out

    def residuals(self, search: FloatArray) -> FloatArray:
        """Errors scaled by 1/sqrt(N_s): their sum of squares is eq. 5.12's loss.

        Args:
            search: One candidate in search coordinates.
        """
        theta = gpi_search_to_params(search)
        res: FloatArray = (self.predict_all(theta) - self.y) * self._weights
        return res


class _GPIStream:
    """Forward GPI stepped one sample at a time (Pa in, rad out): gpi_run on 1-sample chunks."""

    def __init__(self, coef: FloatArray) -> None:
        self._coef = coef
        self._state = gpi_kernels.gpi_rest_state(coef)
        self._x = np.zeros(1)
        self._y = np.zeros(1)

    def reset(self) -> None:
        self._state[:] = gpi_kernels.gpi_rest_state(self._coef)

    def step(self, value: float) -> float:
        self._x[0] = pa_to_bar(check_finite_step(value, "gpi"))
        gpi_kernels.gpi_run(self._x, self._coef, self._state, self._y)
        return float(deg_to_rad(float(self._y[0])))


class InverseGPIStream:
    """Inverse GPI (eqs. 9.17-9.21) stepped one sample at a time: rad in, Pa out.

    A feedforward compensator for the frequency the GPI was identified at.
    """

    def __init__(self, coef: FloatArray, inverse: FloatArray) -> None:
        self._coef = coef
        self._inverse = inverse
        self._state = gpi_kernels.gpi_inverse_rest_state(coef)
        self._y = np.zeros(1)
        self._x = np.zeros(1)

    def reset(self) -> None:
        """Back to rest: the inverse's plays at the forward model's output at rest."""
        self._state[:] = gpi_kernels.gpi_inverse_rest_state(self._coef)

    def step(self, value: float) -> float:
        """Desired angle [rad] -> pressure [Pa gauge]; finite by construction (γ⁻¹ saturates)."""
        self._y[0] = rad_to_deg(check_finite_step(value, "inverse gpi"))
        gpi_kernels.gpi_inverse_run(self._y, self._inverse, self._state, self._x)
        return float(bar_to_pa(float(self._x[0])))


def identify_gpi(
    inputs_bar: Sequence[FloatArray],
    outputs_deg: Sequence[FloatArray],
    *,
    n_play: int,
    bounds: ParameterBounds,
    budget: Budget,
    seed: int,
    progress: bool,
    label: str = "GPI",
) -> tuple[GPIParams, IdentificationResult]:
    """Identify a GPI's 8 parameters on recordings in bar (in) and degrees (out)."""
    problem = GPIProblem(inputs_bar, outputs_deg, n_play=n_play)
    result = identify(problem, bounds, budget=budget, seed=seed, progress=progress, label=label)
    return GPIParams.from_array(gpi_search_to_params(result.theta)), result


class GPI(Model):
    """The GPI (eqs. 9.12-9.16): valve pressure -> bend, rate-independent, with its inverse.

    Args:
        n_play: n, number of play operators (the thesis does not print it).
        bounds: Search box ``{name: (low, high)}`` over :data:`GPI_SEARCH_NAMES`; missing
            names take :data:`GPI_DEFAULT_BOUNDS`; equal bounds hold a parameter fixed.
        budget: Identification effort (``Budget`` or its settings as a mapping).
        seed: Seed of the search.
    """

    kind: ClassVar[str] = "gpi"
    direction = "forward"
    requirement: ClassVar[DataRequirement] = DataRequirement(
        min_samples=1_000,
        why="A GPI's 8 parameters need at least a few loops at its frequency (4 s at 250 Hz).",
    )

    params_: GPIParams
    coef_: FloatArray
    inverse_coef_: FloatArray

    def __init__(
        self,
        *,
        n_play: int = 10,
        bounds: Mapping[str, Sequence[float]] | None = None,
        budget: Budget | Mapping[str, Any] | None = None,
        seed: int = 0,
    ) -> None:
        if not (isinstance(n_play, int) and 1 <= n_play <= 200):
            raise ParameterError(f"n_play = {n_play!r} must be an integer in [1, 200]")
        self.n_play = n_play
        self.bounds = ParameterBounds.from_mapping(
            GPI_SEARCH_NAMES, {**GPI_DEFAULT_BOUNDS, **dict(bounds or {})}
        )
        self.budget = Budget.coerce(budget if budget is not None else _GPI_BUDGET)
        self.seed = int(seed)

    @classmethod
    def from_params(
        cls, params: GPIParams, rate_hz: float = SENSOR_RATE_HZ, **settings: Any
    ) -> Self:
        """A fitted GPI with given parameters."""
        model = cls(**settings)
        model._set_params(params, rate_hz)
        return model

    def _set_params(self, params: GPIParams, rate_hz: float) -> None:
        coef = gpi_coefficients(params, self.n_play)
        self.inverse_coef_ = gpi_kernels.invert_gpi(coef)
        self.coef_ = coef
        self.params_ = params
        self.rate_hz_ = float(rate_hz)

    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Identify the 8 parameters on ``train`` (eq. 5.12); ideally one frequency only."""
        t0 = time.perf_counter()
        rate = self._prepare(train, validation)
        params, result = identify_gpi(
            [pa_to_bar(r.pressure_pa) for r in train],
            [rad_to_deg(r.angle_rad) for r in train],
            n_play=self.n_play,
            bounds=self.bounds,
            budget=self.budget,
            seed=self.seed,
            progress=progress,
        )
        self._set_params(params, rate)
        extra: dict[str, Any] = {"identification": result.summary(), "params": params.to_dict()}
        validation_loss: list[float] = []
        if validation:
            vrmse = [
                float(
                    np.sqrt(np.mean((rad_to_deg(self.predict(r.pressure_pa) - r.angle_rad)) ** 2))
                )
                for r in validation
            ]
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

    def _coefs(self) -> tuple[FloatArray, FloatArray]:
        coef = getattr(self, "coef_", None)
        if coef is None:
            raise NotFittedError("gpi model is not fitted: call fit() or load() first")
        return coef, self.inverse_coef_

    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Bend [rad] for a valve pressure signal [Pa gauge], from rest."""
        coef, _ = self._coefs()
        out: FloatArray = deg_to_rad(run_gpi(coef, pa_to_bar(as_input(input_si, "pressure_pa"))))
        return out

    def stream(self) -> _GPIStream:
        """Stateful stepper: Pa in, rad out, equal to :meth:`predict` sample by sample."""
        coef, _ = self._coefs()
        return _GPIStream(coef)

    def inverse_predict(self, angle_si: npt.ArrayLike) -> FloatArray:
        """Inverse GPI (eqs. 9.17-9.21): the pressure [Pa] that makes the GPI give ``angle_si``.

        Finite for every finite input: γ⁻¹ saturates outside γ's range.
        """
        coef, inverse = self._coefs()
        y = rad_to_deg(as_input(angle_si, "angle_rad"))
        out: FloatArray = bar_to_pa(run_inverse_gpi(coef, inverse, y))
        return out

    def inverse_stream(self) -> InverseGPIStream:
        """The inverse as a stateful stepper (rad in, Pa out), equal to :meth:`inverse_predict`."""
        coef, inverse = self._coefs()
        return InverseGPIStream(coef, inverse)

    # -- persistence -------------------------------------------------------------------------
    def _settings(self) -> dict[str, Any]:
        return {
            "n_play": self.n_play,
            "bounds": self.bounds.to_mapping(),
            "budget": self.budget.to_dict(),
            "seed": self.seed,
        }

    def _payload(self) -> dict[str, bytes]:
        self._coefs()
        structure = {"n_play": self.n_play}
        return {GPI_PARAMS_FILE: GPI_FILE.dump(self.params_, GPI_UNITS, structure)}

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        params, structure = GPI_FILE.read(payload, kind=cls.kind)
        try:
            settings = dict(manifest.metrics.get("settings", {}))
            settings.update(structure)
            model = cls(**settings)
        except (ValueError, KeyError, TypeError, AttributeError) as exc:
            raise ModelError(f"gpi: {GPI_PARAMS_FILE} is malformed: {exc}") from None
        model._set_params(params, saved_rate_hz(manifest, cls.kind))
        return model


__all__ = [
    "GPI",
    "GPI_DEFAULT_BOUNDS",
    "GPI_FILE",
    "GPI_PARAM_NAMES",
    "GPI_SEARCH_NAMES",
    "GPI_UNITS",
    "GPIParams",
    "GPIProblem",
    "InverseGPIStream",
    "gpi_coefficients",
    "gpi_search_to_params",
    "identify_gpi",
    "run_gpi",
    "run_inverse_gpi",
]
