"""Wire protocols as pure functions and streaming parsers: bytes in, values out, no I/O.

Encoders refuse values the wire cannot carry (:class:`~catheter_models.errors.ParameterError`);
decoders of single frames raise :class:`FrameError`; streaming parsers never raise on input,
they drop and count it (:class:`ParserCounters`).
"""

from __future__ import annotations

from dataclasses import dataclass

from catheter_models.errors import CatheterError


class FrameError(CatheterError, ValueError):
    """A frame is malformed: wrong length, header, checksum or field. The message says which."""


@dataclass
class ParserCounters:
    """What a streaming parser did with its input since it was created.

    Attributes:
        frames_ok: frames accepted.
        frame_errors: runs of bytes dropped as garbage (one per run, not per byte).
        crc_failures: well-formed frames dropped for a bad checksum.
        bytes_dropped: bytes dropped in total.
    """

    frames_ok: int = 0
    frame_errors: int = 0
    crc_failures: int = 0
    bytes_dropped: int = 0
