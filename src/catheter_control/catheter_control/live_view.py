"""Stream the running graph to Foxglove over a WebSocket (subprotocol ``foxglove.sdk.v1``).

    follow_trajectory --sim --live           # then Foxglove: Open connection, ws://localhost:8765
    live_view --port 8765                    # beside any running graph, on its own

The contract's streams (``pressure/command``, ``pressure/measured``, ``tip/angle``,
``tip/distance``, ``angle/desired``, ``trajectory``, ``/diagnostics``) are forwarded as they
came off the wire: serialised CDR with their ROS 2 message definitions, under the topic names a
bag has. So the layout shipped with the package (``foxglove/catheter_layout.json``) shows a live
run and a recorded bag alike. Beside them it sends what the view needs and a bag lacks: the URDF
(``robot_description``, and as the asset ``package://catheter_control/urdf/catheter.urdf``),
``joint_states`` and ``/tf`` + ``/tf_static`` from ``tip/angle`` (:mod:`catheter_control.tip_tf`).

It stays off the control path. It never runs in the compensator: ``follow_trajectory --live``
starts it as a child process at niceness 10 (:class:`LiveViewProcess`); it subscribes best
effort, so no publisher ever re-sends to it or waits for it; it takes messages raw (no
deserialising, except ``tip/angle`` for the TF) on rclpy's EventsExecutor in a thread of its
own. What it misses it counts: a sample that never reached it shows as a gap in the stream's
header stamps (``catheter_models.gaps``), and :meth:`LiveView.summary` and the ``live_view``
status on ``/diagnostics`` report it per topic.
A Foxglove client that reads too slowly loses its own oldest messages in the server's
per-client queue (``message_backlog_size``); the server does not report those.

The server binds 127.0.0.1 unless told otherwise: it has no authentication, and anyone who can
reach the port can read everything the graph says. Use an SSH tunnel to watch from elsewhere.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Final

import foxglove
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental.events_executor import EventsExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from rclpy.utilities import remove_ros_args

from catheter_control.tip_tf import (
    BASE_FRAME,
    DISTAL_FRAME,
    TIP_FRAME,
    URDF_PACKAGE_URL,
    TipTf,
    chain,
    urdf_text,
)
from catheter_models.bag.messages import kilted_typestore
from catheter_models.contract import (
    ANGLE_DESIRED,
    DEFAULT_NAMESPACE,
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
    TRAJECTORY,
    TopicSpec,
    qualify,
)
from catheter_models.errors import ParameterError
from catheter_models.gaps import StreamGaps, header_stamp_ns, pauses_between_runs
from catheter_ros import diagnostics
from catheter_ros.messages import angle_rad_from, joint_state, message_class

DEFAULT_PORT: Final = 8765
"""Foxglove's default WebSocket port, which its "Open connection" dialog suggests."""
DEFAULT_HOST: Final = "127.0.0.1"

FORWARDED: Final = (
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TIP_DISTANCE,
    ANGLE_DESIRED,
    TRAJECTORY,
    DIAGNOSTICS,
)
"""Graph topics sent to Foxglove as they are."""

STREAMS: Final = frozenset(
    {PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE, TIP_DISTANCE, ANGLE_DESIRED}
)
"""The periodic ones, whose losses the header stamps reveal."""

_ROBOT_DESCRIPTION: Final = TopicSpec("robot_description", "std_msgs/msg/String")
_JOINT_STATES: Final = TopicSpec("joint_states", "sensor_msgs/msg/JointState")
_TF: Final = TopicSpec("/tf", "tf2_msgs/msg/TFMessage")
_TF_STATIC: Final = TopicSpec("/tf_static", "tf2_msgs/msg/TFMessage")

_REPEAT_S: Final = 1.0
"""How often the URDF and the static transform are sent again: a WebSocket channel has no
latching, and a client that connects later needs them too."""
_DEPTH: Final = 250
"""Reader history per topic (1 s at 250 Hz): the niced view may wait that long for a CPU on a
busy machine before samples are overwritten (and then counted as lost)."""
BACKLOG: Final = 4096
"""Messages the server queues for one slow client (about 3 s of everything) before it drops
that client's oldest."""


@dataclass
class TopicStats:
    """What one forwarded topic did: messages forwarded, and samples missed (from stamps)."""

    forwarded: int = 0
    gaps: StreamGaps | None = None

    @property
    def lost(self) -> int:
        """Samples missed (0 for a topic that is not a periodic stream)."""
        return 0 if self.gaps is None else self.gaps.lost


def _schema(msgtype: str) -> foxglove.Schema:
    """The ROS 2 message definition of ``msgtype`` as a Foxglove schema (as our bags carry it)."""
    text, _ = kilted_typestore().generate_msgdef(msgtype, ros_version=2)
    return foxglove.Schema(name=msgtype, encoding="ros2msg", data=text.encode("utf-8"))


