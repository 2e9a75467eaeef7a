"""The simulated PAM catheter rig (``docs/simulated_rig.md``)."""

from catheter_models.plant.config import EFFECTS, RIG_PARAMS, EffectSpec, PlantConfig
from catheter_models.plant.interface import (
    CheckedPlant,
    PlantError,
    PlantModel,
    PlantRunError,
    ShippedPlant,
    load_plant,
    make_plant,
)
from catheter_models.plant.simulator import Plant, PlantOutput, PlantSample, simulate_signal

__all__ = [
    "EFFECTS",
    "RIG_PARAMS",
    "CheckedPlant",
    "EffectSpec",
    "Plant",
    "PlantConfig",
    "PlantError",
    "PlantModel",
    "PlantOutput",
    "PlantRunError",
    "PlantSample",
    "ShippedPlant",
    "load_plant",
    "make_plant",
    "simulate_signal",
]
