"""Why a bag stopped being written, and what closing it left.

``WriteFailure`` (the error, the file, the time), ``BagWriteError`` (raised with it) and
``CloseOutcome`` (finished, or cut back to the last complete flush) are what ``BagRecorder``
hands out when the disk refuses it; ``bag.writer`` says how a failure is handled. They are
plain values (no I/O), apart from the writer so that it holds the recorder alone, and the
recorder node, which logs and reports a failed recording, imports them from here.
"""

from __future__ import annotations

import datetime as dt
import errno as errno_codes
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from catheter_models.errors import BagError
from catheter_models.units import NS_PER_S


@dataclass(frozen=True)
class WriteFailure:
    """Why a bag stopped being written: the error, the file, and when.

    Attributes:
        path: The file the write failed on.
        operation: What was being done: ``write``, ``flush`` or ``close``.
        errno: The OS error number (``errno.ENOSPC``), or None for an error that is not the
            OS's (a bug, a closed stream).
        reason: The error as a person reads it (``No space left on device``).
        at_ns: When it failed: wall clock [ns since the Unix epoch].
    """

    path: Path
    operation: str
    errno: int | None
    reason: str
    at_ns: int

    @classmethod
    def of(cls, path: Path, operation: str, exc: BaseException) -> WriteFailure:
        """The failure ``exc`` raised while doing ``operation`` on ``path``, timed now."""
        if isinstance(exc, OSError) and exc.errno is not None:
            reason = exc.strerror or str(exc)
            return cls(path, operation, exc.errno, reason, time.time_ns())
        return cls(path, operation, None, repr(exc), time.time_ns())

    @property
    def errno_name(self) -> str:
        """``ENOSPC``; '' when the error is not the OS's."""
        if self.errno is None:
            return ""
        return errno_codes.errorcode.get(self.errno, str(self.errno))

    def describe(self) -> str:
        """``No space left on device (ENOSPC) on flush of /x/bag_0.mcap at 12:00:01.250``."""
        when = dt.datetime.fromtimestamp(self.at_ns / NS_PER_S).isoformat(timespec="milliseconds")
        code = f" ({self.errno_name})" if self.errno_name else ""
        return f"{self.reason}{code} on {self.operation} of {self.path} at {when}"


class BagWriteError(BagError):
    """The bag could not be written (disk full, I/O error); ``failure`` says why and when."""

    def __init__(self, failure: WriteFailure) -> None:
        super().__init__(f"cannot write bag: {failure.describe()}")
        self.failure = failure


@dataclass(frozen=True)
class CloseOutcome:
    """What a closed bag holds, and whether any MCAP reader opens it as it is.

    Attributes:
        finished: True: summary and footer written, the bag is complete. False: the file
            ends at its last complete flush with no footer (a write failed); ``catheter-lab
            bag repair`` recovers every message it holds.
        messages: Messages the file holds (all written when finished, else up to the last
            complete flush).
        until_ns: Log time of the newest message it holds [ns, epoch]; None if none.
        failure: Why writing stopped (None for a bag closed as planned).
        note: One line for a person: what the file holds and what to do with it (the
            failure is ``failure``'s to say).
        per_topic: ``messages`` by topic.
    """

    finished: bool
    messages: int
    until_ns: int | None
    failure: WriteFailure | None
    note: str
    per_topic: Mapping[str, int] = field(default_factory=dict)
