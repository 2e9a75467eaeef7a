"""The simulated rig: batch (a whole signal, as fast as possible) and streaming (one sample).

The streaming path serves the simulated hardware node. Both call the same numba kernel with
the same state, so a streamed run and a batch run from the same seed give the same samples,
bit for bit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.geometry import LaserGeometry
from catheter_models.plant import kernel as k
from catheter_models.plant.config import PlantConfig

FloatArray = npt.NDArray[np.float64]

_LAG_REFERENCE_GAUGE_PA = 1.5e5
"""pneumatic_lag.time_constant_s is the small-signal time constant at this pressure."""
_ASYM_SLIDE_PA = 0.1e5
"""Pressure change over which the braid friction reverses fully after a reversal."""
_DRIFT_TIME_CONSTANT_S = 600.0
_MIN_SUBSTEP_HZ = 2000.0
"""Floor on the integration rate, so dead time and friction reversals resolve finely."""
_MAX_DELAY_S = 0.2
_LASER_VOLTAGE_RANGE_V = (0.0, 10.0)
"""Analog output range of the Baumer OADM: distances beyond it clip, as on the rig."""


@dataclass(frozen=True)
class PlantOutput:
    """What the rig's sensors report, plus the hidden truth for tests and reports.

    Attributes:
        t_s: sample times from the start of the run [s].
        pressure_command_pa: valve set-point as commanded (finite; the valve clips it to
            ``valve_max_pressure_pa``), gauge [Pa].
        pressure_measured_pa: transmitter reading at the valve outlet, gauge [Pa].
        distance_m: laser distance to the tip marker [m].
        angle_rad: bend from eqs. 3.1-3.3 on the laser reading [rad].
        true_angle_rad: the bend without sensor noise or drift [rad].
        muscle_pressure_pa: pressure inside the muscle (not measurable on the rig), gauge [Pa].
    """

    t_s: FloatArray
    pressure_command_pa: FloatArray
    pressure_measured_pa: FloatArray
    distance_m: FloatArray
    angle_rad: FloatArray
    true_angle_rad: FloatArray
    muscle_pressure_pa: FloatArray


@dataclass(frozen=True)
class PlantSample:
    """One streamed sample (scalars, same meaning and units as :class:`PlantOutput`)."""

    t_s: float
    pressure_command_pa: float
    pressure_measured_pa: float
    distance_m: float
    angle_rad: float
    true_angle_rad: float
    muscle_pressure_pa: float


def _substep_s(config: PlantConfig) -> float:
    """Largest stable explicit step for the enabled physics, capped at 1/2 kHz."""
    rig = config.rig
    limits = [1.0 / _MIN_SUBSTEP_HZ]
    stiffness = 1.0
    if config.enabled("play") and config.effect_param("play", "friction_rad") > 0.0:
        stiffness += config.effect_param("play", "friction_rad") / config.effect_param(
            "play", "presliding_rad"
        )
    if config.enabled("saturation"):
        stiffness += 1.0 / (1.0 - 0.9**2)  # tangent stiffness at 90 % of the limit
    if config.enabled("creep"):
        stiffness += 2.0 * _creep_branch_stiffness(config.effect_param("creep", "fraction"))
    viscous_s = (
        config.effect_param("rate_dependence", "viscous_s")
        if config.enabled("rate_dependence")
        else 0.0
    )
    if config.enabled("tip_dynamics"):
        omega = 2 * math.pi * config.effect_param("tip_dynamics", "natural_frequency_hz")
        limits.append(0.1 / (omega * math.sqrt(stiffness)))
    else:
        limits.append(0.5 * (rig["mech_time_constant_s"] + viscous_s) / stiffness)
    if config.enabled("pneumatic_lag"):
        tau_ref = config.effect_param("pneumatic_lag", "time_constant_s")
        amb = rig["ambient_pressure_pa"]
        tau_min = tau_ref * (amb + _LAG_REFERENCE_GAUGE_PA) / (amb + rig["valve_max_pressure_pa"])
        limits.append(0.2 * tau_min)
    return min(limits)


def _creep_branch_stiffness(fraction: float) -> float:
    # Two equal branches of stiffness k: short-term stiffness 1 + 2k, long-term 1, so the
    # share of the final bend that arrives by creep is 2k / (1 + 2k).
    return fraction / (2.0 * (1.0 - fraction))


class Plant:
    """The simulated PAM catheter rig.

    ``simulate`` runs a whole command signal at once; ``step`` advances one sample. Both share
    one state, so they can be mixed (e.g. a batch warm-up, then streaming).

    Args:
        config: validated plant configuration; :meth:`PlantConfig.thesis_rig` by default.
        geometry: laser geometry of eqs. 3.1-3.3 (thesis constants by default).
    """

    def __init__(self, config: PlantConfig | None = None, geometry: LaserGeometry | None = None):
        self.config = config if config is not None else PlantConfig.thesis_rig()
        self.geometry = geometry if geometry is not None else LaserGeometry()
        rig = self.config.rig
        self.sample_period_s = 1.0 / rig["sample_rate_hz"]
        substeps = max(1, math.ceil(self.sample_period_s / _substep_s(self.config)))
        self.substeps_per_sample = substeps
        self._params = self._build_params(substeps)
        n_ring = math.ceil(_MAX_DELAY_S / self._params[k.P_DT_S]) + 2
        self._ring = np.zeros(n_ring)
        self._state = np.zeros(k.N_STATE)
        self._rng = np.random.default_rng(self.config.seed)
        self._n_samples = 0
        self._one_cmd = np.zeros(1)
        self._one_out = np.zeros((1, k.N_OUT))
        self.reset()

    # -- construction ------------------------------------------------------------------
    def _build_params(self, substeps: int) -> FloatArray:
        c = self.config
        rig = c.rig
        dt = self.sample_period_s / substeps
        p = np.zeros(k.N_PARAMS)
        p[k.P_DT_S] = dt
        p[k.P_SUBSTEPS] = substeps
        p[k.P_VALVE_ALPHA] = 1.0 - math.exp(-dt / rig["valve_time_constant_s"])
        p[k.P_VALVE_MAX_PA] = rig["valve_max_pressure_pa"]
        p[k.P_AMBIENT_PA] = rig["ambient_pressure_pa"]
        if c.enabled("pneumatic_lag"):
            tau = c.effect_param("pneumatic_lag", "time_constant_s")
            p[k.P_LAG_ON] = 1.0
            # Small-signal: d(dP)/dt = -2 G P dP, so tau(P) = 1 / (2 G P) at absolute P.
            p[k.P_LAG_G] = 1.0 / (
                2.0 * tau * (rig["ambient_pressure_pa"] + _LAG_REFERENCE_GAUGE_PA)
            )
        if c.enabled("transport_delay"):
            p[k.P_DELAY_SUBSTEPS] = round(c.effect_param("transport_delay", "delay_s") / dt)
        if c.enabled("deadband"):
            p[k.P_DEADBAND_ON] = 1.0
            p[k.P_OPEN_PA] = c.effect_param("deadband", "opening_pressure_pa")
            p[k.P_KNEE_PA] = c.effect_param("deadband", "knee_pa")
        if c.enabled("asymmetry"):
            p[k.P_ASYM_RATIO] = c.effect_param("asymmetry", "ratio")
        p[k.P_ASYM_SLIDE_PA] = _ASYM_SLIDE_PA
        p[k.P_GAIN_RAD_PER_PA] = rig["bend_gain_rad_per_pa"]
        if c.enabled("saturation"):
            p[k.P_SAT_ON] = 1.0
            p[k.P_SAT_LIMIT_RAD] = c.effect_param("saturation", "limit_rad")
        else:
            p[k.P_SAT_LIMIT_RAD] = 1.0
        tau_creep = c.effect_param("creep", "time_constant_s")
        p[k.P_CREEP_TAU1_S] = tau_creep / 2.0
        p[k.P_CREEP_TAU2_S] = tau_creep * 2.0
        if c.enabled("creep"):
            p[k.P_CREEP_K] = _creep_branch_stiffness(c.effect_param("creep", "fraction"))
        if c.enabled("play"):
            p[k.P_FRICTION_RAD] = c.effect_param("play", "friction_rad")
        p[k.P_PRESLIDE_RAD] = c.effect_param("play", "presliding_rad")
        if c.enabled("rate_dependence"):
            p[k.P_VISCOUS_S] = c.effect_param("rate_dependence", "viscous_s")
        p[k.P_MECH_TAU_S] = rig["mech_time_constant_s"]
        if c.enabled("tip_dynamics"):
            omega = 2.0 * math.pi * c.effect_param("tip_dynamics", "natural_frequency_hz")
            p[k.P_TIP_ON] = 1.0
            p[k.P_TIP_INERTIA_S2] = 1.0 / omega**2
            p[k.P_TIP_DAMPING_S] = 2.0 * c.effect_param("tip_dynamics", "damping_ratio") / omega
        return p

    # -- state -------------------------------------------------------------------------
    def warm_up(self) -> None:
        """Compile the kernel now (a no-op run on copies), so the first real-time step is fast.

        numba compiles on first call; in a real-time node that first call would stall the
        loop for about a second. The cached machine code makes later processes quick.
        """
        k.run_kernel(
            self._params, self._state.copy(), self._ring.copy(), np.zeros(0), np.zeros((0, k.N_OUT))
        )

    def reset(self) -> None:
        """Back to rest: vented muscle, straight tip, time zero, noise re-seeded."""
        self._state[:] = 0.0
        self._ring[:] = 0.0
        self._rng = np.random.default_rng(self.config.seed)
        self._n_samples = 0

    @property
    def t_s(self) -> float:
        """Time of the last sample produced [s] (0 at rest, before any)."""
        # Time is an integer sample count times the period, in both paths: accumulating
        # floats would make streamed and batch stamps differ in the last bits.
        return self._n_samples * self.sample_period_s

    # -- sensors -----------------------------------------------------------------------
    def _sense(
        self, t_s: FloatArray, valve_pa: FloatArray, angle_rad: FloatArray, noise: FloatArray
    ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Transmitter and laser readings for true valve pressure and bend (vectorised)."""
        rig = self.config.rig
        geom = self.geometry
        pressure_pa = valve_pa + rig["pressure_noise_pa"] * noise[:, 0]
        # Eq. 3.3 folds back past L/H (~68 deg): a ringing, unsaturated tip can get there, but
        # the marker has then left the laser's range anyway (it clips below), so cap it.
        reachable_rad = np.minimum(np.abs(angle_rad), 0.999 * geom.max_angle_rad)
        displacement_m = np.sign(angle_rad) * geom.angle_to_displacement_m(reachable_rad)
        if self.config.enabled("drift"):
            rate = self.config.effect_param("drift", "rate_rad_per_s")
            # Near a straight tip, d(theta)/d(d') = 2 L / H^2 (eq. 3.3), so this is the
            # displacement drift that shows as `rate` in the measured angle at first.
            speed_m_s = rate * geom.height_m**2 / (2.0 * geom.length_m)
            tau = _DRIFT_TIME_CONSTANT_S
            displacement_m = displacement_m + speed_m_s * tau * (1.0 - np.exp(-t_s / tau))
        straight_m = rig["straight_distance_m"]
        distance_m = straight_m - displacement_m + rig["laser_noise_m"] * noise[:, 1]
        voltage_v = np.clip(geom.distance_to_voltage_v(distance_m), *_LASER_VOLTAGE_RANGE_V)
        distance_m = geom.voltage_to_distance_m(voltage_v)
        measured_rad = geom.displacement_to_angle_rad(straight_m - distance_m)
        return pressure_pa, distance_m, measured_rad

    # -- running -----------------------------------------------------------------------
    @staticmethod
    def _check_commands(command_pa: FloatArray) -> None:
        bad = np.flatnonzero(~np.isfinite(command_pa))
        if bad.size:
            raise ParameterError(
                f"pressure command is not finite at sample {int(bad[0])} "
                f"(value {command_pa[bad[0]]!r}); the plant refuses NaN/inf commands"
            )

    def simulate(self, command_pa: npt.ArrayLike) -> PlantOutput:
        """Run a whole command signal (one value per sample, gauge [Pa]) from the current state.

        Raises:
            ParameterError: a command is NaN or infinite (nothing is simulated).
        """
        cmd = np.ascontiguousarray(command_pa, dtype=np.float64).reshape(-1)
        self._check_commands(cmd)
        n = cmd.shape[0]
        out = np.empty((n, k.N_OUT))
        k.run_kernel(self._params, self._state, self._ring, cmd, out)
        t_s = self.sample_period_s * np.arange(
            self._n_samples + 1, self._n_samples + n + 1, dtype=np.float64
        )
        noise = self._rng.standard_normal((n, 2))
        pressure_pa, distance_m, angle_rad = self._sense(
            t_s, out[:, k.O_VALVE_PA], out[:, k.O_ANGLE_RAD], noise
        )
        self._n_samples += n
        return PlantOutput(
            t_s=t_s,
            pressure_command_pa=cmd,
            pressure_measured_pa=pressure_pa,
            distance_m=distance_m,
            angle_rad=angle_rad,
            true_angle_rad=out[:, k.O_ANGLE_RAD].copy(),
            muscle_pressure_pa=out[:, k.O_MUSCLE_PA].copy(),
        )

    def step(self, command_pa: float) -> PlantSample:
        """Advance one sample period with ``command_pa`` (gauge [Pa]) held over it.

        Raises:
            ParameterError: the command is NaN or infinite (the state does not advance).
        """
        self._one_cmd[0] = command_pa
        self._check_commands(self._one_cmd)
        k.run_kernel(self._params, self._state, self._ring, self._one_cmd, self._one_out)
        self._n_samples += 1
        t = self.sample_period_s * np.arange(self._n_samples, self._n_samples + 1, dtype=np.float64)
        noise = self._rng.standard_normal((1, 2))
        pressure_pa, distance_m, angle_rad = self._sense(
            t, self._one_out[:, k.O_VALVE_PA], self._one_out[:, k.O_ANGLE_RAD], noise
        )
        return PlantSample(
            t_s=float(t[0]),
            pressure_command_pa=float(command_pa),
            pressure_measured_pa=float(pressure_pa[0]),
            distance_m=float(distance_m[0]),
            angle_rad=float(angle_rad[0]),
            true_angle_rad=float(self._one_out[0, k.O_ANGLE_RAD]),
            muscle_pressure_pa=float(self._one_out[0, k.O_MUSCLE_PA]),
        )


def simulate_signal(command_pa: npt.ArrayLike, config: PlantConfig | None = None) -> PlantOutput:
    """Convenience: a fresh plant at rest, run over a whole command signal."""
    return Plant(config).simulate(command_pa)
