"""A sealed ``feedback.json`` with the identified loop a test needs, as ``catheter-lab tune``
would write it: the shipped gains, their tuning's ``loop`` values replaced, sealed by the
tool (``FeedbackGains.save``), so it loads where the compensator and ``commission`` read it."""

from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

from catheter_control.models import shipped_model_dir
from catheter_models.feedback import GAINS_FILE, FeedbackGains


def sealed_gains(
    directory: Path, *, decision: dict[str, object] | None = None, **loop: float
) -> Path:
    """``directory``/feedback.json, sealed, with ``loop`` in its tuning's identified loop.

    ``decision``: keys of the tuning's own record (``shape_from``, ``chain_fits_steps``)."""
    shipped = FeedbackGains.load(shipped_model_dir("feedback") / GAINS_FILE)
    tuning = copy.deepcopy(shipped.tuning)
    unknown = set(loop) - set(tuning["loop"])
    if unknown:
        raise KeyError(f"the tuned loop has no {sorted(unknown)}")
    tuning["loop"].update(loop)
    tuning.update(decision or {})
    directory.mkdir(parents=True, exist_ok=True)
    return dataclasses.replace(shipped, tuning=tuning).save(directory)
