"""Gains a person can defend: identify the loop from recorded steps, then design for margins.

Two steps, each inspectable:

1. :func:`identify`: find the fast pressure steps in a recording (the lab's ``lab_steps_*``
   excitation has dozens), and fit one linear shape to the bend's response to all of them:
   a dead time, a first-order lag and, where the tip rings, a second-order resonance. Each
   step gets its own gain, because a PAM catheter's local gain changes along its curve and
   a step that reverses the friction moves the bend less. The loop is designed for a high
   percentile of those gains (the stiffest place the loop will run), so that it is stable
   everywhere the recording went.
2. :func:`design`: the PI gains with the largest integral gain whose loop keeps the maximum
   sensitivity ``Ms`` (the inverse of the shortest distance of the Nyquist curve from -1)
   under a bound, the MIGO criterion of Astrom and Hagglund. ``Ms <= 1.6`` guarantees a gain
   margin of at least 2.7 and a phase margin of at least 36 degrees. Where the fitted tip
   rings (damping below 0.25), a notch filter on the measured bend at the tip's frequency
   is tried too and kept when it allows a larger integral gain.

The loop the design sees adds to the fitted dead time the controller's own one-sample wait
for the laser and half a sample for the valve's zero-order hold.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import signal
from scipy.optimize import least_squares

from catheter_models.errors import SignalError
from catheter_models.feedback.law import FeedbackGains
from catheter_models.models.base import Recording
from catheter_models.static_map import StaticMap

FloatArray = npt.NDArray[np.float64]

MIN_STEP_PA = 0.3e5
"""Smallest command change that counts as a step [Pa]: below it the friction band dominates."""
MAX_RISE_S = 0.6
"""Longest ramp that still counts as a step [s]."""
SETTLE_S = 0.8
"""Response window after a step starts [s]: a tip's ringing and the lags, not the creep."""
QUIET_BEFORE_S = 0.3
"""The command must have held this long before a step, so the bend starts at rest [s]."""
MOVING_PA_PER_S = 0.5e5
"""A command changing faster than this is moving [Pa/s]."""
MIN_STEPS = 3
"""Fewest steps a fit is made from."""
MAX_STALL_S = 0.02
"""A command that stands still for at most this long between two moves the same way is still
moving [s]: a command lost in a live recording (held over on the grid, as the valve held it)
or a tick the sender skipped would otherwise cut a step's ramp in two and lose the step."""
GAIN_PERCENTILE = 90.0
"""The loop is designed for this percentile of the steps' gains (the stiff end)."""
RESONANCE_GAIN = 0.9
"""The resonance is kept when the fit's residual with it is below this share of the residual
without it."""
RINGING_DAMPING = 0.25
"""A fitted resonance damped below this is a ringing tip: the design tries a notch on it."""
NOTCH_DAMPING = 0.5
"""Width of the notch (damping of its poles): wide, because the tip's frequency moves with
the bend and a sharp notch would miss it away from where it was fitted."""


