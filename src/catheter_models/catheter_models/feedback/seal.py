"""``feedback.json`` sealed like a model's weights, and checked against its tuning and the envelope.

Gains decide how hard the valve answers the laser. A file edited by hand (gains x100, a 6 bar
authority, a 10^6 s authority timeout) once ran without a word and chattered the valve; so a
gains file is now what ``catheter-lab tune`` designed, or it is refused before anything moves:

* **The seal.** The tuner writes, beside the gains, what it designed them on (``tuning``: the
  identified loop, its margins, the designed gains and the range of gains it considers safe)
  and a sha256 of the whole file (``feedback_sha256``, over canonical JSON, as a model's
  manifest is sealed). A file whose content no longer matches its seal is refused, naming the
  file and what moved from the tuned values; a file with no seal (written before gains were
  sealed, or by hand) is refused with how to re-tune it.
* **The tuned range.** ``kp``, ``ki`` and ``kd`` must lie within the factor of the designed
  values that the tuning recorded (:func:`~catheter_models.feedback.tune.safe_gain_factor`:
  the square root of the gain margin it reported). Checked on every load, sealed or not.
* **The envelope.** The authority (``max_correction_pa``) and its timeout
  (``authority_timeout_s``) are safety limits, not the tuner's to design: their bounds are the
  contract's (``FEEDBACK_MAX_AUTHORITY_PA``, ``FEEDBACK_MAX_AUTHORITY_TIMEOUT_S``), and a file
  beyond them is refused by name, sealed or not.

Every problem of a file is said in one refusal. A deliberate edit is kept only through
:func:`catheter_models.feedback.reseal.reseal` (``catheter-lab tune --reseal FILE --reason
TEXT``), which refuses anything outside the envelope or the tuned range and re-checks the
margins on the recorded loop before it seals, recording the reason and what changed.

This module works on the file's content as plain data (no :class:`FeedbackGains`), so that
``FeedbackGains.save`` and ``load`` (:mod:`.law`) can seal and check through it.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from catheter_models.contract import FEEDBACK_MAX_AUTHORITY_PA, FEEDBACK_MAX_AUTHORITY_TIMEOUT_S
from catheter_models.errors import ParameterError

SEAL_KEY = "feedback_sha256"
"""The file's hash of itself (its content without this key, as canonical JSON)."""
RANGE_TOLERANCE = 1e-9
"""Relative slack on the tuned range: the range's ends are the designed values times a factor,
written and read back through JSON; a gain at an end is inside."""
RECORD_KEYS = ("loop", "designed", "designed_margins", "gain_factor", "safe")
"""What a tuning record must hold for the range and the margins to be checked."""


class FeedbackFileError(ParameterError):
    """A ``feedback.json`` is unsealed, edited, outside its tuned range or the envelope."""


def digest(content: Mapping[str, Any]) -> str:
    """sha256 of ``content`` without its seal, as canonical JSON (sorted, compact)."""
    body = {k: v for k, v in content.items() if k != SEAL_KEY}
    try:
        canonical = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except ValueError as exc:  # inf or nan: JSON cannot hold them, nor the seal cover them
        raise ParameterError(f"feedback gains cannot be sealed: {exc}") from None
    return hashlib.sha256(canonical.encode()).hexdigest()


def write_sealed(content: Mapping[str, Any], path: Path) -> Path:
    """Write ``content`` with its seal to the file ``path``; return it.

    Written whole or not at all (a temporary file renamed over it).
    """
    sealed = {**content, SEAL_KEY: digest(content)}
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(sealed, indent=2, sort_keys=True, allow_nan=False) + "\n")
    tmp.replace(path)
    return path


def envelope_problems(values: Mapping[str, Any]) -> list[str]:
    """The safety limits among ``values`` beyond the contract's envelope, each named."""
    problems = []
    authority = float(values["max_correction_pa"])
    timeout = float(values["authority_timeout_s"])
    if authority > FEEDBACK_MAX_AUTHORITY_PA:
        problems.append(
            f"max_correction_pa {authority / 1e5:g} bar is beyond the safety envelope (at most "
            f"{FEEDBACK_MAX_AUTHORITY_PA / 1e5:g} bar, FEEDBACK_MAX_AUTHORITY_PA in "
            "catheter_models/contract.py)"
        )
    if timeout > FEEDBACK_MAX_AUTHORITY_TIMEOUT_S:
        problems.append(
            f"authority_timeout_s {timeout:g} s is beyond the safety envelope (at most "
            f"{FEEDBACK_MAX_AUTHORITY_TIMEOUT_S:g} s, FEEDBACK_MAX_AUTHORITY_TIMEOUT_S in "
            "catheter_models/contract.py)"
        )
    return problems


