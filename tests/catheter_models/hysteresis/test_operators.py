"""Tests of the hysteresis kernels (catheter_models.hysteresis: operators, inverse, GPI, loss).

Identities that hold by the thesis's definitions (eqs. 5.2, 5.5, 9.7-9.21), checked on the
compiled kernels, and the promise that a stream (one-sample chunks) equals the batch run.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from catheter_models.errors import ParameterError
from catheter_models.hysteresis import gpi_kernels
from catheter_models.hysteresis import operators as op
from catheter_models.hysteresis.inverse import invert_chain, invert_deadband, invert_pi
from catheter_models.hysteresis.population import MONOTONE_PENALTY, drdpi_population_loss

FloatArray = npt.NDArray[np.float64]
RATE_HZ = 250.0


def _descending_sine(amplitude: float, freq_hz: float, seconds: float = 12.0) -> FloatArray:
    """Eq. 4.1's shape: multi-loop, starts and ends near zero."""
    t = np.arange(round(seconds * RATE_HZ)) / RATE_HZ
    out: FloatArray = (
        amplitude * np.exp(-0.15 * t) * (np.sin(2 * math.pi * freq_hz * t - math.pi / 2) + 1.0)
    )
    return out


def _theta(beta: float = 0.02) -> FloatArray:
    """A DRDPI with every stage active: 3 plays of weight, a knee at y = 6, a negative side."""
    # alpha0, alpha1, alpha2, beta0, beta1, beta2, dp, dn, zeta, beta, a0, g0
    return np.array([4.0, -1.2, -0.3, 0.6, 0.8, 0.5, 6.0, 2.0, 0.08, beta, 3.0, 0.15])


def _run_chain(coef: FloatArray, x: FloatArray) -> FloatArray:
    out = np.empty(x.size)
    op.chain_run(x, coef, np.zeros(op.chain_state_size(coef)), out)
    return out


# --- play and deadband operators ---------------------------------------------------------------


def test_play_with_zero_threshold_is_the_identity() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=500).cumsum()
    out = np.empty((x.size, 3))
    op.play(x, np.zeros((x.size, 3)), np.array([5.0, -2.0, 0.0]), out)
    np.testing.assert_array_equal(out, np.repeat(x[:, None], 3, axis=1))


def test_play_output_stays_within_threshold_of_input_with_per_sample_thresholds() -> None:
    rng = np.random.default_rng(2)
    x = rng.normal(size=2000).cumsum() * 0.1
    r = rng.uniform(0.0, 0.8, size=(x.size, 4))  # rate-dependent: a new threshold each sample
    state = np.zeros(4)
    out = np.empty_like(r)
    op.play(x, r, state, out)
    assert np.all(out >= x[:, None] - r - 1e-15)
    assert np.all(out <= x[:, None] + r + 1e-15)
    np.testing.assert_array_equal(state, out[-1])  # state out = last output


def test_play_holds_inside_the_band_and_follows_outside() -> None:
    x = np.array([0.0, 1.0, 0.8, 0.6, 0.3, 0.9])
    out = np.empty((x.size, 1))
    op.play(x, np.full((x.size, 1), 0.25), np.zeros(1), out)
    np.testing.assert_allclose(out[:, 0], [0.0, 0.75, 0.75, 0.75, 0.55, 0.65])


@pytest.mark.parametrize("y", [-3.0, -0.5, 0.0, 0.4, 2.5])
def test_deadband_operator_eq_5_5(y: float) -> None:
    assert op.deadband(y, 0.0) == y
    assert op.deadband(y, 1.0) == max(y - 1.0, 0.0)
    assert op.deadband(y, -1.0) == min(y + 1.0, 0.0)
    # the pair +-d splits y into its part beyond the dead zone and the clipped part
    assert op.deadband(y, 1.0) + op.deadband(y, -1.0) + min(max(y, -1.0), 1.0) == pytest.approx(y)


