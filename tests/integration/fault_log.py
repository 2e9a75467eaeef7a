"""The fault-injection suite's record: one row per injected fault, for docs/reliability.md.

A fault test is marked ``@pytest.mark.fault("kill -9 compensator mid-trajectory",
safe="valve vented by sim_hardware's watchdog")`` and takes the ``fault`` fixture. It checks
each invariant through :meth:`FaultRecord.check` (an assertion that is also recorded) and
states when the rig reached its safe state with :meth:`FaultRecord.safe_after`. With
``FAULT_REPORT=path.json`` in the environment, the session writes every row there; the
``make faults`` target turns that into the table (scripts/fault_table.py).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

INVARIANTS = {
    "range": "pressure never left its range",
    "vent": "after command loss the valve vented within the watchdog time",
    "reported": "every refusal and fault was reported",
    "bag": "no bag data from before the fault was lost",
}
"""The issue's four invariants, by short name; a check may also name its own."""


@dataclass
class Check:
    """One invariant checked after a fault."""

    name: str
    ok: bool
    detail: str


@dataclass
class FaultRecord:
    """What a fault test did and saw."""

    test: str
    fault: str
    safe: str
    category: str
    checks: list[Check] = field(default_factory=list)
    time_to_safe_s: float | None = None
    outcome: str = "not run"
    duration_s: float = 0.0

    def check(self, name: str, ok: bool, detail: str = "") -> None:
        """Record invariant ``name`` and assert it (the detail is the failure message)."""
        self.checks.append(Check(INVARIANTS.get(name, name), bool(ok), detail))
        assert ok, f"{INVARIANTS.get(name, name)}: {detail}"

    def safe_after(self, seconds: float) -> None:
        """The rig was in its safe state ``seconds`` after the fault was injected."""
        self.time_to_safe_s = float(seconds)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready row."""
        return asdict(self)


def write_report(records: list[FaultRecord], path: Path) -> None:
    """Every row as JSON (sorted by category, then fault)."""
    rows = sorted((r.to_dict() for r in records), key=lambda r: (r["category"], r["fault"]))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"faults": rows}, indent=2) + "\n")
