"""A foreign PAM catheter whose loops come from Bouc-Wen friction in the wire-tube.

Signal chain, each link written for this plant alone (SI units, gauge pressure):

1. Command: clipped to 0-3 bar and held over each sample (the valve's zero-order hold).
2. ``transport_delay``: an acoustic line between valve and muscle: a pure dead time of
   ``delay_s`` plus a mild second-order dispersion (80 Hz, damping 0.7, about 3 ms) that
   rounds the wave front as a real line does.
3. Muscle filling: polytropic (exponent 1.2) filling of a fixed muscle volume through a valve
   whose flow is proportional to the pressure difference and capped at a maximum flow, so
   large steps ramp at the flow limit and small ones relax exponentially. The local time
   constant scales with ``(p_abs / p_ref) ** -(n - 1) / n``; filling is quicker than venting.
   Without ``pneumatic_lag`` the valve is fast (3-4 ms); with it the small-signal time
   constant at 1.5 bar is ``time_constant_s`` (fill ``tau / 1.12``, vent ``tau * 1.12``).
4. ``slow_lag``: a second muscle chamber behind a small orifice fills first-order with
   ``time_constant_s`` and carries the share ``fraction`` of the muscle force.
5. Muscle force (not McKibben's): a quadratic map of an effective pressure, the opening
   pressure removed by a log-sum-exp soft-plus (a smooth knee about 0.06 bar wide). The force
   is expressed as the free bend ``x`` it would cause on a frictionless catheter.
   ``gain_drift`` scales ``x`` linearly in time (the bend's stiffness softening or hardening).
6. Hysteresis: a Bouc-Wen friction variable ``zeta`` in the wire-tube,
   ``dzeta = (A dx - beta |dx| |zeta|^(n-1) zeta - gamma dx |zeta|^n) / F(x)``, n = 1.5,
   whose level ``F(x) = f0 + f1 x`` grows with the wire tension (capstan friction). Loading and
   unloading use different (beta, gamma): unloading friction is 25 % stronger and of another
   shape (the asymmetry). The friction takes its share from the drive, Bouc-Wen style:
   ``bend_drive = alpha x + (1 - alpha) (x - F zeta)``, so that at a reversal only ``alpha``
   of the motion passes (the wire sticks) until the friction has reversed.
7. ``creep``: power-law (fractional-type) relaxation of the bending section, approximated by
   a Prony bank of 7 first-order terms with time constants log-spaced over two decades around
   ``time_constant_s`` and weights ``~ tau_i ** -0.5`` (a ``t ** -0.5`` kernel); the weighted
   mean time constant is ``time_constant_s`` and the bank's total share is ``fraction``.
8. Structure: a viscous damper (8 ms) in parallel with the bending stiffness and a Hertzian
   hard-stop contact ``K delta ** 1.5`` near the mechanical limit (the saturation). The
   damper is the plant's rate dependence: loops widen with frequency.
9. ``backlash``: a gear-like play between bending section and measured tip: the tip rests on
   one flank at rest and follows only after the gap ``gap_deg`` is taken up.
10. ``tip_dynamics``: a two-mode cantilever: the first bending mode at
    ``natural_frequency_hz`` with ``damping_ratio``, a second at 6.27 times that with 5 %
    participation, both driven by the quasi-static bend.
11. ``sensor_lag``: the laser's second-order Butterworth output filter with cut-off
    ``1 / (2 pi time_constant_s)``.
12. ``drift``: an offset of the measured bend: a linear warm-up ramp plus a slow sinusoidal
    room-temperature swing (period 5 min), whose sum starts with slope ``rate_deg_per_min``.
13. Sensor: white Gaussian noise and a 0.005 deg quantisation step.

The physics is integrated at 2 kHz or finer (an integer number of sub-steps per sample) in one
numba kernel; each output sample is the state at the end of its sample period.
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
"""Top of the valve's range (commands above are clipped)."""
P_ATM_PA: Final = 1.01325e5
P_MID_PA: Final = 1.5e5
"""Mid-range gauge pressure at which ``pneumatic_lag.time_constant_s`` holds."""
SUBSTEP_RATE_HZ: Final = 2000.0
"""Minimum internal integration rate."""
QUANTUM_RAD: Final = math.radians(0.005)
"""The laser's readout resolution."""

