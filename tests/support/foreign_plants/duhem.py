"""A foreign PAM catheter whose loops come from Duhem (Dahl-type) friction (plant ``duhem``).

The third foreign law, written apart from ``catheter_models``, from :mod:`.maxwell_slip` and
from :mod:`.boucwen`, with its own physics for every effect (SI units, gauge pressure):

1. Command: clipped to 0-3 bar and held over each sample (the valve's zero-order hold).
2. ``transport_delay``: a delay with dispersion, as a long, narrow hose gives: a dead time
   of 0.8 ``delay_s`` followed by two equal first-order stages of 0.1 ``delay_s`` each, so
   the mean delay of the wave front is ``delay_s``.
3. Muscle filling: laminar compressible flow through the valve's restriction,
   ``dp/dt = (u_abs**2 - p_abs**2) / (2 p_ref_abs tau)``: the rate grows with the mean
   absolute pressure, so the muscle fills and vents quickly at the top and slowly near
   vented (a lag whose time constant depends on the pressure). The exhaust port is smaller
   than the supply port (venting 8 % slower, filling 8 % quicker). Without
   ``pneumatic_lag`` the small-signal time constant at 1.5 bar is 3 ms; with it, it is
   ``time_constant_s`` (the geometric mean of filling and venting).
4. ``slow_lag``: a second chamber behind a porous braid seam: its pressure follows the
   muscle's through two equal first-order stages of half ``time_constant_s`` (a diffusion),
   and it carries the share ``fraction`` of the force.
5. Muscle force, as the free bend ``x`` it would cause on a frictionless catheter: the
   pressure above the opening pressure through a C1 quadratic knee (0.16 bar wide), then a
   concave map (the braid angle nears its limit, so each bar adds less force).
   ``gain_drift`` changes the muscle's effective area exponentially towards a new level
   (a 10 minute time constant), starting at the rate that makes the held bend at 1.8 bar
   change by ``percent_per_min``.
6. Hysteresis: a Dahl-type Duhem friction state ``w`` in the wire-tube,
   ``dw/dx = kappa * sgn(a) |a|**r / 2**r`` with ``a = 1 - sgn(dx) w / W``, so ``w`` turns
   over towards ``+-W`` as the wire slides and ``kappa`` of the motion is held at a reversal.
   The level ``W`` grows with the wire tension (``W0 + W1 x``, capstan friction), is 20-40 %
   higher while releasing than while pulling (with another ``kappa`` and ``r``: asymmetric
   loops). Because ``W`` depends on ``x``, minor loops are neither congruent nor closed
   (no return-point memory). Beside it, a shear-thinning lubricant film adds a viscous
   force ``f = eta v / sqrt(v_c + |v|)``: Newtonian below ``v_c`` = 0.05 rad/s, growing
   with the square root of the sliding speed above, gone at rest. It is the plant's rate
   dependence (loops widen with frequency). The bend's drive is ``x - w - f``.
7. Bending section: a soft saturation ``L tanh(drive / L)`` (the sheath's wall takes up the
   bend near the limit), then ``creep``: non-linear viscoelasticity of the polymer: a
   log-normal spectrum of 9 relaxation times (one natural-log unit wide) whose weighted
   mean is ``time_constant_s``, and whose share grows with the bend (Schapery-type: the
   share is ``fraction`` at the bend of 2 bar and 60 % larger per unit of relative bend).
8. Structure: a critically damped second-order response of the section (30 Hz).
9. ``tip_dynamics``: the tip in fluid: a hardening (Duffing) spring whose stiffness grows
   with the bend (``natural_frequency_hz`` holds at the bend of 1.6 bar, small amplitude),
   linear damping ``damping_ratio`` plus a quadratic drag on the tip's speed.
10. ``backlash``: the laser's target plate sits loosely on the tip: a play of ``gap_deg``
    between the tip and what the laser sees.
11. ``sensor_lag``: the laser averages over a window of ``2 time_constant_s`` (a boxcar,
    whose mean delay is ``time_constant_s``).
12. ``drift``: a logarithmic warm-up of the laser mount, ``r T ln(1 + t / T)`` with
    ``T = 2 min``, whose initial slope is ``rate_deg_per_min``.
13. Sensor: white Gaussian noise and a 0.002 deg quantisation step.

Integrated at 2 kHz or finer (an integer number of sub-steps per sample) in one numba kernel;
each output sample is the state at the end of its sample period.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar, Final

import numpy as np
import scipy.linalg
from numba import njit

from .base import Effect, FloatArray, ForeignPlant, PlantStepper

P_MAX_PA: Final = 3.0e5
P_ATM_PA: Final = 1.01325e5
P_MID_PA: Final = 1.5e5
SUBSTEP_RATE_HZ: Final = 2000.0
QUANTUM_RAD: Final = math.radians(0.002)
VALVE_S: Final = 0.003
"""Small-signal time constant of the filling at 1.5 bar without ``pneumatic_lag``."""
PORT_ASYMMETRY: Final = 1.08
"""Venting is slower than filling by this factor; the nominal is their geometric mean."""
DEAD_SHARE: Final = 0.8
"""Share of ``delay_s`` that is pure dead time; the rest is dispersion (two lags)."""
KNEE_HALF_PA: Final = 0.08e5
CREEP_TERMS: Final = 9
CREEP_WIDTH_LN: Final = 1.0
"""Standard deviation of the log-normal relaxation spectrum (natural log of time)."""
CREEP_LOAD_SLOPE: Final = 0.6
STRUCTURE_HZ: Final = 30.0
TIP_MID_PA: Final = 1.6e5
TIP_STIFFENING: Final = 0.5
"""Relative change of the tip's stiffness per unit of relative bend."""
TIP_HARDENING: Final = 20.0
"""Cubic (Duffing) share of the tip spring [rad**-2]."""
TIP_DRAG: Final = 1.0
"""Quadratic drag on the tip's speed [rad**-1]."""
DRIFT_WARMUP_S: Final = 120.0
GAIN_SETTLE_S: Final = 600.0
GAIN_FLOOR: Final = 0.1
GAIN_REF_PA: Final = 1.8e5
"""Pressure at which ``gain_drift.percent_per_min`` is the bend's own rate of change."""
FILM_NEWTONIAN_RAD_S: Final = 0.05
"""Sliding speed below which the film is Newtonian (Cross-type: finite viscosity at rest)."""
SENSOR_WINDOW_MAX_S: Final = 0.5
"""Longest boxcar the sensor can average over (``2 time_constant_s``)."""