@dataclass(frozen=True)
class LoopModel:
    """The loop's linear model: pressure command [Pa] to measured bend [rad].

    ``G(s) = gain exp(-s delay) / (1 + s T) * wn^2 / (s^2 + 2 zeta wn s + wn^2)``
    (no resonance when ``resonance_hz`` is 0).
    """

    gain_rad_per_pa: float
    """The gain designed for (:data:`GAIN_PERCENTILE` of the steps') [rad/Pa]."""
    gain_median_rad_per_pa: float
    time_constant_s: float
    delay_s: float
    resonance_hz: float
    resonance_damping: float
    fit_nrmse: float
    """RMS of the fit's residual over RMS of the responses (0: exact)."""
    n_steps: int
    rate_hz: float
    measurement_age_s: float = 0.0
    """How late the bend reaches the controller after its stamp (the recordings' largest
    ``measurement_age_s``). The steps are fitted on stamps, the time the bend was true, so
    ``delay_s`` cannot contain it; the loop runs with it all the same. On the emulated rig
    it was 11.6 ms in one commissioning's recordings (1.7 to 4.6 ms in others): a design
    without it put the crossover at 14 Hz with 63 deg of phase margin, 12 ms of delay to
    spare, and the loop rang at +-1 to 4 deg on the stiff parts of the thesis trajectories."""

    def response(
        self, w_rad_s: FloatArray, extra_delay_s: float = 0.0
    ) -> npt.NDArray[np.complex128]:
        """Loop-plant response at ``w_rad_s``: dead time, measurement age, ``extra_delay_s``."""
        s = 1j * np.asarray(w_rad_s)
        delay_s = self.delay_s + self.measurement_age_s + extra_delay_s
        g = self.gain_rad_per_pa * np.exp(-s * delay_s)
        g = g / (1.0 + s * self.time_constant_s)
        if self.resonance_hz > 0.0:
            wn = 2.0 * math.pi * self.resonance_hz
            g = g * wn**2 / (s**2 + 2.0 * self.resonance_damping * wn * s + wn**2)
        return np.asarray(g)

    def describe(self) -> str:
        """One line for a person: the fitted loop."""
        tip = (
            f", tip {self.resonance_hz:.2f} Hz damped {self.resonance_damping:.2f}"
            if self.resonance_hz > 0.0
            else ""
        )
        age = (
            f", the bend measured {self.measurement_age_s * 1e3:.1f} ms before it arrives"
            if self.measurement_age_s > 0.0
            else ""
        )
        return (
            f"{math.degrees(self.gain_rad_per_pa) * 1e5:.2f} deg/bar (median "
            f"{math.degrees(self.gain_median_rad_per_pa) * 1e5:.2f}), dead time "
            f"{self.delay_s * 1e3:.1f} ms, lag {self.time_constant_s * 1e3:.1f} ms{tip}{age}; "
            f"{self.n_steps} steps fitted to {self.fit_nrmse:.1%} residual"
        )


@dataclass(frozen=True)
class Margins:
    """Robustness of a designed loop, on the identified model."""

    max_sensitivity: float
    gain_margin: float
    phase_margin_deg: float
    crossover_hz: float

    def describe(self) -> str:
        """One line for a person."""
        return (
            f"Ms {self.max_sensitivity:.2f}, gain margin {self.gain_margin:.2f}, phase margin "
            f"{self.phase_margin_deg:.0f} deg, crossover {self.crossover_hz:.2f} Hz"
        )


@dataclass(frozen=True)
class StepWindow:
    """One step found in a recording: samples [start, stop) and the level before it.

    ``continues``: the step goes the way the command last moved, so the wire's friction is
    already engaged in its direction. A step that reverses first has to take the friction
    through its band, which a linear fit would read as extra dead time.
    """

    start: int
    stop: int
    pressure_before_pa: float
    angle_before_rad: float
    continues: bool = True


def find_steps(recording: Recording) -> list[StepWindow]:
    """The fast command steps of ``recording`` that start with the catheter at rest."""
    p = np.asarray(recording.pressure_pa, dtype=float)
    y = np.asarray(recording.angle_rad, dtype=float)
    rate = recording.rate_hz
    delta = np.diff(p, prepend=p[0])
    moving = _bridge_stalls(np.abs(delta) > MOVING_PA_PER_S / rate, delta, rate)
    edges = np.flatnonzero(np.diff(moving.astype(np.int8)))
    starts = [int(e) + 1 for e in edges if moving[e + 1]]
    if moving[0]:
        starts = [0, *starts]
    quiet = round(QUIET_BEFORE_S * rate)
    window = round(SETTLE_S * rate)
    max_rise = round(MAX_RISE_S * rate)
    n_base = max(3, round(0.02 * rate))
    found: list[StepWindow] = []
    for i, start in enumerate(starts):
        if start < quiet or moving[start - quiet : start].any():
            continue
        rise = start
        while rise < p.size and moving[rise]:
            rise += 1
        if rise - start > max_rise:
            continue
        next_start = starts[i + 1] if i + 1 < len(starts) else p.size
        stop = min(start + window, next_start, p.size)
        if stop - rise < round(0.5 * SETTLE_S * rate):
            continue
        before = float(p[start - 1])
        change = float(p[rise - 1]) - before
        if abs(change) < MIN_STEP_PA:
            continue
        # How the command last moved before this step (from rest: upwards).
        last_move = before - (float(p[starts[i - 1] - 1]) if i > 0 and starts[i - 1] > 0 else 0.0)
        continues = last_move == 0.0 or (last_move > 0.0) == (change > 0.0)
        found.append(
            StepWindow(start, stop, before, float(np.mean(y[start - n_base : start])), continues)
        )
    return found


