"""The black boxes a diagnosis is judged against, by name.

The filter bank, the recurrent network, or the stronger of the two: the one place that
chooses between them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Final

from catheter_models.lab.floors import FilterBankReference
from catheter_models.lab.recurrent_reference import NAME, RecurrentReference
from catheter_models.models.base import Recording

REFERENCES: Final = ("filter_bank", "recurrent", "stronger")
"""Black-box references a diagnosis can be judged against: the filter bank (seconds), the
recurrent network (:mod:`catheter_models.lab.recurrent_reference`, minutes), or both, the
stronger one (lower held-out error) being the floor."""

FILTER_BANK: Final = "filter-bank black box"

RECURRENT_SETTINGS: dict[str, Any] = {}
"""Settings of the recurrent reference a diagnosis fits (its defaults where empty)."""


def reference_floor(
    kind: str, train: Sequence[Recording], test: Sequence[Recording]
) -> tuple[float, str, dict[str, float]]:
    """The black-box floor of ``kind`` (:data:`REFERENCES`) on this split.

    Returns its held-out RMSE [deg], the name said beside it, and every reference fitted.
    """
    if kind not in REFERENCES:
        raise ValueError(f"unknown reference {kind!r}; one of {', '.join(REFERENCES)}")
    fitted: dict[str, float] = {}
    if kind in ("filter_bank", "stronger"):
        fitted[FILTER_BANK] = FilterBankReference().fit(train).rmse_deg(test)
    if kind in ("recurrent", "stronger"):
        fitted[NAME] = RecurrentReference(**RECURRENT_SETTINGS).fit(train).rmse_deg(test)
    name = min(fitted, key=lambda n: fitted[n])
    return fitted[name], name, fitted