# Parameter vector of the kernel.
(
    _P_OPEN,
    _X3,
    _CONCAVE,
    _W0,
    _W1,
    _DN_RATIO,
    _KAPPA_UP,
    _KAPPA_DN,
    _R_UP,
    _R_DN,
    _FILM,
    _LIMIT,
    _FILL_S,
    _VENT_S,
    _CREEP_REF,
    _TIP_REF,
) = range(16)
_RATE_HZ, _SUBSTEPS = 16, 17
_DELAY, _CREEP, _TIP, _SENSOR, _BACKLASH, _GAIN, _SLOW = range(18, 25)
_DEAD_S, _DISP_S, _SLOW_FRACTION, _SLOW_STAGE_S, _GAIN_PER_S, _BACKLASH_RAD = range(25, 31)
_TIP_W, _TIP_ZETA, _SENSOR_N = 31, 32, 33
_N_PARS = 34

# Layout of the resumable state: scalars, the creep terms, then the sensor's ring buffer.
_S_D1, _S_D2, _S_P, _S_P2A, _S_P2B, _S_X_PREV, _S_W, _S_Y, _S_YD = range(9)
_S_TIP, _S_TIPV, _S_YB, _S_SUM, _S_HEAD, _S_STARTED = range(9, 14 + 1)
_S_CREEP = 15


@dataclass(frozen=True)
class DuhemParameters:
    """Nominal parameters of one catheter of this make (angles in rad, pressures in Pa).

    Attributes:
        opening_pa: Centre of the quadratic knee (the muscle's opening pressure).
        free_bend_3bar_rad: Free bend of the muscle force at 3 bar.
        concavity: Concave share of the force map (0 = linear in the pressure).
        friction_rad: Friction level at zero tension while pulling (bend-equivalent).
        friction_per_rad: Growth of the level with the free bend (capstan effect).
        release_ratio: Release level over pull level.
        kappa_up: Share of the motion held at a reversal into pulling.
        kappa_down: The same into releasing.
        r_up: Dahl exponent while pulling (how abruptly sliding sets in).
        r_down: Dahl exponent while releasing.
        film_rad: Viscous force of the lubricant film at a sliding speed of 1 rad/s.
        limit_rad: Scale of the section's soft saturation.
        noise_deg: White-noise standard deviation of the laser [deg].
    """

    opening_pa: float = 0.85e5
    free_bend_3bar_rad: float = 0.80
    concavity: float = 0.3
    friction_rad: float = 0.010
    friction_per_rad: float = 0.06
    release_ratio: float = 1.3
    kappa_up: float = 0.85
    kappa_down: float = 0.7
    r_up: float = 1.5
    r_down: float = 1.1
    film_rad: float = 0.009
    limit_rad: float = 0.62
    noise_deg: float = 0.05


