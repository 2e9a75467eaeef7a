"""Support Vector Regression forward model (thesis ch. 6): a window of past pressures -> bend.

The thesis's SVR (after its ref. [58]) predicts the bend angle from "a window of past inputs":
an RBF-kernel epsilon-SVR with C = 10, gamma = 0.1, epsilon = 0.1, chosen by a grid search
(C in {0.001, 0.01, 0.1, 1, 10}, gamma in {0.001, 0.01, 0.1, 1}) with 10-fold cross
validation. The thesis does not print the window; this model uses ``n_taps`` pressure samples
``stride`` samples apart, newest first::

    x_t = (p[t], p[t - stride], ..., p[t - (n_taps - 1) * stride])

The defaults (11 taps, stride 10: the last 0.4 s at 25 Hz, at the rig's 250 Hz) won a
contiguous 10-fold cross validation on the simulated thesis training set (4000 windows, each
span with its own best (C, gamma) from the thesis's grid), CV RMSE by span: 0 s (memoryless)
1.39 deg, 0.2 s 0.78 deg, 0.4 s 0.75 deg (26 taps x 4: 0.81 deg), 0.6 s 0.86 deg, 0.8 s
0.92 deg, 1 s 0.94 deg; the fold-to-fold spread is about 0.1 deg, so 0.2-0.4 s tie and longer
windows lose (more dimensions for the same data). No separate pressure rate feature: the
differences of neighbouring taps carry it, and the RBF kernel sees them.

Before the first sample the window is padded with 0 Pa gauge, the vented muscle at rest, as
every recording and :meth:`SVRModel.predict` start from rest. This is the thesis LSTM's "zero
padding" (sec. 7.2.1) taken in physical units: a zero in normalised units would claim the
muscle had held mid-range pressure (about 1.4 bar) before the recording began.

Units. Inputs and targets are scaled with the thesis's eq. 7.9 onto [-1, 1] (pressure by the
training pressure range, applied to every tap alike; angle by the training angle range), so
the hyperparameters are in those units:

* ``epsilon`` is the half-width of the loss-free tube in normalised angle: 0.1 is 5 % of the
  training angle range, i.e. ±1.43 deg for the thesis training set (-0.16 deg to 28.5 deg).
  Errors below that are not penalised at all, which bounds how well the fit can do.
* ``gamma`` scales the squared Euclidean distance between two windows in normalised pressure
  (units²): k = exp(-gamma * |x - x'|²), so the kernel falls to 1/e at a distance of
  1/sqrt(gamma). For the 11-tap default that is every tap differing by sqrt(1/(11 gamma))
  units: 0.30 units (0.43 bar for the thesis's 0-2.87 bar range, 1 unit = 1.43 bar) at the
  gamma = 1 the cross validation picks, 0.95 units (1.37 bar) at the thesis's 0.1. More taps
  put windows farther apart, so the best gamma shrinks as the window grows (the CV picked 0.1
  for windows of 16 taps and more); the grid search accounts for that.

Inference is numpy only: the fitted support vectors, dual coefficients, intercept, gamma and
the scaler constants are stored in ``svr.npz`` (read with ``allow_pickle=False``) and the RBF
decision function is evaluated here, vectorised and chunked. scikit-learn is imported only by
:meth:`SVRModel.fit`. ``predict`` and ``stream`` share :func:`lagged_windows` and
:meth:`SVRWeights.decision`, so a stream reproduces a batch prediction sample by sample.
"""

from __future__ import annotations

import io
import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Final

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import sliding_window_view

from catheter_models.errors import ParameterError
from catheter_models.model_dir import Manifest
from catheter_models.models.base import (
    DataRequirement,
    FitReport,
    FloatArray,
    MinMaxScaler,
    Model,
    ModelError,
    NotFittedError,
    Recording,
    as_input,
    check_finite_step,
)
from catheter_models.units import rad_to_deg

if TYPE_CHECKING:
    from typing import Self  # 3.11+; annotations only, so 3.10 imports the module