def _bridge_stalls(
    moving: npt.NDArray[np.bool_], delta: FloatArray, rate_hz: float
) -> npt.NDArray[np.bool_]:
    """``moving`` with each stall of at most :data:`MAX_STALL_S` inside a one-way move filled."""
    out = moving.copy()
    longest = max(1, round(MAX_STALL_S * rate_hz))
    still = np.flatnonzero(np.diff(moving.astype(np.int8)) == -1) + 1  # first still samples
    for first in still:
        last = first
        while last < moving.size and not moving[last]:
            last += 1
        if last < moving.size and last - first <= longest and delta[first - 1] * delta[last] > 0:
            out[first:last] = True
    return out


def _shape_response(theta: FloatArray, u: FloatArray, dt_s: float, resonance: bool) -> FloatArray:
    """Unit-gain response of the shape ``theta`` to command deviations ``u`` (rows; ZOH)."""
    delay = math.exp(theta[0])
    tau = math.exp(theta[1])
    num = np.array([1.0])
    den = np.array([tau, 1.0])
    if resonance:
        wn = 2.0 * math.pi * math.exp(theta[2])
        zeta = math.exp(theta[3])
        num = np.array([wn**2])
        den = np.polymul(den, [1.0, 2.0 * zeta * wn, wn**2])
    b, a, _ = signal.cont2discrete((num, den), dt_s, method="zoh")
    out = np.asarray(signal.lfilter(np.ravel(b), np.ravel(a), u, axis=-1), dtype=float)
    # Dead time: whole samples by shifting, the rest by linear interpolation.
    shift = delay / dt_s
    whole = int(shift)
    frac = shift - whole
    padded = np.concatenate([np.zeros((out.shape[0], whole + 1)), out], axis=1)
    n = out.shape[1]
    return np.asarray((1.0 - frac) * padded[:, 1 : 1 + n] + frac * padded[:, :n])


def _gains_and_residual(  # noqa: PLR0917 - the step rows and the shape, as _fit has them
    theta: FloatArray,
    u: FloatArray,
    y: FloatArray,
    mask: FloatArray,
    dt_s: float,
    resonance: bool,
) -> tuple[FloatArray, FloatArray]:
    """Each step's least-squares gain on the shape ``theta``, and the masked residual."""
    r = _shape_response(theta, u, dt_s, resonance) * mask
    rr = np.sum(r * r, axis=1)
    ks = np.where(rr > 0.0, np.sum(r * y, axis=1) / np.where(rr > 0.0, rr, 1.0), 0.0)
    return ks, ((y - ks[:, None] * r) * mask).ravel()


def _nrmse(squared_residual: float, y: FloatArray, mask: FloatArray) -> float:
    """A residual's sum of squares, normalised by the steps' responses (their masked part)."""
    return math.sqrt(squared_residual / max(float(np.sum((y * mask) ** 2)), 1e-300))


def _fit(
    u: FloatArray, y: FloatArray, mask: FloatArray, dt_s: float, resonance: bool
) -> tuple[FloatArray, FloatArray, float]:
    """Best shape (log parameters), each step's gain, and the normalised residual.

    ``u``, ``y``: one step per row (command and bend deviations from before the step),
    zero-padded at the end; ``mask`` is 1 on the samples that belong to the step.
    """

    def gains_and_residual(theta: FloatArray) -> tuple[FloatArray, FloatArray]:
        return _gains_and_residual(theta, u, y, mask, dt_s, resonance)

    lower = [math.log(1e-4), math.log(1e-3)]
    upper = [math.log(0.3), math.log(2.0)]
    starts: list[tuple[float, ...]] = [(d, t) for d in (0.005, 0.04) for t in (0.01, 0.05, 0.2)]
    if resonance:
        lower += [math.log(0.5), math.log(0.01)]
        upper += [math.log(0.2 / dt_s), math.log(1.5)]
        starts = [(d, t, f, 0.1) for d, t in starts[::2] for f in (2.0, 4.0, 8.0)]
    best: tuple[float, FloatArray] | None = None
    for x0 in starts:
        theta0 = np.clip(np.log(np.asarray(x0)), lower, upper)
        sol = least_squares(lambda th: gains_and_residual(th)[1], theta0, bounds=(lower, upper))
        if best is None or float(sol.cost) < best[0]:
            best = (float(sol.cost), sol.x)
    assert best is not None
    ks, resid = gains_and_residual(best[1])
    nrmse = _nrmse(float(np.sum(resid**2)), y, mask)
    return best[1], ks, nrmse


