"""The simulated PAM catheter rig (``docs/simulated_rig.md``)."""

from catheter_models.plant.config import EFFECTS, RIG_PARAMS, EffectSpec, ParamSpec, PlantConfig
from catheter_models.plant.simulator import Plant, PlantOutput, PlantSample, simulate_signal

__all__ = [
    "EFFECTS",
    "RIG_PARAMS",
    "EffectSpec",
    "ParamSpec",
    "Plant",
    "PlantConfig",
    "PlantOutput",
    "PlantSample",
    "simulate_signal",
]
