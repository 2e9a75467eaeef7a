"""``catheter-lab tune --reseal``: keep a deliberate edit of a ``feedback.json``, after checking it.

A sealed gains file (:mod:`.seal`) refuses any edit. A person who means an edit (a softer
integral for one catheter, a measurement filter for a noisy laser) reseals it here, saying
why; what would be refused at configure is refused here too, and the gains are checked on
the loop the tuning recorded before the new seal is written.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from catheter_models.errors import ParameterError
from catheter_models.feedback.law import FeedbackGains
from catheter_models.feedback.seal import (
    RANGE_TOLERANCE,
    FeedbackFileError,
    envelope_problems,
    range_problems,
    tuning_record,
    write_sealed,
)
from catheter_models.feedback.tune import LoopModel, Margins, margins, plainly_stable


def reseal(path: Path, reason: str) -> tuple[Path, FeedbackGains, Margins]:
    """Seal an edited ``feedback.json`` knowingly; return its path, the gains, their margins.

    Refuses (nothing written) gains beyond the envelope, outside the tuned range, or whose
    loop, on the loop the tuning recorded, is not plainly stable or keeps a gain margin below
    the tuned range's factor (the margin that range promises to leave at its edge). The
    designed gains and the range stay as the tuner wrote them, so resealing again cannot widen
    the range; each reseal is appended to ``tuning["resealed"]`` with its reason, what changed
    and the margins.

    Raises:
        ParameterError: no reason given, or the file cannot be read.
        FeedbackFileError: what would be refused, named.
    """
    if not reason.strip():
        raise ParameterError("--reseal: say why (--reason TEXT); it is kept in the file")
    path, _, gains = FeedbackGains.read(path)
    values = dataclasses.asdict(gains)
    record = tuning_record(gains.tuning)
    retune = f"re-tune: catheter-lab tune BAGS -o {path.parent}"
    if record is None:
        raise FeedbackFileError(
            f"{path} cannot be resealed: it records no tuned loop to check the gains on "
            f"(written by hand or before gains files were sealed); {retune}"
        )
    problems = envelope_problems(values) + range_problems(values, record)
    try:
        loop = LoopModel(**record["loop"])
    except TypeError as exc:
        raise FeedbackFileError(f"{path}: its recorded loop is malformed ({exc})") from None
    found = margins(loop, gains)
    factor = float(record["gain_factor"])
    if not plainly_stable(loop, gains):
        problems.append(
            f"on the recorded loop these gains are not plainly stable ({found.describe()})"
        )
    elif found.gain_margin < factor * (1.0 - RANGE_TOLERANCE):
        problems.append(
            f"on the recorded loop these gains leave a gain margin of {found.gain_margin:.2f}, "
            f"below the {factor:.2f} the tuned range promises ({found.describe()})"
        )
    if problems:
        raise FeedbackFileError(f"{path} not resealed: " + "; ".join(problems) + f"; {retune}")
    designed = record["designed"]
    changed = {
        name: [designed.get(name), value]
        for name, value in values.items()
        if name != "tuning" and designed.get(name) != value
    }
    entry = {"reason": reason.strip(), "changed": changed, "margins": found.describe()}
    tuning = {**record, "resealed": [*record.get("resealed", []), entry]}
    resealed = dataclasses.replace(gains, tuning=tuning)
    return write_sealed(dataclasses.asdict(resealed), path), resealed, found