KIND: Final = "svr"
WEIGHTS_FILE: Final = "svr.npz"
SETTINGS_FILE: Final = "svr.json"
PAYLOAD_FORMAT: Final = 1

THESIS_C_GRID: Final = (0.001, 0.01, 0.1, 1.0, 10.0)
"""Penalty values the thesis's grid search tried (sec. 6.2)."""
THESIS_GAMMA_GRID: Final = (0.001, 0.01, 0.1, 1.0)
"""RBF kernel coefficients the thesis's grid search tried [1/normalised-unit²] (sec. 6.2)."""
THESIS_EPSILON: Final = 0.1
"""Half-width of the epsilon-insensitive tube, normalised angle (Table 6.1)."""

REST_PRESSURE_PA: Final = 0.0
"""Gauge pressure assumed before the first sample: the vented muscle at rest."""

# Kernel rows evaluated per block: bounds the (rows x support vectors) matrix at ~32 MB.
_KERNEL_BLOCK_ELEMENTS: Final = 4_000_000
# libsvm's kernel cache [MB]; a larger cache saves recomputing kernel rows during a fit.
_SVM_CACHE_MB: Final = 500.0


def lagged_windows(padded: npt.ArrayLike, n_taps: int, stride: int) -> FloatArray:
    """Rows of lagged samples, newest first, one row per sample that has a full window.

    Args:
        padded: A 1-D signal whose first ``(n_taps - 1) * stride`` samples are history
            (padding) for the first row, any unit.
        n_taps: Samples per row.
        stride: Distance between taps [samples].

    Returns:
        Array ``(len(padded) - (n_taps - 1) * stride, n_taps)``; row ``i`` holds
        ``padded[j], padded[j - stride], ...`` with ``j = i + (n_taps - 1) * stride``.
    """
    arr = np.asarray(padded, dtype=np.float64)
    span = (n_taps - 1) * stride + 1
    if arr.size < span:
        return np.empty((0, n_taps), dtype=np.float64)
    # sliding_window_view gives oldest-first views; reversing then striding keeps "newest
    # first" regardless of span, and the copy makes rows contiguous for the kernel's matmul.
    return np.ascontiguousarray(sliding_window_view(arr, span)[:, ::-1][:, ::stride])