def test_deadband_sum_is_zero_at_zero_and_its_inverse_undoes_it() -> None:
    d = np.array([-4.0, -2.0, 0.0, 3.0, 6.0])
    g = np.array([0.3, 0.2, 0.1, 1.5, 0.4])
    assert op.deadband_sum(0.0, d, g) == 0.0
    b, q = invert_deadband(d, g)
    y = np.linspace(-10.0, 15.0, 501)
    z = np.empty_like(y)
    op.deadband_sum_array(y, d, g, z)
    back = np.empty_like(y)
    op.deadband_sum_array(z, b, q, back)
    np.testing.assert_allclose(back, y, atol=1e-12)
    # eqs. 9.8/9.10: the inverse's thresholds are Z at the forward's thresholds
    np.testing.assert_allclose(b, [op.deadband_sum(float(v), d, g) for v in d], atol=1e-12)


def test_invert_deadband_refuses_a_folding_sum() -> None:
    with pytest.raises(ParameterError, match="not invertible"):
        invert_deadband(np.array([-1.0, 0.0, 1.0]), np.array([0.2, 0.5, -0.6]))
    with pytest.raises(ParameterError, match="d_0 = 0"):
        invert_deadband(np.array([-1.0, 0.5, 1.0]), np.array([0.2, 0.5, 0.6]))


# --- GPI envelope and the GPI ------------------------------------------------------------------


def test_envelope_inverse_undoes_envelope_and_saturates_finite() -> None:
    c = (7.75, 0.6, -0.97, 5.04)  # Table 9.3 (0.4 Hz)
    for x in np.linspace(-2.0, 4.0, 61):
        w = op.envelope(float(x), *c)
        assert op.envelope_inverse(w, *c) == pytest.approx(x, abs=1e-9)
    beyond = [op.envelope_inverse(w, *c) for w in (c[3] + c[0] + 5.0, c[3] - c[0] - 5.0)]
    assert all(math.isfinite(v) for v in beyond)
    assert beyond[0] > 4.0 > -2.0 > beyond[1]


def test_inverse_gpi_composed_with_gpi_is_the_identity_on_a_signal() -> None:
    theta = np.array([7.75, 0.6, -0.97, 5.04, 1.1, 9.9, 1.27, 1.75])  # Table 9.3's values
    coef = gpi_kernels.gpi_coefficients(theta, 10)
    inverse = gpi_kernels.invert_gpi(coef)
    x = _descending_sine(1.5, 0.4)
    y = np.empty_like(x)
    gpi_kernels.gpi_run(x, coef, gpi_kernels.gpi_rest_state(coef), y)
    back = np.empty_like(x)
    gpi_kernels.gpi_inverse_run(y, inverse, gpi_kernels.gpi_inverse_rest_state(coef), back)
    np.testing.assert_allclose(back, x, atol=1e-9)
    # eq. 9.20 (q' = 1/q) and the telescoping sum: q' + sum p'_i = 1 / (q + sum p_i)
    n = int(coef[gpi_kernels.G_N])
    p = coef[gpi_kernels.G_HEADER + n :]
    p_inv = inverse[gpi_kernels.G_HEADER + n :]
    assert inverse[gpi_kernels.G_INPUT_WEIGHT] == pytest.approx(1.0 / theta[7])
    assert inverse[gpi_kernels.G_INPUT_WEIGHT] + p_inv.sum() == pytest.approx(
        1.0 / (theta[7] + p.sum())
    )


# --- the DRDPI chain -----------------------------------------------------------------------------


def test_analytic_inverse_of_a_rate_independent_drdpi_is_exact() -> None:
    coef = op.drdpi_coefficients(_theta(beta=0.0), 10, 3, RATE_HZ, 1.0)
    x = _descending_sine(1.4, 0.3)
    y = _run_chain(coef, x)
    parts = op.unpack_chain(coef)
    # the knees at dp and 2 dp (y = 6, 12) are both crossed
    assert y.max() > op.deadband_sum(12.0, parts["post_thresholds"], parts["post_weights"])
    np.testing.assert_allclose(_run_chain(invert_chain(coef), y), x, atol=1e-12)


def test_analytic_inverse_of_a_rate_dependent_drdpi_is_close_on_a_slow_signal() -> None:
    coef = op.drdpi_coefficients(_theta(beta=0.02), 10, 3, RATE_HZ, 0.2)
    x = _descending_sine(1.4, 0.1, seconds=20.0)
    back = _run_chain(invert_chain(coef), _run_chain(coef, x))
    # the rate term is at most 0.02 s * 1 bar/s: the inverse's rate estimate errs by less
    assert np.max(np.abs(back - x)) < 0.01