def _draw_parameters(variant: int) -> DuhemParameters:
    """Variant 0 is the nominal catheter; others vary its make by about +-20 %."""
    nominal = DuhemParameters()
    if variant == 0:
        return nominal
    rng = np.random.default_rng([variant, 31])

    def vary(value: float, spread: float) -> float:
        return float(value * rng.uniform(1.0 - spread, 1.0 + spread))

    return replace(
        nominal,
        opening_pa=vary(nominal.opening_pa, 0.2),
        free_bend_3bar_rad=vary(nominal.free_bend_3bar_rad, 0.15),
        concavity=vary(nominal.concavity, 0.3),
        friction_rad=vary(nominal.friction_rad, 0.2),
        friction_per_rad=vary(nominal.friction_per_rad, 0.2),
        release_ratio=float(rng.uniform(1.2, 1.4)),
        kappa_up=vary(nominal.kappa_up, 0.08),
        kappa_down=vary(nominal.kappa_down, 0.1),
        r_up=vary(nominal.r_up, 0.15),
        r_down=vary(nominal.r_down, 0.1),
        film_rad=vary(nominal.film_rad, 0.2),
        limit_rad=vary(nominal.limit_rad, 0.08),
        noise_deg=float(rng.uniform(0.03, 0.08)),
    )


@njit(cache=True)
def _knee(p_pa: float, open_pa: float) -> float:
    """The pressure above the opening through a C1 quadratic knee [Pa]."""
    lo = open_pa - KNEE_HALF_PA
    if p_pa <= lo:
        return 0.0
    if p_pa >= open_pa + KNEE_HALF_PA:
        return p_pa - open_pa
    return (p_pa - lo) ** 2 / (4.0 * KNEE_HALF_PA)


@njit(cache=True)
def _free_bend(p_pa: float, pp: FloatArray) -> float:
    """Muscle force at gauge pressure ``p_pa``, as the free bend it causes [rad]."""
    r3 = _knee(P_MAX_PA, pp[_P_OPEN])
    r = _knee(p_pa, pp[_P_OPEN]) / r3
    c = pp[_CONCAVE]
    return pp[_X3] * r * (1.0 - c * r) / (1.0 - c)


@njit(cache=True)
def _signed_power(a: float, r: float) -> float:
    return math.copysign(abs(a) ** r, a)


@njit(cache=True)
def _fresh_state(n_creep: int, n_ring: int) -> FloatArray:
    """The kernel's state at rest (vented, straight)."""
    return np.zeros(_S_CREEP + n_creep + n_ring)