@dataclass(frozen=True, eq=False)
class SVRWeights:
    """What the RBF epsilon-SVR decision function needs, in normalised units.

    ``f(x) = sum_i dual_coef[i] * exp(-gamma * |x - support_vectors[i]|²) + intercept``

    Attributes:
        support_vectors: Windows of normalised pressure that carry weight, ``(n_sv, n_taps)``.
        dual_coef: Their coefficients ``alpha_i - alpha_i*``, normalised angle, ``(n_sv,)``.
        intercept: Bias, normalised angle.
        gamma: RBF coefficient [1/normalised-unit²].
    """

    support_vectors: FloatArray
    dual_coef: FloatArray
    intercept: float
    gamma: float
    _sv_sq: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        sv = np.ascontiguousarray(self.support_vectors, dtype=np.float64)
        dc = np.ascontiguousarray(self.dual_coef, dtype=np.float64).reshape(-1)
        if sv.ndim != 2 or sv.shape[0] != dc.size:
            raise ModelError(
                f"SVR weights: support_vectors {sv.shape} and dual_coef {dc.shape} do not pair "
                "up; expected (n_sv, n_taps) and (n_sv,)"
            )
        if not (np.isfinite(sv).all() and np.isfinite(dc).all()):
            raise ModelError("SVR weights: support vectors or dual coefficients are not finite")
        if not math.isfinite(self.intercept):
            raise ModelError(f"SVR weights: intercept {self.intercept!r} is not finite")
        if not (math.isfinite(self.gamma) and self.gamma > 0.0):
            raise ModelError(f"SVR weights: gamma {self.gamma!r} must be finite and > 0")
        sv.setflags(write=False)
        dc.setflags(write=False)
        object.__setattr__(self, "support_vectors", sv)
        object.__setattr__(self, "dual_coef", dc)
        # |s|² once, not at every stream step.
        sq = np.einsum("ij,ij->i", sv, sv)
        sq.setflags(write=False)
        object.__setattr__(self, "_sv_sq", sq)

    @property
    def n_features(self) -> int:
        """Features per row (the window's taps)."""
        return int(self.support_vectors.shape[1])

    @classmethod
    def from_estimator(cls, estimator: Any) -> SVRWeights:
        """Copy the decision function out of a fitted ``sklearn.svm.SVR`` (RBF, float gamma)."""
        kernel, gamma = getattr(estimator, "kernel", None), getattr(estimator, "gamma", None)
        if kernel != "rbf" or isinstance(gamma, str) or gamma is None:
            raise ModelError(
                f"expected an RBF SVR with a numeric gamma, got kernel {kernel!r}, gamma {gamma!r}"
            )
        return cls(
            support_vectors=np.asarray(estimator.support_vectors_, dtype=np.float64),
            dual_coef=np.asarray(estimator.dual_coef_, dtype=np.float64).reshape(-1),
            intercept=float(np.asarray(estimator.intercept_).reshape(-1)[0]),
            gamma=float(gamma),
        )

    def decision(self, features: npt.ArrayLike) -> FloatArray:
        """The SVR output for each row of ``features`` (normalised pressure windows).

        Computes ``|x - s|² = |x|² + |s|² - 2 x·s`` as libsvm does, in row blocks so the
        kernel matrix never exceeds ~32 MB.

        Args:
            features: ``(n, n_taps)`` normalised windows.

        Returns:
            ``(n,)`` normalised angles.
        """
        x = np.asarray(features, dtype=np.float64)
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ModelError(
                f"SVR features have shape {x.shape}; the model expects (n, {self.n_features})"
            )
        sv = self.support_vectors
        sv_sq = self._sv_sq
        out = np.empty(x.shape[0], dtype=np.float64)
        block = max(1, _KERNEL_BLOCK_ELEMENTS // max(1, sv.shape[0]))
        for start in range(0, x.shape[0], block):
            xb = x[start : start + block]
            d2 = np.einsum("ij,ij->i", xb, xb)[:, None] + sv_sq[None, :] - 2.0 * (xb @ sv.T)
            # Rounding can make |x - s|² of a near-duplicate slightly negative.
            np.maximum(d2, 0.0, out=d2)
            np.multiply(d2, -self.gamma, out=d2)
            np.exp(d2, out=d2)
            out[start : start + block] = d2 @ self.dual_coef + self.intercept
        return out


@dataclass(frozen=True)
class CVRow:
    """One (C, gamma) candidate of the grid search, errors in rad.

    Attributes:
        C: Penalty.
        gamma: RBF coefficient [1/normalised-unit²].
        rmse_rad: Square root of the mean over folds of the validation MSE [rad].
        fold_rmse_std_rad: Standard deviation over folds of the per-fold RMSE [rad].
        train_rmse_rad: As ``rmse_rad``, on the training part of each split [rad].
        rank: 1 for the chosen candidate.
    """

    C: float
    gamma: float
    rmse_rad: float
    fold_rmse_std_rad: float
    train_rmse_rad: float
    rank: int


class SVRModel(Model):
    """RBF epsilon-SVR from a window of past pressures to the bend (thesis ch. 6).

    Args:
        n_taps: Pressure samples per window (>= 1; 1 makes a memoryless regression).
        stride: Samples between taps (>= 1). The window spans ``(n_taps - 1) * stride``
            samples: 0.4 s at 250 Hz with the defaults.
        c_grid: Penalties C to search (thesis: 0.001 ... 10).
        gamma_grid: RBF coefficients to search [1/normalised-unit²] (thesis: 0.001 ... 1).
        epsilon: Half-width of the loss-free tube, normalised angle (thesis 0.1 = ±5 % of the
            training angle range, ±1.43 deg for the thesis training set). On the simulated
            rig 0.02 (±0.29 deg) cut the four test RMSEs by 45-75 % for 2.5x the fit time.
        folds: Cross-validation folds (thesis 10). Folds are contiguous blocks in time, not
            shuffled: neighbouring samples at 250 Hz are near-duplicates with overlapping
            windows, so a shuffled fold would be validated on points its training part almost
            contains, scoring interpolation and rewarding overfitting (large C and gamma).
        grid_samples: Windows drawn from the training set for the grid search. libsvm costs
            O(n²) or worse per fit and the search runs ``folds x |C| x |gamma|`` fits; 4000 of
            the thesis set's 26,800 (one per 6.7 samples, still 37 Hz) keep it near a minute.
        fit_samples: Windows drawn for the final fit with the chosen (C, gamma).
        seed: Seed of the stratified draw (one random window in each of n equal time blocks).
        n_jobs: Processes for the grid search (``sklearn`` meaning; -1 = all cores).
    """

    kind: ClassVar[str] = KIND
    direction = "forward"
    requirement: ClassVar[DataRequirement] = DataRequirement(
        min_samples=2_500,
        why=(
            "The SVR needs several full loading/unloading loops to tell the branches apart "
            "(the thesis trains on 107 s): at least 10 s of data."
        ),
    )

    weights_: SVRWeights
    pressure_scaler_: MinMaxScaler
    angle_scaler_: MinMaxScaler
    hyperparameters_: dict[str, float]

    def __init__(
        self,
        *,
        n_taps: int = 11,
        stride: int = 10,
        c_grid: Sequence[float] = THESIS_C_GRID,
        gamma_grid: Sequence[float] = THESIS_GAMMA_GRID,
        epsilon: float = THESIS_EPSILON,
        folds: int = 10,
        grid_samples: int = 4_000,
        fit_samples: int = 12_000,
        seed: int = 0,
        n_jobs: int = 1,
    ) -> None:
        self.n_taps = n_taps
        self.stride = stride
        self.c_grid = tuple(c_grid)
        self.gamma_grid = tuple(gamma_grid)
        self.epsilon = epsilon
        self.folds = folds
        self.grid_samples = grid_samples
        self.fit_samples = fit_samples
        self.seed = seed
        self.n_jobs = n_jobs

    # -- settings ----------------------------------------------------------------------------
    @property
    def span_samples(self) -> int:
        """Samples from the oldest to the newest tap, both included."""
        return (self.n_taps - 1) * self.stride + 1

    def _check_settings(self) -> None:
        """ParameterError naming the first setting out of range."""
        ints = {
            "n_taps": (self.n_taps, 1),
            "stride": (self.stride, 1),
            "folds": (self.folds, 2),
            "grid_samples": (self.grid_samples, 10),
            "fit_samples": (self.fit_samples, 10),
        }
        for name, (value, low) in ints.items():
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise ParameterError(f"svr: {name} = {value!r} must be an integer >= {low}")
        for name, grid in (("c_grid", self.c_grid), ("gamma_grid", self.gamma_grid)):
            numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in grid)
            if not (grid and numeric and all(math.isfinite(v) and v > 0.0 for v in grid)):
                raise ParameterError(
                    f"svr: {name} = {grid!r} must be a non-empty list of values > 0"
                )
        if not (math.isfinite(self.epsilon) and self.epsilon >= 0.0):
            raise ParameterError(f"svr: epsilon = {self.epsilon!r} must be finite and >= 0")
        if self.grid_samples < 2 * self.folds:
            raise ParameterError(
                f"svr: grid_samples = {self.grid_samples} leaves fewer than 2 windows per fold "
                f"for {self.folds} folds; raise grid_samples or lower folds"
            )

    def _settings(self) -> dict[str, Any]:
        return {
            "n_taps": self.n_taps,
            "stride": self.stride,
            "c_grid": list(self.c_grid),
            "gamma_grid": list(self.gamma_grid),
            "epsilon": self.epsilon,
            "folds": self.folds,
            "grid_samples": self.grid_samples,
            "fit_samples": self.fit_samples,
            "seed": self.seed,
            "n_jobs": self.n_jobs,
        }

    # -- features ----------------------------------------------------------------------------
    def _features(self, padded_pa: FloatArray) -> FloatArray:
        """Normalised windows for every sample of ``padded_pa`` that has a full window."""
        windows_pa = lagged_windows(padded_pa, self.n_taps, self.stride)
        return self.pressure_scaler_.transform(windows_pa)

    def _pad(self, pressure_pa: FloatArray) -> FloatArray:
        """``pressure_pa`` with the window's history at rest in front."""
        history = np.full(self.span_samples - 1, REST_PRESSURE_PA)
        return np.concatenate([history, pressure_pa])

    # -- fit ---------------------------------------------------------------------------------
    def fit(
        self,
        train: Sequence[Recording],
        validation: Sequence[Recording] = (),
        *,
        progress: bool = True,
    ) -> Self:
        """Grid-search (C, gamma) by contiguous k-fold CV, then fit the SVR with the best pair.

        Args:
            train: Recordings to learn from; each starts from rest (its window is padded with
                0 Pa). Windows never straddle two recordings.
            validation: Recordings scored after the fit (RMSE in the fit report); not used for
                selection, which the cross validation does.
            progress: Print the grid search's per-fit progress and the CV table.

        Returns:
            ``self``, fitted.

        Raises:
            InsufficientDataError: Less than :attr:`requirement` of training data.
            RateMismatchError: The recordings have different sample rates.
            ParameterError: A setting is out of range.
        """
        from sklearn.model_selection import GridSearchCV, KFold
        from sklearn.svm import SVR

        self._check_settings()
        started = time.perf_counter()
        rate_hz = self._prepare(train, validation)
        self.pressure_scaler_ = MinMaxScaler.fit(np.concatenate([r.pressure_pa for r in train]))
        angle_rad = np.concatenate([r.angle_rad for r in train])
        self.angle_scaler_ = MinMaxScaler.fit(angle_rad)
        features = np.vstack([self._features(self._pad(r.pressure_pa)) for r in train])
        target = self.angle_scaler_.transform(angle_rad)
        rng = np.random.default_rng(self.seed)
        grid_rows = _stratified_rows(target.size, self.grid_samples, rng)
        fit_rows = _stratified_rows(target.size, self.fit_samples, rng)

        search = GridSearchCV(
            SVR(kernel="rbf", epsilon=self.epsilon, cache_size=_SVM_CACHE_MB),
            {"C": list(self.c_grid), "gamma": list(self.gamma_grid)},
            scoring="neg_mean_squared_error",
            cv=KFold(n_splits=self.folds, shuffle=False),
            n_jobs=self.n_jobs,
            refit=False,
            return_train_score=True,
            verbose=2 if progress else 0,
        )
        search.fit(features[grid_rows], target[grid_rows])
        rad_per_unit = 0.5 * (self.angle_scaler_.hi - self.angle_scaler_.lo)
        table = _cv_table(search.cv_results_, self.folds, rad_per_unit)
        best = min(table, key=lambda row: row.rank)
        grid_done_s = time.perf_counter() - started

        estimator = SVR(
            kernel="rbf",
            C=best.C,
            gamma=best.gamma,
            epsilon=self.epsilon,
            cache_size=_SVM_CACHE_MB,
        )
        estimator.fit(features[fit_rows], target[fit_rows])
        self.weights_ = SVRWeights.from_estimator(estimator)
        self.hyperparameters_ = {"C": best.C, "gamma": best.gamma, "epsilon": self.epsilon}

        fitted_rad = self.angle_scaler_.inverse(self.weights_.decision(features))
        train_mse = float(np.mean((fitted_rad - angle_rad) ** 2))
        validation_mse = [
            float(np.mean((self.predict(r.pressure_pa) - r.angle_rad) ** 2)) for r in validation
        ]
        edges = [
            name
            for name, value, grid in (
                ("C", best.C, self.c_grid),
                ("gamma", best.gamma, self.gamma_grid),
            )
            if len(grid) > 1 and value in (min(grid), max(grid))
        ]
        self.fit_report_ = FitReport(
            duration_s=time.perf_counter() - started,
            train_loss=[train_mse],
            validation_loss=[float(np.mean(validation_mse))] if validation_mse else [],
            extra={
                "loss_unit": "rad^2",
                "hyperparameters": {**self.hyperparameters_, "kernel": "rbf"},
                "window": {
                    "n_taps": self.n_taps,
                    "stride": self.stride,
                    "span_s": (self.span_samples - 1) / rate_hz,
                    "padding_pa": REST_PRESSURE_PA,
                },
                "cross_validation": {
                    "folds": self.folds,
                    "scheme": "contiguous blocks in time (KFold, shuffle=False)",
                    "scoring": "mean squared error, normalised angle; reported as RMSE in rad",
                    "rows": int(grid_rows.size),
                    "duration_s": grid_done_s,
                    "best_on_grid_edge": edges,
                    "table": [asdict(row) for row in table],
                },
                "final_fit_rows": int(fit_rows.size),
                "training_rows": int(target.size),
                "n_support_vectors": int(self.weights_.dual_coef.size),
                "train_rmse_rad": math.sqrt(train_mse),
                "validation_rmse_rad": [math.sqrt(v) for v in validation_mse],
            },
        )
        if progress:
            print(_format_cv_table(table, best, edges))
            print(
                f"svr: chose C = {best.C:g}, gamma = {best.gamma:g} (epsilon {self.epsilon:g}); "
                f"{self.weights_.dual_coef.size} support vectors from {fit_rows.size} windows; "
                f"fit took {self.fit_report_.duration_s:.1f} s"
            )
        return self

    # -- inference ---------------------------------------------------------------------------
    def _require_fitted(self) -> None:
        if getattr(self, "weights_", None) is None:
            raise NotFittedError(f"{self.kind} model is not fitted: call fit() or load() first")

    def predict(self, input_si: npt.ArrayLike) -> FloatArray:
        """Bend angle [rad] for a pressure signal [Pa gauge] that starts from rest."""
        self._require_fitted()
        pressure_pa = as_input(input_si, "pressure_pa")
        normalised = self.weights_.decision(self._features(self._pad(pressure_pa)))
        return self.angle_scaler_.inverse(normalised)

    def stream(self) -> SVRStream:
        """A stepper at rest whose outputs equal :meth:`predict`'s sample by sample."""
        self._require_fitted()
        return SVRStream(self)

    def _output_for_window(self, window_pa: FloatArray) -> float:
        """The bend [rad] for one window of ``span_samples`` pressures, oldest first."""
        normalised = self.weights_.decision(self._features(window_pa))
        return float(self.angle_scaler_.inverse(normalised)[0])

    # -- persistence -------------------------------------------------------------------------
    def _normalization(self) -> dict[str, Any]:
        self._require_fitted()
        return {
            "pressure_pa": self.pressure_scaler_.to_dict(),
            "angle_rad": self.angle_scaler_.to_dict(),
            "equation": "thesis 7.9, onto [-1, 1]",
        }

    def _payload(self) -> dict[str, bytes]:
        self._require_fitted()
        buffer = io.BytesIO()
        np.savez(
            buffer,
            support_vectors=self.weights_.support_vectors,
            dual_coef=self.weights_.dual_coef,
            intercept=np.float64(self.weights_.intercept),
            gamma=np.float64(self.weights_.gamma),
            pressure_range_pa=np.array([self.pressure_scaler_.lo, self.pressure_scaler_.hi]),
            angle_range_rad=np.array([self.angle_scaler_.lo, self.angle_scaler_.hi]),
        )
        # The settings (window layout included) sit beside the arrays so the hash check
        # covers everything inference reads; the manifest repeats them for people.
        settings = {
            "format": PAYLOAD_FORMAT,
            "settings": self._settings(),
            "hyperparameters": self.hyperparameters_,
        }
        return {
            WEIGHTS_FILE: buffer.getvalue(),
            SETTINGS_FILE: (json.dumps(settings, indent=2, sort_keys=True) + "\n").encode(),
        }

    @classmethod
    def _from_payload(cls, manifest: Manifest, payload: Mapping[str, bytes]) -> Self:
        for name in (WEIGHTS_FILE, SETTINGS_FILE):
            if name not in payload:
                raise ModelError(f"svr model directory lacks {name!r} (files: {sorted(payload)})")
        try:
            raw = json.loads(payload[SETTINGS_FILE])
            if raw["format"] != PAYLOAD_FORMAT:
                raise ModelError(
                    f"{SETTINGS_FILE} has format {raw['format']!r}; this software reads "
                    f"{PAYLOAD_FORMAT}"
                )
            model = cls(**raw["settings"])
            hyper = {k: float(raw["hyperparameters"][k]) for k in ("C", "gamma", "epsilon")}
        except (ValueError, KeyError, TypeError) as exc:
            raise ModelError(f"{SETTINGS_FILE} is malformed: {exc!r}") from None
        model._check_settings()
        try:
            with np.load(io.BytesIO(payload[WEIGHTS_FILE]), allow_pickle=False) as npz:
                arrays = {key: np.asarray(npz[key], dtype=np.float64) for key in npz.files}
            weights = SVRWeights(
                support_vectors=arrays["support_vectors"],
                dual_coef=arrays["dual_coef"],
                intercept=float(arrays["intercept"]),
                gamma=float(arrays["gamma"]),
            )
            p_lo, p_hi = (float(v) for v in arrays["pressure_range_pa"])
            a_lo, a_hi = (float(v) for v in arrays["angle_range_rad"])
        except (ValueError, KeyError, TypeError, OSError) as exc:
            raise ModelError(f"{WEIGHTS_FILE} is malformed: {exc!r}") from None
        if weights.n_features != model.n_taps:
            raise ModelError(
                f"{WEIGHTS_FILE} holds {weights.n_features}-tap support vectors but "
                f"{SETTINGS_FILE} says n_taps = {model.n_taps}"
            )
        if not math.isclose(weights.gamma, hyper["gamma"], rel_tol=1e-12):
            raise ModelError(
                f"{WEIGHTS_FILE} gamma {weights.gamma!r} differs from {SETTINGS_FILE}'s "
                f"{hyper['gamma']!r}"
            )
        model.weights_ = weights
        model.pressure_scaler_ = MinMaxScaler(p_lo, p_hi)
        model.angle_scaler_ = MinMaxScaler(a_lo, a_hi)
        model.hyperparameters_ = hyper
        model.fit_report_ = _report_from_manifest(manifest)
        return model


