"""Compensators the node can host, chosen by name, and the models shipped with the package."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from catheter_control.control_core import StaticInverseCompensator, StreamingCompensator
from catheter_models.errors import ParameterError
from catheter_models.static_map import StaticMap

COMPENSATORS = ("none",)
"""``none``: the static inverse of the quasi-static curve (no hysteresis compensation).
The c-LSTM and inverse DRDPI join with the models issue."""


def shipped_model_dir(name: str = "static_map") -> Path:
    """Directory of a model shipped inside this package (fitted on the simulated rig)."""
    return Path(str(resources.files("catheter_control") / "data" / name))


def load_compensator(kind: str, model_dir: str) -> StreamingCompensator:
    """Build the named compensator from a model directory ('' = the shipped default)."""
    if kind == "none":
        path = Path(model_dir) if model_dir else shipped_model_dir("static_map")
        return StaticInverseCompensator(StaticMap.load(path))
    raise ParameterError(f"unknown compensator {kind!r}; available: {', '.join(COMPENSATORS)}")