DISPERSION_HZ: Final = 80.0
DISPERSION_ZETA: Final = 0.7
SECOND_MODE_RATIO: Final = 6.267
"""Second to first bending-mode frequency of a uniform cantilever (4.694**2 / 1.875**2)."""
SECOND_MODE_SHARE: Final = 0.05
SECOND_MODE_ZETA: Final = 0.08
CREEP_TERMS: Final = 7
CREEP_DECADES: Final = 2.0
CREEP_EXPONENT: Final = 0.5
SWING_PERIOD_S: Final = 300.0
SWING_SHARE: Final = 0.4
"""Share of the drift's initial slope that comes from the room-temperature swing."""
LAG_ASYMMETRY: Final = 1.12
"""Venting over filling time constant is this squared; their geometric mean is the nominal."""
LAG_LINEAR_SPAN_PA: Final = 0.8e5
"""Pressure error at which the valve's flow saturates (filling; venting uses 0.75 of it)."""
GAIN_FLOOR: Final = 0.1
"""Lowest gain factor ``gain_drift`` can reach (a catheter does not lose all stiffness)."""

# Indices of the kernel's plant-parameter vector.
_P_OPEN, _P_KNEE, _X3, _QUAD, _ALPHA, _F0, _F1, _BW_N = range(8)
_BETA_UP, _GAMMA_UP, _BETA_DN, _GAMMA_DN = range(8, 12)
_LIMIT, _CONTACT_K, _DAMPER = range(12, 15)
_FILL_S, _VENT_S, _FILL_MAX, _VENT_MAX, _POLY_N = range(15, 20)
# Indices of the kernel's run settings, effect switches (1.0 = on) and effect strengths,
# stored after the plant parameters in the same vector.
_RATE_HZ, _SUBSTEPS = range(20, 22)
_DELAY, _CREEP, _TIP, _SENSOR, _BACKLASH, _GAIN, _SLOW = range(22, 29)
_DELAY_S, _SLOW_FRACTION, _SLOW_TAU_S, _GAIN_PER_S, _BACKLASH_RAD = range(29, 34)
_N_PARS = 34
# Rows of the kernel's table of exact second-order steps (Phi in columns 0-1, Gamma in 2).
_LIN_DISPERSION, _LIN_MODE1, _LIN_MODE2, _LIN_SENSOR = range(4)


@dataclass(frozen=True)
class BoucWenParameters:
    """Nominal parameters of one catheter of this make (angles in rad, pressures in Pa).

    Attributes:
        opening_pa: Gauge pressure at the centre of the soft-plus knee (the muscle's
            opening pressure: braid slack and wire pre-load taken up).
        knee_pa: Width of the soft-plus knee.
        free_bend_3bar_rad: Bend the muscle force at 3 bar would cause without friction
            and without the hard stop.
        force_curvature: Quadratic share of the pressure-force map (0 = linear).
        alpha: Share of the drive that passes a reversal while the wire sticks.
        friction_rad: Wire-tube friction level at zero tension (bend-equivalent).
        friction_per_rad: Growth of the friction level with the drive (capstan effect).
        bw_exponent: Bouc-Wen exponent n (smoothness of the approach to sliding).
        beta_up: Bouc-Wen beta while loading.
        gamma_up: Bouc-Wen gamma while loading.
        beta_down: Bouc-Wen beta while unloading.
        gamma_down: Bouc-Wen gamma while unloading.
        limit_share: Bend at which the hard stop is touched, as a share of
            ``free_bend_3bar_rad`` (the stop sits where the top of the range bends).
        contact_stiffness: Hertzian contact coefficient K in ``K delta**1.5`` relative to
            the bending stiffness [rad**-0.5].
        damper_s: Viscous damper over bending stiffness (the structure's time constant).
        valve_fill_s: Fast valve's small-signal filling time constant at 1.5 bar.
        valve_vent_s: Fast valve's small-signal venting time constant at 1.5 bar.
        polytropic_exponent: Polytropic exponent of the filling gas.
        noise_deg: White-noise standard deviation of the laser [deg].
    """

    opening_pa: float = 0.8e5
    knee_pa: float = 0.06e5
    free_bend_3bar_rad: float = 0.95
    force_curvature: float = 0.4
    alpha: float = 0.25
    friction_rad: float = 0.004
    friction_per_rad: float = 0.12
    bw_exponent: float = 1.5
    beta_up: float = 0.55
    gamma_up: float = 0.45
    beta_down: float = 0.40
    gamma_down: float = 0.3155
    limit_share: float = 0.653
    contact_stiffness: float = 7.0
    damper_s: float = 0.008
    valve_fill_s: float = 0.003
    valve_vent_s: float = 0.0036
    polytropic_exponent: float = 1.2
    noise_deg: float = 0.05


