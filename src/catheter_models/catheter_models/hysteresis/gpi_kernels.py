"""The GPI (thesis eqs. 9.12-9.16) and its inverse (eqs. 9.17-9.21), in numba.

Apart from :mod:`catheter_models.hysteresis.operators` because the GPI is its own model with
its own coefficient layout (``G_*``, below, shared by forward and inverse); it is built from
that module's play operator and envelope, and its inverse weights are
:func:`~catheter_models.hysteresis.inverse.invert_pi`'s.

* :func:`gpi_step`, :func:`gpi_run`: the GPI, eqs. 9.12-9.16.
* :func:`gpi_inverse_step`, :func:`gpi_inverse_run`: its inverse, eqs. 9.17-9.21.
* :func:`gpi_coefficients`: Table 9.1's parameters -> coefficients; :func:`invert_gpi`: the
  inverse's coefficients, eqs. 9.19-9.20.
* :func:`gpi_rest_state`, :func:`gpi_inverse_rest_state`: the plays at rest.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from catheter_models.hysteresis.inverse import invert_pi
from catheter_models.hysteresis.operators import (
    FloatArray,
    envelope,
    envelope_inverse,
    play_step,
)

# --- GPI coefficient layout (forward and inverse share it) -------------------------------
G_N = 0  # number of play operators
G_C0 = 1  # envelope c_0, c_1, c_2, c_3 (eq. 9.14)
G_C1 = 2
G_C2 = 3
G_C3 = 4
G_INPUT_WEIGHT = 5  # q (eq. 9.12) or q' = 1/q (eq. 9.20)
G_HEADER = 6
# then: thresholds[n] (r_i, eq. 9.16, or r'_i, eq. 9.19), weights[n] (p(r_i), eq. 9.15, or p'_i)


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
