"""Watching the recorder during a run: a recorder that dies or cannot write stops the run.

``follow_trajectory --sim`` (and ``commission``'s recordings) start a recorder beside the
rig. A bag that silently ends part-way is a run that cannot be analysed or trained on, found
out hours later; so the run watches the recorder and, the moment it exits (a kill, a crash)
or reports ERROR on ``/diagnostics`` (it cannot write: disk full, I/O error), says so and
stops the run (the compensator ramps down), unless the person chose to go on without a bag
(``--continue-without-bag``). Either way the report says how many seconds went unrecorded,
starting when, and what the bag file holds.
"""

from __future__ import annotations

import datetime as dt
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from catheter_models.bag.metadata import read_metadata
from catheter_models.errors import BagError
from catheter_models.units import NS_PER_S

if TYPE_CHECKING:
    from catheter_control.process_graph import ProcessGraph
    from catheter_control.tracking_report import RunRecord

RECORDER = "recorder"
"""The recorder's node (and process) name in a started graph."""


def wall_text(wall_ns: int) -> str:
    """``2026-11-26T22:41:07.250``: local wall time to the millisecond."""
    return dt.datetime.fromtimestamp(wall_ns / NS_PER_S).isoformat(timespec="milliseconds")


def bag_end_ns(bag_path: Path) -> int | None:
    """The newest log time ``metadata.yaml`` counts [ns, epoch]: the recorder's last flush.

    The recorder rewrites metadata.yaml after each flush, so after a kill it says what the
    file holds (and ``bag repair`` recovers). None when there is none or it says nothing.
    """
    try:
        info = read_metadata(bag_path)
        if not info or not int(info.get("message_count", 0)):
            return None
        start = int(info.get("starting_time", {}).get("nanoseconds_since_epoch", 0))
        duration = int(info.get("duration", {}).get("nanoseconds", 0))
    except (BagError, OSError, ValueError, TypeError, AttributeError):
        return None  # a half-written or foreign metadata.yaml: unknown, said as such
    return start + duration if start else None


@dataclass
class RecordingFailure:
    """What happened to the recording, as first noticed."""

    reason: str
    noticed_ns: int
    """When this tool noticed [ns, wall clock]."""
    recorded_until_ns: int | None
    """Log time of the newest message the bag file holds [ns, epoch]; None if unknown."""
    bag_file: str
    """``finished``, ``repairable`` (``catheter-lab bag repair``), or ``unknown``."""


@dataclass
class RecordingWatch:
    """Watches one recorder through a run; :meth:`check` is called every spin of the run.

    Args:
        bag_path: The bag the recorder writes.
        graph: The started graph the recorder runs in (None: only its /diagnostics).
        record: The run's record: the recorder's /diagnostics land there.
        continue_without_bag: Go on with the run when the recording fails (say so, still).
        tool: The tool's name, for what it prints.
        stopping: What the tool does when the recording fails, as it says it.
    """

    bag_path: Path
    graph: ProcessGraph | None
    record: RunRecord
    continue_without_bag: bool = False
    tool: str = "follow_trajectory"
    stopping: str = (
        "stopping the run (the compensator ramps down; --continue-without-bag would go on "
        "without a bag)"
    )
    """What the tool does when the recording fails (said with the failure)."""
    failure: RecordingFailure | None = None
    _said: bool = field(default=False, repr=False)

    def check(self) -> str:
        """'' while the recording is fine (or the run goes on without it); else why to stop."""
        if self.failure is None:
            self.failure = self._look()
            if self.failure is None:
                return ""
            self._say()
        elif self.failure.recorded_until_ns is None or self.failure.bag_file == "unknown":
            # A later report may say what the first did not (until when, the file's state).
            later = self._look()
            if later is not None:
                self.failure.recorded_until_ns = (
                    self.failure.recorded_until_ns or later.recorded_until_ns
                )
                if self.failure.bag_file == "unknown":
                    self.failure.bag_file = later.bag_file
        if self.continue_without_bag:
            return ""
        return f"the recording failed: {self.failure.reason}"

    def _look(self) -> RecordingFailure | None:
        now_ns = time.time_ns()
        dead = self.graph.failed() if self.graph is not None else {}
        if RECORDER in dead:
            # Its last flush is what the file holds; metadata.yaml was rewritten with it.
            until = bag_end_ns(self.bag_path)
            return RecordingFailure(
                f"the recorder exited (code {dead[RECORDER]}); its bag holds up to its last "
                f"flush, with no footer: `catheter-lab bag repair {self.bag_path}` recovers it",
                now_ns,
                until,
                "repairable",
            )
        error = self.record.recorder_error
        if error:
            values = self.record.recorder
            until_text = str(values.get("recorded_until_ns", ""))
            return RecordingFailure(
                f"the recorder reports: {error}",
                now_ns,
                int(until_text) if until_text.isdigit() else bag_end_ns(self.bag_path),
                str(values.get("bag_file", "unknown")),
            )
        return None

    def _say(self) -> None:
        failure = self.failure
        assert failure is not None
        then = (
            "going on without a bag (--continue-without-bag)"
            if self.continue_without_bag
            else self.stopping
        )
        print(
            f"{self.tool}: the recording failed at {wall_text(failure.noticed_ns)}: "
            f"{failure.reason}; {then}",
            file=sys.stderr,
            flush=True,
        )

    def finish(self, end_ns: int, run_start_ns: int | None) -> dict[str, Any]:
        """What became of the recording, for report.json; says the unrecorded span if any.

        Args:
            end_ns: When the run ended (after its ramp-down) [ns, wall clock].
            run_start_ns: The run's first set-point [ns, wall clock]; None if none came.
        """
        self.check()  # a failure in the run's last moments counts too
        failure = self.failure
        facts: dict[str, Any] = {"bag": str(self.bag_path)}
        if failure is None:
            facts["state"] = "recorded"
            return facts
        # What the bag lacks starts after its newest message; not known: when it was noticed.
        from_ns = failure.recorded_until_ns or failure.noticed_ns
        unrecorded_s = max(0.0, (end_ns - from_ns) / NS_PER_S)
        into_s = None if run_start_ns is None else (from_ns - run_start_ns) / NS_PER_S
        facts.update(
            state="failed",
            reason=failure.reason,
            noticed_at=wall_text(failure.noticed_ns),
            bag_file=failure.bag_file,
            unrecorded_from=wall_text(from_ns),
            unrecorded_from_run_s=None if into_s is None else round(into_s, 3),
            unrecorded_s=round(unrecorded_s, 3),
            continued_without_bag=self.continue_without_bag,
        )
        where = "" if into_s is None else f" ({into_s:.1f} s into the run)"
        print(
            f"{self.tool}: {unrecorded_s:.1f} s of the run went unrecorded, from "
            f"{wall_text(from_ns)}{where} to its end (the bag: {failure.bag_file})",
            file=sys.stderr,
            flush=True,
        )
        return facts