def _draw_parameters(variant: int) -> BoucWenParameters:
    """Variant 0 is the nominal catheter; others vary its make by about +-20 %."""
    nominal = BoucWenParameters()
    if variant == 0:
        return nominal
    rng = np.random.default_rng(variant)

    def vary(value: float, spread: float) -> float:
        return float(value * rng.uniform(1.0 - spread, 1.0 + spread))

    down_level = rng.uniform(1.1, 1.4)  # unloading friction over loading friction
    n = nominal.bw_exponent
    down_sum = down_level**-n  # beta + gamma that saturates zeta at -down_level
    down_split = rng.uniform(0.52, 0.6)  # beta share while unloading (keeps beta > gamma)
    return replace(
        nominal,
        opening_pa=vary(nominal.opening_pa, 0.2),
        knee_pa=vary(nominal.knee_pa, 0.2),
        free_bend_3bar_rad=vary(nominal.free_bend_3bar_rad, 0.2),
        force_curvature=vary(nominal.force_curvature, 0.3),
        alpha=vary(nominal.alpha, 0.1),
        friction_rad=vary(nominal.friction_rad, 0.2),
        friction_per_rad=vary(nominal.friction_per_rad, 0.2),
        beta_down=down_sum * down_split,
        gamma_down=down_sum * (1.0 - down_split),
        limit_share=vary(nominal.limit_share, 0.06),
        contact_stiffness=vary(nominal.contact_stiffness, 0.2),
        damper_s=vary(nominal.damper_s, 0.15),
        noise_deg=float(rng.uniform(0.03, 0.08)),
    )


def _second_order_zoh(
    frequency_rad_s: float, damping: float, dt_s: float
) -> tuple[FloatArray, FloatArray]:
    """Exact zero-order-hold step of ``y'' + 2 d w y' + w**2 y = w**2 u``.

    Returns (Phi, Gamma) with ``[y, y'] <- Phi [y, y'] + Gamma u``; exact for any step, so
    stiff modes stay stable at any sample rate.
    """
    w = frequency_rad_s
    a = np.array([[0.0, 1.0], [-(w**2), -2.0 * damping * w]])
    b = np.array([0.0, w**2])
    aug = np.zeros((3, 3))
    aug[:2, :2] = a * dt_s
    aug[:2, 2] = b * dt_s
    e = scipy.linalg.expm(aug)
    return np.ascontiguousarray(e[:2, :2]), np.ascontiguousarray(e[:2, 2])


def creep_bank(fraction: float, time_constant_s: float) -> tuple[FloatArray, FloatArray]:
    """Time constants [s] and weights of the Prony bank approximating power-law creep.

    Time constants are log-spaced over two decades; weights follow ``tau ** -0.5`` (the Prony
    image of a ``t ** -0.5`` relaxation kernel). They are scaled so that the weighted mean
    time constant is ``time_constant_s`` and the weights sum to ``fraction``.
    """
    ratio = np.logspace(-CREEP_DECADES / 2, CREEP_DECADES / 2, CREEP_TERMS)
    weights = ratio**-CREEP_EXPONENT
    mean_ratio = float(np.sum(weights * ratio) / np.sum(weights))
    taus = time_constant_s * ratio / mean_ratio
    return taus, fraction * weights / np.sum(weights)


@njit(cache=True)
def _soft_plus(z: float) -> float:
    """log(1 + e**z) without overflow: the log-sum-exp smooth maximum of 0 and z."""
    return max(z, 0.0) + math.log1p(math.exp(-abs(z)))


@njit(cache=True)
def _free_bend(p_pa: float, pp: FloatArray, e3: float) -> float:
    """Muscle force at gauge pressure ``p_pa`` as the free bend it causes [rad]."""
    s = pp[_P_KNEE]
    r = s * _soft_plus((p_pa - pp[_P_OPEN]) / s) / e3
    q = pp[_QUAD]
    return pp[_X3] * r * (1.0 + q * r) / (1.0 + q)


