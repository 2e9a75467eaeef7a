"""The ZVD input shaper: it cancels the mode it was designed for, and is honest about its cost."""

from __future__ import annotations

import math

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.shaping import MAX_SHAPER_DELAY_S, InputShaper, ShaperStream

RATE_HZ = 1000.0


def _ringing_after(command: np.ndarray, mode_hz: float, damping: float, settle_s: float) -> float:
    """Peak deviation of a unit-gain mode's output from its input's end value after
    ``settle_s`` (exact discretisation of the mode: the shaper is judged, not an integrator)."""
    from scipy.signal import cont2discrete, dlsim

    wn = 2.0 * math.pi * mode_hz
    a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * damping * wn]])
    b = np.array([[0.0], [wn * wn]])
    c, d = np.array([[1.0, 0.0]]), np.zeros((1, 1))
    ad, bd, cd, dd, dt = cont2discrete((a, b, c, d), 1.0 / RATE_HZ)
    _, y, _ = dlsim((ad, bd, cd, dd, dt), command)
    tail = y.ravel()[int(settle_s * RATE_HZ) :]
    return float(np.max(np.abs(tail - command[-1])))


def _shaped(shaper: InputShaper, command: np.ndarray) -> np.ndarray:
    stream = ShaperStream(shaper, 1.0 / RATE_HZ)
    return np.array([stream.step(float(v)) for v in command])


def _step(n_s: float = 3.0) -> np.ndarray:
    u = np.ones(int(n_s * RATE_HZ))
    u[:100] = 0.0
    return u


@pytest.mark.parametrize(("mode_hz", "damping"), [(4.5, 0.07), (3.0, 0.15), (6.0, 0.0)])
def test_zvd_leaves_the_mode_at_rest_after_a_step(mode_hz: float, damping: float) -> None:
    shaper = InputShaper.zvd(mode_hz, damping)
    settle_s = 0.1 + shaper.times_s[-1] + 0.01
    plain = _ringing_after(_step(), mode_hz, damping, settle_s)
    shaped = _ringing_after(_shaped(shaper, _step()), mode_hz, damping, settle_s)
    assert plain > 0.3  # the unshaped step rings
    assert shaped < 0.01 * plain, (plain, shaped)


def test_zvd_still_works_on_a_mode_ten_percent_off() -> None:
    # tune identifies the tip to a few percent; ZVD's zero derivative is what makes that enough.
    shaper = InputShaper.zvd(4.5, 0.07)
    for true_hz in (4.05, 4.95):
        plain = _ringing_after(_step(), true_hz, 0.07, 0.5)
        shaped = _ringing_after(_shaped(shaper, _step()), true_hz, 0.07, 0.5)
        assert shaped < 0.05 * plain, (true_hz, plain, shaped)


def test_gain_delay_and_grid() -> None:
    shaper = InputShaper.zvd(4.5, 0.07)
    assert sum(shaper.amplitudes) == pytest.approx(1.0)
    assert all(a > 0.0 for a in shaper.amplitudes)
    # Half a damped period on average.
    half_period_s = 0.5 / (4.5 * math.sqrt(1.0 - 0.07**2))
    assert shaper.times_s[1] == pytest.approx(half_period_s)
    assert shaper.mean_delay_s == pytest.approx(float(np.dot(shaper.times_s, shaper.amplitudes)))
    # On a grid that does not divide the impulse times, gain and mean delay stay exact.
    for period_s in (0.004, 0.001, 0.0037):
        delays, weights = shaper.taps(period_s)
        assert weights.sum() == pytest.approx(1.0)
        assert float(np.dot(delays, weights)) * period_s == pytest.approx(shaper.mean_delay_s)


def test_stream_starts_without_a_jump_and_holds_a_constant() -> None:
    stream = ShaperStream(InputShaper.zvd(4.5, 0.07), 0.004)
    assert stream.step(1.2e5) == pytest.approx(1.2e5)
    assert all(stream.step(1.2e5) == pytest.approx(1.2e5) for _ in range(200))
    stream.reset()
    assert stream.step(0.0) == 0.0


def test_refusals_name_the_problem() -> None:
    with pytest.raises(ParameterError, match="frequency > 0"):
        InputShaper.zvd(0.0, 0.1)
    with pytest.raises(ParameterError, match=r"damping must be in \[0, 1\)"):
        InputShaper.zvd(4.0, 1.0)
    with pytest.raises(ParameterError, match="too slow to shape"):
        InputShaper.zvd(0.9 / (2.0 * MAX_SHAPER_DELAY_S) * 0.5, 0.1)
    with pytest.raises(ParameterError, match="has none"):
        InputShaper.of_loop("zvd", {"resonance_hz": 0.0, "resonance_damping": 0.0}, "f.json")
    with pytest.raises(ParameterError, match="records no identified loop"):
        InputShaper.of_loop("zvd", {}, "f.json")
    with pytest.raises(ParameterError, match="unknown feedforward shaping 'ei'"):
        InputShaper.of_loop("ei", {}, "f.json")
    assert InputShaper.of_loop("none", {}, "f.json") is None
    shaper = InputShaper.of_loop("zvd", {"resonance_hz": 4.5, "resonance_damping": 0.07}, "f")
    assert shaper is not None and shaper.mode_hz == 4.5