def step_rows(recordings: Sequence[Recording]) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """The steps a loop is fitted to: command and bend deviations, one step a row; the rate.

    Rows are zero-padded at the end; the mask is 1 on the samples that belong to the step.

    Raises:
        SignalError: fewer than 3 steps (record a ``lab_steps_*`` excitation), or recordings
            at different rates.
    """
    if not recordings:
        raise SignalError("tune: no recordings given")
    rates = {r.rate_hz for r in recordings}
    if len(rates) != 1:
        raise SignalError(f"tune: recordings at different rates {sorted(rates)} Hz")
    rate = rates.pop()
    found: list[tuple[StepWindow, FloatArray, FloatArray]] = []
    for rec in recordings:
        p = np.asarray(rec.pressure_pa, dtype=float)
        y = np.asarray(rec.angle_rad, dtype=float)
        found += [(w, p, y) for w in find_steps(rec)]
    # The loop's own dynamics show in the steps that keep the friction's direction; the
    # reversals' friction band is the feedforward's to compensate. Without enough of those
    # steps, all are used (a cautious design: the band reads as dead time).
    continuing = [f for f in found if f[0].continues]
    chosen = continuing if len(continuing) >= MIN_STEPS else found
    steps = [
        (p[w.start : w.stop] - w.pressure_before_pa, y[w.start : w.stop] - w.angle_before_rad)
        for w, p, y in chosen
    ]
    if len(steps) < MIN_STEPS:
        raise SignalError(
            f"tune: found {len(steps)} pressure steps (>= {MIN_STEP_PA / 1e5:g} bar within "
            f"{MAX_RISE_S:g} s, after {QUIET_BEFORE_S:g} s at rest) in "
            f"{', '.join(r.name for r in recordings)}; need at least {MIN_STEPS}: record a steps "
            "excitation such as lab_steps_<seed>"
        )
    n = max(len(du) for du, _ in steps)
    u_rows = np.zeros((len(steps), n))
    y_rows = np.zeros((len(steps), n))
    mask = np.zeros((len(steps), n))
    for i, (du, dy) in enumerate(steps):
        # Past its window a step's command is held (the response keeps its shape) but its
        # samples do not count.
        u_rows[i, : du.size] = du
        u_rows[i, du.size :] = du[-1]
        y_rows[i, : dy.size] = dy
        mask[i, : du.size] = 1.0
    return u_rows, y_rows, mask, rate


def shape_fit(
    u: FloatArray,
    y: FloatArray,
    mask: FloatArray,
    dt_s: float,
    theta: FloatArray,
    *,
    resonance: bool,
) -> tuple[FloatArray, float]:
    """Each step's gain and the normalised residual of the fixed shape ``theta`` (log values)."""
    ks, resid = _gains_and_residual(theta, u, y, mask, dt_s, resonance)
    return ks, _nrmse(float(np.sum(resid**2)), y, mask)


def held_out_nrmse(recordings: Sequence[Recording], model: LoopModel) -> float:
    """How well the steps' own shape predicts a step it was not fitted to: leave one out.

    Each step in turn is left out, the shape of ``model`` (its dead time, lag and, where it
    has one, tip) is fitted again to the others, and the step left out is predicted with that
    shape and its own least-squares gain; the residuals of all the steps left out, normalised
    as ``fit_nrmse`` is. Another model of the loop's shape (the lab's chain) is judged by its
    residual on the same steps with the same free gain, and it was fitted to none of them:
    against this, not against ``fit_nrmse``, the two are compared on equal terms. With 6-8
    steps it is 1.0-1.5 times ``fit_nrmse`` on the plants of tests/support, and 3 times on
    a live recording of a ringing tip (a step left out moves the tip's fit the most).

    Raises:
        SignalError: as :func:`identify` (too few steps).
    """
    u_rows, y_rows, mask, rate = step_rows(recordings)
    dt = 1.0 / rate
    resonance = model.resonance_hz > 0.0
    squared = 0.0
    for i in range(u_rows.shape[0]):
        others = np.arange(u_rows.shape[0]) != i
        theta, _, _ = _fit(u_rows[others], y_rows[others], mask[others], dt, resonance)
        _, resid = _gains_and_residual(
            theta, u_rows[i : i + 1], y_rows[i : i + 1], mask[i : i + 1], dt, resonance
        )
        squared += float(np.sum(resid**2))
    return _nrmse(squared, y_rows, mask)