@njit(cache=True)
def _contact_solve(a: float, b: float, limit: float, k: float) -> float:
    """Solve ``a theta + k max(theta - limit, 0) ** 1.5 = b`` for theta (monotone in theta)."""
    if b <= a * limit:
        return b / a
    r = b - a * limit
    # Both guesses over-estimate the root of a convex increasing function, so Newton's
    # iterates fall monotonically onto it.
    d = min(r / a, (r / k) ** (2.0 / 3.0))
    for _ in range(60):
        sq = math.sqrt(d)
        h = a * d + k * d * sq - r
        if abs(h) <= 1e-13 * (1.0 + r):
            break
        d -= h / (a + 1.5 * k * sq)
        d = max(d, 0.0)
    return limit + d


@njit(cache=True)
def _step2(lin: FloatArray, row: int, state: FloatArray, u: float) -> float:
    """Advance the second-order state ``lin`` row ``row`` by one sub-step; return y."""
    y = lin[row, 0, 0] * state[0] + lin[row, 0, 1] * state[1] + lin[row, 0, 2] * u
    state[1] = lin[row, 1, 0] * state[0] + lin[row, 1, 1] * state[1] + lin[row, 1, 2] * u
    state[0] = y
    return y


# Layout of the kernel's resumable state: scalars, then the line, the four second-order
# links' states and the creep bank's terms.
_S_P, _S_P2, _S_X_PREV, _S_ZETA, _S_THETA, _S_YB = range(6)
_S_LINE, _S_MODE1, _S_MODE2, _S_LASER = 6, 8, 10, 12
_S_CREEP = 14


@njit(cache=True)
def _fresh_state(n_creep: int) -> FloatArray:
    """The kernel's state at rest (vented, straight)."""
    return np.zeros(_S_CREEP + n_creep)


@njit(cache=True)
def _simulate_kernel(
    cmd: FloatArray, pars: FloatArray, creep: FloatArray, lin: FloatArray
) -> FloatArray:
    """Noise-free measured bend [rad] at the end of each sample period (see module doc).

    Args:
        cmd: Pressure command [Pa], already clipped to the valve's range.
        pars: Plant parameters, run settings, effect switches and strengths (``_*`` indices).
        creep: Per-sub-step decay factors (row 0) and weights (row 1) of the creep bank.
        lin: Exact sub-step matrices of the second-order links (``_LIN_*`` rows).
    """
    out = np.empty(cmd.size)
    _advance(cmd, 0, pars, creep, lin, _fresh_state(creep.shape[1]), out)
    return out