@njit(cache=True)
def _advance(  # noqa: PLR0917 - numba compiles positional arguments only
    cmd: FloatArray,
    k_start: int,
    pars: FloatArray,
    creep: FloatArray,
    structure: FloatArray,
    state: FloatArray,
    out: FloatArray,
) -> None:
    """Integrate samples ``k_start`` to the end of ``cmd`` from ``state`` (updated in place).

    ``cmd`` holds every command since rest (the dead time reads back into it); sample k's
    bend goes to ``out[k - k_start]``. Consecutive spans give what one span gives.
    """
    pp = pars
    rate_hz = pp[_RATE_HZ]
    substeps = int(pp[_SUBSTEPS])
    dt = 1.0 / (rate_hz * substeps)
    on_delay = pp[_DELAY] > 0.5
    on_creep = pp[_CREEP] > 0.5
    on_tip = pp[_TIP] > 0.5
    on_sensor = pp[_SENSOR] > 0.5
    on_backlash = pp[_BACKLASH] > 0.5
    on_gain = pp[_GAIN] > 0.5
    on_slow = pp[_SLOW] > 0.5
    p_ref_abs = P_ATM_PA + P_MID_PA
    disp_decay = math.exp(-dt / pp[_DISP_S]) if on_delay else 0.0
    slow_decay = math.exp(-dt / pp[_SLOW_STAGE_S]) if on_slow else 0.0
    w0, w1 = pp[_W0], pp[_W1]
    n_creep = creep.shape[1]
    n_ring = int(pp[_SENSOR_N])
    c = state[_S_CREEP : _S_CREEP + n_creep]
    ring = state[_S_CREEP + n_creep : _S_CREEP + n_creep + n_ring]
    tip_w0 = pp[_TIP_W]
    tip_zeta = pp[_TIP_ZETA]
    y = 0.0
    for k in range(k_start, cmd.size):
        for j in range(substeps):
            t = (k * substeps + j) * dt
            if on_delay:
                idx = math.floor((t - pp[_DEAD_S]) * rate_hz + 1e-9)
                u0 = cmd[idx] if idx >= 0 else 0.0
                state[_S_D1] = u0 + (state[_S_D1] - u0) * disp_decay
                state[_S_D2] = state[_S_D1] + (state[_S_D2] - state[_S_D1]) * disp_decay
                u = state[_S_D2]
            else:
                u = cmd[k]
            # Laminar compressible flow: u**2 - p**2 = (u - p)(u + p) in absolute pressure,
            # stepped exactly for the local rate (stable at any sub-step).
            p = state[_S_P]
            tau = pp[_FILL_S] if u >= p else pp[_VENT_S]
            k_rate = (u + p + 2.0 * P_ATM_PA) / (2.0 * p_ref_abs * tau)
            p = max(u + (p - u) * math.exp(-k_rate * dt), 0.0)
            state[_S_P] = p
            if on_slow:
                state[_S_P2A] = p + (state[_S_P2A] - p) * slow_decay
                state[_S_P2B] = state[_S_P2A] + (state[_S_P2B] - state[_S_P2A]) * slow_decay
                f = pp[_SLOW_FRACTION]
                x = (1.0 - f) * _free_bend(p, pp) + f * _free_bend(state[_S_P2B], pp)
            else:
                x = _free_bend(p, pp)
            if on_gain:
                tg = GAIN_SETTLE_S
                x *= max(GAIN_FLOOR, 1.0 + pp[_GAIN_PER_S] * tg * (1.0 - math.exp(-(t + dt) / tg)))
            # Duhem friction, sub-stepped so each piece is a small share of the level.
            x_prev = state[_S_X_PREV]
            w = state[_S_W]
            dx = x - x_prev
            film = 0.0
            if dx != 0.0:
                v = dx / dt
                film = pp[_FILM] * v / math.sqrt(FILM_NEWTONIAN_RAD_S + abs(v))
                if dx > 0.0:
                    kappa, r, ratio, s = pp[_KAPPA_UP], pp[_R_UP], 1.0, 1.0
                else:
                    kappa, r, ratio, s = pp[_KAPPA_DN], pp[_R_DN], pp[_DN_RATIO], -1.0
                level_min = ratio * (w0 + w1 * max(min(x, x_prev), 0.0))
                m = min(4000, 1 + int(abs(dx) / (0.02 * level_min)))
                h = dx / m
                scale = kappa / 2.0**r
                for i in range(m):
                    xi = x_prev + (i + 0.5) * h
                    level = ratio * (w0 + w1 * max(xi, 0.0))
                    # At most the whole motion is held (stick): the slope never exceeds 1.
                    slope = min(scale * _signed_power(1.0 - s * w / level, r), 1.0)
                    w += slope * h
            state[_S_X_PREV] = x
            state[_S_W] = w
            drive = x - w - film
            yv = pp[_LIMIT] * math.tanh(drive / pp[_LIMIT])
            if on_creep:
                load = min(max(1.0 + CREEP_LOAD_SLOPE * (yv / pp[_CREEP_REF] - 1.0), 0.4), 1.6)
                lagging = 0.0
                for i in range(n_creep):
                    c[i] = yv + (c[i] - yv) * creep[0, i]
                    lagging += creep[1, i] * (yv - c[i])
                yv -= load * lagging
            # The section's critically damped response (exact ZOH step).
            y0, y1 = state[_S_Y], state[_S_YD]
            ys = structure[0, 0] * y0 + structure[0, 1] * y1 + structure[0, 2] * yv
            state[_S_YD] = structure[1, 0] * y0 + structure[1, 1] * y1 + structure[1, 2] * yv
            state[_S_Y] = ys
            y = ys
            if on_tip:
                stiff = max(0.3, 1.0 + TIP_STIFFENING * (ys / pp[_TIP_REF] - 1.0))
                wn = tip_w0 * math.sqrt(stiff)
                e = ys - state[_S_TIP]
                v = state[_S_TIPV]
                acc = (
                    wn * wn * e * (1.0 + TIP_HARDENING * e * e)
                    - 2.0 * tip_zeta * tip_w0 * v
                    - TIP_DRAG * abs(v) * v
                )
                # Semi-implicit Euler: the damping implicitly, then the position.
                v = (v + dt * (acc + 2.0 * tip_zeta * tip_w0 * v)) / (
                    1.0 + 2.0 * tip_zeta * tip_w0 * dt
                )
                state[_S_TIPV] = v
                state[_S_TIP] += dt * v
                y = state[_S_TIP]
            if on_backlash:
                state[_S_YB] = min(max(state[_S_YB], y - pp[_BACKLASH_RAD]), y)
                y = state[_S_YB]
            if on_sensor:
                head = int(state[_S_HEAD])
                if state[_S_STARTED] < 0.5:  # at rest the window holds the resting bend
                    for i in range(n_ring):
                        ring[i] = y
                    state[_S_SUM] = y * n_ring
                    state[_S_STARTED] = 1.0
                state[_S_SUM] += y - ring[head]
                ring[head] = y
                state[_S_HEAD] = (head + 1) % n_ring
                y = state[_S_SUM] / n_ring
        out[k - k_start] = y