def identify(recordings: Sequence[Recording]) -> LoopModel:
    """Fit the loop's model to every step of ``recordings`` (see the module doc).

    Raises:
        SignalError: fewer than 3 steps (record a ``lab_steps_*`` excitation), or recordings
            at different rates.
    """
    u_rows, y_rows, mask, rate = step_rows(recordings)
    dt = 1.0 / rate
    plain, ks_plain, err_plain = _fit(u_rows, y_rows, mask, dt, resonance=False)
    ringing, ks_ring, err_ring = _fit(u_rows, y_rows, mask, dt, resonance=True)
    # A ringing tip left out of the model makes a design that drives it unstable, while one
    # put in by mistake only makes the design cautious: the resonance is kept whenever it
    # explains a tenth more of the responses.
    use_ring = err_ring < RESONANCE_GAIN * err_plain
    theta, ks, err = (ringing, ks_ring, err_ring) if use_ring else (plain, ks_plain, err_plain)
    return loop_of_shape(theta, ks, err, recordings, rate, resonance=use_ring)


def loop_of_shape(
    theta: FloatArray,
    ks: FloatArray,
    nrmse: float,
    recordings: Sequence[Recording],
    rate_hz: float,
    *,
    resonance: bool,
) -> LoopModel:
    """The loop of shape ``theta`` (log delay, lag, and tip) with the steps' gains ``ks``.

    Raises:
        SignalError: no step's gain is positive (the bend fell as the pressure rose).
    """
    positive = ks[ks > 0.0]
    if positive.size == 0:
        raise SignalError("tune: no step moved the bend up with the pressure: check the sign")
    return LoopModel(
        gain_rad_per_pa=float(np.percentile(positive, GAIN_PERCENTILE)),
        gain_median_rad_per_pa=float(np.median(positive)),
        time_constant_s=math.exp(theta[1]),
        delay_s=math.exp(theta[0]),
        resonance_hz=math.exp(theta[2]) if resonance else 0.0,
        resonance_damping=math.exp(theta[3]) if resonance else 0.0,
        fit_nrmse=nrmse,
        n_steps=ks.size,
        rate_hz=rate_hz,
        measurement_age_s=max(r.measurement_age_s for r in recordings),
    )


def fitted_steps(
    recordings: Sequence[Recording], model: LoopModel
) -> list[tuple[FloatArray, FloatArray, FloatArray, bool]]:
    """Every step, for a person to check the fit.

    Each as its time [s], measured and modelled bend change [rad], and whether it kept the
    friction's direction (those are the ones the model is fitted to, when there are enough).
    """
    theta = [math.log(model.delay_s), math.log(model.time_constant_s)]
    resonance = model.resonance_hz > 0.0
    if resonance:
        theta += [math.log(model.resonance_hz), math.log(model.resonance_damping)]
    out = []
    for rec in recordings:
        p = np.asarray(rec.pressure_pa, dtype=float)
        y = np.asarray(rec.angle_rad, dtype=float)
        for w in find_steps(rec):
            du = p[w.start : w.stop] - w.pressure_before_pa
            dy = y[w.start : w.stop] - w.angle_before_rad
            r = _shape_response(np.asarray(theta), du[None, :], 1.0 / rec.rate_hz, resonance)[0]
            k = float(r @ dy) / max(float(r @ r), 1e-300)
            out.append((np.arange(du.size) / rec.rate_hz, dy, k * r, w.continues))
    return out


def opening_pressure_pa(recordings: Sequence[Recording]) -> float:
    """Where the muscle starts to move [Pa].

    The first pressure on the central curve whose bend is clearly above the rest bend
    (0.3 deg, or 2 % of the range if that is more).
    """
    p = np.concatenate([np.asarray(r.pressure_pa, dtype=float) for r in recordings])
    y = np.concatenate([np.asarray(r.angle_rad, dtype=float) for r in recordings])
    curve = StaticMap.fit(p, y)
    rise = curve.angle_rad - curve.angle_rad[0]
    clear = max(math.radians(0.3), 0.02 * float(rise[-1]))
    moving = np.flatnonzero(rise > clear)
    return float(curve.pressure_pa[moving[0] - 1]) if moving.size and moving[0] > 0 else 0.0


