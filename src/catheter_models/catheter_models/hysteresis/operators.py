"""Hysteresis operators of the thesis, written once in numba, for batch, stream and search.

Every kernel takes the operator state in and leaves the final state out (updated in place),
so ``predict`` (a whole signal), a stream (a one-sample chunk) and the identification (a whole
population of parameter sets, in parallel) all run the same machine code.

Which function implements which equation (numbers of the thesis):

* :func:`play_step`, :func:`play`: the play operator with per-sample thresholds, eq. 5.2
  (rate-dependent thresholds, eq. 5.6) and eq. 9.13 / 9.18 (constant thresholds).
* :func:`deadband`: the deadband operator Λ_d, eq. 5.5.
* :func:`deadband_sum`, :func:`deadband_sum_array`: the weighted deadband sum Z, eq. 5.4,
  and its inverse Z⁻¹ of the same form, eq. 9.7.
* :func:`envelope`, :func:`envelope_inverse`: the GPI envelope γ, eq. 9.14, and γ⁻¹, eq. 9.21.
* :func:`chain_step`, :func:`chain_run`: a DRDPI-structure operator chain
  ``input deadband sum -> rate-dependent PI (eq. 5.1) -> output deadband sum``. With an
  identity input stage it is the DRDPI E = Z(y), eqs. 5.1-5.11; with an identity output
  stage it is the analytic inverse E⁻¹ = y⁻¹(Z⁻¹(u)), eqs. 9.2-9.11.
* :func:`drdpi_coefficients`: Table 5.1's 12 parameters -> a chain, eqs. 5.6-5.11.
* :func:`drdpi_population_loss`: eq. 5.12 (sum over recordings of the per-recording MSE)
  for a whole population of parameter sets, one numba thread per candidate.
* :func:`invert_pi`: inverse PI weights and threshold map, eqs. 9.3-9.6 = 9.19-9.20.
* :func:`invert_deadband`: inverse deadband thresholds and weights, eqs. 9.8-9.11.
* :func:`gpi_step`, :func:`gpi_run`: the GPI, eqs. 9.12-9.16; :func:`gpi_inverse_step`,
  :func:`gpi_inverse_run`: its inverse, eqs. 9.17-9.21; :func:`gpi_population_loss`.

Coefficients travel as one flat float64 vector with a small header (the ``C_*`` and ``G_*``
layouts below), like the plant kernel's: numba compiles plain arrays to tight loops, and a
flat vector is one argument, one JSON list, one thing to compare in a test.

The rate in the DRDPI thresholds (eq. 5.6) is a causal estimate of the PI stage's input rate:
a backward difference ``(v[k] - v[k-1]) * rate_hz`` through a first-order low-pass
``rate[k] = rate[k-1] + alpha (diff - rate[k-1])`` (``alpha = 1`` is the raw difference). It
lives in the chain's state, so batch and stream compute it identically.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit, prange

from catheter_models.errors import ParameterError

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

# --- DRDPI-structure chain coefficient layout ---------------------------------------------
C_N_PRE = 0  # number of input-stage deadband operators
C_N_PLAY = 1  # number of play operators
C_N_POST = 2  # number of output-stage deadband operators
C_INPUT_WEIGHT = 3  # a_0 (eq. 5.1) or c_0 (eq. 9.5)
C_RATE_HZ = 4  # sample rate used by the rate estimate [Hz]
C_RATE_ALPHA = 5  # low-pass factor of the rate estimate, in (0, 1]
C_HEADER = 6
# then: pre_thresholds[n_pre], pre_weights[n_pre], threshold_base[n_play],
#       threshold_per_rate[n_play], play_weights[n_play], post_thresholds[n_post],
#       post_weights[n_post]

# --- chain state layout --------------------------------------------------------------------
S_PREVIOUS_INPUT = 0  # the PI stage's input at the previous sample
S_RATE = 1  # filtered rate of the PI stage's input [input unit / s]
S_PLAYS = 2  # then one play output per operator

# --- GPI coefficient layout (forward and inverse share it) -------------------------------
G_N = 0  # number of play operators
G_C0 = 1  # envelope c_0, c_1, c_2, c_3 (eq. 9.14)
G_C1 = 2
G_C2 = 3
G_C3 = 4
G_INPUT_WEIGHT = 5  # q (eq. 9.12) or q' = 1/q (eq. 9.20)
G_HEADER = 6
# then: thresholds[n] (r_i, eq. 9.16, or r'_i, eq. 9.19), weights[n] (p(r_i), eq. 9.15, or p'_i)

ENVELOPE_MARGIN = 1e-9
"""γ⁻¹ (eq. 9.21) saturates at tanh argument ±atanh(1 - margin) outside γ's range."""


