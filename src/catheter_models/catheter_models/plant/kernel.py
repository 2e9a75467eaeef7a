"""The plant's physics, integrated in one numba kernel used by batch and streaming alike.

State and parameters travel as flat float64 arrays with the index constants below, because
numba compiles plain arrays to tight loops and a dataclass would cost a Python call per step.
Everything is in "bend-equivalent" units: torques are divided by the small-bend stiffness, so
a torque reads as the bend [rad] it would hold against the linear spring.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

_REFERENCE_PULL_PA = 1.0e5
"""play.friction_rad is the Coulomb level at the pull of this effective muscle pressure."""

# --- parameter vector layout -------------------------------------------------------------
P_DT_S = 0
P_SUBSTEPS = 1
P_VALVE_ALPHA = 2  # 1 - exp(-dt / valve tau): exact first-order regulator step
P_VALVE_MAX_PA = 3
P_AMBIENT_PA = 4
P_LAG_ON = 5
P_LAG_G = 6  # tube conductance: dP/dt = G (Pv^2 - Pm^2), [1/(Pa s)]
P_DELAY_SUBSTEPS = 7
P_OPEN_PA = 8
P_KNEE_PA = 9
P_DEADBAND_ON = 10
P_ASYM_RATIO = 11
P_ASYM_SLIDE_PA = 12
P_GAIN_RAD_PER_PA = 13
P_SAT_ON = 14
P_SAT_LIMIT_RAD = 15
P_CREEP_K = 16  # stiffness of each of the two Maxwell branches, relative to the main spring
P_CREEP_TAU1_S = 17
P_CREEP_TAU2_S = 18
P_FRICTION_RAD = 19
P_PRESLIDE_RAD = 20
P_VISCOUS_S = 21
P_MECH_TAU_S = 22
P_TIP_ON = 23
P_TIP_INERTIA_S2 = 24  # J / K = 1 / omega_n^2
P_TIP_DAMPING_S = 25  # c / K = 2 zeta / omega_n
N_PARAMS = 26

# --- state vector layout ------------------------------------------------------------------
S_VALVE_PA = 0  # valve outlet gauge pressure = what the transmitter reads
S_MUSCLE_PA = 1  # gauge pressure inside the muscle
S_PEFF_PREV_PA = 2
S_ASYM_Z = 3  # braid-friction state in [-1, 1]
S_ANGLE_RAD = 4
S_RATE_RAD_S = 5
S_FRICTION_RAD = 6  # Dahl friction state
S_CREEP1_RAD = 7
S_CREEP2_RAD = 8
S_RING_POS = 9
N_STATE = 10

# --- per-sample output columns ------------------------------------------------------------
O_VALVE_PA = 0
O_MUSCLE_PA = 1
O_ANGLE_RAD = 2
N_OUT = 3


@njit(cache=True, inline="always")
def _effective_pressure_pa(muscle_pa: float, open_pa: float, knee_pa: float, on: float) -> float:
    """Pressure that turns into pull: zero below opening, a quadratic knee, then linear."""
    if on == 0.0:
        return max(muscle_pa, 0.0)
    x = muscle_pa - open_pa
    if x <= 0.0:
        return 0.0
    if x < knee_pa:
        return x * x / (2.0 * knee_pa)
    return x - 0.5 * knee_pa


@njit(cache=True, inline="always")
def _elastic_rad(angle_rad: float, on: float, limit_rad: float) -> float:
    """Elastic torque of the bend: linear, or artanh-stiffening towards the limit."""
    if on == 0.0:
        return angle_rad
    ratio = angle_rad / limit_rad
    # Past 0.999 of the limit artanh explodes; the kernel clamps the angle there anyway.
    ratio = min(max(ratio, -0.999), 0.999)
    return limit_rad * math.atanh(ratio)


@njit(cache=True)
def run_kernel(
    params: npt.NDArray[np.float64],
    state: npt.NDArray[np.float64],
    ring: npt.NDArray[np.float64],
    command_pa: npt.NDArray[np.float64],
    out: npt.NDArray[np.float64],
) -> None:
    """Advance the plant by ``len(command_pa)`` samples, each held for ``P_SUBSTEPS`` substeps.

    Args:
        params: parameter vector (``P_*`` layout).
        state: state vector (``S_*`` layout), updated in place.
        ring: transport-delay ring buffer of valve pressures [Pa], updated in place.
        command_pa: valve set-point per output sample, gauge [Pa]; must be finite.
        out: ``(n, N_OUT)`` output, filled at the end of each sample.
    """
    dt = params[P_DT_S]
    n_sub = int(params[P_SUBSTEPS])
    alpha = params[P_VALVE_ALPHA]
    pmax = params[P_VALVE_MAX_PA]
    amb = params[P_AMBIENT_PA]
    lag_on = params[P_LAG_ON]
    lag_g = params[P_LAG_G]
    n_delay = int(params[P_DELAY_SUBSTEPS])
    n_ring = ring.shape[0]
    open_pa = params[P_OPEN_PA]
    knee_pa = params[P_KNEE_PA]
    db_on = params[P_DEADBAND_ON]
    asym = params[P_ASYM_RATIO]
    slide_pa = params[P_ASYM_SLIDE_PA]
    gain = params[P_GAIN_RAD_PER_PA]
    sat_on = params[P_SAT_ON]
    limit = params[P_SAT_LIMIT_RAD]
    k_creep = params[P_CREEP_K]
    tau1 = params[P_CREEP_TAU1_S]
    tau2 = params[P_CREEP_TAU2_S]
    fc = params[P_FRICTION_RAD]
    presl = params[P_PRESLIDE_RAD]
    visc = params[P_VISCOUS_S]
    mech_tau = params[P_MECH_TAU_S]
    tip_on = params[P_TIP_ON]
    inertia = params[P_TIP_INERTIA_S2]
    tip_damp = params[P_TIP_DAMPING_S]
    sigma = fc / presl if fc > 0.0 else 0.0
    angle_max = 0.999 * limit if sat_on != 0.0 else 10.0

    p_valve = state[S_VALVE_PA]
    p_muscle = state[S_MUSCLE_PA]
    peff_prev = state[S_PEFF_PREV_PA]
    z = state[S_ASYM_Z]
    angle = state[S_ANGLE_RAD]
    rate = state[S_RATE_RAD_S]
    fric = state[S_FRICTION_RAD]
    c1 = state[S_CREEP1_RAD]
    c2 = state[S_CREEP2_RAD]
    pos = int(state[S_RING_POS])

    for i in range(command_pa.shape[0]):
        setpoint = min(max(command_pa[i], 0.0), pmax)
        for _ in range(n_sub):
            # Valve: proportional regulator, exact first-order step.
            p_valve += alpha * (setpoint - p_valve)

            # Line: dead time first (a ring buffer of valve pressures), then the flow lag.
            ring[pos] = p_valve
            p_in = ring[(pos - n_delay) % n_ring]
            pos = (pos + 1) % n_ring
            if lag_on != 0.0:
                pv_abs = p_in + amb
                pm_abs = p_muscle + amb
                p_muscle += dt * lag_g * (pv_abs * pv_abs - pm_abs * pm_abs)
            else:
                p_muscle = p_in

            # Muscle: opening pressure, then braid friction (Dahl state on pressure).
            peff = _effective_pressure_pa(p_muscle, open_pa, knee_pa, db_on)
            if asym != 0.0:
                dp = peff - peff_prev
                sgn = 1.0 if dp > 0.0 else (-1.0 if dp < 0.0 else 0.0)
                z += dp / slide_pa * (1.0 - z * sgn)
                z = min(max(z, -1.0), 1.0)
            peff_prev = peff
            drive = gain * peff * (1.0 - asym * z)

            # Bend: spring (+ creep branches) against the pull, wire friction (Dahl) and
            # viscous friction; massless and overdamped unless tip dynamics are on.
            elastic = _elastic_rad(angle, sat_on, limit)
            elastic += k_creep * ((angle - c1) + (angle - c2))
            net = drive - elastic - fric
            if tip_on != 0.0:
                accel = (net - (visc + tip_damp) * rate) / inertia
                rate += dt * accel
            else:
                rate = net / (mech_tau + visc)
            angle += dt * rate
            if angle > angle_max:
                angle = angle_max
                rate = min(rate, 0.0)
            if fc > 0.0:
                # Capstan: the wire presses on the tube in proportion to its tension, so the
                # Coulomb level follows the pull (in bend units, relative to the pull of one
                # bar). With the muscle vented there is no friction and the tip comes home.
                level = fc * max(drive, 0.0) / (gain * _REFERENCE_PULL_PA)
                sgn_v = 1.0 if rate > 0.0 else (-1.0 if rate < 0.0 else 0.0)
                if level > 0.0:
                    fric += dt * sigma * (1.0 - fric / level * sgn_v) * rate
                fric = min(max(fric, -level), level)
            if k_creep != 0.0:
                c1 += dt / tau1 * (angle - c1)
                c2 += dt / tau2 * (angle - c2)

        out[i, O_VALVE_PA] = p_valve
        out[i, O_MUSCLE_PA] = p_muscle
        out[i, O_ANGLE_RAD] = angle

    state[S_VALVE_PA] = p_valve
    state[S_MUSCLE_PA] = p_muscle
    state[S_PEFF_PREV_PA] = peff_prev
    state[S_ASYM_Z] = z
    state[S_ANGLE_RAD] = angle
    state[S_RATE_RAD_S] = rate
    state[S_FRICTION_RAD] = fric
    state[S_CREEP1_RAD] = c1
    state[S_CREEP2_RAD] = c2
    state[S_RING_POS] = float(pos)