def _second_order_zoh(frequency_rad_s: float, damping: float, dt_s: float) -> FloatArray:
    """Exact zero-order-hold step of ``y'' + 2 d w y' + w**2 y = w**2 u``: rows
    ``[Phi | Gamma]`` with ``[y, y'] <- Phi [y, y'] + Gamma u``."""
    w = frequency_rad_s
    aug = np.zeros((3, 3))
    aug[:2, :2] = np.array([[0.0, 1.0], [-(w**2), -2.0 * damping * w]]) * dt_s
    aug[:2, 2] = np.array([0.0, w**2]) * dt_s
    return np.ascontiguousarray(scipy.linalg.expm(aug)[:2, :])


def creep_spectrum(fraction: float, time_constant_s: float) -> tuple[FloatArray, FloatArray]:
    """Times [s] and weights of the log-normal relaxation spectrum: weighted mean time
    ``time_constant_s``, weights summing to ``fraction``."""
    z = np.linspace(-2.0, 2.0, CREEP_TERMS)
    ratio = np.exp(CREEP_WIDTH_LN * z)
    weights = np.exp(-0.5 * z**2)
    mean_ratio = float(np.sum(weights * ratio) / np.sum(weights))
    return time_constant_s * ratio / mean_ratio, fraction * weights / np.sum(weights)


@dataclass(frozen=True)
class _Run:
    pars: FloatArray
    creep: FloatArray
    structure: FloatArray
    drift_deg_per_min: float

    def drift_rad(self, t_s: FloatArray) -> FloatArray:
        if self.drift_deg_per_min == 0.0:
            return np.zeros_like(t_s)
        return drift_offset_rad(self.drift_deg_per_min, t_s)