def notch_response(
    w_rad_s: FloatArray, frequency_hz: float, damping: float
) -> npt.NDArray[np.complex128]:
    """The measurement notch's frequency response (1 everywhere when frequency is 0)."""
    if frequency_hz <= 0.0:
        return np.ones(np.shape(w_rad_s), dtype=complex)
    wn = 2.0 * math.pi * frequency_hz
    s = 1j * np.asarray(w_rad_s)
    return np.asarray((s**2 + wn**2) / (s**2 + 2.0 * damping * wn * s + wn**2))


def frequency_grid(rate_hz: float) -> FloatArray:
    """The design's frequencies [rad/s]: 0.1 rad/s to the loop's Nyquist frequency."""
    return np.logspace(-1.0, math.log10(math.pi * rate_hz), 600)


def loop_response(
    model: LoopModel, gains: FeedbackGains, w_rad_s: FloatArray
) -> npt.NDArray[np.complex128]:
    """Open-loop response C(jw) N(jw) F(jw) G(jw), with the controller's own sample of delay.

    F is the measurement's low-pass (1 when ``measurement_filter_s`` is 0, as the design
    leaves it): a gains file that adds one is checked on the loop it will run.
    """
    s = 1j * w_rad_s
    c = gains.kp_pa_per_rad + gains.ki_pa_per_rad_s / s
    n = notch_response(w_rad_s, gains.notch_frequency_hz, gains.notch_damping)
    f = 1.0 / (1.0 + s * gains.measurement_filter_s)
    return np.asarray(c * n * f * model.response(w_rad_s, 1.5 / model.rate_hz))


def margins(model: LoopModel, gains: FeedbackGains) -> Margins:
    """Ms, gain and phase margins and crossover of ``gains`` on ``model``."""
    w = frequency_grid(model.rate_hz)
    loop = loop_response(model, gains, w)
    ms = float(np.max(1.0 / np.abs(1.0 + loop)))
    phase = np.unwrap(np.angle(loop))
    mag = np.abs(loop)
    gm = math.inf
    cross = np.flatnonzero(np.diff(np.sign(phase + math.pi)))
    if cross.size:
        gm = float(1.0 / mag[cross[0]])
    above = np.flatnonzero(mag >= 1.0)
    if above.size:
        k = int(above[-1])
        pm = float(math.degrees(phase[k] + math.pi))
        fc = float(w[k] / (2.0 * math.pi))
    else:
        pm, fc = math.inf, 0.0
    return Margins(ms, gm, pm, fc)


def plainly_stable(model: LoopModel, gains: FeedbackGains) -> bool:
    """Whether ``gains`` on ``model`` is a loop the design would accept as stable (below)."""
    loop = loop_response(model, gains, frequency_grid(model.rate_hz))
    return bool(_plainly_stable(loop[None, :])[0])


def _plainly_stable(loops: npt.NDArray[np.complex128]) -> npt.NDArray[np.bool_]:
    """Rows (open loops over the frequency grid) that are stable in the plainest way.

    The loop gain falls below 1 before the Nyquist frequency and stays there, and while it
    is above 1 the phase never reaches -180 degrees. Such a loop cannot encircle -1, so the
    Ms bound means what it says; conditionally stable loops, which a friction's lower gain
    at a reversal could destabilise, are refused with the rest.
    """
    mag = np.abs(loops)
    phase = np.unwrap(np.angle(loops), axis=1)
    above = mag >= 1.0
    ends_below = ~above[:, -1]
    # Phase anywhere the gain is above 1 (the integrator starts the phase near -90 deg).
    worst = np.min(np.where(above, phase, 0.0), axis=1)
    return np.asarray(ends_below & (worst > -math.pi))


