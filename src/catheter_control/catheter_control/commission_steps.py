"""What a ``commission`` run records of itself: its steps, their by-hand commands, its protocol.

``OUT/commission.json`` (:class:`State`) holds the rig a directory was commissioned on and one
:class:`StepRecord` per step: whether it finished, how long it took, the commands a person
would type to do it by hand, and what it printed. A rerun reads it and skips what is done.
The lab's verbs run in-process through :func:`run_lab`, recorded as typed. The protocols say
which excitations are recorded.

Apart from :mod:`catheter_control.commission`, which runs the steps on a rig.
"""

from __future__ import annotations

import contextlib
import io
import json
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from catheter_control.commission_rig import RigChoice
from catheter_models.errors import CatheterError
from catheter_models.lab.signals import lab_training_specs

STATE_FILE = "commission.json"

PROTOCOLS = ("full", "quick")
FULL_TEST_SIGNALS = (
    "model_test_up_chirp",
    "lab_plateaus_999",
    "lab_steps_998",
    "model_test_descending_sine",
)
"""The held-out recording (about 2 minutes): a chirp, plateaus, fast steps and a sine, the
lab's held-out signals of other seeds than its training set's."""


def protocol_signals(protocol: str) -> dict[str, list[str]]:
    """The excitations, by recording: the lab's sets (``full``), or a short smoke set.

    ``full`` is the lab's training set (the thesis's eight sines, two plateau signals and one
    with fast steps, about 4.5 minutes) and its held-out set (about 2 minutes). ``quick``
    (about a minute in all) is for tests and trying the tool: enough to fit and tune, not
    enough for a model to trust.
    """
    if protocol == "quick":
        return {
            "train": ["train_zero_f0.4", "train_nonzero_f0.6", "lab_steps_102"],
            "test": ["lab_steps_998"],
        }
    return {"train": [s.name for s in lab_training_specs()], "test": list(FULL_TEST_SIGNALS)}


class StepError(CatheterError):
    """A step failed; the message says which and why."""


@dataclass
class StepRecord:
    """One step's entry in commission.json."""

    done: bool = False
    seconds: float = 0.0
    commands: list[str] = field(default_factory=list)
    """The by-hand equivalent, as run."""
    output: str = ""
    """What the step printed (for the report)."""
    facts: dict[str, Any] = field(default_factory=dict)


class State:
    """commission.json: the rig it was made on and every step's record; saved after each step."""

    def __init__(self, out_dir: Path, rig: RigChoice, protocol: str) -> None:
        self.path = out_dir / STATE_FILE
        self.steps: dict[str, StepRecord] = {}
        self.rig = rig.to_dict()
        self.protocol = protocol
        if self.path.exists():
            data = json.loads(self.path.read_text())
            if data.get("rig") != self.rig or data.get("protocol") != protocol:
                raise CatheterError(
                    f"{out_dir} was commissioned on {data.get('rig')} with the "
                    f"{data.get('protocol')!r} protocol, not {self.rig} / {protocol!r}; its "
                    "recordings belong to that rig: choose a new directory"
                )
            self.steps = {k: StepRecord(**v) for k, v in data.get("steps", {}).items()}

    def save(self) -> None:
        """Write it atomically, so a kill mid-write leaves the previous state."""
        data = {
            "rig": self.rig,
            "protocol": self.protocol,
            "steps": {k: vars(v) for k, v in self.steps.items()},
        }
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(data, indent=2, default=float) + "\n")
        tmp.replace(self.path)

    def done(self, name: str) -> bool:
        """Whether ``name`` finished (its outputs are checked by the caller)."""
        rec = self.steps.get(name)
        return rec is not None and rec.done


class _Tee(io.TextIOBase):
    """Prints through to the terminal and keeps a copy for the report."""

    def __init__(self, out: Any) -> None:
        self.out = out
        self.kept = io.StringIO()

    def write(self, text: str) -> int:
        self.out.write(text)
        self.kept.write(text)
        return len(text)

    def flush(self) -> None:
        self.out.flush()


@contextlib.contextmanager
def _captured() -> Iterator[_Tee]:
    tee = _Tee(sys.stdout)
    with contextlib.redirect_stdout(tee):
        yield tee


def run_lab(argv: list[str], record: StepRecord) -> None:
    """Run a ``catheter-lab`` verb in this process, as a person would type it.

    Raises:
        StepError: it refused or failed (its own message is above).
    """
    from catheter_models import cli

    line = "catheter-lab " + " ".join(argv)
    record.commands.append(line)
    print(f"$ {line}", flush=True)
    with _captured() as tee:
        try:
            cli.main(argv)
            code: object = 0
        except SystemExit as exc:
            code = exc.code
    record.output += tee.kept.getvalue()
    if code not in (0, None):
        raise StepError(f"`{line}` failed (exit {code}); its reason is printed above")