class SVRStream:
    """An :class:`SVRModel` stepped one pressure sample at a time.

    Keeps the last ``span_samples`` pressures in a ring buffer stored twice over, so the
    window is always one contiguous slice (no copy or roll per step), and evaluates it with
    the same feature and kernel code as :meth:`SVRModel.predict`.
    """

    def __init__(self, model: SVRModel) -> None:
        self._model = model
        self._span = model.span_samples
        self._buffer = np.empty(2 * self._span, dtype=np.float64)
        self._head = 0
        self.reset()

    def reset(self) -> None:
        """Forget the past: the window holds the rest pressure, as at a recording's start."""
        self._buffer.fill(REST_PRESSURE_PA)
        self._head = 0

    def step(self, value: float) -> float:
        """Take one pressure sample [Pa gauge]; return the predicted bend [rad]."""
        pressure_pa = check_finite_step(value, KIND)
        self._buffer[self._head] = pressure_pa
        self._buffer[self._head + self._span] = pressure_pa
        self._head = (self._head + 1) % self._span
        # After the write, slots head .. head + span - 1 hold the window oldest first.
        window = self._buffer[self._head : self._head + self._span]
        return self._model._output_for_window(window)


def _report_from_manifest(manifest: Manifest) -> FitReport:
    """The fit report a saved model's manifest repeats (for display; inference ignores it)."""
    fit = dict(manifest.metrics.get("fit", {}))
    try:
        return FitReport(
            duration_s=float(fit.pop("duration_s", 0.0)),
            train_loss=[float(v) for v in fit.pop("train_loss", [])],
            validation_loss=[float(v) for v in fit.pop("validation_loss", [])],
            extra=fit,
        )
    except (TypeError, ValueError) as exc:
        raise ModelError(f"manifest metrics 'fit' entry is malformed: {exc!r}") from None