# --------------------------------------------------------------------------------------------
# Elementary operators
# --------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def play_step(x: float, threshold: float, previous: float) -> float:
    """One step of the play operator, eqs. 5.2 / 9.13: ``max(x - r, min(x + r, previous))``.

    Args:
        x: Input at this sample.
        threshold: r >= 0 at this sample, in the input's unit.
        previous: The operator's output at the previous sample.

    Returns:
        The operator's output, always within ``[x - r, x + r]``.
    """
    return max(x - threshold, min(x + threshold, previous))


@njit(cache=True)
def play(x: FloatArray, thresholds: FloatArray, state: FloatArray, out: FloatArray) -> None:
    """Run ``m`` play operators over a signal, with a threshold per sample and operator.

    Constant thresholds (eq. 9.13) are rows that repeat; rate-dependent ones (eqs. 5.2, 5.6)
    change from row to row.

    Args:
        x: Input signal, shape ``(n,)``.
        thresholds: r_i at each sample, shape ``(n, m)``, each >= 0.
        state: Each operator's output before the first sample, shape ``(m,)``; left holding
            the output at the last sample.
        out: Filled with the operators' outputs, shape ``(n, m)``.
    """
    m = state.size
    for k in range(x.size):
        for i in range(m):
            state[i] = play_step(x[k], thresholds[k, i], state[i])
            out[k, i] = state[i]


@njit(cache=True, inline="always")
def deadband(y: float, d: float) -> float:
    """The deadband operator Λ_d, eq. 5.5: ``max(y-d, 0)`` (d>0), ``y`` (d=0), ``min(y-d, 0)``."""
    if d > 0.0:
        return max(y - d, 0.0)
    if d < 0.0:
        return min(y - d, 0.0)
    return y


@njit(cache=True)
def deadband_sum(y: float, thresholds: FloatArray, weights: FloatArray) -> float:
    """Weighted deadband sum, eq. 5.4 (Z) or eq. 9.7 (Z⁻¹): ``sum_j g_j Λ_{d_j}(y)``.

    Args:
        y: Input value.
        thresholds: d_j (or b_j), any order.
        weights: g_j (or q_j), same length.

    Returns:
        The sum; 0 at y = 0 whatever the coefficients.
    """
    total = 0.0
    for j in range(thresholds.size):
        total += weights[j] * deadband(y, thresholds[j])
    return total


@njit(cache=True)
def deadband_sum_array(
    y: FloatArray, thresholds: FloatArray, weights: FloatArray, out: FloatArray
) -> None:
    """:func:`deadband_sum` for every sample of ``y`` (it is static: no state)."""
    for k in range(y.size):
        out[k] = deadband_sum(y[k], thresholds, weights)


@njit(cache=True, inline="always")
def envelope(x: float, c0: float, c1: float, c2: float, c3: float) -> float:
    """The GPI envelope, eq. 9.14: ``γ(x) = c0 tanh(c1 x + c2) + c3`` (c0, c1 > 0)."""
    return c0 * math.tanh(c1 * x + c2) + c3


