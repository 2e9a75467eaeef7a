"""The lab's whole loop: diagnose, make the best change, diagnose again, until nothing helps.

``explain(model, train, test)`` is what a person does by hand with ``catheter-lab diagnose``
and ``catheter-lab add`` / ``core``, one step at a time: each step's diagnosis ranks every
core change and every missing catalogue effect by the held-out error it removes; the best
change that earns its place is made (its refitted model is the next version); the loop stops
when no change does, with the last diagnosis's verdict: adequate (within 3x the noise floor)
or unexplained (how far above the floors, where, and with which signature).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

from catheter_models.lab.diagnose import Diagnosis, diagnose, refit_executor
from catheter_models.models.base import Model, Recording
from catheter_models.models.cores import CORES
from catheter_models.models.drdpi import DRDPI


def _core_of(model: Model) -> str:
    return "drdpi" if isinstance(model, DRDPI) else str(getattr(model, "core_name", ""))


@dataclass
class Step:
    """One version of the model in the loop and what its diagnosis said."""

    model: Model
    change: str | None
    """The change that made this version (None for the model the loop started from)."""
    diagnosis: Diagnosis
    seconds: float = float("nan")
    """Wall time of this step's diagnosis (every change refitted and scored) [s]."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, without the model."""
        d = self.diagnosis
        return {
            "change": self.change,
            "chain": d.chain,
            "rmse_train_deg": d.rmse_train_deg,
            "rmse_test_deg": d.rmse_test_deg,
            "verdict": d.verdict,
            "seconds": self.seconds,
        }


@dataclass
class Explanation:
    """Every step of the loop; the last one's diagnosis is the answer."""

    steps: list[Step]

    @property
    def final(self) -> Diagnosis:
        """The last diagnosis (its verdict is adequate or unexplained)."""
        return self.steps[-1].diagnosis

    @property
    def changes(self) -> list[str]:
        """The changes made, in order (``core:<name>`` for a core change)."""
        return [s.change for s in self.steps if s.change is not None]

    def text(self) -> str:
        """The table of steps, then the final diagnosis."""
        floors = self.final.floors
        lines = [
            f"{'step':>4} {'train':>7} {'held-out':>8} {'diagnosed':>9}  change              chain"
        ]
        for i, s in enumerate(self.steps):
            d = s.diagnosis
            lines.append(
                f"{i:>4} {d.rmse_train_deg:7.3f} {d.rmse_test_deg:8.3f} {s.seconds:8.0f}s  "
                f"{(s.change or '-'):<19} {' -> '.join(d.chain)}"
            )
        lines.append(f"(RMSE in deg; {floors.text(self.final.rmse_test_deg)})")
        lines.append("")
        lines.append(self.final.text())
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "steps": [s.to_dict() for s in self.steps],
            "changes": self.changes,
            "final": self.final.to_dict(),
        }


def explain(
    model: Model,
    train: Sequence[Recording],
    test: Sequence[Recording],
    *,
    max_steps: int = 4,
    progress: bool = False,
    on_step: Callable[[Step], None] | None = None,
    workers: int | None = None,
    reference: bool | str = True,
    ray: str | None = None,
) -> Explanation:
    """Diagnose and make the best change until none earns its place (at most ``max_steps``).

    ``on_step`` is called with each step as it is made (to save the version, say).
    ``workers``: processes for each diagnosis's refits, started once for the whole loop
    (default: one per core; 1: in this process). ``reference``: the black box the first
    step fits and every step is judged against (:func:`~catheter_models.lab.diagnose.diagnose`).
    ``ray``: a Ray cluster's address to run the refits on instead (``local``: a Ray started
    here), the same answers (:class:`~catheter_models.lab.refit_pool.RayExecutor`).
    """
    with refit_executor(workers, progress=progress, ray=ray) as pool:
        return _explain(
            model,
            train,
            test,
            max_steps=max_steps,
            progress=progress,
            on_step=on_step,
            pool=pool,
            reference=reference,
        )


def _explain(
    model: Model,
    train: Sequence[Recording],
    test: Sequence[Recording],
    *,
    max_steps: int,
    progress: bool,
    on_step: Callable[[Step], None] | None,
    pool: Executor,
    reference: bool | str,
) -> Explanation:
    t0 = time.perf_counter()
    diagnosis = diagnose(model, train, test, progress=progress, pool=pool, reference=reference)
    steps = [Step(model, None, diagnosis, time.perf_counter() - t0)]
    if on_step is not None:
        on_step(steps[-1])
    # A core, once left, does not come back: only untried cores compete in later steps.
    tried_cores = {_core_of(model)}
    while len(steps) <= max_steps:
        best = diagnosis.best
        if best is None or best.model is None:
            break
        model = best.model
        tried_cores.add(_core_of(model))
        t0 = time.perf_counter()
        diagnosis = diagnose(
            model,
            train,
            test,
            cores=[c for c in CORES if c not in tried_cores],
            # The reference depends on the split alone: fitted once, for the first step.
            reference=reference,
            reference_deg=steps[0].diagnosis.floors.reference_deg,
            reference_name=steps[0].diagnosis.floors.reference,
            progress=progress,
            pool=pool,
        )
        steps.append(Step(model, best.effect, diagnosis, time.perf_counter() - t0))
        if on_step is not None:
            on_step(steps[-1])
    return Explanation(steps)