@njit(cache=True)
def _advance(  # noqa: PLR0917 - numba compiles positional arguments only
    cmd: FloatArray,
    k_start: int,
    pars: FloatArray,
    creep: FloatArray,
    lin: FloatArray,
    state: FloatArray,
    out: FloatArray,
) -> None:
    """Integrate samples ``k_start`` to the end of ``cmd`` from ``state`` (updated in place).

    ``cmd`` holds every command since rest (the delay line reads back into it); sample k's
    bend goes to ``out[k - k_start]``. Two calls on consecutive spans give what one call on
    both gives, which lets a controller close the loop one sample at a time.
    """
    pp = pars
    n = cmd.size
    rate_hz = pars[_RATE_HZ]
    substeps = int(pars[_SUBSTEPS])
    delay_s = pars[_DELAY_S]
    slow_fraction = pars[_SLOW_FRACTION]
    gain_per_s = pars[_GAIN_PER_S]
    backlash_rad = pars[_BACKLASH_RAD]
    on_delay = pars[_DELAY] > 0.5
    on_creep = pars[_CREEP] > 0.5
    on_tip = pars[_TIP] > 0.5
    on_sensor = pars[_SENSOR] > 0.5
    on_backlash = pars[_BACKLASH] > 0.5
    on_gain = pars[_GAIN] > 0.5
    on_slow = pars[_SLOW] > 0.5
    dt = 1.0 / (rate_hz * substeps)
    e3 = pp[_P_KNEE] * _soft_plus((P_MAX_PA - pp[_P_OPEN]) / pp[_P_KNEE])
    p_ref_abs = P_ATM_PA + P_MID_PA
    poly = (pp[_POLY_N] - 1.0) / pp[_POLY_N]
    bw_n = pp[_BW_N]
    alpha = pp[_ALPHA]
    f0 = pp[_F0]
    f1 = pp[_F1]
    z_up = (1.0 / (pp[_BETA_UP] + pp[_GAMMA_UP])) ** (1.0 / bw_n)
    z_dn = (1.0 / (pp[_BETA_DN] + pp[_GAMMA_DN])) ** (1.0 / bw_n)
    damp = pp[_DAMPER] / dt
    slow_decay = math.exp(-dt / pars[_SLOW_TAU_S]) if on_slow else 0.0
    n_creep = creep.shape[1]
    creep_total = 0.0
    for i in range(n_creep):
        creep_total += creep[1, i]

    p = state[_S_P]
    p2 = state[_S_P2]
    line = state[_S_LINE : _S_LINE + 2]
    x_prev = state[_S_X_PREV]
    zeta = state[_S_ZETA]
    theta = state[_S_THETA]
    yb = state[_S_YB]
    c = state[_S_CREEP : _S_CREEP + n_creep]
    mode1 = state[_S_MODE1 : _S_MODE1 + 2]
    mode2 = state[_S_MODE2 : _S_MODE2 + 2]
    laser = state[_S_LASER : _S_LASER + 2]
    y = 0.0
    for k in range(k_start, n):
        for j in range(substeps):
            t = (k * substeps + j) * dt
            # Command at the muscle end of the line (zero-order hold of the samples).
            if on_delay:
                idx = math.floor((t - delay_s) * rate_hz + 1e-9)
                u = _step2(lin, _LIN_DISPERSION, line, cmd[idx] if idx >= 0 else 0.0)
            else:
                u = cmd[k]
            # Polytropic filling through a linear-with-saturation valve.
            kappa = ((p + P_ATM_PA) / p_ref_abs) ** poly
            err = u - p
            if err >= 0.0:
                dp = min(
                    err * (1.0 - math.exp(-kappa * dt / pp[_FILL_S])), kappa * pp[_FILL_MAX] * dt
                )
            else:
                dp = max(
                    err * (1.0 - math.exp(-kappa * dt / pp[_VENT_S])), -kappa * pp[_VENT_MAX] * dt
                )
            p = max(p + dp, 0.0)
            # Muscle force as free bend, with the second chamber's share.
            if on_slow:
                p2 = p + (p2 - p) * slow_decay
                x = (1.0 - slow_fraction) * _free_bend(p, pp, e3) + slow_fraction * _free_bend(
                    p2, pp, e3
                )
            else:
                x = _free_bend(p, pp, e3)
            if on_gain:
                x *= max(GAIN_FLOOR, 1.0 + gain_per_s * (t + dt))
            # Bouc-Wen friction, sub-stepped so each increment is a small share of the
            # friction level (fast steps move x by many friction levels in one sub-step).
            dx = x - x_prev
            level = f0 + f1 * min(x, x_prev)
            m = min(2000, 1 + int(abs(dx) / (0.05 * level)))
            h = dx / m
            if h >= 0.0:
                beta = pp[_BETA_UP]
                gamma = pp[_GAMMA_UP]
            else:
                beta = pp[_BETA_DN]
                gamma = pp[_GAMMA_DN]
            for i in range(m):
                xi = x_prev + (i + 0.5) * h
                az = abs(zeta)
                dz = h - beta * abs(h) * az ** (bw_n - 1.0) * zeta - gamma * h * az**bw_n
                zeta += dz / (f0 + f1 * xi)
                zeta = min(max(zeta, -z_dn), z_up)
            x_prev = x
            drive = alpha * x + (1.0 - alpha) * (x - (f0 + f1 * x) * zeta)
            # Power-law creep of the bending section (Prony bank).
            if on_creep:
                acc = (1.0 - creep_total) * drive
                for i in range(n_creep):
                    c[i] = drive + (c[i] - drive) * creep[0, i]
                    acc += creep[1, i] * c[i]
                drive = acc
            # Parallel damper and Hertzian hard stop, implicit Euler.
            theta = _contact_solve(1.0 + damp, drive + damp * theta, pp[_LIMIT], pp[_CONTACT_K])
            y = theta
            if on_backlash:
                yb = min(max(yb, theta - backlash_rad), theta)
                y = yb
            if on_tip:
                y = (1.0 - SECOND_MODE_SHARE) * _step2(
                    lin, _LIN_MODE1, mode1, y
                ) + SECOND_MODE_SHARE * _step2(lin, _LIN_MODE2, mode2, y)
            if on_sensor:
                y = _step2(lin, _LIN_SENSOR, laser, y)
        out[k - k_start] = y
    state[_S_P] = p
    state[_S_P2] = p2
    state[_S_X_PREV] = x_prev
    state[_S_ZETA] = zeta
    state[_S_THETA] = theta
    state[_S_YB] = yb


