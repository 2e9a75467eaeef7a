"""The emulator's end of a pseudo-terminal pair: the driver opens :attr:`slave_path`.

The driver side is a real tty, so the real :class:`SerialTransport` opens it like a USB
adapter. The emulator keeps the slave open too, so the pty survives the driver closing and
reopening it, and writes to the master without blocking: bytes no one reads are dropped
(counted), as a real device's UART would overrun rather than stall.

:class:`PtyDevice` puts a stable symlink in front of an endpoint and can unplug and replug
it, as the rig program's ``unplug``/``replug`` commands do.
"""

from __future__ import annotations

import contextlib
import errno
import os
import select
import tty
from pathlib import Path
from typing import Any

from catheter_driver.transports.base import ByteTransport, TransportError


class PtyEndpoint(ByteTransport):
    """A pty master as a :class:`ByteTransport` (POSIX only).

    The pair is created at construction, so :attr:`slave_path` is known before the emulator
    starts; :meth:`close` destroys it (the driver's reads then fail: an unplugged device).
    """

    def __init__(self) -> None:
        self._master: int | None = None
        self._slave: int | None = None
        self.slave_path = ""
        self.bytes_dropped = 0
        """Bytes written while the driver's input buffer was full."""
        self._create()

    def _create(self) -> None:
        master, slave = os.openpty()
        # Raw mode: no echo, no line editing, no CR/LF translation; binary frames pass intact.
        tty.setraw(slave)
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.slave_path = os.ttyname(slave)

    def describe(self) -> str:
        """E.g. ``pty master of /dev/pts/4``."""
        return f"pty master of {self.slave_path or '(closed)'}"

    def open(self) -> None:
        """Re-create the pair if it was closed (a new slave path)."""
        if self._master is None:
            self._create()

    def close(self) -> None:
        """Close both ends (idempotent)."""
        for fd in (self._master, self._slave):
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self._master = self._slave = None

    @property
    def is_open(self) -> bool:
        """Whether the pair exists."""
        return self._master is not None

    def _require(self) -> int:
        if self._master is None:
            raise TransportError(f"{self.describe()} is closed")
        return self._master

    def write(self, data: bytes) -> None:
        """Write without blocking; what does not fit is dropped and counted."""
        fd = self._require()
        view = memoryview(data)
        while view:
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                self.bytes_dropped += len(view)
                return
            except OSError as exc:
                raise TransportError(f"write to {self.describe()} failed: {exc}") from None
            view = view[n:]

    def read(self, n: int, timeout_s: float) -> bytes:
        """Up to ``n`` bytes as soon as one is there; empty after ``timeout_s`` [s]."""
        fd = self._require()
        try:
            ready, _, _ = select.select([fd], [], [], max(timeout_s, 0.0))
            if not ready:
                return b""
            return os.read(fd, n)
        except BlockingIOError:
            return b""
        except OSError as exc:
            if exc.errno == errno.EIO:
                return b""  # no slave open right now (only if the emulator's was closed)
            raise TransportError(f"read from {self.describe()} failed: {exc}") from None
        except ValueError as exc:  # fd closed under select by another thread
            raise TransportError(f"read from {self.describe()} failed: {exc}") from None

    def reset_input(self) -> None:
        """Discard what the driver has sent and we have not read."""
        while self.read(4096, 0.0):
            pass


class PtyDevice:
    """A pty endpoint reachable at a stable symlink, which can be unplugged and replugged.

    The symlink stands for the path a udev rule gives a real adapter: a driver finds a
    replugged device at the same path although its ``/dev/pts/N`` changed.

    Args:
        endpoint: the emulator's end of the pty.
        link: where the symlink goes (replaced if it exists).
    """

    def __init__(self, endpoint: PtyEndpoint, link: Path) -> None:
        self.endpoint = endpoint
        self.link = link
        self.plugged = True
        self._point_link()

    def _point_link(self) -> None:
        # Atomic: a driver opening the path sees the old target or the new one, never none.
        tmp = self.link.with_name(f".{self.link.name}.tmp")
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        tmp.symlink_to(self.endpoint.slave_path)
        tmp.replace(self.link)

    def unplug(self) -> None:
        """Close the pty (the driver's port dies) and remove the symlink, as udev would.

        The emulator keeps running, as a device keeps its own power: a valve interface's
        fail-safe still vents.
        """
        self.endpoint.close()
        with contextlib.suppress(FileNotFoundError):
            self.link.unlink()
        self.plugged = False

    def replug(self) -> None:
        """A new pty (a new /dev/pts/N); the symlink points at it."""
        self.endpoint.open()
        self._point_link()
        self.plugged = True

    def state(self) -> dict[str, Any]:
        """Plain values for a status report: the symlink, its pty, whether plugged."""
        return {
            "port": str(self.link),
            "pty": self.endpoint.slave_path if self.plugged else None,
            "plugged": self.plugged,
        }
