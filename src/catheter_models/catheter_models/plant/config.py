"""Parameters of the simulated rig: the always-present hardware and the switchable effects.

Every number has a unit in its name, a default that reproduces what the thesis saw (ch. 3-4:
deadband of about 0-1 bar from rest, about 30 deg of bend at 3 bar, loops that widen from
0.2 to 0.8 Hz, laser noise at 250 Hz) and a range. A value outside its range is refused with
the range named, here and in the ROS parameter descriptors built from the same table.

The effect names are the vocabulary of the lab's catalogue (``docs/simulated_rig.md``,
``docs/lab.md``). The plant models the *physics*
of each effect (orifice/tube flow, Dahl friction, Zener creep, ...); the lab's identifiable
blocks are deliberately different approximations, so a lab test never checks code against
itself.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Final

from catheter_models.contract import MAX_PRESSURE_PA, SENSOR_RATE_HZ
from catheter_models.errors import ParameterError
from catheter_models.limits import BoundedParam
from catheter_models.units import AMBIENT_PRESSURE_PA, deg_to_rad


@dataclass(frozen=True)
class EffectSpec:
    """A physical effect of the catalogue (``docs/simulated_rig.md``) as the plant implements it."""

    name: str
    physics: str
    params: tuple[BoundedParam, ...]
    enabled_in_thesis_rig: bool

    def param(self, name: str) -> BoundedParam:
        """The spec of parameter ``name``; ParameterError lists the valid names."""
        for spec in self.params:
            if spec.name == name:
                return spec
        valid = ", ".join(p.name for p in self.params)
        raise ParameterError(f"effect {self.name!r} has no parameter {name!r}; it has: {valid}")


_DEG = deg_to_rad(1.0)

EFFECTS: Final[Mapping[str, EffectSpec]] = {
    spec.name: spec
    for spec in (
        EffectSpec(
            "play",
            "Coulomb friction between steer wire and Nitinol tube, as a Dahl friction state "
            "(smooth pre-sliding, then sliding at the Coulomb level); the level scales with "
            "the wire's tension (capstan), so a vented muscle lets the tip come home",
            (
                BoundedParam(
                    "friction_rad",
                    1.5 * _DEG,
                    0.0,
                    10 * _DEG,
                    "Coulomb friction as equivalent bend at the pull of 1 bar effective pressure "
                    "[rad]",
                ),
                BoundedParam(
                    "presliding_rad",
                    0.6 * _DEG,
                    0.05 * _DEG,
                    5 * _DEG,
                    "bend over which friction builds up after a reversal [rad]",
                ),
            ),
            True,
        ),
        EffectSpec(
            "rate_dependence",
            "viscous friction of the wire in the tube: torque proportional to bend rate",
            (
                BoundedParam(
                    "viscous_s",
                    0.005,
                    0.0,
                    0.2,
                    "viscous torque as equivalent bend per bend rate [rad/(rad/s)] = [s]",
                ),
            ),
            True,
        ),
        EffectSpec(
            "deadband",
            "balloon and braid preload: the muscle makes no force until the balloon meets the "
            "braid at the opening pressure; contact grows over a knee",
            (
                BoundedParam(
                    "opening_pressure_pa",
                    0.85e5,
                    0.0,
                    2.0e5,
                    "gauge pressure at which the muscle starts to pull [Pa]",
                ),
                BoundedParam(
                    "knee_pa",
                    0.1e5,
                    1.0e2,
                    1.0e5,
                    "pressure span over which balloon-braid contact becomes full [Pa]",
                ),
            ),
            True,
        ),
        EffectSpec(
            "asymmetry",
            "braid friction whose normal force grows with pressure: the muscle's force gain is "
            "lower while inflating than while deflating",
            (
                BoundedParam(
                    "ratio",
                    0.08,
                    0.0,
                    0.5,
                    "relative gain difference; loading gain 1-ratio, unloading 1+ratio [1]",
                ),
            ),
            True,
        ),
        EffectSpec(
            "saturation",
            "the bend stiffens towards its mechanical limit (elastic torque ~ artanh)",
            (
                BoundedParam(
                    "limit_rad",
                    55 * _DEG,
                    20 * _DEG,
                    67 * _DEG,
                    "mechanical bend limit the stiffness diverges at [rad]",
                ),
            ),
            True,
        ),
        EffectSpec(
            "pneumatic_lag",
            "laminar compressible flow through the line into the muscle volume: "
            "dP/dt = G (P_valve^2 - P_muscle^2), absolute pressures, so the lag is shorter at "
            "high pressure and filling differs from venting",
            (
                BoundedParam(
                    "time_constant_s",
                    0.06,
                    0.005,
                    0.5,
                    "small-signal time constant at 1.5 bar gauge [s]",
                ),
            ),
            False,
        ),
        EffectSpec(
            "transport_delay",
            "pressure-wave travel and valve dead time between the transmitter and the muscle",
            (BoundedParam("delay_s", 0.02, 0.0, 0.2, "dead time [s]"),),
            False,
        ),
        EffectSpec(
            "creep",
            "viscoelastic relaxation of polymer and Nitinol: two Maxwell branches (Zener solid) "
            "with time constants tau/2 and 2 tau",
            (
                BoundedParam(
                    "fraction",
                    0.1,
                    0.0,
                    0.3,
                    "share of the final bend that arrives by creep after a step [1]",
                ),
                BoundedParam(
                    "time_constant_s",
                    2.0,
                    0.2,
                    20.0,
                    "geometric mean of the two relaxation times [s]",
                ),
            ),
            False,
        ),
        EffectSpec(
            "tip_dynamics",
            "tip inertia against bending stiffness: a lightly damped second-order bend",
            (
                BoundedParam(
                    "natural_frequency_hz", 8.0, 2.0, 30.0, "undamped natural frequency [Hz]"
                ),
                BoundedParam("damping_ratio", 0.15, 0.02, 1.0, "damping ratio [1]"),
            ),
            False,
        ),
        EffectSpec(
            "drift",
            "thermal drift of the laser mount: the distance offset approaches its new value "
            "exponentially (10 min), seen through the nonlinear eq. 3.3",
            (
                BoundedParam(
                    "rate_rad_per_s",
                    1.0 * _DEG / 60.0,
                    -10 * _DEG / 60,
                    10 * _DEG / 60,
                    "initial drift rate of the measured straight-tip angle [rad/s]",
                ),
            ),
            False,
        ),
    )
}
"""The effect catalogue (docs/simulated_rig.md), as the plant's physics implements it."""

