"""The static map's monotone projection equals the libraries' isotonic regression.

``isotonic_increasing`` replaced ``scipy.optimize.isotonic_regression`` (SciPy >= 1.12, which
Ubuntu 24.04 lacks); a map fitted on either must be the same. Compared with scikit-learn's
isotonic regression always, and with SciPy's where the installed SciPy has it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from sklearn.isotonic import IsotonicRegression

from catheter_models.errors import ParameterError
from catheter_models.static_map import isotonic_increasing

FloatArray = np.ndarray


def _sklearn(values: FloatArray, weights: FloatArray) -> FloatArray:
    x = np.arange(values.size, dtype=np.float64)
    return np.asarray(IsotonicRegression().fit_transform(x, values, sample_weight=weights))


def _scipy(values: FloatArray, weights: FloatArray) -> FloatArray:
    optimize = pytest.importorskip("scipy.optimize")
    if not hasattr(optimize, "isotonic_regression"):
        pytest.skip("this SciPy has no optimize.isotonic_regression (< 1.12)")
    return np.asarray(optimize.isotonic_regression(values, weights=weights).x)


@pytest.mark.parametrize("reference", [_sklearn, _scipy], ids=["sklearn", "scipy"])
def test_same_projection_as_the_libraries(
    reference: Callable[[FloatArray, FloatArray], FloatArray],
) -> None:
    rng = np.random.default_rng(16)
    for trial in range(300):
        n = int(rng.integers(1, 40))
        # A rising curve with noise (what the static map sees), runs of ties and outliers.
        values = np.cumsum(rng.normal(0.01, 0.05, n)) + rng.normal(0.0, 0.02, n)
        values[rng.random(n) < 0.1] = 0.3
        weights = rng.integers(1, 50, n).astype(np.float64)
        ours = isotonic_increasing(values, weights)
        assert np.all(np.diff(ours) >= 0.0), f"trial {trial}: not non-decreasing"
        np.testing.assert_allclose(ours, reference(values, weights), rtol=1e-10, atol=1e-12)


def test_refuses_weights_it_cannot_use() -> None:
    with pytest.raises(ParameterError, match="positive and finite"):
        isotonic_increasing(np.array([1.0, 0.0]), np.array([1.0, 0.0]))
    with pytest.raises(ParameterError, match="equal length"):
        isotonic_increasing(np.array([1.0, 0.0]), np.array([1.0]))
