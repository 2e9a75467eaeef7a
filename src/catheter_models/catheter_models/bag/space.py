"""Will a recording fit? The bytes a recorder writes per second, and the free space it needs.

A tool that starts a recording (``follow_trajectory --sim``, ``commission``) checks before
anything moves that the bag's disk holds what the run will write: the recorded streams' rates
times their message sizes on disk (the CDR bytes plus MCAP's per-message record and index),
times the run's duration, times :data:`SPACE_MARGIN`. A run refused here costs nothing; a
disk that fills mid-run costs the run.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr, range_cdr
from catheter_models.contract import (
    ANGLE_DESIRED,
    CONTROL_RATE_HZ,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    SENSOR_RATE_HZ,
    TIP_ANGLE,
    TIP_DISTANCE,
)
from catheter_models.errors import CatheterError
from catheter_models.units import AMBIENT_PRESSURE_PA

MCAP_BYTES_PER_MESSAGE: Final = 31 + 16
"""What MCAP adds to each message on disk: its record (opcode, length, channel, sequence, log
and publish time: 31 bytes) and its entry in the chunk's message index (16 bytes)."""

SPACE_MARGIN: Final = 2.0
"""Free space asked for beyond the estimate: chunk and summary records, ``metadata.yaml``
rewrites, longer frame ids than the estimate's, a driver that samples faster than the
contract, and what other programs write meanwhile."""

_FRAME_ID: Final = "f" * 32
"""A frame id longer than any this stack sends, so the estimate errs on the large side."""

_STAMP_NS: Final = 1_800_000_000_000_000_000


class DiskSpaceError(CatheterError):
    """The disk where a recording goes has less free space than the run will write."""


@dataclass(frozen=True)
class StreamSize:
    """One recorded stream: its rate [Hz] and the bytes each message takes on disk."""

    topic: str
    rate_hz: float
    bytes_per_message: int

    @property
    def bytes_per_s(self) -> float:
        """What the stream writes per second [bytes/s]."""
        return self.rate_hz * self.bytes_per_message


def contract_streams(
    control_rate_hz: float = CONTROL_RATE_HZ, sensor_rate_hz: float = SENSOR_RATE_HZ
) -> tuple[StreamSize, ...]:
    """The recorder's streams at the given rates, sized from real CDR messages."""
    pressure = len(fluid_pressure_cdr(_STAMP_NS, 1.0e5, ambient_pa=AMBIENT_PRESSURE_PA))
    pressure += len(_FRAME_ID)
    joint = len(joint_state_cdr(_STAMP_NS, 0.1)) + len(_FRAME_ID)
    distance = len(range_cdr(_STAMP_NS, 0.05, min_range_m=0.0, max_range_m=1.0, frame_id=_FRAME_ID))
    return tuple(
        StreamSize(spec.name, rate, size + MCAP_BYTES_PER_MESSAGE)
        for spec, rate, size in (
            (PRESSURE_COMMAND, control_rate_hz, pressure),
            (ANGLE_DESIRED, control_rate_hz, joint),
            (PRESSURE_MEASURED, sensor_rate_hz, pressure),
            (TIP_ANGLE, sensor_rate_hz, joint),
            (TIP_DISTANCE, sensor_rate_hz, distance),
        )
    )


@dataclass(frozen=True)
class SpaceNeed:
    """What a run will write and where: the estimate a start-up check compares with the disk.

    Attributes:
        path: Where the recording (and the run's files) go.
        duration_s: How long the recorder runs: the run and its start and stop [s].
        bytes_per_s: What the recorded streams write per second [bytes/s].
        extra_bytes: What else the run writes there (trajectory, report, plot, logs) [bytes].
    """

    path: Path
    duration_s: float
    bytes_per_s: float
    extra_bytes: int = 0

    @property
    def estimate_bytes(self) -> int:
        """The recording and the rest, without the margin [bytes]."""
        return int(self.bytes_per_s * self.duration_s) + self.extra_bytes

    @property
    def need_bytes(self) -> int:
        """What must be free: the estimate times :data:`SPACE_MARGIN` [bytes]."""
        return int(SPACE_MARGIN * self.estimate_bytes)


def need_for(
    path: Path,
    duration_s: float,
    streams: Sequence[StreamSize] | None = None,
    extra_bytes: int = 0,
) -> SpaceNeed:
    """The space a recording of ``streams`` (default: the contract's) for ``duration_s`` takes."""
    chosen = contract_streams() if streams is None else streams
    return SpaceNeed(path, duration_s, sum(s.bytes_per_s for s in chosen), extra_bytes)


def existing_ancestor(path: Path) -> Path:
    """``path`` or the nearest directory above it that exists (where it will be created)."""
    here = path.absolute()
    while not here.exists() and here != here.parent:
        here = here.parent
    return here


def check_free_space(need: SpaceNeed, free_bytes: int | None = None) -> int:
    """Refuse a run whose recording will not fit; the free bytes when it does.

    Args:
        need: What the run will write, and where.
        free_bytes: The free space to compare with (None: ask the OS for ``need.path``'s disk).

    Raises:
        DiskSpaceError: less is free than :attr:`SpaceNeed.need_bytes`; the message gives
            the figures and the path.
    """
    if free_bytes is None:
        free_bytes = shutil.disk_usage(existing_ancestor(need.path)).free
    if free_bytes < need.need_bytes:
        raise DiskSpaceError(
            f"not enough free space for the recording at {need.path}: "
            f"{_mb(free_bytes)} free, {_mb(need.need_bytes)} needed "
            f"({need.bytes_per_s / 1e3:.0f} kB/s for {need.duration_s:.0f} s"
            + (
                f" plus {_mb(need.extra_bytes)} of report, plot and logs"
                if need.extra_bytes
                else ""
            )
            + f" = {_mb(need.estimate_bytes)}, times {SPACE_MARGIN:g} for margin); free "
            "space there, or choose another directory"
        )
    return free_bytes


def _mb(n_bytes: float) -> str:
    return f"{n_bytes / 1e6:.1f} MB"