RIG_PARAMS: Final[tuple[BoundedParam, ...]] = (
    BoundedParam(
        "valve_time_constant_s",
        0.005,
        0.001,
        0.1,
        "proportional regulator's first-order response [s]",
    ),
    BoundedParam(
        "valve_max_pressure_pa",
        MAX_PRESSURE_PA,
        0.5e5,
        10.0e5,
        "highest gauge pressure the valve can deliver; commands are clipped to it [Pa]",
    ),
    BoundedParam(
        "bend_gain_rad_per_pa",
        18 * _DEG / 1e5,
        1 * _DEG / 1e5,
        60 * _DEG / 1e5,
        "bend per effective muscle pressure, small-bend stiffness [rad/Pa]",
    ),
    BoundedParam(
        "mech_time_constant_s",
        0.003,
        0.0005,
        0.05,
        "structural damping over stiffness of the massless bend [s]",
    ),
    BoundedParam(
        "straight_distance_m",
        0.065,
        0.035,
        0.0699,
        "laser distance to the tip marker with the tip straight [m]",
    ),
    BoundedParam("laser_noise_m", 0.02e-3, 0.0, 1e-3, "laser distance noise, std [m]"),
    BoundedParam("pressure_noise_pa", 300.0, 0.0, 1e4, "pressure transmitter noise, std [Pa]"),
    BoundedParam("ambient_pressure_pa", AMBIENT_PRESSURE_PA, 5.0e4, 1.2e5, "ambient pressure [Pa]"),
    BoundedParam("sample_rate_hz", SENSOR_RATE_HZ, 10.0, 5000.0, "sensor sample rate [Hz]"),
)
"""Parameters of the rig that are always present (not effects)."""

_RIG_SPECS: Final = {p.name: p for p in RIG_PARAMS}


@dataclass(frozen=True)
class EffectSetting:
    """Whether an effect is on, and its parameter values (defaults filled in)."""

    enabled: bool
    params: Mapping[str, float]


def _default_settings(*, thesis_rig: bool) -> dict[str, EffectSetting]:
    return {
        name: EffectSetting(
            enabled=spec.enabled_in_thesis_rig if thesis_rig else False,
            params={p.name: p.default for p in spec.params},
        )
        for name, spec in EFFECTS.items()
    }


