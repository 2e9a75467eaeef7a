"""``trajectory`` taken in a process of its own, so no message can stall the control loop.

The compensator's loop thread and rclpy's executor share one GIL. Taking a message, even
serialised, holds it while rclpy copies the whole message into a Python ``bytes``: a 32 MB
(10^6-point) message held it about 90 ms on an idle machine, and on a busy 2-core CI machine,
where the holding thread (normal priority) was pre-empted while the loop thread (real-time
priority) waited for it, over a second: 395 missed deadlines against 91 in a normal run. No
check inside the process can be earlier than that copy.

So the compensator does not subscribe to ``trajectory`` itself. It starts this module as a
child process (a helper node named ``<compensator>_intake`` in its namespace) that
subscribes serialised, refuses a message over ``MAX_TRAJECTORY_MESSAGE_BYTES`` by its length,
and hands a message within it (at most 1 MiB) to the compensator over a pipe. What the child
holds or copies never touches the compensator's GIL; the rest of the checks (point count,
duration, shape) stay in the compensator, which deserialises only what passed here.

The pipe speaks a framing we designed (not a ROS protocol): one kind byte, a little-endian
u32 length, then the payload.

- ``R``: the subscription exists (empty payload); sent once.
- ``M``: a message within the limit: a u8 length and the publisher's gid, then the CDR bytes.
- ``X``: a message refused by its length: the reason, UTF-8.

The child lives as long as its parent: it stops when the pipe to the parent breaks, when
its stdin closes, or when the parent's pid is gone (``node_main.PARENT_PID_ENV``), and it
runs in a session of its own so a Ctrl-C for the compensator's terminal reaches the
compensator first, which then stops it.
"""

from __future__ import annotations

import argparse
import os
import select
import struct
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from queue import Empty, SimpleQueue
from typing import Any, Final

from rclpy.node import Node
from trajectory_msgs.msg import JointTrajectory

from catheter_models.contract import MAX_TRAJECTORY_MESSAGE_BYTES, MAX_TRAJECTORY_POINTS
from catheter_models.errors import CatheterError
from catheter_ros import qos
from catheter_ros.node_main import PARENT_PID_ENV, run_nodes

READY: Final = b"R"
MESSAGE: Final = b"M"
REFUSED: Final = b"X"
_HEADER = struct.Struct("<cI")

READY_TIMEOUT_S: Final = 60.0
"""How long configure waits for the child's subscription: a Python start with rclpy's import
and the ROS wheels' re-exec takes 1-3 s here, far longer on a loaded machine."""

STOP_TIMEOUT_S: Final = 5.0
"""How long a stop waits for the child to exit on SIGTERM before it is killed."""


class IntakeError(CatheterError):
    """The intake process did not start, or stopped on its own."""


def oversize_refusal(n_bytes: int) -> str:
    """Why a ``trajectory`` message of ``n_bytes`` is refused, or '' within the limit."""
    if n_bytes <= MAX_TRAJECTORY_MESSAGE_BYTES:
        return ""
    return (
        f"the message is {n_bytes} bytes, over the limit of {MAX_TRAJECTORY_MESSAGE_BYTES} "
        f"(MAX_TRAJECTORY_MESSAGE_BYTES, about {MAX_TRAJECTORY_POINTS} points); not deserialised"
    )


def encode(kind: bytes, payload: bytes = b"") -> bytes:
    """One frame of the pipe."""
    return _HEADER.pack(kind, len(payload)) + payload


def message_payload(gid: bytes, data: bytes) -> bytes:
    """An ``M`` frame's payload: the publisher's gid (for the action's echo), then the CDR."""
    return bytes([len(gid)]) + gid + data


def split_message(payload: bytes) -> tuple[bytes, bytes]:
    """``(gid, cdr)`` of an ``M`` frame's payload."""
    n_gid = payload[0]
    return payload[1 : 1 + n_gid], payload[1 + n_gid :]


def _read_exactly(fd: int, n: int) -> bytes | None:
    """``n`` bytes from ``fd``, or None at end of file (blocking; the GIL is released)."""
    parts: list[bytes] = []
    while n > 0:
        chunk = os.read(fd, min(n, 1 << 20))
        if not chunk:
            return None
        parts.append(chunk)
        n -= len(chunk)
    return b"".join(parts)


def read_frame(fd: int) -> tuple[bytes, bytes] | None:
    """The next ``(kind, payload)`` from ``fd``, or None when the writer has gone.

    A frame longer than a message within the limit can be (plus its gid) is a broken pipe
    protocol, not a message: it is refused here rather than read into memory.
    """
    head = _read_exactly(fd, _HEADER.size)
    if head is None:
        return None
    kind, length = _HEADER.unpack(head)
    if length > MAX_TRAJECTORY_MESSAGE_BYTES + 256:
        raise IntakeError(f"intake frame {kind!r} of {length} bytes: over any message's size")
    payload = _read_exactly(fd, length)
    if payload is None:
        return None
    return kind, payload


