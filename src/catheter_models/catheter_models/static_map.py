"""The quasi-static pressure-to-bend curve and its inverse: the simplest compensator.

Fitted from a recording (command pressure against measured bend), the curve runs through the
middle of the hysteresis loops: per pressure bin, the mean of the loading and the unloading
branch. It ignores hysteresis on purpose; it is the baseline the thesis's compensators beat,
and the stand-in the compensator node hosts until a learned model is given.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.model_dir import read_model_dir, write_model_dir

KIND = "static_map"
PARAMS_FILE = "static_map.json"
FloatArray = npt.NDArray[np.float64]


def isotonic_increasing(values: FloatArray, weights: FloatArray) -> FloatArray:
    """Weighted least-squares projection of ``values`` onto non-decreasing sequences.

    scikit-learn's pool-adjacent-violators rather than SciPy's
    ``optimize.isotonic_regression``, which needs SciPy >= 1.12: Ubuntu 24.04 (the container
    image) ships 1.11, and one implementation keeps the fitted map identical on both.

    Raises:
        ParameterError: Shapes differ, or a weight is not positive and finite.
    """
    # Imported here, as models/svr.py does: scikit-learn costs its import time only where a
    # map is fitted, not in every process that loads one.
    from sklearn.isotonic import isotonic_regression

    values = np.asarray(values, dtype=np.float64)
    weights = np.asarray(weights, dtype=np.float64)
    if values.ndim != 1 or values.shape != weights.shape:
        raise ParameterError(
            f"isotonic fit: values and weights must be 1-D of equal length, "
            f"{values.shape} vs {weights.shape}"
        )
    if not (np.isfinite(weights).all() and (weights > 0).all()):
        raise ParameterError("isotonic fit: every weight must be positive and finite")
    fitted = isotonic_regression(values, sample_weight=weights, increasing=True)
    return np.asarray(fitted, dtype=np.float64)


@dataclass(frozen=True)
class StaticMap:
    """A monotone curve bend(pressure) sampled at increasing pressures.

    Attributes:
        pressure_pa: knot pressures, gauge [Pa], strictly increasing.
        angle_rad: bend at each knot [rad], non-decreasing.
    """

    pressure_pa: FloatArray
    angle_rad: FloatArray

    @classmethod
    def fit(
        cls,
        pressure_pa: npt.ArrayLike,
        angle_rad: npt.ArrayLike,
        n_bins: int = 40,
        min_per_bin: int = 5,
    ) -> StaticMap:
        """Fit from paired samples of command pressure (gauge [Pa]) and measured bend [rad].

        Raises:
            ParameterError: inputs of different length, non-finite, or too few to fill bins.
        """
        p = np.asarray(pressure_pa, dtype=float)
        a = np.asarray(angle_rad, dtype=float)
        if p.shape != a.shape or p.ndim != 1:
            raise ParameterError(
                f"pressure and angle must be 1-D of equal length, {p.shape} vs {a.shape}"
            )
        if not (np.isfinite(p).all() and np.isfinite(a).all()):
            raise ParameterError("static map fit: pressure or angle contains NaN/inf")
        rate = np.gradient(p)
        edges = np.linspace(p.min(), p.max(), n_bins + 1)
        idx = np.clip(np.digitize(p, edges) - 1, 0, n_bins - 1)
        knots_p: list[float] = []
        knots_a: list[float] = []
        weights: list[float] = []
        for b in range(n_bins):
            in_bin = idx == b
            loading = in_bin & (rate > 0)
            unloading = in_bin & (rate < 0)
            # The central curve needs both branches: a bin seen only while loading (near a
            # peak) would pull the curve onto that branch.
            if loading.sum() < min_per_bin or unloading.sum() < min_per_bin:
                continue
            knots_p.append(float(p[in_bin].mean()))
            knots_a.append(0.5 * float(a[loading].mean() + a[unloading].mean()))
            weights.append(float(min(loading.sum(), unloading.sum())))
        if len(knots_p) < 3:
            raise ParameterError(
                f"static map fit: only {len(knots_p)} pressure bins saw both loading and "
                "unloading; record a signal that sweeps the pressure range up and down"
            )
        knots = np.array(knots_p)
        # Bend never falls as pressure rises on the central curve: project onto monotone.
        angles = isotonic_increasing(np.array(knots_a), np.array(weights))
        return cls(pressure_pa=knots, angle_rad=angles)

    def angle(self, pressure_pa: npt.ArrayLike) -> FloatArray:
        """Forward map: bend [rad] at gauge pressure [Pa] (clamped to the fitted range)."""
        return np.asarray(
            np.interp(np.asarray(pressure_pa, dtype=float), self.pressure_pa, self.angle_rad),
            dtype=np.float64,
        )

    def pressure(self, angle_rad: npt.ArrayLike) -> FloatArray:
        """Inverse map: gauge pressure [Pa] that holds ``angle_rad`` on the central curve.

        In the deadband the curve is flat, so the inverse takes the highest pressure at which
        the bend is still at its rest value: a zero set-point then sits at the edge of motion.
        """
        a = self.angle_rad
        # Keep the last knot of each flat run, so the inverse is a function.
        keep = np.append(np.diff(a) > 1e-9, True)
        strictly_a = a[keep]
        strictly_p = self.pressure_pa[keep]
        return np.asarray(
            np.interp(np.asarray(angle_rad, dtype=float), strictly_a, strictly_p), dtype=np.float64
        )

    def save(self, path: Path, **manifest_extra: object) -> None:
        """Write a model directory (manifest + hashed parameter file)."""
        data = json.dumps(
            {"pressure_pa": self.pressure_pa.tolist(), "angle_rad": self.angle_rad.tolist()},
            indent=1,
        ).encode()
        write_model_dir(
            path,
            KIND,
            inputs={"angle_desired": "rad"},
            outputs={"pressure_command": "Pa (gauge)"},
            payload={PARAMS_FILE: data},
            **manifest_extra,
        )

    @classmethod
    def load(cls, path: Path) -> StaticMap:
        """Read and hash-check a model directory written by :meth:`save`."""
        _, payload = read_model_dir(path, expected_kind=KIND)
        raw = json.loads(payload[PARAMS_FILE])
        p = np.asarray(raw["pressure_pa"], dtype=float)
        a = np.asarray(raw["angle_rad"], dtype=float)
        if p.ndim != 1 or p.shape != a.shape or p.size < 2 or np.any(np.diff(p) <= 0):
            raise ParameterError(f"{path}: static map knots are malformed")
        return cls(pressure_pa=p, angle_rad=a)