@njit(cache=True, inline="always")
def envelope_inverse(w: float, c0: float, c1: float, c2: float, c3: float) -> float:
    """γ⁻¹, eq. 9.21: ``(1 / (2 c1)) ln((w + c0 - c3) / (c0 + c3 - w)) - c2 / c1``.

    Written as ``(atanh((w - c3) / c0) - c2) / c1``, the same function. γ only reaches
    ``(c3 - c0, c3 + c0)``; beyond it the ratio is held at ``±(1 - ENVELOPE_MARGIN)``, so the
    inverse saturates at a large but finite input instead of returning NaN or inf.
    """
    ratio = (w - c3) / c0
    limit = 1.0 - ENVELOPE_MARGIN
    ratio = min(max(ratio, -limit), limit)
    return (math.atanh(ratio) - c2) / c1


# --------------------------------------------------------------------------------------------
# The DRDPI-structure chain (eqs. 5.1-5.11 forward, 9.2-9.11 inverse)
# --------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def chain_views(
    coef: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]:
    """The parts of a chain's coefficient vector, as views, decoded once per run.

    Returns:
        ``(pre_thresholds, pre_weights, threshold_base, threshold_per_rate, play_weights,
        post_thresholds, post_weights)``.
    """
    n_pre = int(coef[C_N_PRE])
    n_play = int(coef[C_N_PLAY])
    n_post = int(coef[C_N_POST])
    a = C_HEADER
    b = a + 2 * n_pre
    c = b + 3 * n_play
    return (
        coef[a : a + n_pre],
        coef[a + n_pre : b],
        coef[b : b + n_play],
        coef[b + n_play : b + 2 * n_play],
        coef[b + 2 * n_play : c],
        coef[c : c + n_post],
        coef[c + n_post : c + 2 * n_post],
    )


@njit(cache=True, inline="always")
def chain_step(
    x: float,
    coef: FloatArray,
    views: tuple[
        FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray
    ],
    state: FloatArray,
) -> float:
    """Advance a DRDPI-structure chain by one sample.

    ``v = Z_in(x)``; ``rate`` = filtered backward difference of v; thresholds
    ``r_i = base_i + per_rate_i |rate|`` (eq. 5.6 with ζ i and β); ``y = w0 v + sum_i w_i
    Φ_{r_i}[v]`` (eq. 5.1 / 9.5); output ``Z_out(y)`` (eq. 5.4 / 9.7).

    Args:
        x: Input sample.
        coef: Chain coefficients (``C_*`` layout); the header's scalars are read here.
        views: ``chain_views(coef)``.
        state: Chain state (``S_*`` layout, ``2 + n_play`` long), updated in place.

    Returns:
        The chain's output at this sample.
    """
    pre_d, pre_g, base, per_rate, weights, post_d, post_g = views
    v = 0.0
    for j in range(pre_d.size):
        v += pre_g[j] * deadband(x, pre_d[j])
    rate = state[S_RATE] + coef[C_RATE_ALPHA] * (
        (v - state[S_PREVIOUS_INPUT]) * coef[C_RATE_HZ] - state[S_RATE]
    )
    state[S_PREVIOUS_INPUT] = v
    state[S_RATE] = rate
    speed = abs(rate)
    y = coef[C_INPUT_WEIGHT] * v
    for i in range(base.size):
        phi = play_step(v, base[i] + per_rate[i] * speed, state[S_PLAYS + i])
        state[S_PLAYS + i] = phi
        y += weights[i] * phi
    out = 0.0
    for j in range(post_d.size):
        out += post_g[j] * deadband(y, post_d[j])
    return out


@njit(cache=True)
def chain_run(x: FloatArray, coef: FloatArray, state: FloatArray, out: FloatArray) -> None:
    """:func:`chain_step` over a whole signal; a stream calls it with one-sample chunks.

    Args:
        x: Input signal, shape ``(n,)``.
        coef: Chain coefficients (``C_*`` layout).
        state: Chain state; all zeros is rest. Left holding the state after the last sample.
        out: Filled with the output, shape ``(n,)``.
    """
    views = chain_views(coef)
    for k in range(x.size):
        out[k] = chain_step(x[k], coef, views, state)


