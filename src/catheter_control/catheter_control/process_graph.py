"""Run a graph's nodes as processes (or composed in one), configured and stopped in order.

:class:`NodeSpec` is one node as a launcher runs it; :class:`ProcessGraph` starts a list of
them as child processes, configures and activates the lifecycle nodes through their services
(catheter_ros.lifecycle_client), and stops them in an order that is safe for the catheter
and complete for the record: the compensator deactivated first (its ramp-down), then every
node in reverse start order, the recorder last. :func:`run_composed` runs the same nodes on
one executor in this process. ``bringup``, ``follow_trajectory --sim``, ``commission`` and the
integration tests start their graphs through it; which nodes make up a graph is
:mod:`catheter_control.graph_description`'s.

Apart from :mod:`catheter_control.bringup`, which is the command line that chooses a graph.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import TYPE_CHECKING

from catheter_control.graph_description import BY_NAME, DEACTIVATE_FIRST, LIFECYCLE_MODULES
from catheter_models.contract import DEFAULT_NAMESPACE

if TYPE_CHECKING:
    from rclpy.node import Node

    from catheter_ros.lifecycle_client import ManagerContext

Params = Mapping[str, object]


def _ros_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        # Quote so that YAML keeps it a string (e.g. JSON objects, empty strings).
        return json.dumps(value)
    return repr(value)


@dataclass
class NodeSpec:
    """One node as ``bringup`` runs it: its module (with a ``main``) and parameters.

    The graph's nodes come from :data:`catheter_control.graph_description.GRAPH`
    (:meth:`of`); a spec may also run a helper node (``excite``, a recorder of its own).
    """

    name: str
    module: str
    params: dict[str, object] = field(default_factory=dict)

    @property
    def lifecycle(self) -> bool:
        """Whether the node is a lifecycle node (configured and activated by its launcher)."""
        return self.module in LIFECYCLE_MODULES

    def argv(self, namespace: str, ros_args: Sequence[str] = ()) -> list[str]:
        """Command line that runs the node with this interpreter (``ros_args`` appended)."""
        args = [sys.executable, "-m", self.module, "--ros-args", "-r", f"__ns:={namespace}"]
        for key, value in self.params.items():
            args += ["-p", f"{key}:={_ros_value(value)}"]
        return args + list(ros_args)

    def full_name(self, namespace: str) -> str:
        """``/catheter/compensator``."""
        return f"{namespace.rstrip('/')}/{self.name}"

    @classmethod
    def of(cls, name: str, params: Params | None = None) -> NodeSpec:
        """The graph's node ``name`` (graph_description.GRAPH) with ``params``."""
        return cls(name, BY_NAME[name].module, dict(params or {}))


