"""Hysteresis operators of the thesis, written once in numba, for batch, stream and search.

Every kernel takes the operator state in and leaves the final state out (updated in place),
so ``predict`` (a whole signal), a stream (a one-sample chunk) and the identification (a whole
population of parameter sets, in parallel) all run the same machine code.

This module holds the elementary operators and the forward DRDPI-structure chain; the rest
of the package builds on it (and it imports none of them):

* :mod:`catheter_models.hysteresis.inverse`: the analytic inverses of PI, deadband sum and
  chain (eqs. 9.2-9.11).
* :mod:`catheter_models.hysteresis.gpi_kernels`: the GPI and its inverse (eqs. 9.12-9.21).
* :mod:`catheter_models.hysteresis.population`: the identification's loss, eq. 5.12, over a
  whole population of parameter sets.

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
* :func:`drdpi_monotone_margin`: whether every stage of a chain is increasing (invertible).

Coefficients travel as one flat float64 vector with a small header (the ``C_*`` layout
below; the GPI's ``G_*`` layout is in :mod:`~catheter_models.hysteresis.gpi_kernels`), like
the plant kernel's: numba compiles plain arrays to tight loops, and a flat vector is one
argument, one JSON list, one thing to compare in a test.

The rate in the DRDPI thresholds (eq. 5.6) is a causal estimate of the PI stage's input rate:
a backward difference ``(v[k] - v[k-1]) * rate_hz`` through a first-order low-pass
``rate[k] = rate[k-1] + alpha (diff - rate[k-1])`` (``alpha = 1`` is the raw difference). It
lives in the chain's state, so batch and stream compute it identically.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

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
# The DRDPI-structure chain (eqs. 5.1-5.11 forward, 9.2-9.11 inverse: see inverse.py)
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


# --------------------------------------------------------------------------------------------
# A chain's coefficient vector (``C_*`` layout) from its parts and back
# --------------------------------------------------------------------------------------------


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
