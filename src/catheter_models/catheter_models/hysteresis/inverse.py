"""Analytic inverses of PI, deadband sum and DRDPI chain (thesis eqs. 9.2-9.11, 9.19-9.20).

The inverse of a chain is another chain of the same ``C_*`` layout (input stage Z⁻¹, play
stage the PI's inverse, identity output stage), so :func:`operators.chain_run` runs it; this
module only computes its coefficients. It is apart from
:mod:`catheter_models.hysteresis.operators` because it is algebra on coefficients, done once
per parameter set, not a per-sample kernel. The GPI's inverse
(:mod:`~catheter_models.hysteresis.gpi_kernels`) reuses :func:`invert_pi`.

* :func:`invert_pi`: inverse PI weights and threshold map, eqs. 9.3-9.6 = 9.19-9.20.
* :func:`invert_deadband`: inverse deadband thresholds and weights, eqs. 9.8-9.11.
* :func:`invert_chain`, :func:`invert_chain_kernel`: E⁻¹ = y⁻¹ ∘ Z⁻¹ (eq. 9.2), checked and
  unchecked (the population loss calls the kernel inside numba).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from catheter_models.errors import ParameterError
from catheter_models.hysteresis.operators import (
    C_HEADER,
    C_INPUT_WEIGHT,
    C_N_PLAY,
    C_N_POST,
    C_N_PRE,
    C_RATE_ALPHA,
    C_RATE_HZ,
    FloatArray,
    unpack_chain,
)

# --------------------------------------------------------------------------------------------
# Kernels (numba, unchecked: the wrappers below check first; the population loss calls
# invert_chain_kernel on candidates already known to be increasing)
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _invert_pi_kernel(w0: float, w: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    n = w.size
    c = np.empty(n)
    m = np.zeros((n, n))
    before = w0  # W_{i-1} = w0 + sum_{j<i} w_j
    for i in range(n):
        m[i, i] = before
        for j in range(i):
            m[i, j] = -w[j]
        after = before + w[i]
        c[i] = -w[i] / (after * before)
        before = after
    return 1.0 / w0, c, m


@njit(cache=True)
def _invert_deadband_kernel(d: FloatArray, g: FloatArray) -> tuple[FloatArray, FloatArray]:
    n = d.size
    k = (n - 1) // 2
    b = np.zeros(n)
    q = np.zeros(n)
    q[k] = 1.0 / g[k]
    for side in (1, -1):
        before = g[k]  # Z's slope just inside threshold j, from g_0 outwards
        for j in range(1, k + 1):
            m = k + side * j
            acc = 0.0
            for i in range(j + 1):
                acc += g[k + side * i] * (d[m] - d[k + side * i])
            b[m] = acc
            after = before + g[m]
            q[m] = -g[m] / (after * before)
            before = after
    return b, q


@njit(cache=True)
def invert_chain_kernel(coef: FloatArray) -> FloatArray:
    """Analytic inverse of a chain with an identity input stage; no checks (see invert_chain)."""
    n_play = int(coef[C_N_PLAY])
    n_post = int(coef[C_N_POST])
    at = C_HEADER + 2 * int(coef[C_N_PRE])
    base = coef[at : at + n_play]
    per_rate = coef[at + n_play : at + 2 * n_play]
    w = coef[at + 2 * n_play : at + 3 * n_play]
    at += 3 * n_play
    d = coef[at : at + n_post]
    g = coef[at + n_post : at + 2 * n_post]
    w0 = coef[C_INPUT_WEIGHT]
    c0, c, m = _invert_pi_kernel(w0, w)
    b, q = _invert_deadband_kernel(d, g)
    major_slope = w0 + np.sum(w)
    out = np.empty(C_HEADER + 2 * n_post + 3 * n_play + 2)
    out[C_N_PRE] = n_post
    out[C_N_PLAY] = n_play
    out[C_N_POST] = 1.0
    out[C_INPUT_WEIGHT] = c0
    out[C_RATE_HZ] = coef[C_RATE_HZ]
    out[C_RATE_ALPHA] = coef[C_RATE_ALPHA]
    at = C_HEADER
    out[at : at + n_post] = b
    out[at + n_post : at + 2 * n_post] = q
    at += 2 * n_post
    out[at : at + n_play] = m @ base
    # v̇ [y-unit/s] -> estimated u̇ [u-unit/s]: divide by the major-loop slope W_N.
    out[at + n_play : at + 2 * n_play] = (m @ per_rate) / major_slope
    out[at + 2 * n_play : at + 3 * n_play] = c
    at += 3 * n_play
    out[at] = 0.0  # identity output stage
    out[at + 1] = 1.0
    return out


# --------------------------------------------------------------------------------------------
# Inverse weights (eqs. 9.3-9.11, 9.19-9.20), checked wrappers of the kernels above
# --------------------------------------------------------------------------------------------


def invert_pi(input_weight: float, weights: FloatArray) -> tuple[float, FloatArray, FloatArray]:
    """Inverse of a PI ``y = w0 u + sum_i w_i Φ_{r_i}[u]`` with ascending thresholds.

    Eqs. 9.3-9.6 (DRDPI) and 9.19-9.20 (GPI) are the same algebra:
    ``c0 = 1/w0``, ``c_i = -w_i / (W_i W_{i-1})`` with ``W_i = w0 + sum_{j<=i} w_j``, and the
    inverse thresholds ``rho_i = w0 r_i + sum_{j<i} w_j (r_i - r_j)``, which are linear in the
    forward thresholds: ``rho = M r``. Returning M lets a caller map rate-dependent
    thresholds ``r_i = base_i + per_rate_i |rate|`` term by term.

    Args:
        input_weight: w0 > 0 (a_0 or q).
        weights: w_i, with every partial sum ``W_i > 0``.

    Returns:
        ``(c0, c, M)``: inverse input weight, inverse play weights, threshold map (n x n).

    Raises:
        ParameterError: If a partial sum ``W_i`` is not positive (the PI is not invertible).
    """
    w = np.ascontiguousarray(weights, dtype=np.float64)
    partial = input_weight + np.concatenate(([0.0], np.cumsum(w)))
    if not np.all(partial > 0.0):
        bad = int(np.flatnonzero(~(partial > 0.0))[0])
        raise ParameterError(
            f"PI not invertible: w0 + sum of the first {bad} play weights is "
            f"{partial[bad]:.6g}, must be > 0"
        )
    c0, c, m = _invert_pi_kernel(float(input_weight), w)
    return float(c0), c, m


def invert_deadband(thresholds: FloatArray, weights: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Thresholds and weights of Z⁻¹ (eq. 9.7) from those of Z (eq. 5.4), eqs. 9.8-9.11.

    ``b_j = Z(d_j)`` (eqs. 9.8, 9.10); ``q_0 = 1/g_0`` and ``q_j = -g_j / (G_j G_{j-1})`` with
    ``G_j`` the partial sum of the weights from g_0 out to g_j (eqs. 9.9, 9.11; the printed
    numerators g_i mean g_j).

    Args:
        thresholds: d_j for j = -k..k, ascending with d_0 = 0 in the middle.
        weights: g_j for the same j; every partial sum from g_0 outwards > 0.

    Returns:
        ``(b, q)``: the inverse's thresholds and weights, same order.

    Raises:
        ParameterError: If the layout is not -k..k around d_0 = 0, or Z is not increasing.
    """
    d = np.ascontiguousarray(thresholds, dtype=np.float64)
    g = np.ascontiguousarray(weights, dtype=np.float64)
    n = d.size
    k = (n - 1) // 2
    if n % 2 != 1 or g.size != n or d[k] != 0.0 or np.any(np.diff(d) <= 0.0):
        raise ParameterError(
            f"deadband thresholds must be d_-k < ... < d_0 = 0 < ... < d_k, got {d.tolist()}"
        )
    slopes_up = np.cumsum(g[k:])
    slopes_down = np.cumsum(g[k::-1])
    if not (np.all(slopes_up > 0.0) and np.all(slopes_down > 0.0)):
        raise ParameterError(
            "deadband sum not invertible: g_0 and every partial sum from g_0 outwards must be "
            f"> 0, got {slopes_down[::-1].tolist()} (down) and {slopes_up.tolist()} (up)"
        )
    b, q = _invert_deadband_kernel(d, g)
    return b, q