def _cdr(msgtype: str, msg: Any) -> bytes:
    """Serialise a rosbags message object to CDR (for types without an rclpy wheel here)."""
    return bytes(kilted_typestore().serialize_cdr(msg, msgtype))


class LiveView:
    """A Foxglove WebSocket server fed from the ROS graph; :meth:`start`, then :meth:`stop`.

    Args:
        port: TCP port (0: any free one; :attr:`port` says which).
        host: address to bind; 127.0.0.1 by default (see the module docstring).
        namespace: the graph's namespace.
    """

    def __init__(
        self, port: int = DEFAULT_PORT, host: str = DEFAULT_HOST, namespace: str = DEFAULT_NAMESPACE
    ) -> None:
        if not 0 <= port <= 65535:
            raise ParameterError(f"live view: port must be 0..65535, got {port}")
        self.requested_port = port
        self.host = host
        self.namespace = namespace
        self.stats: dict[str, TopicStats] = {}
        self.bad_tip_angle = 0
        """``tip/angle`` messages without the ``bend`` joint (forwarded, but no TF from them)."""
        self.port = 0
        self._server: Any = None
        self._channels: dict[str, foxglove.Channel] = {}
        self._context: Any = None
        self._node: Any = None
        self._executor: Any = None
        self._thread: threading.Thread | None = None
        self._tip_tf: TipTf | None = None
        self._stop = threading.Event()
        self._repeat_thread: threading.Thread | None = None
        self._diag_pub: Any = None

    # -- lifecycle ---------------------------------------------------------------------------
    def start(self) -> LiveView:
        """Open the server and subscribe to the graph (returns self).

        Raises:
            ParameterError: the port cannot be bound (in use, or not allowed).
        """
        try:
            self._server = foxglove.start_server(
                name="catheter",
                host=self.host,
                port=self.requested_port,
                asset_handler=self._asset,
                message_backlog_size=BACKLOG,
            )
        except RuntimeError as exc:
            raise ParameterError(
                f"live view: cannot serve on {self.host}:{self.requested_port}: {exc}"
            ) from None
        self.port = int(self._server.port)
        for spec in (*FORWARDED, _ROBOT_DESCRIPTION, _JOINT_STATES, _TF, _TF_STATIC):
            topic = qualify(spec, self.namespace)
            self._channels[topic] = foxglove.Channel(
                topic, schema=_schema(spec.msgtype), message_encoding="cdr"
            )
        # A context of its own: the host process (follow_trajectory) spins the default one
        # itself, one message at a time, and must not find these callbacks in its way.
        self._context = rclpy.Context()
        self._context.init(args=["live_view", "--ros-args", "-r", f"__ns:={self.namespace}"])
        self._node = Node("live_view", context=self._context)
        self._tip_tf = TipTf(self._node)
        for spec in FORWARDED:
            self._forward(spec)
        self._diag_pub = diagnostics.create_diagnostics_publisher(self._node)
        self._node.create_timer(1.0, self._publish_diagnostics)
        self._executor = EventsExecutor(context=self._context)
        self._executor.add_node(self._node)
        self._thread = threading.Thread(target=self._spin, name="live_view", daemon=True)
        self._thread.start()
        self._repeat_thread = threading.Thread(
            target=self._repeat, name="live_view_latched", daemon=True
        )
        self._repeat_thread.start()
        return self

    def stop(self) -> None:
        """Close the server and leave the graph (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None
        if self._repeat_thread is not None:
            self._repeat_thread.join(5.0)
            self._repeat_thread = None
        if self._executor is not None:
            self._executor.shutdown()
            self._executor = None
        if self._node is not None:
            self._node.destroy_node()
            self._node = None
        if self._context is not None:
            self._context.try_shutdown()
            self._context = None
        if self._server is not None:
            self._server.stop()
            self._server = None
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()

    def __enter__(self) -> LiveView:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def url(self) -> str:
        """Where Foxglove connects."""
        return f"ws://{'localhost' if self.host == DEFAULT_HOST else self.host}:{self.port}"

    # -- intake (executor thread) ------------------------------------------------------------
    def _spin(self) -> None:

        # spin_once with a timeout, not spin(): the EventsExecutor's shutdown() does not stop
        # a spin() in another thread (seen: stop() hung there).
        with contextlib.suppress(ExternalShutdownException):
            while not self._stop.is_set():
                self._executor.spin_once(timeout_sec=0.1)

    def _forward(self, spec: TopicSpec) -> None:

        topic = qualify(spec, self.namespace)
        channel = self._channels[topic]
        stats = self.stats[topic] = TopicStats(
            gaps=StreamGaps(pauses=pauses_between_runs(spec.name)) if spec in STREAMS else None
        )
        cls = message_class(spec.msgtype)
        tip_tf = self._tip_tf if spec == TIP_ANGLE else None

        def on_message(data: bytes) -> None:
            now_ns = time.time_ns()
            stamp_ns = header_stamp_ns(data)
            if stats.gaps is not None and stamp_ns is not None:
                stats.gaps.add(stamp_ns)
            channel.log(data, log_time=now_ns)
            stats.forwarded += 1
            if tip_tf is not None and stamp_ns is not None:
                try:
                    angle_rad = angle_rad_from(deserialize_message(data, cls))
                except ValueError:
                    self.bad_tip_angle += 1
                    return
                if tip_tf.on_angle(stamp_ns, angle_rad):
                    self._log_tf(stamp_ns, angle_rad)

        # Best effort: no publisher re-sends to the view or waits on it. `trajectory` keeps
        # its transient-local durability so a view started mid-run still shows the plan.
        latched = spec == TRAJECTORY
        profile = QoSProfile(
            depth=1 if latched else _DEPTH,
            reliability=ReliabilityPolicy.RELIABLE if latched else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE,
        )
        self._node.create_subscription(cls, spec.name, on_message, profile, raw=True)

    def _log_tf(self, stamp_ns: int, angle_rad: float) -> None:

        now_ns = time.time_ns()
        self._channels[qualify(_JOINT_STATES, self.namespace)].log(
            serialize_message(joint_state(angle_rad, stamp_ns)), log_time=now_ns
        )
        self._channels[_TF.name].log(
            self._tf_cdr(stamp_ns, angle_rad, BASE_FRAME, DISTAL_FRAME), log_time=now_ns
        )

    @staticmethod
    def _tf_cdr(stamp_ns: int, angle_rad: float, parent: str, child: str) -> bytes:

        types = kilted_typestore().types
        time_t = types["builtin_interfaces/msg/Time"]
        (x, y, z), (qx, qy, qz, qw) = chain().transforms(angle_rad)[(parent, child)]
        sec, nanosec = divmod(stamp_ns, 1_000_000_000)
        transform = types["geometry_msgs/msg/TransformStamped"](
            header=types["std_msgs/msg/Header"](
                stamp=time_t(sec=sec, nanosec=nanosec), frame_id=parent
            ),
            child_frame_id=child,
            transform=types["geometry_msgs/msg/Transform"](
                translation=types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z),
                rotation=types["geometry_msgs/msg/Quaternion"](x=qx, y=qy, z=qz, w=qw),
            ),
        )
        return _cdr(_TF.msgtype, types[_TF.msgtype](transforms=[transform]))

    # -- latched data and assets -------------------------------------------------------------
    def _repeat(self) -> None:

        description = _cdr(
            _ROBOT_DESCRIPTION.msgtype,
            kilted_typestore().types[_ROBOT_DESCRIPTION.msgtype](data=urdf_text()),
        )
        while not self._stop.is_set():
            now_ns = time.time_ns()
            channels = self._channels
            described = channels.get(qualify(_ROBOT_DESCRIPTION, self.namespace))
            static = channels.get(_TF_STATIC.name)
            if described is None or static is None:
                return
            described.log(description, log_time=now_ns)
            static.log(self._tf_cdr(now_ns, 0.0, DISTAL_FRAME, TIP_FRAME), log_time=now_ns)
            self._stop.wait(_REPEAT_S)

    @staticmethod
    def _asset(uri: str) -> bytes | None:
        """Foxglove fetches the model by its package URL; nothing else is served."""
        return urdf_text().encode("utf-8") if uri == URDF_PACKAGE_URL else None

    # -- reporting ---------------------------------------------------------------------------
    def lost(self) -> dict[str, int]:
        """Samples of each stream that never reached the view (from gaps in their stamps)."""
        return {t: s.lost for t, s in self.stats.items() if s.gaps is not None}

    def summary(self) -> str:
        """One line for a person: forwarded and lost, by topic where anything was lost."""
        forwarded = sum(s.forwarded for s in self.stats.values())
        lost = {t: n for t, n in self.lost().items() if n}
        text = f"live view on {self.url}: forwarded {forwarded} messages"
        if lost:
            text += "; missed " + ", ".join(
                f"{n} of {t} ({100.0 * n / (n + self.stats[t].forwarded):.1f} %)"
                for t, n in lost.items()
            )
        else:
            text += ", missed none"
        if self.bad_tip_angle:
            text += f"; {self.bad_tip_angle} tip/angle without joint 'bend' (no TF from them)"
        return text

    def _publish_diagnostics(self) -> None:
        values: dict[str, object] = {"url": self.url}
        values.update({f"forwarded {t}": s.forwarded for t, s in self.stats.items()})
        values.update({f"lost {t}": n for t, n in self.lost().items()})
        values["tip_angle_without_bend"] = self.bad_tip_angle
        lost = {t: n for t, n in self.lost().items() if n}
        level, message = diagnostics.OK, "streaming"
        if lost:
            level = diagnostics.WARN
            message = "streaming; missed " + ", ".join(f"{n} of {t}" for t, n in lost.items())
        diagnostics.publish_status(
            self._diag_pub, self._node, level=level, message=message, values=values
        )


def parse_port(text: str) -> int:
    """The ``argparse`` type of a TCP port, with a message that names the bad value."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"port must be a number 0..65535, got {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"port must be 0..65535, got {port}")
    return port


