"""Foreign plants: simulated catheters written apart from ``catheter_models.plant``.

Test support only: the lab must never import this package (``tests/catheter_models/lab/
test_foreign_plants.py`` checks). Each plant module has its own hysteresis law and its own
physics for every effect it can hide; :mod:`.base` holds the contract they share and
:mod:`.cases` the training / held-out recordings a case is scored on.
"""

from __future__ import annotations

import os
from pathlib import Path

from .base import CATALOGUE, OUTSIDE, RANGES, Effect, ForeignPlant

__all__ = [
    "CATALOGUE",
    "OUTSIDE",
    "PLANTS",
    "RANGES",
    "Effect",
    "ForeignPlant",
    "pythonpath_with_support",
]

SUPPORT_DIR = Path(__file__).resolve().parents[1]
"""tests/support: the directory that makes ``foreign_plants`` importable."""


def pythonpath_with_support() -> str:
    """This process's PYTHONPATH with tests/support first, for processes that load a plant
    by its module path (``--plant foreign_plants.plugin:boucwen``)."""
    return os.pathsep.join([str(SUPPORT_DIR), *filter(None, [os.environ.get("PYTHONPATH")])])


def _plants() -> dict[str, type[ForeignPlant]]:
    from .boucwen import BoucWenPlant
    from .duhem import DuhemPlant
    from .maxwell_slip import MaxwellSlipPlant

    return {p.name: p for p in (MaxwellSlipPlant, BoucWenPlant, DuhemPlant)}


def __getattr__(name: str) -> object:
    if name == "PLANTS":
        return _plants()
    raise AttributeError(name)
