"""The thesis's models and their common contract (see :mod:`catheter_models.models.base`).

Kinds are found by name and imported only when used, so loading an IDRDPI compensator never
imports torch, and the c-LSTM runs on ONNX Runtime without it.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Final

from catheter_models.model_dir import read_model_dir
from catheter_models.models.base import (
    InsufficientDataError,
    Model,
    ModelError,
    NotFittedError,
    RateMismatchError,
    Recording,
    Stream,
)

# kind -> (module, class). Inference-only classes; training code lives beside them.
MODEL_KINDS: Final[dict[str, tuple[str, str]]] = {
    "drdpi": ("catheter_models.models.drdpi", "DRDPI"),
    "gpi": ("catheter_models.models.gpi", "GPI"),
    "idrdpi": ("catheter_models.models.idrdpi", "IDRDPI"),
    "svr": ("catheter_models.models.svr", "SVRModel"),
    "lstm": ("catheter_models.models.lstm", "LSTMModel"),
    "clstm": ("catheter_models.models.lstm", "CLSTMModel"),
    "greybox": ("catheter_models.lab.greybox", "GreyBox"),
}


def model_class(kind: str) -> type[Model]:
    """The class for ``kind``; ModelError lists the known kinds."""
    try:
        module_name, class_name = MODEL_KINDS[kind]
    except KeyError:
        known = ", ".join(MODEL_KINDS)
        raise ModelError(f"unknown model kind {kind!r}; known kinds: {known}") from None
    cls: type[Model] = getattr(importlib.import_module(module_name), class_name)
    return cls


def load_model(path: Path | str) -> Model:
    """Load any model directory (kind read from its manifest, every file hash-checked)."""
    manifest, _ = read_model_dir(Path(path))
    return model_class(manifest.kind).load(path)


__all__ = [
    "MODEL_KINDS",
    "InsufficientDataError",
    "Model",
    "ModelError",
    "NotFittedError",
    "RateMismatchError",
    "Recording",
    "Stream",
    "load_model",
    "model_class",
]