@dataclass(frozen=True)
class PlantConfig:
    """A validated, immutable configuration of the simulated rig.

    Build one with :meth:`thesis_rig` (the default) and change it with :meth:`with_effect`
    and :meth:`with_rig`, which validate every value against its range.
    """

    rig: Mapping[str, float] = field(
        default_factory=lambda: {p.name: p.default for p in RIG_PARAMS}
    )
    effects: Mapping[str, EffectSetting] = field(
        default_factory=lambda: _default_settings(thesis_rig=True)
    )
    seed: int = 0

    def __post_init__(self) -> None:
        # A partial mapping (say, only "play") means "defaults for the rest": fill them in so
        # the plant never meets a missing key. The dataclass is frozen, hence __setattr__.
        rig = {p.name: p.default for p in RIG_PARAMS} | dict(self.rig)
        effects = _default_settings(thesis_rig=False) | dict(self.effects)
        for name in list(effects):
            if name in EFFECTS:
                defaults = {p.name: p.default for p in EFFECTS[name].params}
                setting = effects[name]
                effects[name] = EffectSetting(setting.enabled, defaults | dict(setting.params))
        object.__setattr__(self, "rig", rig)
        object.__setattr__(self, "effects", effects)
        for name, value in self.rig.items():
            if name not in _RIG_SPECS:
                raise ParameterError(
                    f"unknown rig parameter {name!r}; known: {', '.join(_RIG_SPECS)}"
                )
            _RIG_SPECS[name].check(value, "rig")
        for name, setting in self.effects.items():
            if name not in EFFECTS:
                raise ParameterError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
            for pname, value in setting.params.items():
                EFFECTS[name].param(pname).check(value, name)

    @classmethod
    def thesis_rig(cls, seed: int = 0) -> PlantConfig:
        """The rig of the thesis: friction, rate dependence, deadband, asymmetry, saturation."""
        return cls(seed=seed)

    @classmethod
    def ideal(cls, seed: int = 0) -> PlantConfig:
        """Every effect off: a linear, memoryless bend behind the valve (for tests)."""
        return cls(effects=_default_settings(thesis_rig=False), seed=seed)

    def with_effect(self, name: str, enabled: bool = True, **params: float) -> PlantConfig:
        """A copy with effect ``name`` switched and any of its parameters set.

        Example: ``PlantConfig.thesis_rig().with_effect("pneumatic_lag", time_constant_s=0.1)``.
        """
        if name not in EFFECTS:
            raise ParameterError(f"unknown effect {name!r}; known: {', '.join(EFFECTS)}")
        old = self.effects[name]
        new_params = dict(old.params)
        for pname, value in params.items():
            new_params[pname] = EFFECTS[name].param(pname).check(value, name)
        effects = dict(self.effects)
        effects[name] = EffectSetting(enabled=enabled, params=new_params)
        return replace(self, effects=effects)

    def with_rig(self, **params: float) -> PlantConfig:
        """A copy with rig parameters set (each checked against its range)."""
        rig = dict(self.rig)
        for name, value in params.items():
            if name not in _RIG_SPECS:
                raise ParameterError(
                    f"unknown rig parameter {name!r}; known: {', '.join(_RIG_SPECS)}"
                )
            rig[name] = _RIG_SPECS[name].check(value, "rig")
        return replace(self, rig=rig)

    def enabled(self, name: str) -> bool:
        """Whether effect ``name`` is on."""
        return self.effects[name].enabled

    def effect_param(self, effect: str, name: str) -> float:
        """Value of an effect's parameter (whether or not the effect is on)."""
        return float(self.effects[effect].params[name])

    def describe(self) -> dict[str, str]:
        """Flat, string-valued description for bag ``custom_data`` and reports."""
        out = {f"rig.{k}": f"{v:.6g}" for k, v in self.rig.items()}
        for name, setting in self.effects.items():
            out[f"effect.{name}"] = "on" if setting.enabled else "off"
            if setting.enabled:
                out.update({f"effect.{name}.{k}": f"{v:.6g}" for k, v in setting.params.items()})
        out["seed"] = str(self.seed)
        return out

    @classmethod
    def from_flat(cls, values: Mapping[str, float | bool | str], seed: int = 0) -> PlantConfig:
        """Build from flat names as ROS parameters carry them.

        Keys: ``<rig_param>``, ``<effect>.enabled`` and ``<effect>.<param>``. Anything else is
        refused by name, so a typo never silently leaves the default in place.
        """
        config = cls.thesis_rig(seed=seed)
        rig: dict[str, float] = {}
        for key, value in values.items():
            if "." not in key:
                rig[key] = float(value)
                continue
            effect, pname = key.split(".", 1)
            if pname == "enabled":
                config = config.with_effect(effect, enabled=bool(value))
            else:
                config = config.with_effect(
                    effect,
                    enabled=config.enabled(effect) if effect in EFFECTS else True,
                    **{pname: float(value)},
                )
        return config.with_rig(**rig) if rig else config
