"""``feedback.json`` sealed like a model's weights, and checked against its tuning and the envelope.

Gains decide how hard the valve answers the laser. A file edited by hand (gains x100, a 6 bar
authority, a 10^6 s authority timeout) once ran without a word and chattered the valve; so a
gains file is now what ``catheter-lab tune`` designed, or it is refused before anything moves:

* **The seal.** The tuner writes, beside the gains, what it designed them on (``tuning``: the
  identified loop, its margins, the designed gains and the range of gains it considers safe)
  and a sha256 of the whole file (``feedback_sha256``, over canonical JSON, as a model's
  manifest is sealed). A file whose content no longer matches its seal is refused, naming the
  file and what moved; a file with no seal (written before gains were sealed, or by hand) is
  refused with how to re-tune it.
* **The tuned range.** ``kp``, ``ki`` and ``kd`` must lie within the factor of the designed
  values that the tuning recorded (:func:`~catheter_models.feedback.tune.safe_gain_factor`:
  the square root of the gain margin it reported). Checked on every load, sealed or not.
* **The envelope.** The authority (``max_correction_pa``) and its timeout
  (``authority_timeout_s``) are safety limits, not the tuner's to design: their bounds are the
  contract's (``FEEDBACK_MAX_AUTHORITY_PA``, ``FEEDBACK_MAX_AUTHORITY_TIMEOUT_S``), and a file
  beyond them is refused by name, sealed or not.

Every problem of a file is said in one refusal. A deliberate edit is kept only through
:func:`reseal` (``catheter-lab tune --reseal FILE --reason TEXT``), which refuses anything
outside the envelope or the tuned range and re-checks the margins on the recorded loop
before it seals, recording the reason and what changed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from catheter_models.contract import FEEDBACK_MAX_AUTHORITY_PA, FEEDBACK_MAX_AUTHORITY_TIMEOUT_S
from catheter_models.errors import ParameterError
from catheter_models.feedback.law import GAINS_FILE, FeedbackGains

SEAL_KEY = "feedback_sha256"
"""The file's hash of itself (its content without this key, as canonical JSON)."""
RANGE_TOLERANCE = 1e-9
"""Relative slack on the tuned range: the range's ends are the designed values times a factor,
written and read back through JSON; a gain at an end is inside."""
RECORD_KEYS = ("loop", "designed", "designed_margins", "gain_factor", "safe")
"""What a tuning record must hold for the range and the margins to be checked."""


class FeedbackFileError(ParameterError):
    """A ``feedback.json`` is unsealed, edited, outside its tuned range or the envelope."""


def _digest(content: Mapping[str, Any]) -> str:
    body = {k: v for k, v in content.items() if k != SEAL_KEY}
    try:
        canonical = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except ValueError as exc:  # inf or nan: JSON cannot hold them, nor the seal cover them
        raise ParameterError(f"feedback gains cannot be sealed: {exc}") from None
    return hashlib.sha256(canonical.encode()).hexdigest()


def write_sealed(gains: FeedbackGains, path: Path) -> Path:
    """Write ``gains`` with their seal to ``path`` (a directory: its ``feedback.json``).

    Written whole or not at all (a temporary file renamed over it). Returns the file's path.
    """
    content = dataclasses.asdict(gains)
    sealed = {**content, SEAL_KEY: _digest(content)}
    path = Path(path)
    if path.is_dir():
        path = path / GAINS_FILE
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(sealed, indent=2, sort_keys=True, allow_nan=False) + "\n")
    tmp.replace(path)
    return path


