"""The thesis's models and their common contract (see :mod:`catheter_models.models.base`).

Kinds are found by name and imported only when used, so loading an IDRDPI compensator never
imports torch, and the c-LSTM runs on ONNX Runtime without it. Each kind's loader below is a
plain import statement, so the registry's dependencies are visible to mypy, to grep and to
the layering tests, rather than hidden in module-name strings.

The grey-box kind (:mod:`catheter_models.models.greybox`) is a hysteresis core
(:mod:`catheter_models.models.cores`) with effect blocks (:mod:`catheter_models.models.blocks`)
around it; the thesis's DRDPI is that chain with the DRDPI core and no blocks. The model lab
(:mod:`catheter_models.lab`) sits above all of them: it compares, diagnoses and explains, and
edits chains through this package, never the other way round.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Final

from catheter_models.model_dir import read_manifest
from catheter_models.models.base import (
    InsufficientDataError,
    Model,
    ModelError,
    NotFittedError,
    RateMismatchError,
    Recording,
    Stream,
)


def _drdpi() -> type[Model]:
    from catheter_models.models.drdpi import DRDPI

    return DRDPI


def _gpi() -> type[Model]:
    from catheter_models.models.gpi import GPI

    return GPI


def _idrdpi() -> type[Model]:
    from catheter_models.models.idrdpi import IDRDPI

    return IDRDPI


def _svr() -> type[Model]:
    from catheter_models.models.svr import SVRModel

    return SVRModel


def _lstm() -> type[Model]:
    from catheter_models.models.lstm import LSTMModel

    return LSTMModel


def _clstm() -> type[Model]:
    from catheter_models.models.lstm import CLSTMModel

    return CLSTMModel


def _greybox() -> type[Model]:
    from catheter_models.models.greybox import GreyBox

    return GreyBox


# kind -> loader of its class. Inference-only classes; training code lives beside them.
MODEL_KINDS: Final[dict[str, Callable[[], type[Model]]]] = {
    "drdpi": _drdpi,
    "gpi": _gpi,
    "idrdpi": _idrdpi,
    "svr": _svr,
    "lstm": _lstm,
    "clstm": _clstm,
    "greybox": _greybox,
}


def model_class(kind: str) -> type[Model]:
    """The class for ``kind``; ModelError lists the known kinds."""
    try:
        loader = MODEL_KINDS[kind]
    except KeyError:
        known = ", ".join(MODEL_KINDS)
        raise ModelError(f"unknown model kind {kind!r}; known kinds: {known}") from None
    return loader()


def load_model(path: Path | str) -> Model:
    """Load any model directory (kind read from its manifest, every file hash-checked)."""
    # The manifest alone names the kind; the kind's own load reads and checks every file once.
    return model_class(read_manifest(Path(path)).kind).load(path)


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