class BoucWenPlant(ForeignPlant):
    """A catheter whose hysteresis is Bouc-Wen friction in the wire-tube (see module doc).

    Args:
        variant: 0 is the nominal catheter; any other value draws another catheter of the
            same make (gain, opening pressure, friction, hard stop, damper, noise).
    """

    name: ClassVar[str] = "boucwen"
    hysteresis_law: ClassVar[str] = (
        "Bouc-Wen wire-tube friction (n=1.5, tension-scaled, asymmetric loading/unloading) "
        "with a parallel viscous damper and a Hertzian hard stop"
    )

    def __init__(self, variant: int = 0) -> None:
        super().__init__(variant)
        self.params: BoucWenParameters = _draw_parameters(self.variant)

    @property
    def noise_std_rad(self) -> float:
        """White noise of the laser plus its quantisation (uniform, step**2 / 12) [rad]."""
        return math.sqrt(math.radians(self.params.noise_deg) ** 2 + QUANTUM_RAD**2 / 12.0)

    def _plant_vector(self, effects: dict[str, Effect]) -> FloatArray:
        """The kernel's parameter vector with the plant's part filled in (the valve slowed
        by ``pneumatic_lag``); run settings and other effects are left at zero."""
        pr = self.params
        pp = np.zeros(_N_PARS)
        pp[_P_OPEN] = pr.opening_pa
        pp[_P_KNEE] = pr.knee_pa
        pp[_X3] = pr.free_bend_3bar_rad
        pp[_QUAD] = pr.force_curvature
        pp[_ALPHA] = pr.alpha
        pp[_F0] = pr.friction_rad
        pp[_F1] = pr.friction_per_rad
        pp[_BW_N] = pr.bw_exponent
        pp[_BETA_UP] = pr.beta_up
        pp[_GAMMA_UP] = pr.gamma_up
        pp[_BETA_DN] = pr.beta_down
        pp[_GAMMA_DN] = pr.gamma_down
        pp[_LIMIT] = pr.limit_share * pr.free_bend_3bar_rad
        pp[_CONTACT_K] = pr.contact_stiffness
        pp[_DAMPER] = pr.damper_s
        pp[_POLY_N] = pr.polytropic_exponent
        fill_s, vent_s = pr.valve_fill_s, pr.valve_vent_s
        if "pneumatic_lag" in effects:
            tau = float(effects["pneumatic_lag"].params["time_constant_s"])
            fill_s, vent_s = tau / LAG_ASYMMETRY, tau * LAG_ASYMMETRY
        pp[_FILL_S] = fill_s
        pp[_VENT_S] = vent_s
        # Flow cap: the linear range of the valve spans a fixed pressure error.
        pp[_FILL_MAX] = LAG_LINEAR_SPAN_PA / fill_s
        pp[_VENT_MAX] = 0.75 * LAG_LINEAR_SPAN_PA / vent_s
        return pp

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
        bend = _simulate_kernel(cmd, run.pars, run.creep, run.lin)
        return bend + run.drift_rad(np.arange(1, cmd.size + 1) / rate_hz)

    def _measure(self, bend: FloatArray, rng: np.random.Generator) -> FloatArray:
        """The laser: white noise, then quantisation."""
        noise = rng.standard_normal(bend.size)
        measured = bend + math.radians(self.params.noise_deg) * noise
        return np.asarray(np.round(measured / QUANTUM_RAD) * QUANTUM_RAD)

    def _run(self, rate_hz: float, effects: Sequence[Effect]) -> _Run:
        """The kernel's inputs for a run at ``rate_hz`` with ``effects``."""
        if not rate_hz > 0.0 or not math.isfinite(rate_hz):
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        by_name = self.effects_by_name(effects)
        substeps = max(1, math.ceil(SUBSTEP_RATE_HZ / rate_hz))
        dt = 1.0 / (rate_hz * substeps)

        def par(name: str, key: str, default: float) -> float:
            return float(by_name[name].params[key]) if name in by_name else default

        pars = self._plant_vector(by_name)
        pars[_RATE_HZ] = rate_hz
        pars[_SUBSTEPS] = substeps
        for flag, name in (
            (_DELAY, "transport_delay"),
            (_CREEP, "creep"),
            (_TIP, "tip_dynamics"),
            (_SENSOR, "sensor_lag"),
            (_BACKLASH, "backlash"),
            (_GAIN, "gain_drift"),
            (_SLOW, "slow_lag"),
        ):
            pars[flag] = float(name in by_name)
        pars[_DELAY_S] = par("transport_delay", "delay_s", 0.0)
        pars[_SLOW_FRACTION] = par("slow_lag", "fraction", 0.0)
        pars[_SLOW_TAU_S] = par("slow_lag", "time_constant_s", 1.0)
        pars[_GAIN_PER_S] = par("gain_drift", "percent_per_min", 0.0) / 100.0 / 60.0
        pars[_BACKLASH_RAD] = math.radians(par("backlash", "gap_deg", 0.0))

        creep = np.zeros((2, 0))
        if "creep" in by_name:
            taus, weights = creep_bank(
                par("creep", "fraction", 0.0), par("creep", "time_constant_s", 1.0)
            )
            creep = np.ascontiguousarray(np.vstack([np.exp(-dt / taus), weights]))
        f_hz = par("tip_dynamics", "natural_frequency_hz", 5.0)
        links = {
            _LIN_DISPERSION: (2.0 * math.pi * DISPERSION_HZ, DISPERSION_ZETA),
            _LIN_MODE1: (2.0 * math.pi * f_hz, par("tip_dynamics", "damping_ratio", 0.1)),
            _LIN_MODE2: (2.0 * math.pi * f_hz * SECOND_MODE_RATIO, SECOND_MODE_ZETA),
            # Butterworth: cut-off 1 / tau, damping 1 / sqrt(2).
            _LIN_SENSOR: (1.0 / par("sensor_lag", "time_constant_s", 0.05), 1.0 / math.sqrt(2)),
        }
        lin = np.zeros((len(links), 2, 3))
        for row, (w, z) in links.items():
            lin[row, :, :2], lin[row, :, 2] = _second_order_zoh(w, z, dt)
        return _Run(pars, creep, lin, par("drift", "rate_deg_per_min", 0.0))

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
        return _BoucWenStepper(self, self._run(rate_hz, effects), rate_hz, seed)