class TrajectoryIntake:
    """The parent's side: start the child, and hand its frames to the executor's thread.

    ``on_message(cdr, gid)`` and ``on_refused(reason)`` run on the node's executor (through a
    guard condition), as a subscription callback would; so does ``on_lost(reason)`` when the
    child stops on its own. A reader thread blocks on the pipe, which costs the GIL only for
    what passed the size check.
    """

    def __init__(
        self,
        node: Any,
        topic: str,
        on_message: Callable[[bytes, bytes], None],
        on_refused: Callable[[str], None],
        on_lost: Callable[[str], None],
        *,
        ready_timeout_s: float = READY_TIMEOUT_S,
    ) -> None:
        self._node = node
        self._on_message, self._on_refused, self._on_lost = on_message, on_refused, on_lost
        self._queue: SimpleQueue[tuple[bytes, bytes]] = SimpleQueue()
        self._closing = threading.Event()
        self.name = f"{node.get_name()}_intake"
        read_fd, write_fd = os.pipe()
        env = dict(os.environ)
        env[PARENT_PID_ENV] = str(os.getpid())
        argv = [
            sys.executable,
            "-m",
            "catheter_control.trajectory_intake",
            "--fd",
            str(write_fd),
            "--topic",
            topic,
            "--ros-args",
            "-r",
            f"__node:={self.name}",
            "-r",
            f"__ns:={node.get_namespace()}",
        ]
        try:
            self._proc = subprocess.Popen(
                argv,
                pass_fds=(write_fd,),
                stdin=subprocess.PIPE,
                env=env,
                start_new_session=True,
            )
        finally:
            os.close(write_fd)
        self._fd = read_fd
        try:
            self._wait_ready(ready_timeout_s)
        except BaseException:
            self._stop_child()
            os.close(self._fd)
            raise
        self._guard = node.create_guard_condition(self._drain)
        self._reader = threading.Thread(target=self._read, name="trajectory_intake", daemon=True)
        self._reader.start()

    @property
    def pid(self) -> int:
        """The child's process id (on /diagnostics, so a person can find it)."""
        return self._proc.pid

    def _wait_ready(self, timeout_s: float) -> None:
        end_s = time.monotonic() + timeout_s
        while True:
            left_s = end_s - time.monotonic()
            if left_s <= 0.0:
                raise IntakeError(
                    f"trajectory intake process (pid {self._proc.pid}) did not subscribe "
                    f"within {timeout_s:g} s"
                )
            ready, _, _ = select.select([self._fd], [], [], min(left_s, 0.5))
            if ready:
                frame = read_frame(self._fd)
                if frame is None:
                    rc = self._proc.wait(STOP_TIMEOUT_S)
                    raise IntakeError(
                        f"trajectory intake process exited with code {rc} before subscribing "
                        "(its log is above)"
                    )
                if frame[0] == READY:
                    return
                raise IntakeError(f"trajectory intake process sent {frame[0]!r} before ready")

    def _read(self) -> None:
        reason = ""
        try:
            while (frame := read_frame(self._fd)) is not None:
                self._queue.put(frame)
                self._guard.trigger()
        except (IntakeError, OSError) as exc:
            reason = str(exc)
        if self._closing.is_set():
            return
        try:
            rc = self._proc.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            rc = None
        why = reason or f"exited with code {rc}"
        self._queue.put((b"L", f"trajectory intake process (pid {self._proc.pid}) {why}".encode()))
        self._guard.trigger()

    def _drain(self) -> None:
        while True:
            try:
                kind, payload = self._queue.get_nowait()
            except Empty:
                return
            if kind == MESSAGE:
                gid, cdr = split_message(payload)
                self._on_message(cdr, gid)
            elif kind == REFUSED:
                self._on_refused(payload.decode("utf-8", "replace"))
            elif kind == b"L":
                self._on_lost(payload.decode())

    def _stop_child(self) -> None:
        if self._proc.stdin is not None:
            self._proc.stdin.close()  # the child's cue to stop
        if self._proc.poll() is None:
            self._proc.terminate()
            try:
                self._proc.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()

    def close(self) -> None:
        """Stop the child and the reader; nothing is handed on after this returns."""
        self._closing.set()
        self._stop_child()
        self._reader.join(STOP_TIMEOUT_S)
        os.close(self._fd)
        self._node.destroy_guard_condition(self._guard)


# -- the child -----------------------------------------------------------------------------------


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view) :]


def _child_node(fd: int, topic: str) -> Any:
    class _IntakeNode(Node):
        """Subscribes ``topic`` serialised and passes on what is within the size limit."""

        def __init__(self) -> None:
            super().__init__("trajectory_intake")
            self.create_subscription(JointTrajectory, topic, self._on, qos.TRAJECTORY, raw=True)
            self.broken = False
            _write_all(fd, encode(READY))

        def _on(self, data: bytes, info: Any) -> None:
            refusal = oversize_refusal(len(data))
            gid = bytes((info.get("publisher_gid") or {}).get("data", b""))
            frame = (
                encode(REFUSED, refusal.encode())
                if refusal
                else encode(MESSAGE, message_payload(gid, data))
            )
            try:
                _write_all(fd, frame)
            except OSError:
                self.broken = True  # the parent has gone: stop (see main)

        def start(self) -> None:
            # stdin closes when the parent stops us or dies.
            threading.Thread(target=self._watch_stdin, daemon=True).start()

        def _watch_stdin(self) -> None:
            while sys.stdin.buffer.read(4096):
                pass
            self.broken = True

    return _IntakeNode()


def main(argv: list[str] | None = None) -> int:
    """``python -m catheter_control.trajectory_intake --fd N --topic T --ros-args ...``."""
    args = list(sys.argv[1:] if argv is None else argv)
    ros_args = args[args.index("--ros-args") :] if "--ros-args" in args else []
    own = args[: len(args) - len(ros_args)]
    parser = argparse.ArgumentParser(prog="trajectory_intake", description=__doc__)
    parser.add_argument("--fd", type=int, required=True, help="the pipe to the compensator")
    parser.add_argument("--topic", required=True, help="the fully qualified trajectory topic")
    opts = parser.parse_args(own)
    return run_nodes(
        [lambda: _child_node(opts.fd, opts.topic)],
        ["trajectory_intake", *ros_args],
        until=lambda nodes: any(getattr(n, "broken", False) for n in nodes),
    )


if __name__ == "__main__":
    sys.exit(main())
