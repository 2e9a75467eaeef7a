"""A PAM catheter whose wire friction is a Maxwell-slip model (foreign plant ``maxwell_slip``).

Written apart from ``catheter_models.plant`` and the lab's blocks, as ground truth for the
model lab. Everything happens along one pull wire, in physical units (metres, newtons,
pascals); the bend is the wire's travel over its offset from the neutral axis.

Base physics (what every recording has):

* Valve: a proportional pressure regulator, first order with a 2 ms time constant.
* Muscle: a McKibben static force law ``F = A0 * p_eff * (a (1 - eps)^2 - b)`` with
  ``a = 3 / tan^2(alpha0)``, ``b = 1 / sin^2(alpha0)`` (minus the derivative of the braid
  volume), the contraction ``eps`` set by the wire travel, i.e. by the load. The bladder
  only pushes on the braid once it has inflated against it: ``p_eff`` is a softplus of the
  pressure above the opening pressure, which makes a smooth knee, not a kink.
* Wire friction (the hysteresis law): N = 12 parallel elasto-slide (Maxwell-slip)
  elements between the muscle's pull and the bending section, each a spring ``k_i`` in
  series with a Coulomb slider of break-away force ``f_i`` (break-away travels spread
  geometrically, so loops have rounded corners). Each slider is viscoplastic: when its
  spring force exceeds the break-away force it slides at a speed proportional to the excess,
  i.e. a velocity-strengthening friction ``f_i + f_i v / v_ref`` that widens loops with
  frequency. The break-away forces grow with the wire tension (capstan-like normal force in
  the bent sheath) and are larger for pulling than for releasing (asymmetry). After a
  vent the friction holds a small residual bend (about 1 deg), as on a real catheter.
* Bending section: a spring that stiffens exponentially towards a mechanical limit, with a
  small wire-level damping (time constant a few ms).
* Sensor: white noise plus a quantisation step of the laser read-out.

Hidden effects, each with its own physics here:

* ``pneumatic_lag``: isentropic orifice flow (ISO 6358: sonic conductance, critical
  pressure ratio, laminar near equal pressures) from the regulator into the muscle volume,
  polytropic filling, and a volume that grows with contraction; the conductance is
  calibrated so the mean time of a small step response of the muscle pressure at 1.5 bar
  equals ``time_constant_s``.
* ``transport_delay``: a ring buffer of the commanded pressure.
* ``creep``: a Prony series in the bending section's stiffness: the polymer's linear
  stiffness ``k0`` splits into a relaxed part and three Maxwell branches (spring and
  dashpot, relaxation times spread as ``tau/3``, ``tau``, ``3 tau``); the contact stiffening
  near the limit does not creep. The branch stiffness is calibrated so that the relaxed share
  of a step to mid-range is ``fraction`` and the time spread is rescaled so the mean time of
  the bend's creep is ``time_constant_s`` (both calibrations include the muscle's pull
  falling as it contracts).
* ``tip_dynamics``: a tip inertia on the bending spring (tangent stiffness of the section, so
  it rings faster near the limit), light viscous damping and a little Coulomb friction
  against the sheath; ``natural_frequency_hz`` and ``damping_ratio`` hold at mid-range bend.
* ``drift``: thermal expansion of the sensor mount, a first-order temperature heading to a
  set-point with a several-minute time constant, scaled so the initial slope is
  ``rate_deg_per_min``.
* ``sensor_lag``: the laser's own first-order filter on the measured bend.
* ``backlash``: slack (a play operator) in the wire between muscle and tip: the tip holds
  while the wire's pull reverses through the gap.
* ``gain_drift``: the muscle's effective area changes linearly with time, at the stated
  rate divided by the bend's sensitivity to area at mid-range (about 0.9), so that the
  bend's gain drifts at ``percent_per_min``.
* ``slow_lag``: a leak into a second, larger chamber whose pressure follows the muscle's
  through a slow first-order path; its share ``fraction`` of the effective pressure acts late.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar, Final

import numpy as np
from numba import njit
from scipy.optimize import brentq

from .base import Effect, FloatArray, ForeignPlant, PlantStepper

P_ATM_PA: Final = 101_325.0
P_MAX_PA: Final = 3.0e5
"""Highest command the valve follows (commands above are clipped)."""
_SUBSTEP_HZ: Final = 2000.0
"""Internal integration rate (at least): the stiffest base time constant is ~1 ms."""

# Air and the ISO 6358 flow law.
_R_AIR: Final = 287.0
_T_AIR_K: Final = 293.15
_RHO0: Final = 1.185
_B_CRIT: Final = 0.30
_R_LAM: Final = 0.97
_POLYTROPIC: Final = 1.2
_PHI_LAM: Final = math.sqrt(1.0 - ((_R_LAM - _B_CRIT) / (1.0 - _B_CRIT)) ** 2)

# Layout of the parameter vector handed to the numba kernel.
(
    _P_OPEN,
    _P_KNEE,
    _AREA,
    _A_MCK,
    _B_MCK,
    _LENGTH,
    _V_DEAD,
    _ARM,
    _K0,
    _X_LIM,
    _X_STIFF,
    _C_WIRE,
    _TAU_VALVE,
    _ASYM,
    _CAPSTAN,
    _F_REF,
    _V_REF,
    _DELAY_STEPS,
    _PNEU_C,
    _CREEP_K0,
    _CREEP_K1,
    _CREEP_K2,
    _CREEP_T0,
    _CREEP_T1,
    _CREEP_T2,
    _TIP_WN,
    _TIP_ZETA,
    _TIP_KMID,
    _TIP_COUL,
    _DRIFT_RATE,
    _DRIFT_TAU,
    _SENSOR_TAU,
    _GAP,
    _GAIN_RATE,
    _SLOW_FRAC,
    _SLOW_TAU,
    _N_SUB,
    _DT,
    _N_PAR,
) = range(39)

_CREEP_WEIGHTS: Final = (0.40, 0.35, 0.25)
"""Share of the relaxing stiffness in the tau/3, tau and 3 tau branches."""
_CREEP_SPAN: Final = (1.0 / 3.0, 1.0, 3.0)


@njit(cache=True)
def _softplus(u: float) -> float:
    if u > 30.0:
        return u
    return math.log1p(math.exp(u))


@njit(cache=True)
def _elastic(x_e: float, k0: float, x_lim: float, x_stiff: float) -> tuple[float, float]:
    """Bending-section elastic force [N] and tangent stiffness [N/m] at wire travel x_e [m]."""
    u = (x_e - x_lim) / x_stiff
    u0 = -x_lim / x_stiff
    if u > 40.0:
        # Beyond any reachable bend: continue linearly so the law stays finite.
        e40 = math.exp(40.0)
        force = k0 * x_e + k0 * x_stiff * (e40 * (1.0 + u - 40.0) - math.exp(u0))
        return force, k0 * (1.0 + e40)
    eu = math.exp(u)
    return k0 * x_e + k0 * x_stiff * (eu - math.exp(u0)), k0 * (1.0 + eu)


# Layout of the kernel's resumable state: scalars first, then the sliders, the creep
# dashpots and the delay ring (sized by the run's parameters).
(
    _S_P_VALVE,
    _S_P_MUSCLE,
    _S_P_SLOW,
    _S_X,
    _S_VEL,
    _S_CREEP_RELIEF,
    _S_TH_BACK,
    _S_TH_TIP,
    _S_OM_TIP,
    _S_OFFSET,
    _S_Y_SENSOR,
    _S_STEP,
    _S_I_RING,
    _N_SCALARS,
) = range(14)


@njit(cache=True)
def _fresh_state(par: np.ndarray, n_el: int) -> np.ndarray:
    """The state at rest (vented, straight) for a run with parameters ``par``."""
    return np.zeros(_N_SCALARS + n_el + 3 + max(int(par[_DELAY_STEPS]), 1))


@njit(cache=True)
def _kernel(cmd_pa: np.ndarray, par: np.ndarray, k_el: np.ndarray, f_el: np.ndarray) -> np.ndarray:
    """Integrate the plant from rest: the noise-free measured bend and the muscle pressure.

    The command is held over each sample (zero-order hold) and integrated in ``par[_N_SUB]``
    sub-steps of ``par[_DT]``; the output of sample k is the state at the end of that hold.
    Returns a (2, n) array: bend [rad], muscle pressure [Pa].
    """
    state = _fresh_state(par, k_el.size)
    out = np.zeros((2, cmd_pa.size))
    _advance(cmd_pa, par, k_el, f_el, state, out)
    return out


@njit(cache=True)
def _advance(  # noqa: PLR0917 - numba compiles positional arguments only
    cmd_pa: np.ndarray,
    par: np.ndarray,
    k_el: np.ndarray,
    f_el: np.ndarray,
    state: np.ndarray,
    out: np.ndarray,
) -> None:
    """Integrate ``cmd_pa`` from ``state`` (updated in place), writing ``out`` (2, n).

    Resumable: two calls on the halves of a command give what one call on the whole gives,
    which lets a controller close the loop one sample at a time.
    """
    n_sub = int(par[_N_SUB])
    dt_s = par[_DT]
    n_el = k_el.size
    z = state[_N_SCALARS : _N_SCALARS + n_el]
    p_open = par[_P_OPEN]
    p_knee = par[_P_KNEE]
    area = par[_AREA]
    a_mck = par[_A_MCK]
    b_mck = par[_B_MCK]
    length = par[_LENGTH]
    v_dead = par[_V_DEAD]
    arm = par[_ARM]
    k0 = par[_K0]
    x_lim = par[_X_LIM]
    x_stiff = par[_X_STIFF]
    c_wire = par[_C_WIRE]
    asym = par[_ASYM]
    capstan = par[_CAPSTAN]
    f_ref = par[_F_REF]
    v_ref = par[_V_REF]
    sp0 = p_knee * _softplus(-p_open / p_knee)
    k_sum = 0.0
    for i in range(n_el):
        k_sum += k_el[i]

    a_valve = 1.0 - math.exp(-dt_s / par[_TAU_VALVE])
    # Transport delay: a ring buffer of the command, one slot per sub-step of dead time.
    n_delay = int(par[_DELAY_STEPS])
    ring = state[_N_SCALARS + n_el + 3 :]
    i_ring = int(state[_S_I_RING])
    pneu_c = par[_PNEU_C]
    # Creep: Maxwell branches of stiffness creep_k [N/m]; creep_u is each dashpot's travel.
    creep_k = np.array([par[_CREEP_K0], par[_CREEP_K1], par[_CREEP_K2]])
    creep_on = creep_k.sum() > 0.0
    creep_a = np.zeros(3)
    if creep_on:
        creep_a[0] = 1.0 - math.exp(-dt_s / par[_CREEP_T0])
        creep_a[1] = 1.0 - math.exp(-dt_s / par[_CREEP_T1])
        creep_a[2] = 1.0 - math.exp(-dt_s / par[_CREEP_T2])
    creep_u = state[_N_SCALARS + n_el : _N_SCALARS + n_el + 3]
    tip_wn = par[_TIP_WN]
    tip_on = tip_wn > 0.0
    tip_c = 2.0 * par[_TIP_ZETA] * tip_wn
    tip_kmid = par[_TIP_KMID]
    tip_coul = par[_TIP_COUL]
    tip_v_eps = 0.002  # [rad/s] regularises the Coulomb sign, far below ringing speeds
    drift_rate = par[_DRIFT_RATE]
    drift_target = drift_rate * par[_DRIFT_TAU]
    a_drift = 1.0 - math.exp(-dt_s / par[_DRIFT_TAU]) if drift_rate != 0.0 else 0.0
    sensor_on = par[_SENSOR_TAU] > 0.0
    a_sensor = 1.0 - math.exp(-dt_s / par[_SENSOR_TAU]) if sensor_on else 1.0
    gap = par[_GAP]
    gain_rate = par[_GAIN_RATE]
    slow_frac = par[_SLOW_FRAC]
    a_slow = 1.0 - math.exp(-dt_s / par[_SLOW_TAU]) if slow_frac > 0.0 else 0.0

    p_valve = state[_S_P_VALVE]
    p_muscle = state[_S_P_MUSCLE]
    p_slow = state[_S_P_SLOW]
    x = state[_S_X]
    vel = state[_S_VEL]
    # Sum of k_j u_j: the force the relaxed creep branches no longer carry [N].
    creep_relief = state[_S_CREEP_RELIEF]
    th_back = state[_S_TH_BACK]
    th_tip = state[_S_TH_TIP]
    om_tip = state[_S_OM_TIP]
    offset = state[_S_OFFSET]
    y_sensor = state[_S_Y_SENSOR]
    step = int(state[_S_STEP])
    for k in range(cmd_pa.size):
        u = min(max(cmd_pa[k], 0.0), P_MAX_PA)
        if not math.isfinite(u):
            u = 0.0
        for _ in range(n_sub):
            step += 1
            t = step * dt_s
            if n_delay > 0:
                u_del = ring[i_ring]
                ring[i_ring] = u
                i_ring = (i_ring + 1) % n_delay
            else:
                u_del = u
            p_valve += (u_del - p_valve) * a_valve

            eps = min(max(x / length, -0.05), 0.3)
            if pneu_c > 0.0:
                # ISO 6358 mass flow between regulator and muscle, then polytropic filling.
                if p_valve >= p_muscle:
                    p_up = p_valve + P_ATM_PA
                    ratio = (p_muscle + P_ATM_PA) / p_up
                    sign = 1.0
                else:
                    p_up = p_muscle + P_ATM_PA
                    ratio = (p_valve + P_ATM_PA) / p_up
                    sign = -1.0
                if ratio <= _B_CRIT:
                    phi = 1.0
                elif ratio < _R_LAM:
                    q = (ratio - _B_CRIT) / (1.0 - _B_CRIT)
                    phi = math.sqrt(1.0 - q * q)
                else:
                    phi = _PHI_LAM * (1.0 - ratio) / (1.0 - _R_LAM)
                m_dot = sign * pneu_c * _RHO0 * p_up * phi
                one_m = 1.0 - eps
                cos2 = 1.0 - 1.0 / b_mck
                vol = v_dead + area * length * one_m * (1.0 - cos2 * one_m * one_m) / (1.0 - cos2)
                vol_dot = area * (a_mck * one_m * one_m - b_mck) * vel
                dp = (
                    _POLYTROPIC
                    / vol
                    * (_R_AIR * _T_AIR_K * m_dot - (p_muscle + P_ATM_PA) * vol_dot)
                )
                p_new = p_muscle + dt_s * dp
                # Flow alone never carries the muscle past the regulator's pressure.
                if (p_valve - p_muscle) * (p_valve - p_new) < 0.0 and m_dot != 0.0:
                    p_new = p_valve
                p_muscle = min(max(p_new, -0.5 * P_ATM_PA), 1.5 * P_MAX_PA)
            else:
                p_muscle = p_valve

            if slow_frac > 0.0:
                p_slow += (p_muscle - p_slow) * a_slow
                p_in = (1.0 - slow_frac) * p_muscle + slow_frac * p_slow
            else:
                p_in = p_muscle

            # Muscle: McKibben force with the softplus contact knee; gain drift scales area.
            gain = 1.0 + gain_rate * t
            gain = min(max(gain, 0.2), 2.0)
            p_eff = max(p_knee * _softplus((p_in - p_open) / p_knee) - sp0, 0.0)
            one_m = 1.0 - eps
            shape = a_mck * one_m * one_m - b_mck
            f_muscle = gain * area * p_eff * shape
            k_muscle = gain * area * p_eff * 2.0 * a_mck * one_m / length

            # Wire: one implicit (Newton) step of c x' = F_muscle - F_section - F_friction.
            f_sec, k_sec = _elastic(x, k0, x_lim, x_stiff)
            f_sec -= creep_relief
            f_fric = 0.0
            for i in range(n_el):
                f_fric += k_el[i] * (x - z[i])
            resid = f_muscle - f_sec - f_fric
            x_new = x + resid / (c_wire / dt_s + max(k_muscle, 0.0) + k_sec + k_sum)
            vel = (x_new - x) / dt_s
            x = x_new

            # Sliders: break-away force grows with tension, larger when pulling; a viscous
            # excess (velocity strengthening) is integrated implicitly.
            tension = max(f_muscle, 0.0) / f_ref
            normal = (1.0 - capstan) + capstan * tension
            for i in range(n_el):
                s = k_el[i] * (x - z[i])
                if s >= 0.0:
                    f_lim = f_el[i] * normal * (1.0 + asym)
                    sg = 1.0
                else:
                    f_lim = f_el[i] * normal * (1.0 - asym)
                    sg = -1.0
                if abs(s) > f_lim:
                    c_i = f_lim / v_ref + 1e-12
                    z[i] = (c_i / dt_s * z[i] + k_el[i] * x - f_lim * sg) / (c_i / dt_s + k_el[i])

            if creep_on:
                creep_relief = 0.0
                for j in range(3):
                    creep_u[j] += (x - creep_u[j]) * creep_a[j]
                    creep_relief += creep_k[j] * creep_u[j]

            th_wire = x / arm
            # Slack: the tip holds while the wire travels back or forth through the gap.
            th_back = min(th_wire, max(th_wire - gap, th_back)) if gap > 0.0 else th_wire

            if tip_on:
                # Tip inertia on the section's tangent stiffness (stiffer near the limit).
                _, k_tan = _elastic(x, k0, x_lim, x_stiff)
                w2 = tip_wn * tip_wn * k_tan / tip_kmid
                acc = -w2 * (th_tip - th_back) - tip_coul * math.tanh(om_tip / tip_v_eps)
                om_tip = (om_tip + dt_s * acc) / (1.0 + dt_s * tip_c)
                th_tip += dt_s * om_tip
            else:
                th_tip = th_back

            if drift_rate != 0.0:
                offset += (drift_target - offset) * a_drift
            y_sensor += (th_tip + offset - y_sensor) * a_sensor
        out[0, k] = y_sensor
        out[1, k] = p_muscle
    state[_S_P_VALVE] = p_valve
    state[_S_P_MUSCLE] = p_muscle
    state[_S_P_SLOW] = p_slow
    state[_S_X] = x
    state[_S_VEL] = vel
    state[_S_CREEP_RELIEF] = creep_relief
    state[_S_TH_BACK] = th_back
    state[_S_TH_TIP] = th_tip
    state[_S_OM_TIP] = om_tip
    state[_S_OFFSET] = offset
    state[_S_Y_SENSOR] = y_sensor
    state[_S_STEP] = step
    state[_S_I_RING] = i_ring


class MaxwellSlipPlant(ForeignPlant):
    """PAM catheter with Maxwell-slip wire friction (see the module docstring for physics).

    Args:
        variant: 0 is the nominal catheter; other values draw another catheter of the same
            make (gain, opening pressure, friction, saturation, rate dependence, asymmetry,
            noise each within roughly +-20 %).
    """

    name: ClassVar[str] = "maxwell_slip"
    hysteresis_law: ClassVar[str] = (
        "Maxwell-slip: 12 parallel elasto-viscoplastic slide elements on the pull wire, "
        "tension- and direction-dependent break-away"
    )

    N_ELEMENTS: ClassVar[int] = 12

    def __init__(self, variant: int = 0) -> None:
        super().__init__(variant)
        rng = np.random.default_rng(self.variant)
        spread = 0.0 if self.variant == 0 else 1.0

        def vary(rel: float) -> float:
            return 1.0 + spread * float(rng.uniform(-rel, rel))

        self.opening_pressure_pa: float = 0.8e5 * vary(0.2)
        """Pressure at which the bladder meets the braid (centre of the knee) [Pa]."""
        self.knee_width_pa: float = 0.08e5 * vary(0.2)
        alpha0 = math.radians(22.0 * vary(0.05))
        self.a_mck: float = 3.0 / math.tan(alpha0) ** 2
        self.b_mck: float = 1.0 / math.sin(alpha0) ** 2
        self.area_m2: float = math.pi * 0.0025**2 * vary(0.2)
        self.length_m: float = 0.020
        self.dead_volume_m3: float = 1.0e-6
        self.arm_m: float = 0.002
        self.limit_rad: float = math.radians(37.0) * vary(0.15)
        self.stiffening_rad: float = math.radians(3.0) * vary(0.2)
        self.k0_n_per_m: float = 25_600.0
        self.wire_tau_s: float = 0.002
        self.valve_tau_s: float = 0.002
        self.friction_n: float = 1.8 * vary(0.2)
        """Total break-away force of the wire friction at the reference tension [N]."""
        self.asymmetry: float = 0.2 * vary(0.25)
        self.capstan: float = 0.5 * vary(0.2)
        self.v_ref_m_per_s: float = 0.016 * vary(0.2)
        self.drift_tau_s: float = 360.0 * vary(0.25)
        self._noise_white_rad: float = math.radians(
            0.05 if self.variant == 0 else float(rng.uniform(0.035, 0.07))
        )
        self.quant_step_rad: float = math.radians(0.005)
        # Break-away travels spread geometrically (bend-equivalent 0.05 to 2 deg).
        travel_m = self.arm_m * np.radians(np.geomspace(0.05, 2.0, self.N_ELEMENTS))
        self._f_el: FloatArray = np.full(self.N_ELEMENTS, self.friction_n / self.N_ELEMENTS)
        self._k_el: FloatArray = self._f_el / travel_m
        self.f_ref_n: float = self.muscle_force_n(1.9e5, 0.02)
        if self.variant != 0:
            # Every catheter of the make is built to reach its limit at full pressure: the
            # section stiffness puts the frictionless 3 bar bend just into the stiffening.
            target = self.limit_rad + self.stiffening_rad * float(rng.uniform(0.2, 0.7))

            def excess(k0: float) -> float:
                self.k0_n_per_m = k0
                return self.static_bend_rad(P_MAX_PA) - target

            self.k0_n_per_m = float(brentq(excess, 2.0e3, 2.0e5, xtol=1.0))
        self._pneu_ref: float | None = None

    # ------------------------------------------------------------------ static helpers

    def muscle_force_n(self, pressure_pa: float, contraction: float) -> float:
        """McKibben force [N] at a gauge pressure and contraction (no gain drift)."""
        w = self.knee_width_pa
        sp = w * math.log1p(math.exp(min((pressure_pa - self.opening_pressure_pa) / w, 30.0)))
        if (pressure_pa - self.opening_pressure_pa) / w > 30.0:
            sp = pressure_pa - self.opening_pressure_pa
        sp0 = w * math.log1p(math.exp(-self.opening_pressure_pa / w))
        shape = self.a_mck * (1.0 - contraction) ** 2 - self.b_mck
        return self.area_m2 * max(sp - sp0, 0.0) * shape

    def section_force_n(self, x_e_m: float) -> float:
        """Bending-section elastic force [N] at elastic wire travel ``x_e_m``."""
        x_lim = self.arm_m * self.limit_rad
        x_st = self.arm_m * self.stiffening_rad
        return self.k0_n_per_m * (
            x_e_m + x_st * (math.exp((x_e_m - x_lim) / x_st) - math.exp(-x_lim / x_st))
        )

    def section_stiffness_n_per_m(self, x_e_m: float) -> float:
        """Tangent stiffness [N/m] of the bending section at elastic wire travel ``x_e_m``."""
        x_lim = self.arm_m * self.limit_rad
        x_st = self.arm_m * self.stiffening_rad
        return self.k0_n_per_m * (1.0 + math.exp((x_e_m - x_lim) / x_st))

    def static_travel_m(
        self,
        pressure_pa: float,
        relaxed_share: float = 0.0,
        friction_sign: float = 0.0,
        gain: float = 1.0,
    ) -> float:
        """Equilibrium wire travel [m] at a held pressure.

        Args:
            pressure_pa: Gauge muscle pressure [Pa].
            relaxed_share: Share of the polymer stiffness ``k0`` that has relaxed (creep).
            friction_sign: +1 after loading (friction at its pulling break-away), -1 after
                unloading, 0 frictionless.
            gain: Factor on the muscle's effective area.
        """

        def net(x: float) -> float:
            f_m = gain * self.muscle_force_n(pressure_pa, x / self.length_m)
            normal = (1.0 - self.capstan) + self.capstan * max(f_m, 0.0) / self.f_ref_n
            side = 1.0 + self.asymmetry * friction_sign
            fric = friction_sign * self.friction_n * normal * side
            relief = relaxed_share * self.k0_n_per_m * x
            return f_m - fric - self.section_force_n(x) + relief

        if net(0.0) <= 0.0:
            return 0.0
        return float(brentq(net, 0.0, 0.2 * self.length_m, xtol=1e-12))

    def static_bend_rad(self, pressure_pa: float, friction_sign: float = 0.0) -> float:
        """Quasi-static bend [rad] at a held pressure (no hidden effect)."""
        return self.static_travel_m(pressure_pa, friction_sign=friction_sign) / self.arm_m

    @property
    def mid_bend_rad(self) -> float:
        """Mid-range bend [rad]: half the frictionless bend at 3 bar."""
        return 0.5 * self.static_bend_rad(P_MAX_PA)

    @property
    def mid_pressure_pa(self) -> float:
        """Gauge pressure [Pa] whose frictionless static bend is the mid-range bend."""
        target = self.mid_bend_rad
        return float(
            brentq(lambda p: self.static_bend_rad(p) - target, self.opening_pressure_pa, P_MAX_PA)
        )

    def area_sensitivity(self) -> float:
        """Relative change of the mid-range static bend per relative change of muscle area.

        Below one: the muscle's own compliance grows with its area and the section
        stiffens, so the bend follows the area less than proportionally. ``gain_drift``
        divides by it so that the bend's gain drifts at the stated rate.
        """
        p_mid = self.mid_pressure_pa
        up = self.static_travel_m(p_mid, gain=1.01)
        down = self.static_travel_m(p_mid, gain=0.99)
        return (up - down) / (0.02 * self.static_travel_m(p_mid))

    @property
    def noise_std_rad(self) -> float:
        """Std of the sensor's white noise including its quantisation [rad]."""
        return math.sqrt(self._noise_white_rad**2 + self.quant_step_rad**2 / 12.0)

    # ------------------------------------------------------------------ effects

    def _base_params(self) -> FloatArray:
        par = np.zeros(_N_PAR)
        par[_P_OPEN] = self.opening_pressure_pa
        par[_P_KNEE] = self.knee_width_pa
        par[_AREA] = self.area_m2
        par[_A_MCK] = self.a_mck
        par[_B_MCK] = self.b_mck
        par[_LENGTH] = self.length_m
        par[_V_DEAD] = self.dead_volume_m3
        par[_ARM] = self.arm_m
        par[_K0] = self.k0_n_per_m
        par[_X_LIM] = self.arm_m * self.limit_rad
        par[_X_STIFF] = self.arm_m * self.stiffening_rad
        par[_C_WIRE] = self.wire_tau_s * self.k0_n_per_m
        par[_TAU_VALVE] = self.valve_tau_s
        par[_ASYM] = self.asymmetry
        par[_CAPSTAN] = self.capstan
        par[_F_REF] = self.f_ref_n
        par[_V_REF] = self.v_ref_m_per_s
        par[_DRIFT_TAU] = self.drift_tau_s
        return par

    def _pneumatic_reference(self) -> float:
        """Mean time [s] of the muscle pressure's small steps at 1.5 bar for unit conductance.

        The orifice law makes the filling time inversely proportional to the conductance,
        so one simulation at a reference conductance calibrates every ``time_constant_s``.
        """
        if self._pneu_ref is None:
            c_ref = 4.0e-11
            rate = 1000.0
            hold = 3.0
            lo, hi = 1.35e5, 1.65e5
            cmd = np.repeat([lo, hi, lo], int(hold * rate))
            par = self._base_params()
            par[_PNEU_C] = c_ref
            par[_N_SUB] = 2
            par[_DT] = 1.0 / (2 * rate)
            pres = _kernel(cmd, par, self._k_el, self._f_el)[1]
            n = int(hold * rate)
            means = []
            for seg, start, end in ((pres[n : 2 * n], lo, hi), (pres[2 * n :], hi, lo)):
                norm = (seg - end) / (start - end)
                means.append(float(np.sum(norm)) / rate)
            # Remove the valve's own share (mean times of a cascade add).
            self._pneu_ref = c_ref * (0.5 * (means[0] + means[1]) - self.valve_tau_s)
        return self._pneu_ref

    def _creep_params(self, fraction: float, tau_s: float) -> tuple[FloatArray, FloatArray]:
        """Maxwell-branch stiffnesses [N/m] and relaxation times [s] for a creep effect.

        The muscle's pull falls as it contracts and the contact stiffening does not creep,
        so the relaxing share of ``k0`` is solved (on the static law after a step to
        mid-range, friction at its pulling break-away) for a relaxed share ``fraction`` of
        the final bend. The bend creeps slower than the branches relax (the relaxed part
        still holds); the times are rescaled so that the mean time of the linearised creep
        after the step is ``tau_s``.
        """
        p_ref = self.mid_pressure_pa
        x0 = self.static_travel_m(p_ref, friction_sign=1.0)

        def share(q: float) -> float:
            x_f = self.static_travel_m(p_ref, relaxed_share=q, friction_sign=1.0)
            return (x_f - x0) / x_f - fraction

        q = float(brentq(share, 0.0, 0.9, xtol=1e-10))
        k_br = q * self.k0_n_per_m * np.asarray(_CREEP_WEIGHTS)
        # Linearised about the relaxed state: the wire travel follows the dashpots as
        # x = sum(k_j u_j) / K with K the stiffness of everything holding the wire.
        x_f = self.static_travel_m(p_ref, relaxed_share=q, friction_sign=1.0)
        eps = x_f / self.length_m
        f_m = self.muscle_force_n(p_ref, eps)
        k_m = f_m * 2.0 * self.a_mck * (1.0 - eps) / (self.a_mck * (1.0 - eps) ** 2 - self.b_mck)
        k_m /= self.length_m
        k_hold = k_m + self.section_stiffness_n_per_m(x_f)
        tau = tau_s * np.asarray(_CREEP_SPAN)
        c_vec = k_br / k_hold
        a_mat = np.diag(1.0 / tau) @ (np.outer(np.ones(3), c_vec) - np.eye(3))
        mean = float(c_vec @ -np.linalg.solve(a_mat, np.ones(3))) / float(np.sum(c_vec))
        return k_br, tau * (tau_s / mean)

    def _params(self, effects: Sequence[Effect], dt_s: float) -> FloatArray:
        par = self._base_params()
        seen: set[str] = set()
        for effect in effects:
            if effect.name in seen:
                raise ValueError(f"effect {effect.name!r} given twice")
            seen.add(effect.name)
            prm = effect.params
            if effect.name == "pneumatic_lag":
                par[_PNEU_C] = self._pneumatic_reference() / float(prm["time_constant_s"])
            elif effect.name == "transport_delay":
                par[_DELAY_STEPS] = max(round(float(prm["delay_s"]) / dt_s), 0)
            elif effect.name == "creep":
                k_br, tau = self._creep_params(
                    float(prm["fraction"]), float(prm["time_constant_s"])
                )
                par[_CREEP_K0 : _CREEP_K2 + 1] = k_br
                par[_CREEP_T0 : _CREEP_T2 + 1] = tau
            elif effect.name == "tip_dynamics":
                wn = 2.0 * math.pi * float(prm["natural_frequency_hz"])
                par[_TIP_WN] = wn
                par[_TIP_ZETA] = float(prm["damping_ratio"])
                par[_TIP_KMID] = self.section_stiffness_n_per_m(self.mid_bend_rad * self.arm_m)
                # Coulomb friction of the tip on the sheath: a 0.005 deg dead band.
                par[_TIP_COUL] = wn * wn * math.radians(0.005)
            elif effect.name == "drift":
                par[_DRIFT_RATE] = math.radians(float(prm["rate_deg_per_min"])) / 60.0
            elif effect.name == "sensor_lag":
                par[_SENSOR_TAU] = float(prm["time_constant_s"])
            elif effect.name == "backlash":
                par[_GAP] = math.radians(float(prm["gap_deg"]))
            elif effect.name == "gain_drift":
                rate_per_s = float(prm["percent_per_min"]) / 100.0 / 60.0
                par[_GAIN_RATE] = rate_per_s / self.area_sensitivity()
            elif effect.name == "slow_lag":
                par[_SLOW_FRAC] = float(prm["fraction"])
                par[_SLOW_TAU] = float(prm["time_constant_s"])
            else:  # pragma: no cover - Effect validates names
                raise ValueError(f"unsupported effect {effect.name!r}")
        return par

    def _run_params(self, rate_hz: float, effects: Sequence[Effect]) -> FloatArray:
        """The kernel's parameters for a run at ``rate_hz`` with ``effects``."""
        if not rate_hz > 0.0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        n_sub = max(1, math.ceil(_SUBSTEP_HZ / rate_hz))
        dt_s = 1.0 / (rate_hz * n_sub)
        par = self._params(effects, dt_s)
        par[_N_SUB] = n_sub
        par[_DT] = dt_s
        return par

    def _measure(self, bend: FloatArray, rng: np.random.Generator) -> FloatArray:
        """The sensor: white noise, then quantisation."""
        noisy = bend + rng.normal(0.0, self._noise_white_rad, bend.size)
        return np.asarray(np.round(noisy / self.quant_step_rad) * self.quant_step_rad)

    def simulate_clean(
        self,
        pressure_command_pa: FloatArray,
        rate_hz: float,
        effects: Sequence[Effect] = (),
    ) -> tuple[FloatArray, FloatArray]:
        """Noise-free measured bend [rad] and muscle pressure [Pa] at each command sample."""
        cmd = np.ascontiguousarray(pressure_command_pa, dtype=np.float64).ravel()
        par = self._run_params(rate_hz, effects)
        out = _kernel(cmd, par, self._k_el, self._f_el)
        return out[0].copy(), out[1].copy()

    def simulate(
        self,
        pressure_command_pa: FloatArray,
        rate_hz: float,
        effects: Sequence[Effect] = (),
        seed: int = 0,
    ) -> FloatArray:
        """The measured bend [rad]: the clean bend plus white noise, quantised."""
        bend, _ = self.simulate_clean(pressure_command_pa, rate_hz, effects)
        return self._measure(bend, np.random.default_rng(seed))

    def stepper(
        self, rate_hz: float, effects: Sequence[Effect] = (), seed: int = 0
    ) -> PlantStepper:
        """This plant from rest, one command sample at a time (see :class:`PlantStepper`)."""
        return _MaxwellSlipStepper(self, self._run_params(rate_hz, effects), seed)


class _MaxwellSlipStepper(PlantStepper):
    """Carries the kernel's state from one sample to the next."""

    def __init__(self, plant: MaxwellSlipPlant, par: FloatArray, seed: int) -> None:
        self._plant = plant
        self._par = par
        self._state = _fresh_state(par, plant._k_el.size)
        self._rng = np.random.default_rng(seed)
        self._cmd = np.zeros(1)
        self._out = np.zeros((2, 1))

    def step(self, pressure_command_pa: float) -> float:
        self._cmd[0] = pressure_command_pa
        _advance(self._cmd, self._par, self._plant._k_el, self._plant._f_el, self._state, self._out)
        return float(self._plant._measure(self._out[0], self._rng)[0])
