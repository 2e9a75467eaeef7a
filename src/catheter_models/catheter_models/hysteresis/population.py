"""The identification's loss (thesis eq. 5.12) for a whole population of parameter sets.

Each kernel scores every candidate of a differential-evolution generation in one numba
``prange`` (one thread per candidate), so both cores work. Apart from the operators because
it composes them: the DRDPI's loss runs the forward chain
(:mod:`catheter_models.hysteresis.operators`) or its analytic inverse
(:mod:`catheter_models.hysteresis.inverse`), the GPI's runs
:mod:`catheter_models.hysteresis.gpi_kernels`; kept in ``operators`` it would make that module
import its own inverse, a cycle.

* :func:`drdpi_population_loss`: eq. 5.12 for the DRDPI E or its inverse E⁻¹.
* :func:`gpi_population_loss`: eq. 5.12 for the GPI.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from catheter_models.hysteresis.gpi_kernels import gpi_coefficients, gpi_rest_state, gpi_step
from catheter_models.hysteresis.inverse import invert_chain_kernel
from catheter_models.hysteresis.operators import (
    S_PLAYS,
    FloatArray,
    IntArray,
    chain_step,
    chain_views,
    drdpi_coefficients,
    drdpi_monotone_margin,
)

MONOTONE_PENALTY = 1e6
"""Loss of a candidate whose chain is not increasing (plus its violation): DE rejects it."""


# numba compiles positional scalars and arrays; a parameter object would cost a Python call.
@njit(cache=True, parallel=True)
def drdpi_population_loss(  # noqa: PLR0917
    thetas: FloatArray,
    n_play: int,
    n_deadband: int,
    rate_hz: float,
    rate_alpha: float,
    inverse: bool,
    x: FloatArray,
    y: FloatArray,
    starts: IntArray,
) -> FloatArray:
    """Eq. 5.12 for each row of ``thetas``: sum over recordings of the per-recording MSE.

    Candidates run in parallel (numba ``prange``); each recording starts from rest. A
    candidate whose chain is not increasing (:func:`drdpi_monotone_margin` <= 0) scores
    ``MONOTONE_PENALTY`` plus its violation, so the search leaves that region.

    Args:
        thetas: Parameter sets, shape ``(P, 12)``, Table 5.1's order.
        n_play: N.
        n_deadband: k.
        rate_hz: Sample rate [Hz].
        rate_alpha: Low-pass factor of the rate estimate.
        inverse: Score the analytic inverse E⁻¹ of each candidate (eqs. 9.2-9.11) instead
            of the DRDPI E itself.
        x: All recordings' inputs back to back.
        y: All recordings' measured outputs back to back.
        starts: Index of each recording's first sample, then ``x.size``.

    Returns:
        The loss of each candidate, shape ``(P,)``; ``inf`` where the output overflowed.
    """
    n_cand = thetas.shape[0]
    loss = np.empty(n_cand)
    for c in prange(n_cand):
        margin = drdpi_monotone_margin(thetas[c], n_play, n_deadband)
        if not margin > 0.0:
            loss[c] = MONOTONE_PENALTY * (1.0 - margin)
            continue
        coef = drdpi_coefficients(thetas[c], n_play, n_deadband, rate_hz, rate_alpha)
        if inverse:
            coef = invert_chain_kernel(coef)
        views = chain_views(coef)
        state = np.empty(S_PLAYS + n_play)
        total = 0.0
        for s in range(starts.size - 1):
            state[:] = 0.0
            acc = 0.0
            for k in range(starts[s], starts[s + 1]):
                err = chain_step(x[k], coef, views, state) - y[k]
                acc += err * err
            total += acc / (starts[s + 1] - starts[s])
        loss[c] = total if math.isfinite(total) else math.inf
    return loss


@njit(cache=True, parallel=True)
def gpi_population_loss(
    thetas: FloatArray, n: int, x: FloatArray, y: FloatArray, starts: IntArray
) -> FloatArray:
    """Eq. 5.12 with the GPI for each row of ``thetas`` (see :func:`drdpi_population_loss`)."""
    n_cand = thetas.shape[0]
    loss = np.empty(n_cand)
    for c in prange(n_cand):
        coef = gpi_coefficients(thetas[c], n)
        total = 0.0
        for s in range(starts.size - 1):
            state = gpi_rest_state(coef)
            acc = 0.0
            for k in range(starts[s], starts[s + 1]):
                err = gpi_step(x[k], coef, state) - y[k]
                acc += err * err
            total += acc / (starts[s + 1] - starts[s])
        loss[c] = total if math.isfinite(total) else math.inf
    return loss