def _stratified_rows(n_rows: int, n_draw: int, rng: np.random.Generator) -> npt.NDArray[np.intp]:
    """``n_draw`` sorted row indices, one at random in each of ``n_draw`` equal blocks.

    Covers the whole recording evenly (unlike a plain random draw, which leaves gaps and
    clumps) while the seed still decides which of the near-identical neighbours is taken.
    All rows if ``n_draw >= n_rows``. Sorted, so KFold's contiguous folds stay contiguous.
    """
    if n_draw >= n_rows:
        return np.arange(n_rows, dtype=np.intp)
    edges = np.linspace(0, n_rows, n_draw + 1).astype(np.intp)
    # n_draw < n_rows makes every block at least one row wide.
    return rng.integers(edges[:-1], edges[1:]).astype(np.intp)


def _cv_table(results: Mapping[str, Any], folds: int, rad_per_unit: float) -> list[CVRow]:
    """GridSearchCV's ``cv_results_`` as rows with RMSE in rad."""
    rows = []
    for i, params in enumerate(results["params"]):
        test_mse = np.array([-results[f"split{k}_test_score"][i] for k in range(folds)])
        train_mse = np.array([-results[f"split{k}_train_score"][i] for k in range(folds)])
        rows.append(
            CVRow(
                C=float(params["C"]),
                gamma=float(params["gamma"]),
                rmse_rad=math.sqrt(float(np.mean(test_mse))) * rad_per_unit,
                fold_rmse_std_rad=float(np.std(np.sqrt(test_mse))) * rad_per_unit,
                train_rmse_rad=math.sqrt(float(np.mean(train_mse))) * rad_per_unit,
                rank=int(results["rank_test_score"][i]),
            )
        )
    return rows