def invert_chain(coef: FloatArray) -> FloatArray:
    """Analytic inverse E⁻¹ = y⁻¹ ∘ Z⁻¹ (eq. 9.2) of a DRDPI chain with identity input stage.

    Z⁻¹ becomes the input stage (eqs. 9.7-9.11), the PI inverse the play stage (eqs. 9.3-9.6),
    and the output stage is the identity.

    Rate: the forward thresholds depend on the rate of the *forward* input (pressure,
    eq. 5.6); the inverse knows only the rate of its own PI-stage input v = Z⁻¹(desired)
    (eqs. 9.3-9.4 write ρ_i(u̇) with u the inverse's input). It estimates the pressure rate
    as ``v̇ / (a0 + sum a_i)``: the reciprocal of the PI's slope once every play slides,
    i.e. the mean slope over a major loop. With eq. 5.6's thresholds the increments
    ``r_{i+1} - r_i = ζ`` do not depend on the rate, so the rate enters every inverse
    threshold as the same shift ``a0 β |u̇|``.

    Args:
        coef: A forward chain (``C_*`` layout) whose input stage is the identity.

    Returns:
        The inverse chain's coefficients (``C_*`` layout).

    Raises:
        ParameterError: If the input stage is not the identity, the thresholds do not
            ascend, or a stage is not invertible (the message names it).
    """
    parts = unpack_chain(coef)
    pre_d, pre_g = parts["pre_thresholds"], parts["pre_weights"]
    if not (pre_d.size == 1 and pre_d[0] == 0.0 and pre_g[0] == 1.0):
        raise ParameterError("invert_chain needs a chain whose input stage is the identity")
    if np.any(np.diff(parts["threshold_base"]) < 0.0) or np.any(parts["threshold_base"] < 0.0):
        raise ParameterError(
            "play thresholds must be >= 0 and ascend (eq. 5.3), got "
            f"{parts['threshold_base'].tolist()}"
        )
    # The checked wrappers raise with the offending sums named; the kernel assumes them.
    invert_pi(float(parts["input_weight"]), parts["play_weights"])
    invert_deadband(parts["post_thresholds"], parts["post_weights"])
    out: FloatArray = invert_chain_kernel(np.ascontiguousarray(coef, dtype=np.float64))
    return out