READY: Final = "live_view: Foxglove -> Open connection -> "
"""The line ``live_view`` prints once it serves (then the URL); :class:`LiveViewProcess` waits
for it."""
NICE: Final = 10
"""The view's niceness: below the graph's nodes and the process that scores the run."""
_START_TIMEOUT_S: Final = 30.0
"""Importing rclpy and the SDK takes seconds on a busy 2-core machine."""


def main(argv: list[str] | None = None) -> int:
    """``live_view``: serve the running graph to Foxglove until Ctrl-C (or its parent exits)."""
    parser = argparse.ArgumentParser(
        prog="live_view", description="Stream the running catheter graph to Foxglove."
    )
    parser.add_argument("--port", type=parse_port, default=DEFAULT_PORT)
    parser.add_argument(
        "--host",
        default=DEFAULT_HOST,
        help="address to bind (default 127.0.0.1; the server has no authentication)",
    )
    parser.add_argument(
        "--namespace", default=DEFAULT_NAMESPACE, help="the graph's (or -r __ns:=/x)"
    )
    parser.add_argument(
        "--nice", type=int, default=NICE, help=f"niceness increment (default {NICE})"
    )
    given = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(remove_ros_args(["live_view", *given])[1:])
    # `--ros-args -r __ns:=/x` names the graph's namespace, as for the other executables.
    remapped = [a.removeprefix("__ns:=") for a in given if a.startswith("__ns:=")]
    if remapped:
        args.namespace = remapped[-1]
    os.nice(args.nice)
    parent_pid = os.getppid()
    try:
        view = LiveView(args.port, args.host, args.namespace).start()
    except ParameterError as exc:
        print(f"live_view: {exc}", file=sys.stderr, flush=True)
        return 2
    stop = threading.Event()
    # Handlers of our own, set after start(): by then something below rclpy or the SDK has
    # replaced Python's at the C level and Ctrl-C no longer raised KeyboardInterrupt (seen).
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    print(f"{READY}{view.url} (Ctrl-C stops)", flush=True)
    try:
        # A launcher killed with -9 cannot stop us: leave with it rather than serve on.
        while not stop.wait(0.5) and os.getppid() == parent_pid:
            pass
    finally:
        view.stop()
        print(f"live_view: {view.summary()}", flush=True)
    return 0