def chain_state_size(coef: FloatArray) -> int:
    """Length of the state vector a chain with coefficients ``coef`` needs."""
    return S_PLAYS + int(coef[C_N_PLAY])


@njit(cache=True)
def drdpi_coefficients(
    theta: FloatArray, n_play: int, n_deadband: int, rate_hz: float, rate_alpha: float
) -> FloatArray:
    """Table 5.1's parameters -> the coefficients of the DRDPI chain (eqs. 5.6-5.11).

    ``theta`` = (alpha0, alpha1, alpha2, beta0, beta1, beta2, dp, dn, zeta, beta, a0, g0).
    Play operators i = 1..N: threshold ``zeta i + beta |rate|`` (eq. 5.6 with the input rate),
    weight ``alpha0 exp(-beta0 i)`` (eq. 5.7); input weight a0. Deadband operators
    j = -k..k: thresholds ``dn j`` (j < 0), 0, ``dp j`` (j > 0) (eqs. 5.8, 5.10); weights
    ``-alpha2 exp(-beta2 |j|)`` (j < 0, eq. 5.11 with |j|: see ``models.drdpi``), g0,
    ``-alpha1 exp(-beta1 j)`` (j > 0, eq. 5.9).

    Args:
        theta: The 12 parameters, in Table 5.1's order.
        n_play: N, number of play operators.
        n_deadband: k; the output stage has 2k + 1 deadband operators.
        rate_hz: Sample rate [Hz] of the signals the chain will see.
        rate_alpha: Low-pass factor of the rate estimate, in (0, 1].

    Returns:
        The coefficient vector (``C_*`` layout) with an identity input stage.
    """
    n_post = 2 * n_deadband + 1
    coef = np.empty(C_HEADER + 2 + 3 * n_play + 2 * n_post)
    coef[C_N_PRE] = 1.0
    coef[C_N_PLAY] = n_play
    coef[C_N_POST] = n_post
    coef[C_INPUT_WEIGHT] = theta[10]
    coef[C_RATE_HZ] = rate_hz
    coef[C_RATE_ALPHA] = rate_alpha
    at = C_HEADER
    coef[at] = 0.0  # identity input stage: one operator with d = 0 and weight 1
    coef[at + 1] = 1.0
    at += 2
    for i in range(n_play):
        idx = i + 1.0
        coef[at + i] = theta[8] * idx
        coef[at + n_play + i] = theta[9]
        coef[at + 2 * n_play + i] = theta[0] * math.exp(-theta[3] * idx)
    at += 3 * n_play
    for m in range(n_post):
        j = m - n_deadband
        if j < 0:
            coef[at + m] = theta[7] * j
            coef[at + n_post + m] = -theta[2] * math.exp(-theta[5] * (-j))
        elif j == 0:
            coef[at + m] = 0.0
            coef[at + n_post + m] = theta[11]
        else:
            coef[at + m] = theta[6] * j
            coef[at + n_post + m] = -theta[1] * math.exp(-theta[4] * j)
    return coef


@njit(cache=True)
def drdpi_monotone_margin(theta: FloatArray, n_play: int, n_deadband: int) -> float:
    """Smallest partial slope of a DRDPI chain; > 0 means every stage is increasing.

    The PI's slopes ``a0 + sum_{j<=i} a_j`` (i = 0..N) and the deadband sum's slopes
    ``g0 + sum of g_j from 0 outwards`` are the denominators of the inverse weights
    (eqs. 9.6, 9.9, 9.11): all positive is exactly "invertible", and it is also what makes
    more input give more output on every branch.

    Args:
        theta: The 12 parameters, Table 5.1's order.
        n_play: N.
        n_deadband: k.

    Returns:
        The smallest of these partial sums (the PI's and Z's together).
    """
    slope: float = theta[10]
    margin = slope
    for i in range(n_play):
        slope += theta[0] * math.exp(-theta[3] * (i + 1.0))
        margin = min(margin, slope)
    up: float = theta[11]
    down: float = theta[11]
    margin = min(margin, up)
    for j in range(1, n_deadband + 1):
        up += -theta[1] * math.exp(-theta[4] * j)
        down += -theta[2] * math.exp(-theta[5] * j)
        margin = min(margin, up, down)
    return margin


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