def tuning_record(tuning: Any) -> dict[str, Any] | None:
    """The tuning record, when it holds what the checks need (else None)."""
    if not isinstance(tuning, dict) or not all(k in tuning for k in RECORD_KEYS):
        return None
    if not isinstance(tuning["safe"], dict) or not isinstance(tuning["designed"], dict):
        return None
    return tuning


def range_problems(values: Mapping[str, Any], record: Mapping[str, Any]) -> list[str]:
    """The gains among ``values`` outside the range the tuning ``record`` considers safe."""
    problems = []
    factor = float(record["gain_factor"])
    margin = (record.get("designed_margins") or {}).get("gain_margin")
    why = (
        f"within {factor:.2f}x, the square root of its gain margin {margin:.2f}"
        if isinstance(margin, (int, float))
        else f"within {factor:.2f}x"
    )
    for name, bounds in sorted(record["safe"].items()):
        value = values.get(name)
        try:
            low, high = (float(b) for b in bounds)
        except (TypeError, ValueError):
            problems.append(f"the tuning's safe range of {name} is malformed ({bounds!r})")
            continue
        if not isinstance(value, (int, float)):
            problems.append(f"the tuning records a range for {name!r}, which is no gain")
            continue
        slack = RANGE_TOLERANCE * max(abs(low), abs(high))
        if low - slack <= value <= high + slack:
            continue
        designed = float(record["designed"].get(name, math.nan))
        if designed == 0.0:
            problems.append(
                f"{name} {value:.4g} where the tuning designed 0 (a term never checked on the loop)"
            )
        else:
            problems.append(
                f"{name} {value:.4g} is {value / designed:.3g}x the tuned {designed:.4g} (the "
                f"tuning considers {low:.4g}..{high:.4g} safe: {why})"
            )
    return problems


def moved(values: Mapping[str, Any], record: Mapping[str, Any]) -> list[str]:
    """Each value that differs from what was tuned (and resealed since), as 'name was -> now'."""
    expected = dict(record["designed"])
    for entry in record.get("resealed", []):
        if isinstance(entry, dict) and isinstance(entry.get("changed"), dict):
            for name, change in entry["changed"].items():
                if isinstance(change, list) and len(change) == 2:
                    expected[name] = change[1]
    return [
        f"{name} {expected[name]!r} -> {values[name]!r}"
        for name in sorted(expected)
        if name in values and values[name] != expected[name]
    ]


def check(path: Path, raw: Mapping[str, Any], values: Mapping[str, Any]) -> None:
    """Check a gains file's seal, tuned range and envelope (see the module).

    ``raw``: the file's content as read (with its seal); ``values``: its gains and limits,
    each already checked on its own (:class:`~catheter_models.feedback.law.FeedbackGains`).

    Raises:
        FeedbackFileError: beyond the envelope, unsealed, its seal broken, no tuning record,
            or a gain outside the tuned range; every problem named in one message.
    """
    envelope = envelope_problems(values)
    record = tuning_record(raw.get("tuning", {}))
    tuned = [] if record is None else range_problems(values, record)
    sealed = raw.get(SEAL_KEY)
    retune = f"re-tune (catheter-lab tune BAGS -o {path.parent})"
    # Resealing is offered only where it could succeed: never past the envelope or the range.
    resealable = record is not None and not envelope and not tuned
    reseal = f"catheter-lab tune --reseal {path} --reason '...'"
    problems = list(envelope)
    if sealed is None:
        problems.append(
            f"it is not sealed (no {SEAL_KEY}): written by hand or before gains files were "
            f"sealed; the compensator runs only gains whose tuning it can check: {retune}"
            + (f", or, to keep these gains knowingly, {reseal}" if resealable else "")
        )
    elif sealed != (actual := digest(raw)):
        changes = [] if record is None else moved(values, record)
        what = (
            f" ({', '.join(changes)})"
            if changes
            else " (no gain differs from the tuned ones: its tuning record was edited)"
            if record is not None
            else ""
        )
        problems.append(
            f"its {SEAL_KEY} does not match its content (sealed {str(sealed)[:12]}..., "
            f"content {actual[:12]}...): it was edited after catheter-lab tune wrote it{what}; "
            + (
                f"{retune}, or keep a deliberate edit by resealing it knowingly ({reseal}, "
                "which first re-checks the gains on the recorded loop)"
                if resealable
                else retune
            )
        )
    if record is None and sealed is not None:
        problems.append(
            f"its tuning records no loop and no safe range (not written by catheter-lab tune): "
            f"{retune}"
        )
    problems += tuned
    if problems:
        raise FeedbackFileError(f"{path} refused: " + "; ".join(problems))