class DuhemPlant(ForeignPlant):
    """A catheter whose hysteresis is Duhem friction in the wire-tube (see module doc).

    Args:
        variant: 0 is the nominal catheter; any other value draws another of the same make.
    """

    name: ClassVar[str] = "duhem"
    hysteresis_law: ClassVar[str] = (
        "Dahl-type Duhem wire-tube friction (tension-scaled, asymmetric pull/release, "
        "a shear-thinning viscous film; non-congruent minor loops) with a soft wall saturation"
    )

    def __init__(self, variant: int = 0) -> None:
        super().__init__(variant)
        self.params: DuhemParameters = _draw_parameters(self.variant)

    @property
    def noise_std_rad(self) -> float:
        """White noise of the laser plus its quantisation (uniform, step**2 / 12) [rad]."""
        return math.sqrt(math.radians(self.params.noise_deg) ** 2 + QUANTUM_RAD**2 / 12.0)

    def _run(self, rate_hz: float, effects: Sequence[Effect]) -> _Run:
        if not rate_hz > 0.0 or not math.isfinite(rate_hz):
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        by_name = self.effects_by_name(effects)

        def par(name: str, key: str, default: float) -> float:
            return float(by_name[name].params[key]) if name in by_name else default

        substeps = max(1, math.ceil(SUBSTEP_RATE_HZ / rate_hz))
        dt = 1.0 / (rate_hz * substeps)
        pr = self.params
        pp = np.zeros(_N_PARS)
        pp[_P_OPEN] = pr.opening_pa
        pp[_X3] = pr.free_bend_3bar_rad
        pp[_CONCAVE] = pr.concavity
        pp[_W0] = pr.friction_rad
        pp[_W1] = pr.friction_per_rad
        pp[_DN_RATIO] = pr.release_ratio
        pp[_KAPPA_UP] = pr.kappa_up
        pp[_KAPPA_DN] = pr.kappa_down
        pp[_R_UP] = pr.r_up
        pp[_R_DN] = pr.r_down
        pp[_FILM] = pr.film_rad
        pp[_LIMIT] = pr.limit_rad
        tau = par("pneumatic_lag", "time_constant_s", VALVE_S)
        pp[_FILL_S] = tau / PORT_ASYMMETRY
        pp[_VENT_S] = tau * PORT_ASYMMETRY
        pp[_CREEP_REF] = self._static_bend(2.0e5)
        pp[_TIP_REF] = self._static_bend(TIP_MID_PA)
        pp[_RATE_HZ] = rate_hz
        pp[_SUBSTEPS] = substeps
        for flag, name in (
            (_DELAY, "transport_delay"),
            (_CREEP, "creep"),
            (_TIP, "tip_dynamics"),
            (_SENSOR, "sensor_lag"),
            (_BACKLASH, "backlash"),
            (_GAIN, "gain_drift"),
            (_SLOW, "slow_lag"),
        ):
            pp[flag] = float(name in by_name)
        delay_s = par("transport_delay", "delay_s", 0.0)
        pp[_DEAD_S] = DEAD_SHARE * delay_s
        pp[_DISP_S] = max(0.5 * (1.0 - DEAD_SHARE) * delay_s, 1e-6)
        pp[_SLOW_FRACTION] = par("slow_lag", "fraction", 0.0)
        pp[_SLOW_STAGE_S] = 0.5 * par("slow_lag", "time_constant_s", 1.0)
        area_per_s = par("gain_drift", "percent_per_min", 0.0) / 100.0 / 60.0
        pp[_GAIN_PER_S] = area_per_s / self._gain_sensitivity(GAIN_REF_PA)
        pp[_BACKLASH_RAD] = math.radians(par("backlash", "gap_deg", 0.0))
        pp[_TIP_W] = 2.0 * math.pi * par("tip_dynamics", "natural_frequency_hz", 5.0)
        pp[_TIP_ZETA] = par("tip_dynamics", "damping_ratio", 0.1)
        window_s = 2.0 * par("sensor_lag", "time_constant_s", 0.0)
        if window_s > SENSOR_WINDOW_MAX_S:
            raise ValueError(f"sensor_lag window {window_s} s exceeds {SENSOR_WINDOW_MAX_S} s")
        # A boxcar of n sub-steps delays by (n - 1) / 2 sub-steps on average.
        pp[_SENSOR_N] = max(1, round(window_s / dt) + 1) if "sensor_lag" in by_name else 1
        creep = np.zeros((2, 0))
        if "creep" in by_name:
            taus, weights = creep_spectrum(
                par("creep", "fraction", 0.0), par("creep", "time_constant_s", 1.0)
            )
            creep = np.ascontiguousarray(np.vstack([np.exp(-dt / taus), weights]))
        structure = _second_order_zoh(2.0 * math.pi * STRUCTURE_HZ, 1.0, dt)
        return _Run(pp, creep, structure, par("drift", "rate_deg_per_min", 0.0))

    def _gain_sensitivity(self, p_pa: float) -> float:
        """Relative change of the held bend per relative change of the muscle's area at
        ``p_pa``, the geometric mean of the pulling and releasing branches (friction and the
        wall make it less than one)."""
        pr = self.params
        pp = np.zeros(_N_PARS)
        pp[_P_OPEN], pp[_X3], pp[_CONCAVE] = pr.opening_pa, pr.free_bend_3bar_rad, pr.concavity
        x = _free_bend(p_pa, pp)
        level = pr.friction_rad + pr.friction_per_rad * x
        product = 1.0
        for drive in (x - level, x + pr.release_ratio * level):
            t = math.tanh(drive / pr.limit_rad)
            product *= x * (1.0 - t * t) / (pr.limit_rad * t)
        return math.sqrt(product)

    def _static_bend(self, p_pa: float) -> float:
        """The section's bend at a held pressure, approached from below (pulling friction)."""
        pr = self.params
        pp = np.zeros(_N_PARS)
        pp[_P_OPEN], pp[_X3], pp[_CONCAVE] = pr.opening_pa, pr.free_bend_3bar_rad, pr.concavity
        x = _free_bend(p_pa, pp)
        w = pr.friction_rad + pr.friction_per_rad * x  # slid to the pull level
        return pr.limit_rad * math.tanh((x - w) / pr.limit_rad)

    def bend_without_noise(
        self,
        pressure_command_pa: FloatArray,
        rate_hz: float,
        effects: Sequence[Effect] = (),
    ) -> FloatArray:
        """The bend [rad] the laser would report without its noise and quantisation."""
        cmd = np.asarray(pressure_command_pa, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(cmd)):
            raise ValueError("pressure command contains non-finite values")
        cmd = np.ascontiguousarray(np.clip(cmd, 0.0, P_MAX_PA))
        run = self._run(rate_hz, effects)
        out = np.empty(cmd.size)
        state = _fresh_state(run.creep.shape[1], int(run.pars[_SENSOR_N]))
        _advance(cmd, 0, run.pars, run.creep, run.structure, state, out)
        return out + run.drift_rad(np.arange(1, cmd.size + 1) / rate_hz)

    def _measure(self, bend: FloatArray, rng: np.random.Generator) -> FloatArray:
        measured = bend + math.radians(self.params.noise_deg) * rng.standard_normal(bend.size)
        return np.asarray(np.round(measured / QUANTUM_RAD) * QUANTUM_RAD)

    def simulate(
        self,
        pressure_command_pa: FloatArray,
        rate_hz: float,
        effects: Sequence[Effect] = (),
        seed: int = 0,
    ) -> FloatArray:
        """Measured bend [rad] for a pressure command [Pa], from rest (see module doc)."""
        bend = self.bend_without_noise(pressure_command_pa, rate_hz, effects)
        return self._measure(bend, np.random.default_rng(seed))

    def stepper(
        self, rate_hz: float, effects: Sequence[Effect] = (), seed: int = 0
    ) -> PlantStepper:
        """This plant from rest, one command sample at a time (see :class:`PlantStepper`)."""
        return _DuhemStepper(self, self._run(rate_hz, effects), rate_hz, seed)