def _read(path: Path) -> tuple[Path, dict[str, Any]]:
    path = Path(path)
    if path.is_dir():
        path = path / GAINS_FILE
    try:
        raw = json.loads(path.read_text())
    except FileNotFoundError:
        raise ParameterError(f"no feedback gains at {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ParameterError(f"{path}: cannot be read ({exc})") from None
    except json.JSONDecodeError as exc:
        raise ParameterError(f"{path}: not JSON ({exc})") from None
    if not isinstance(raw, dict):
        raise ParameterError(f"{path}: expected an object of gains")
    return path, raw


def _gains(path: Path, raw: Mapping[str, Any]) -> FeedbackGains:
    """The gains of ``raw`` (without its seal), each value checked by :class:`FeedbackGains`."""
    body = {k: v for k, v in raw.items() if k != SEAL_KEY}
    known = {f.name for f in dataclasses.fields(FeedbackGains)}
    unknown = sorted(set(body) - known)
    if unknown:
        raise ParameterError(
            f"{path}: unknown feedback keys {', '.join(unknown)}; "
            f"known: {', '.join(sorted(known | {SEAL_KEY}))}"
        )
    if not isinstance(body.get("tuning", {}), dict):
        raise ParameterError(f"{path}: tuning must be an object")
    try:
        return FeedbackGains(**body)
    except TypeError as exc:  # a required gain missing
        raise ParameterError(f"{path}: {exc}") from None


def envelope_problems(gains: FeedbackGains) -> list[str]:
    """The safety limits of ``gains`` beyond the contract's envelope, each named (or none)."""
    problems = []
    if gains.max_correction_pa > FEEDBACK_MAX_AUTHORITY_PA:
        problems.append(
            f"max_correction_pa {gains.max_correction_pa / 1e5:g} bar is beyond the safety "
            f"envelope (at most {FEEDBACK_MAX_AUTHORITY_PA / 1e5:g} bar, "
            "FEEDBACK_MAX_AUTHORITY_PA in catheter_models/contract.py)"
        )
    if gains.authority_timeout_s > FEEDBACK_MAX_AUTHORITY_TIMEOUT_S:
        problems.append(
            f"authority_timeout_s {gains.authority_timeout_s:g} s is beyond the safety envelope "
            f"(at most {FEEDBACK_MAX_AUTHORITY_TIMEOUT_S:g} s, "
            "FEEDBACK_MAX_AUTHORITY_TIMEOUT_S in catheter_models/contract.py)"
        )
    return problems


def _record(gains: FeedbackGains) -> dict[str, Any] | None:
    """The tuning record, when it holds what the checks need (else None)."""
    tuning = gains.tuning
    if not all(k in tuning for k in RECORD_KEYS):
        return None
    if not isinstance(tuning["safe"], dict) or not isinstance(tuning["designed"], dict):
        return None
    return tuning


def range_problems(gains: FeedbackGains, record: Mapping[str, Any]) -> list[str]:
    """The gains of ``gains`` outside the range its tuning ``record`` considers safe."""
    problems = []
    factor = float(record["gain_factor"])
    margin = (record.get("designed_margins") or {}).get("gain_margin")
    why = (
        f"within {factor:.2f}x, the square root of its gain margin {margin:.2f}"
        if isinstance(margin, (int, float))
        else f"within {factor:.2f}x"
    )
    for name, bounds in sorted(record["safe"].items()):
        value = getattr(gains, name, None)
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


def load_checked(path: Path) -> FeedbackGains:
    """Read a ``feedback.json`` (or the directory holding one) and check it (see the module).

    Raises:
        ParameterError: missing, malformed, unknown keys, or a value out of its range.
        FeedbackFileError: beyond the envelope, unsealed, its seal broken, no tuning record,
            or a gain outside the tuned range; every problem named in one message.
    """
    path, raw = _read(path)
    gains = _gains(path, raw)
    envelope = envelope_problems(gains)
    record = _record(gains)
    tuned = [] if record is None else range_problems(gains, record)
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
    elif sealed != (actual := _digest(raw)):
        problems.append(
            f"its {SEAL_KEY} does not match its content (sealed {str(sealed)[:12]}..., "
            f"content {actual[:12]}...): it was edited after catheter-lab tune wrote it; "
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
    return gains


def reseal(path: Path, reason: str) -> tuple[Path, FeedbackGains, Any]:
    """Seal an edited ``feedback.json`` knowingly; return its path, the gains, their margins.

    Refuses (nothing written) gains beyond the envelope, outside the tuned range, or whose
    loop, on the loop the tuning recorded, is not plainly stable or keeps a gain margin below
    the tuned range's factor (the margin that range promises to leave). The designed gains and
    range stay as the tuner wrote them, so resealing again cannot widen the range; each reseal
    is appended to ``tuning["resealed"]`` with its reason, what changed and the margins.

    Raises:
        ParameterError: no reason given, or the file cannot be read.
        FeedbackFileError: what would be refused, named.
    """
    from catheter_models.feedback.tune import LoopModel, margins, plainly_stable

    if not reason.strip():
        raise ParameterError("tune --reseal: say why (--reason TEXT); it is kept in the file")
    path, raw = _read(path)
    gains = _gains(path, raw)
    problems = envelope_problems(gains)
    record = _record(gains)
    if record is None:
        raise FeedbackFileError(
            f"{path} cannot be resealed: it records no tuned loop to check the gains on "
            f"(written by hand or before gains files were sealed); re-tune: catheter-lab tune "
            f"BAGS -o {path.parent}"
        )
    problems += range_problems(gains, record)
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
        raise FeedbackFileError(
            f"{path} not resealed: " + "; ".join(problems) + f"; re-tune: catheter-lab tune "
            f"BAGS -o {path.parent}"
        )
    designed = record["designed"]
    changed = {
        f.name: [designed.get(f.name), getattr(gains, f.name)]
        for f in dataclasses.fields(gains)
        if f.name != "tuning" and designed.get(f.name) != getattr(gains, f.name)
    }
    entry = {"reason": reason.strip(), "changed": changed, "margins": found.describe()}
    tuning = {**record, "resealed": [*record.get("resealed", []), entry]}
    resealed = dataclasses.replace(gains, tuning=tuning)
    return write_sealed(resealed, path), resealed, found