class LiveViewProcess:
    """``live_view`` as a child process, for a tool that runs the graph (``follow_trajectory``).

    A process of its own because, in the tool's process, the view's callbacks took the GIL
    from the tool's own intake: ``follow_trajectory`` then missed 1,019 of 1,500 ``tip/angle``
    samples it scores a run on (2 cores, load 10), against none without the view. Apart and
    niced, it competes for CPU below everything that matters.
    """

    def __init__(self, port: int, namespace: str = DEFAULT_NAMESPACE) -> None:
        self.port = port
        self.namespace = namespace
        self.url = ""
        self._proc: subprocess.Popen[str] | None = None

    def start(self) -> LiveViewProcess:
        """Start it and wait until it serves (returns self).

        Raises:
            ParameterError: it could not serve (port taken), with what it said.
        """
        argv = [sys.executable, "-m", "catheter_control.live_view", "--port", str(self.port)]
        argv += ["--namespace", self.namespace]
        self._proc = proc = subprocess.Popen(
            argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )
        assert proc.stdout is not None
        ready = threading.Event()
        said: list[str] = []

        def read_first() -> None:
            for line in proc.stdout:  # type: ignore[union-attr]
                said.append(line.rstrip())
                if line.startswith(READY):
                    ready.set()
                    return

        reader = threading.Thread(target=read_first, daemon=True)
        reader.start()
        reader.join(_START_TIMEOUT_S)
        if not ready.is_set():
            self.stop()
            raise ParameterError(
                "live view did not start: " + (" | ".join(said) or f"silent {_START_TIMEOUT_S} s")
            )
        self.url = said[-1][len(READY) :].split()[0]
        return self

    def stop(self) -> str:
        """Stop it; returns what it said since it started serving (its summary)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return ""
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=15.0)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
        return out.strip()


def entry() -> None:
    """Console-script wrapper that turns the return code into the exit status."""
    sys.exit(main())


if __name__ == "__main__":
    entry()