class _DuhemStepper(PlantStepper):
    """Carries the kernel's state, and every command so far (the dead time reads back)."""

    def __init__(self, plant: DuhemPlant, run: _Run, rate_hz: float, seed: int) -> None:
        self._plant = plant
        self._run = run
        self._rate_hz = rate_hz
        self._state = _fresh_state(run.creep.shape[1], int(run.pars[_SENSOR_N]))
        self._rng = np.random.default_rng(seed)
        self._cmd = np.zeros(1024)
        self._k = 0
        self._out = np.zeros(1)

    def step(self, pressure_command_pa: float) -> float:
        if not math.isfinite(pressure_command_pa):
            raise ValueError("pressure command contains non-finite values")
        if self._k == self._cmd.size:
            self._cmd = np.concatenate([self._cmd, np.zeros(self._cmd.size)])
        self._cmd[self._k] = min(max(pressure_command_pa, 0.0), P_MAX_PA)
        k = self._k
        self._k += 1
        run = self._run
        _advance(self._cmd[: k + 1], k, run.pars, run.creep, run.structure, self._state, self._out)
        bend = self._out + run.drift_rad(np.array([(k + 1) / self._rate_hz]))
        return float(self._plant._measure(bend, self._rng)[0])


def drift_offset_rad(rate_deg_per_min: float, t_s: FloatArray) -> FloatArray:
    """Logarithmic warm-up of the laser mount; slope ``rate_deg_per_min`` at t = 0."""
    rate_rad_s = math.radians(rate_deg_per_min) / 60.0
    return rate_rad_s * DRIFT_WARMUP_S * np.log1p(np.asarray(t_s) / DRIFT_WARMUP_S)


__all__ = ["DuhemParameters", "DuhemPlant", "creep_spectrum", "drift_offset_rad"]