def pack_chain(
    *,
    pre_thresholds: FloatArray,
    pre_weights: FloatArray,
    input_weight: float,
    threshold_base: FloatArray,
    threshold_per_rate: FloatArray,
    play_weights: FloatArray,
    post_thresholds: FloatArray,
    post_weights: FloatArray,
    rate_hz: float,
    rate_alpha: float,
) -> FloatArray:
    """Build a chain's coefficient vector (``C_*`` layout) from its parts.

    Raises:
        ParameterError: If the parts of a stage disagree in length.
    """
    parts = [
        np.asarray(a, dtype=np.float64).ravel()
        for a in (
            pre_thresholds,
            pre_weights,
            threshold_base,
            threshold_per_rate,
            play_weights,
            post_thresholds,
            post_weights,
        )
    ]
    n_pre, n_play, n_post = parts[0].size, parts[2].size, parts[5].size
    if parts[1].size != n_pre or parts[3].size != n_play or parts[4].size != n_play:
        raise ParameterError(
            f"chain parts disagree in length: {n_pre} input-stage thresholds but "
            f"{parts[1].size} weights; {n_play} play thresholds but {parts[3].size} rate "
            f"coefficients and {parts[4].size} weights"
        )
    if parts[6].size != n_post:
        raise ParameterError(f"chain output stage: {n_post} thresholds but {parts[6].size} weights")
    header = np.array([n_pre, n_play, n_post, input_weight, rate_hz, rate_alpha], dtype=float)
    out: FloatArray = np.concatenate([header, *parts])
    return out


def unpack_chain(coef: FloatArray) -> dict[str, FloatArray]:
    """Inverse of :func:`pack_chain`: each part as an array (header scalars as 0-d arrays)."""
    n_pre, n_play, n_post = (int(coef[i]) for i in (C_N_PRE, C_N_PLAY, C_N_POST))
    at = C_HEADER
    out: dict[str, FloatArray] = {
        "input_weight": np.asarray(coef[C_INPUT_WEIGHT]),
        "rate_hz": np.asarray(coef[C_RATE_HZ]),
        "rate_alpha": np.asarray(coef[C_RATE_ALPHA]),
    }
    for name, size in (
        ("pre_thresholds", n_pre),
        ("pre_weights", n_pre),
        ("threshold_base", n_play),
        ("threshold_per_rate", n_play),
        ("play_weights", n_play),
        ("post_thresholds", n_post),
        ("post_weights", n_post),
    ):
        out[name] = coef[at : at + size]
        at += size
    return out


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


# --------------------------------------------------------------------------------------------
# GPI (eqs. 9.12-9.16) and its inverse (eqs. 9.17-9.21)
# --------------------------------------------------------------------------------------------


@njit(cache=True, inline="always")
def gpi_step(x: float, coef: FloatArray, state: FloatArray) -> float:
    """One GPI sample, eq. 9.12: ``q γ(x) + sum_i p_i F_{r_i}[γ(x)]`` (eqs. 9.13, 9.14).

    Args:
        x: Input sample.
        coef: GPI coefficients (``G_*`` layout, forward).
        state: The n play outputs, updated in place.

    Returns:
        The GPI's output.
    """
    n = int(coef[G_N])
    w = envelope(x, coef[G_C0], coef[G_C1], coef[G_C2], coef[G_C3])
    y: float = coef[G_INPUT_WEIGHT] * w
    for i in range(n):
        phi = play_step(w, coef[G_HEADER + i], state[i])
        state[i] = phi
        y += coef[G_HEADER + n + i] * phi
    return y