def test_inverse_pi_weights_eq_9_6_and_thresholds_eq_9_3_9_4() -> None:
    w0, w = 2.0, np.array([1.0, 0.5, 0.25])
    c0, c, m = invert_pi(w0, w)
    assert c0 == 0.5
    np.testing.assert_allclose(c, [-1.0 / (3.0 * 2.0), -0.5 / (3.5 * 3.0), -0.25 / (3.75 * 3.5)])
    r = np.array([0.1, 0.2, 0.3])
    rho = m @ r
    assert rho[0] == pytest.approx(w0 * r[0])  # eq. 9.3
    for i in range(2):  # eq. 9.4
        assert rho[i + 1] == pytest.approx(rho[i] + (w0 + w[: i + 1].sum()) * (r[i + 1] - r[i]))
    with pytest.raises(ParameterError, match="not invertible"):
        invert_pi(1.0, np.array([-0.5, -0.6]))


def test_stream_in_one_sample_chunks_equals_batch_bitwise() -> None:
    x = _descending_sine(1.5, 0.6)
    for coef in (
        op.drdpi_coefficients(_theta(), 10, 3, RATE_HZ, 0.2),
        invert_chain(op.drdpi_coefficients(_theta(), 10, 3, RATE_HZ, 0.2)),
    ):
        batch = _run_chain(coef, x)
        state = np.zeros(op.chain_state_size(coef))
        one, out = np.zeros(1), np.zeros(1)
        streamed = np.empty_like(x)
        for k, v in enumerate(x):
            one[0] = v
            op.chain_run(one, coef, state, out)
            streamed[k] = out[0]
        np.testing.assert_array_equal(streamed, batch)
    gpi = gpi_kernels.gpi_coefficients(np.array([10.0, 1.2, -2.0, 8.0, 1.0, 3.0, 1.3, 0.4]), 8)
    batch = np.empty_like(x)
    gpi_kernels.gpi_run(x, gpi, gpi_kernels.gpi_rest_state(gpi), batch)
    state = gpi_kernels.gpi_rest_state(gpi)
    halves = [np.empty(600), np.empty(x.size - 600)]
    gpi_kernels.gpi_run(x[:600], gpi, state, halves[0])
    gpi_kernels.gpi_run(x[600:], gpi, state, halves[1])
    np.testing.assert_array_equal(np.concatenate(halves), batch)


def test_population_loss_is_eq_5_12_of_the_same_chain() -> None:
    rng = np.random.default_rng(3)
    xs = [_descending_sine(1.5, f) for f in (0.2, 0.5)]
    truth = _theta()
    coef = op.drdpi_coefficients(truth, 10, 3, RATE_HZ, 0.2)
    ys = [_run_chain(coef, x) + rng.normal(0, 0.1, x.size) for x in xs]
    starts = np.array([0, xs[0].size, xs[0].size + xs[1].size], dtype=np.int64)
    thetas = np.stack([truth, truth * 1.05])
    losses = drdpi_population_loss(
        thetas, 10, 3, RATE_HZ, 0.2, False, np.concatenate(xs), np.concatenate(ys), starts
    )
    for theta, loss in zip(thetas, losses, strict=True):
        c = op.drdpi_coefficients(theta, 10, 3, RATE_HZ, 0.2)
        expected = sum(np.mean((_run_chain(c, x) - y) ** 2) for x, y in zip(xs, ys, strict=True))
        assert loss == pytest.approx(expected, rel=1e-12)
    assert losses[0] < losses[1]
    # a chain that is not increasing is scored by the penalty, not run
    folded = truth.copy()
    folded[1] = 50.0  # g_1 = -50 e^{-0.8}: Z folds back
    bad = drdpi_population_loss(
        folded[None, :], 10, 3, RATE_HZ, 0.2, False, np.concatenate(xs), np.concatenate(ys), starts
    )
    assert bad[0] >= MONOTONE_PENALTY
