"""Process handling for the DDS integration tests: domains, child processes, bounded waits.

Every test that starts DDS participants gets its own ``ROS_DOMAIN_ID`` (100-230, from the pid
and a counter) and discovery limited to this machine, so parallel runs (and the lead's
``make_sample_bags.py`` on domain 77) never see each other. Every child is tracked by a
:class:`Children` and stopped at teardown, even when the test failed; every wait is bounded.
"""

from __future__ import annotations

import itertools
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from catheter_control.bringup import NodeSpec, ProcessGraph
from catheter_models.contract import DEFAULT_NAMESPACE
from catheter_models.units import AMBIENT_PRESSURE_PA

DOMAIN_LOW, DOMAIN_HIGH = 100, 230
_domain_counter = itertools.count()


COMPENSATOR = "catheter/compensator"
SIM = "catheter/sim_hardware"
"""/diagnostics status names of the compensator and the simulated rig."""
MAX_PRESSURE_PA = 3.0e5
"""The command range's top (compensator and drivers), gauge."""
NOISE_MARGIN_PA = 2000.0
"""Pressure transmitter noise is 300 Pa std (rig.pressure_noise_pa): 2000 Pa is > 6 sigma."""
SLACK_SENSOR_TIMEOUT_S = 0.5
"""The compensator's ``sensor_timeout_s`` for tests that are not about it. Beside two busy
loops on a 2-core machine, the rig's and the laser's Python processes go quiet for 100 ms or more
at times, and the node's 0.1 s default then ramps down, as it must on a rig. test_compensator's
timeout tests keep the default; test_faults judges the stop of a killed rig against this limit."""


def unique_domain_id() -> int:
    """A ROS_DOMAIN_ID in [100, 230] that differs for each call in this process."""
    span = DOMAIN_HIGH - DOMAIN_LOW + 1
    return DOMAIN_LOW + (os.getpid() * 7 + next(_domain_counter)) % span


def ros_env(domain_id: int, log_dir: Path) -> dict[str, str]:
    """Environment additions of every child: own domain, localhost discovery, own log dir."""
    return {
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "ROS_LOG_DIR": str(log_dir / "ros"),
        "PYTHONUNBUFFERED": "1",
    }


def node_argv(module: str, params: Mapping[str, object] | None = None) -> list[str]:
    """``python -m <module> --ros-args -r __ns:=/catheter -p k:=v ...`` for a node run alone.

    A lifecycle node gets ``autostart:=true`` (unless ``params`` says otherwise): started
    alone, nothing else configures and activates it. Graphs started through
    :meth:`Children.graph` are driven through the lifecycle services by ``bringup``'s manager.
    """
    spec = NodeSpec(module.rsplit(".", 1)[-1], module, dict(params or {}))
    if spec.lifecycle:
        spec.params.setdefault("autostart", True)
    return spec.argv(DEFAULT_NAMESPACE)


def follow_argv(*args: str) -> list[str]:
    """``follow_trajectory`` with ``args``, as a person runs it, in this interpreter."""
    return [sys.executable, "-m", "catheter_control.follow_trajectory", *args]


def _stop(proc: subprocess.Popen[bytes], sig: int = signal.SIGINT, timeout_s: float = 10.0) -> int:
    """Signal a child, then SIGKILL it if it has not exited within ``timeout_s``."""
    if proc.poll() is None:
        proc.send_signal(sig)
        try:
            proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(10.0)
    return proc.returncode