def _format_cv_table(table: Sequence[CVRow], chosen: CVRow, edges: Sequence[str]) -> str:
    """The CV RMSE [deg] as a C x gamma grid, the chosen cell starred."""
    cs = sorted({row.C for row in table})
    gammas = sorted({row.gamma for row in table})
    cell = {(row.C, row.gamma): row for row in table}
    lines = [
        "svr: cross-validated RMSE [deg]",
        "   C \\ gamma " + "".join(f"{g:>10g}" for g in gammas),
    ]
    for c in cs:
        parts = []
        for g in gammas:
            row = cell[(c, g)]
            mark = "*" if row is chosen else " "
            parts.append(f"{rad_to_deg(row.rmse_rad):>9.3f}{mark}")
        lines.append(f"{c:>12g} " + "".join(parts))
    if edges:
        which = " and ".join(edges)
        verb = (
            "lies on the edge of its grid" if len(edges) == 1 else "lie on the edges of their grids"
        )
        lines.append(f"svr: the best {which} {verb}; a wider grid might do better")
    return "\n".join(lines)


__all__ = [
    "REST_PRESSURE_PA",
    "THESIS_C_GRID",
    "THESIS_EPSILON",
    "THESIS_GAMMA_GRID",
    "CVRow",
    "SVRModel",
    "SVRStream",
    "SVRWeights",
    "lagged_windows",
]
