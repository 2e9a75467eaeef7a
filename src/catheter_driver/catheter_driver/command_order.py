"""Commands in the order they were meant: a driver refuses one stamped before the last applied.

A pressure command's stamp is its intended application time (docs/interfaces.md). One that
arrives after a newer one (reordered on the wire, or late behind it) carries an older intent;
applying it would step the valve back. Both drivers (``sim_hardware`` and ``valve_driver``)
keep one of these; venting forgets the last stamp, so a new publisher, or a clock stepped
back, is taken after at most one watchdog period.
"""

from __future__ import annotations


class CommandOrder:
    """The stamp of the last command applied, and the count of those refused as older."""

    def __init__(self) -> None:
        self._last_ns: int | None = None
        self.refused = 0

    def admit(self, stamp_ns: int | None) -> str:
        """'' if a command stamped ``stamp_ns`` may be applied (and remember it), else why not.

        ``None`` (no stamp known) is always admitted and changes nothing.
        """
        if stamp_ns is None:
            return ""
        if self._last_ns is not None and stamp_ns < self._last_ns:
            self.refused += 1
            return (
                "refused out-of-order pressure command: stamped "
                f"{(self._last_ns - stamp_ns) * 1e-6:.1f} ms before the last one applied"
            )
        self._last_ns = stamp_ns
        return ""

    def forget(self) -> None:
        """Venting: the next command is taken whatever its stamp."""
        self._last_ns = None