class Children:
    """The child processes of one test, with their logs; :meth:`close` stops them all.

    Args:
        env: environment additions of every child (see :func:`ros_env`).
        log_dir: each child's combined stdout/stderr goes to ``<log_dir>/<name>.log``.
    """

    def __init__(self, env: Mapping[str, str], log_dir: Path) -> None:
        self.env = dict(env)
        self.log_dir = log_dir
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self.graphs: list[ProcessGraph] = []

    @property
    def domain_id(self) -> int:
        """The ROS_DOMAIN_ID of every child."""
        return int(self.env["ROS_DOMAIN_ID"])

    def full_env(self) -> dict[str, str]:
        """This process's environment with the children's additions."""
        return {**os.environ, **self.env}

    def graph(self, specs: Sequence[NodeSpec], log_subdir: str = "graph") -> ProcessGraph:
        """Start ``specs`` as a :class:`ProcessGraph` (stopped in order at teardown)."""
        graph = ProcessGraph(specs, DEFAULT_NAMESPACE, self.log_dir / log_subdir, self.env)
        self.graphs.append(graph)
        graph.start()
        return graph

    def start(self, name: str, argv: Sequence[str]) -> subprocess.Popen[bytes]:
        """Start one child; its output goes to ``<name>.log``."""
        if name in self.procs:
            raise ValueError(f"child {name!r} already started")
        with (self.log_dir / f"{name}.log").open("wb") as out:
            proc = subprocess.Popen(
                list(argv), stdout=out, stderr=subprocess.STDOUT, env=self.full_env()
            )
        self.procs[name] = proc
        return proc

    def run(self, name: str, argv: Sequence[str], timeout_s: float) -> subprocess.CompletedProcess:
        """Run one child to completion (killed after ``timeout_s``); output captured as text.

        Raises:
            AssertionError: it did not finish within ``timeout_s`` (it is killed first).
        """
        proc = subprocess.Popen(
            list(argv),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=self.full_env(),
            text=True,
        )
        self.procs[name] = proc  # type: ignore[assignment]
        try:
            out, err = proc.communicate(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            out, err = proc.communicate(timeout=10.0)
            (self.log_dir / f"{name}.log").write_text(out + err)
            raise AssertionError(
                f"{name} did not finish within {timeout_s:g} s; output:\n{out}\n{err}"
            ) from None
        (self.log_dir / f"{name}.log").write_text(out + err)
        return subprocess.CompletedProcess(proc.args, proc.returncode, out, err)

    def log(self, name: str, graph_subdir: str | None = None) -> str:
        """A child's log so far (``graph_subdir``: a node of a graph started here)."""
        base = self.log_dir / graph_subdir if graph_subdir else self.log_dir
        path = base / f"{name}.log"
        return path.read_text(errors="replace") if path.exists() else ""

    def all_logs(self, tail_lines: int = 30) -> str:
        """Tails of every log under ``log_dir`` (for failure reports)."""
        parts = []
        for path in sorted(self.log_dir.rglob("*.log")):
            lines = path.read_text(errors="replace").splitlines()[-tail_lines:]
            parts.append(f"--- {path.relative_to(self.log_dir)} ---\n" + "\n".join(lines))
        return "\n".join(parts)

    def close(self) -> None:
        """Stop every graph (ordered SIGINT) and every child; SIGKILL what does not exit."""
        for graph in reversed(self.graphs):
            graph.stop(timeout_s=10.0)
        for proc in self.procs.values():
            _stop(proc)  # type: ignore[arg-type]


# -- a test-side ROS node, in this process -----------------------------------------------------


@dataclass
class Stamped:
    """A received message with the monotonic time it arrived."""

    mono_s: float
    msg: Any


class Probe:
    """An rclpy node in the test process, on its own context and the test's domain.

    ``ROS_DOMAIN_ID`` and the discovery range are read when the context initialises, so the
    environment is set just before ``rclpy.init`` and restored afterwards.
    """

    def __init__(self, domain_id: int, name: str = "test_probe") -> None:
        self.domain_id = domain_id
        self.name = name
        self.received: dict[str, list[Stamped]] = {}
        self.subscriptions: dict[str, Any] = {}

    def __enter__(self) -> Probe:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.signals import SignalHandlerOptions

        self._saved_env = {
            k: os.environ.get(k) for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")
        }
        os.environ["ROS_DOMAIN_ID"] = str(self.domain_id)
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        self.context = Context()
        rclpy.init(
            context=self.context,
            domain_id=self.domain_id,
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self.node = Node(self.name, namespace=DEFAULT_NAMESPACE, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        return self

    def __exit__(self, *exc: object) -> None:
        import rclpy

        try:
            self.executor.shutdown(timeout_sec=2.0)
            self.node.destroy_node()
        finally:
            rclpy.shutdown(context=self.context)
            for key, value in self._saved_env.items():
                if value is None:
                    os.environ.pop(key, None)
                else:
                    os.environ[key] = value

    def subscribe(self, msg_type: type, topic: str, qos: Any) -> list[Stamped]:
        """Keep every message on ``topic``; returns the (growing) list."""
        store = self.received.setdefault(topic, [])

        def keep(msg: Any) -> None:
            store.append(Stamped(time.monotonic(), msg))

        self.subscriptions[topic] = self.node.create_subscription(msg_type, topic, keep, qos)
        return store

    def spin_for(self, seconds: float) -> None:
        """Process callbacks for ``seconds``."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            self.executor.spin_once(timeout_sec=min(0.05, left))

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Process callbacks until ``predicate`` holds or ``timeout_s`` passes."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()


def diagnostic_values(status: Any) -> dict[str, str]:
    """A DiagnosticStatus's key/values as a dict."""
    return {kv.key: kv.value for kv in status.values}


def statuses(messages: Sequence[Stamped], node_name: str) -> list[Any]:
    """DiagnosticStatus entries of one node (e.g. ``catheter/sim_hardware``), oldest first."""
    return [s for m in messages for s in m.msg.status if s.name == node_name]


def recorder_values(probe: Probe) -> dict[str, str]:
    """The recorder's latest /diagnostics values seen by ``probe`` (which must subscribe to
    ``/diagnostics`` first, see :meth:`Probe.subscribe`); empty if none yet."""
    values: dict[str, str] = {}
    for status in statuses(probe.received.get("/diagnostics", []), "catheter/recorder"):
        values = diagnostic_values(status)
    return values


def wait_for_recorder(probe: Probe, topics: Sequence[str], timeout_s: float) -> dict[str, str]:
    """Wait until the recorder says on /diagnostics that it hears a publisher on each topic.

    Discovery between two processes can take seconds; a run started before the recorder has
    matched the publishers would be missing from the bag. Returns the recorder's last values.

    Raises:
        AssertionError: not within ``timeout_s``; names the topics still unmatched.
    """

    def unmatched() -> list[str]:
        values = recorder_values(probe)
        return [t for t in topics if int(values.get(f"publishers {t}", "0")) < 1]

    ok = probe.spin_until(lambda: bool(recorder_values(probe)) and not unmatched(), timeout_s)
    assert ok, (
        f"recorder hears no publisher on {unmatched()} after {timeout_s:g} s: "
        f"{recorder_values(probe)}"
    )
    return recorder_values(probe)


def trajectory_msg(points: Sequence[tuple[float, float]]) -> Any:
    """JointTrajectory for joint ``bend`` from (time_from_start [s], angle [deg]) points."""
    import math

    from builtin_interfaces.msg import Duration
    from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

    msg = JointTrajectory()
    msg.joint_names = ["bend"]
    for t, angle_deg in points:
        point = JointTrajectoryPoint()
        point.positions = [math.radians(angle_deg)]
        point.time_from_start = Duration(sec=int(t), nanosec=round((t - int(t)) * 1e9))
        msg.points.append(point)
    return msg


def gauge_pa(stamped: Sequence[Stamped]) -> np.ndarray:
    """Gauge pressure [Pa] of received FluidPressure messages (absolute on the wire)."""
    return np.array([m.msg.fluid_pressure - AMBIENT_PRESSURE_PA for m in stamped])