@njit(cache=True, inline="always")
def gpi_inverse_step(y: float, coef: FloatArray, state: FloatArray) -> float:
    """One inverse-GPI sample, eqs. 9.17-9.18: ``γ⁻¹(q' y + sum_i p'_i x_i)``.

    Args:
        y: Desired output sample.
        coef: Inverse GPI coefficients (``G_*`` layout: q', r'_i, p'_i).
        state: The n inverse play outputs x_i, updated in place.

    Returns:
        The input that makes the GPI produce ``y`` (finite: γ⁻¹ saturates).
    """
    n = int(coef[G_N])
    z = coef[G_INPUT_WEIGHT] * y
    for i in range(n):
        phi = play_step(y, coef[G_HEADER + i], state[i])
        state[i] = phi
        z += coef[G_HEADER + n + i] * phi
    return envelope_inverse(z, coef[G_C0], coef[G_C1], coef[G_C2], coef[G_C3])


@njit(cache=True)
def gpi_run(x: FloatArray, coef: FloatArray, state: FloatArray, out: FloatArray) -> None:
    """:func:`gpi_step` over a whole signal (``state`` in and out)."""
    for k in range(x.size):
        out[k] = gpi_step(x[k], coef, state)


@njit(cache=True)
def gpi_inverse_run(y: FloatArray, coef: FloatArray, state: FloatArray, out: FloatArray) -> None:
    """:func:`gpi_inverse_step` over a whole signal (``state`` in and out)."""
    for k in range(y.size):
        out[k] = gpi_inverse_step(y[k], coef, state)


@njit(cache=True)
def gpi_coefficients(theta: FloatArray, n: int) -> FloatArray:
    """Table 9.1's parameters -> GPI coefficients: r_i = β i (eq. 9.16), p_i = ρ e^{-τ r_i}.

    Args:
        theta: (c0, c1, c2, c3, beta, rho, tau, q).
        n: Number of play operators.

    Returns:
        The coefficient vector (``G_*`` layout, forward).
    """
    coef = np.empty(G_HEADER + 2 * n)
    coef[G_N] = n
    coef[G_C0] = theta[0]
    coef[G_C1] = theta[1]
    coef[G_C2] = theta[2]
    coef[G_C3] = theta[3]
    coef[G_INPUT_WEIGHT] = theta[7]
    for i in range(n):
        r = theta[4] * (i + 1.0)
        coef[G_HEADER + i] = r
        coef[G_HEADER + n + i] = theta[5] * math.exp(-theta[6] * r)
    return coef


@njit(cache=True)
def gpi_rest_state(coef: FloatArray) -> FloatArray:
    """Forward GPI plays at rest: each equal to its input γ(0), as a PI's are at u = 0."""
    rest = envelope(0.0, coef[G_C0], coef[G_C1], coef[G_C2], coef[G_C3])
    return np.full(int(coef[G_N]), rest)


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


def invert_gpi(coef: FloatArray) -> FloatArray:
    """Inverse GPI coefficients, eqs. 9.19-9.20 (q' = 1/q: eq. 9.20 prints 1/q', a typo).

    Args:
        coef: Forward GPI coefficients (``G_*`` layout).

    Returns:
        Inverse coefficients in the same layout: the envelope constants unchanged (used by
        γ⁻¹), q', r'_i, p'_i.
    """
    n = int(coef[G_N])
    r = coef[G_HEADER : G_HEADER + n]
    p = coef[G_HEADER + n : G_HEADER + 2 * n]
    q_inv, p_inv, m = invert_pi(float(coef[G_INPUT_WEIGHT]), p)
    out = coef.copy()
    out[G_INPUT_WEIGHT] = q_inv
    out[G_HEADER : G_HEADER + n] = m @ r
    out[G_HEADER + n : G_HEADER + 2 * n] = p_inv
    return out


def gpi_inverse_rest_state(coef: FloatArray) -> FloatArray:
    """Inverse GPI plays at rest: each at the forward GPI's output at rest.

    With it, the inverse maps the forward GPI's rest output back to exactly x = 0.

    Args:
        coef: Forward GPI coefficients (``G_*`` layout).
    """
    rest_out = float(gpi_step(0.0, coef, gpi_rest_state(coef)))
    return np.full(int(coef[G_N]), rest_out)