class ProcessGraph:
    """Run node specs as child processes; context manager with ordered, bounded shutdown.

    Args:
        specs: nodes in start order (stopped in reverse).
        namespace: ROS namespace of every node.
        log_dir: where each node's stdout/stderr go (``<name>.log``); inherited if None.
        env: extra environment (e.g. ``ROS_DOMAIN_ID``).
        ros_args: more ROS arguments for every node (after its own).
        manage_lifecycle: configure and activate the lifecycle nodes in :meth:`start`.
    """

    def __init__(
        self,
        specs: Sequence[NodeSpec],
        namespace: str = DEFAULT_NAMESPACE,
        log_dir: Path | None = None,
        env: Mapping[str, str] | None = None,
        *,
        ros_args: Sequence[str] = (),
        manage_lifecycle: bool = True,
    ) -> None:
        self.specs = list(specs)
        self.namespace = namespace
        self.log_dir = log_dir
        self.env = {**os.environ, **(env or {})}
        self.ros_args = list(ros_args)
        self.manage_lifecycle = manage_lifecycle
        self.procs: dict[str, subprocess.Popen[bytes]] = {}
        self._manager: ManagerContext | None = None

    def start(self) -> None:
        """Start every node, then configure and activate the lifecycle nodes, in order.

        Raises:
            LifecycleError: a node failed a transition or exited first; names it and why
                (every node is stopped before it is raised).
        """
        self.spawn()
        if self.manage_lifecycle:
            try:
                self.activate()
            except BaseException:
                self.stop()
                raise

    def _gone(self, full_name: str) -> str | None:
        for spec in self.specs:
            if spec.full_name(self.namespace) == full_name:
                proc = self.procs.get(spec.name)
                if proc is not None and proc.poll() is not None:
                    tail = self.log_tail(spec.name, 5)
                    return f"its process exited with code {proc.returncode}" + (
                        f"; its log ends:\n{tail}" if tail else ""
                    )
        return None

    def activate(self) -> None:
        """Configure, then activate, every lifecycle node through its services."""
        from catheter_ros.lifecycle_client import ManagerContext

        managed = [s.full_name(self.namespace) for s in self.specs if s.lifecycle]
        if not managed:
            return
        first = [
            s.full_name(self.namespace)
            for name in DEACTIVATE_FIRST
            for s in self.specs
            if s.name == name and s.lifecycle
        ]
        self._manager = ManagerContext(managed, first, self.env, self._gone)
        self._manager.bring_up()

    def spawn(self) -> None:
        """Start every node's process (lifecycle nodes then wait, unconfigured)."""
        from catheter_ros.node_main import PARENT_PID_ENV  # imports rclpy: only when used

        for spec in self.specs:
            out = None
            if self.log_dir is not None:
                self.log_dir.mkdir(parents=True, exist_ok=True)
                out = (self.log_dir / f"{spec.name}.log").open("wb")
            try:
                self.procs[spec.name] = subprocess.Popen(
                    spec.argv(self.namespace, self.ros_args),
                    stdout=out,
                    stderr=subprocess.STDOUT if out else None,
                    # The nodes watch this pid and shut down cleanly if it dies (kill -9).
                    env={**self.env, PARENT_PID_ENV: str(os.getpid())},
                    # Out of the terminal's process group: Ctrl-C reaches the launcher alone,
                    # which stops the graph in order (compensator ramp-down first, recorder
                    # last). Signalled with the rest, the rig and the recorder quit while the
                    # compensator was still ramping down.
                    start_new_session=True,
                )
            finally:
                if out is not None:
                    out.close()  # the child has its own descriptor

    def failed(self) -> dict[str, int]:
        """Nodes that have exited already, with their exit codes."""
        return {n: p.returncode for n, p in self.procs.items() if p.poll() is not None}

    def log_tail(self, name: str, lines: int = 20) -> str:
        """Last lines of a node's log (empty if logs are inherited)."""
        if self.log_dir is None:
            return ""
        path = self.log_dir / f"{name}.log"
        if not path.exists():
            return ""
        return "\n".join(path.read_text(errors="replace").splitlines()[-lines:])

    def stop(self, timeout_s: float = 10.0) -> dict[str, int]:
        """Deactivate the compensator (ramp-down), then SIGINT each node in reverse order.

        A node still running ``timeout_s`` after its SIGINT is killed (SIGKILL).
        """
        if self._manager is not None:
            for failure in self._manager.wind_down():
                print(f"bringup: {failure}", file=sys.stderr)
            self._manager.close()
            self._manager = None
        codes = {}
        for spec in reversed(self.specs):
            proc = self.procs.get(spec.name)
            if proc is None:
                continue
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
                try:
                    proc.wait(timeout_s)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            codes[spec.name] = proc.returncode
        return codes

    def __enter__(self) -> ProcessGraph:
        self.start()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


def run_composed(specs: Sequence[NodeSpec], namespace: str, ros_args: Sequence[str] = ()) -> int:
    """Run the nodes in this process on one executor until SIGINT/SIGTERM; returns exit code.

    Separate processes are the default: with the GIL, one Python process shares one core
    between every node's loop and callbacks. A lifecycle manager on the same executor
    configures and activates the lifecycle nodes through their services once all are built,
    and deactivates the compensator (ramp-down) first on the way out; a failed transition
    ends the process with exit code 2 and the node's name and reason.
    """
    import importlib
    import tempfile

    import yaml

    from catheter_ros.lifecycle_client import LifecycleManager
    from catheter_ros.node_main import run_nodes

    # Per-node parameters in one process need a params file keyed by the node's full name.
    ns = namespace.rstrip("/")
    params = {f"{ns}/{spec.name}": {"ros__parameters": dict(spec.params)} for spec in specs}
    with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as fh:
        yaml.safe_dump(params, fh)
    argv = ["bringup", "--ros-args", "-r", f"__ns:={namespace}", "--params-file", fh.name]
    argv += list(ros_args)
    factories: list[Callable[[], Node]] = []
    for spec in specs:
        module = importlib.import_module(spec.module)
        factories.append(
            next(
                obj
                for n, obj in vars(module).items()
                if n.endswith("Node") and getattr(obj, "__module__", "") == module.__name__
            )
        )
    managed = [s.full_name(namespace) for s in specs if s.lifecycle]
    first = [s.full_name(namespace) for s in specs if s.lifecycle and s.name in DEACTIVATE_FIRST]
    # Built last, so it starts last (every node exists) and is closed first (its close
    # deactivates the compensator while the other nodes still run).
    factories.append(lambda: LifecycleManager(managed, first))
    try:
        return run_nodes(factories, argv)
    finally:
        Path(fh.name).unlink(missing_ok=True)