@dataclass(frozen=True)
class _Run:
    """The kernel's inputs for one run, and the drift added to its output."""

    pars: FloatArray
    creep: FloatArray
    lin: FloatArray
    drift_deg_per_min: float

    def drift_rad(self, t_s: FloatArray) -> FloatArray:
        """The drift's offset [rad] at the sample times ``t_s`` (zero without drift)."""
        if self.drift_deg_per_min == 0.0:
            return np.zeros_like(t_s)
        return drift_offset_rad(self.drift_deg_per_min, t_s)


class _BoucWenStepper(PlantStepper):
    """Carries the kernel's state, and every command so far (the delay line reads back)."""

    def __init__(self, plant: BoucWenPlant, run: _Run, rate_hz: float, seed: int) -> None:
        self._plant = plant
        self._run = run
        self._rate_hz = rate_hz
        self._state = _fresh_state(run.creep.shape[1])
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
        _advance(
            self._cmd[: k + 1],
            k,
            self._run.pars,
            self._run.creep,
            self._run.lin,
            self._state,
            self._out,
        )
        bend = self._out + self._run.drift_rad(np.array([(k + 1) / self._rate_hz]))
        return float(self._plant._measure(bend, self._rng)[0])


def drift_offset_rad(rate_deg_per_min: float, t_s: FloatArray) -> FloatArray:
    """Warm-up ramp plus room-temperature swing; slope ``rate_deg_per_min`` at t = 0."""
    rate_rad_s = math.radians(rate_deg_per_min) / 60.0
    w = 2.0 * math.pi / SWING_PERIOD_S
    return (1.0 - SWING_SHARE) * rate_rad_s * t_s + SWING_SHARE * rate_rad_s / w * np.sin(w * t_s)


__all__ = ["BoucWenParameters", "BoucWenPlant", "creep_bank", "drift_offset_rad"]