def design(
    model: LoopModel, max_sensitivity: float = 1.6, opening_pressure_pa: float = 0.0
) -> tuple[FeedbackGains, Margins]:
    """The PI (with a notch where the tip rings) of largest integral gain within ``Ms``.

    Raises:
        SignalError: no PI keeps ``Ms`` under the bound on this model (e.g. a dead time of
            seconds); the message says what was fitted.
    """
    if not 1.1 <= max_sensitivity <= 3.0:
        raise SignalError(f"tune: max_sensitivity must be in [1.1, 3], got {max_sensitivity}")
    k = model.gain_rad_per_pa
    w = frequency_grid(model.rate_hz)
    notches = [(0.0, NOTCH_DAMPING)]
    if model.resonance_hz > 0.0 and model.resonance_damping < RINGING_DAMPING:
        notches.append((model.resonance_hz, NOTCH_DAMPING))
    kp_grid = np.concatenate([[0.0], np.logspace(-3.0, 1.5, 91)]) / k
    ki_grid = np.logspace(-2.0, 4.0, 241) / k
    best: tuple[float, float, float, float] | None = None
    for notch_hz, notch_zeta in notches:
        g = model.response(w, 1.5 / model.rate_hz) * notch_response(w, notch_hz, notch_zeta)
        s = 1j * w
        for kp in kp_grid:
            loops = (kp + ki_grid[:, None] / s[None, :]) * g[None, :]
            ms = np.max(1.0 / np.abs(1.0 + loops), axis=1)
            ok = np.flatnonzero((ms <= max_sensitivity) & _plainly_stable(loops))
            if ok.size == 0:
                continue
            ki = float(ki_grid[ok[-1]])
            if best is None or ki > best[1] * 1.001:
                best = (float(kp), ki, notch_hz, notch_zeta)
    if best is None:
        raise SignalError(
            f"tune: no PI keeps Ms <= {max_sensitivity:g} on the fitted loop ({model.describe()})"
        )
    kp, ki, notch_hz, notch_zeta = best
    gains = FeedbackGains(
        kp_pa_per_rad=kp,
        ki_pa_per_rad_s=ki,
        notch_frequency_hz=notch_hz,
        notch_damping=notch_zeta,
        opening_pressure_pa=opening_pressure_pa,
    )
    found = margins(model, gains)
    tuning = {
        "method": f"MIGO: the largest ki with Ms <= {max_sensitivity:g} on the identified loop",
        "model": model.describe(),
        "margins": found.describe(),
        **design_record(model, gains, found, max_sensitivity),
    }
    return dataclasses.replace(gains, tuning=tuning), found


GAIN_FIELDS = ("kp_pa_per_rad", "ki_pa_per_rad_s", "kd_pa_s_per_rad")
"""The gains whose range the tuning records: they set the loop's gain, hence its margins."""


def safe_gain_factor(gain_margin: float) -> float:
    """How far either way a gain may sit from its designed value and still count as tuned.

    Scaling the gains by f divides the loop's gain margin by f. At f = sqrt(GM) the loop keeps
    a gain margin of sqrt(GM) as well: the margin is split evenly between what a person may
    change by hand and what is left for the catheter's gain that the design did not see (a
    PAM catheter's gain changes along its curve, with the bend of the shaft and with wear; the
    design took the 90th percentile of the recorded steps', so a stiffer place exists). The
    MIGO bound Ms <= 1.6 guarantees GM >= 2.67, so this is at least 1.63 either way, with a
    gain margin of at least 1.63 left at its edge; gains x100 are far outside. Below the
    designed gains the loop stays stable (the design refuses conditionally stable loops), but
    it is no longer the loop that was verified, so the range is the same factor down.

    Raises:
        SignalError: no finite gain margin (a loop whose phase never reaches -180 deg before
            the Nyquist frequency, which the controller's own delay rules out).
    """
    if not (math.isfinite(gain_margin) and gain_margin > 0.0):
        raise SignalError(f"tune: gain margin {gain_margin} gives no range to record")
    return max(1.0, math.sqrt(gain_margin))


def design_record(
    model: LoopModel, gains: FeedbackGains, found: Margins, max_sensitivity: float
) -> dict[str, Any]:
    """What the tuning designed, for ``feedback.json``: the loop, the gains, their safe range.

    The loader (:mod:`catheter_models.feedback.seal`) refuses gains outside ``safe`` and
    ``catheter-lab tune --reseal`` re-checks the margins on ``loop``.
    """
    factor = safe_gain_factor(found.gain_margin)
    designed = {f.name: getattr(gains, f.name) for f in dataclasses.fields(gains)}
    del designed["tuning"]
    return {
        "loop": dataclasses.asdict(model),
        "max_sensitivity": max_sensitivity,
        # JSON has no inf: a margin that is not finite (none found on the grid) is null.
        "designed_margins": {
            k: (v if math.isfinite(v) else None) for k, v in dataclasses.asdict(found).items()
        },
        "designed": designed,
        "gain_factor": factor,
        "safe": {name: [designed[name] / factor, designed[name] * factor] for name in GAIN_FIELDS},
    }
