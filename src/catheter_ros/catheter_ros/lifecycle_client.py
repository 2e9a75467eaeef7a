"""A small lifecycle manager: drive nodes through the standard ``<node>/change_state`` services.

``bringup`` uses it in both of its modes. With separate processes it runs in the launcher on
a context of its own (:class:`ManagerContext`); composed, it is one more node on the nodes'
executor, and drives them from :meth:`LifecycleManager.start` (called by ``run_nodes`` once
every node is built, outside any callback, so it may spin that executor itself).

The services answer only success or failure. The reason a node gives for a failure is on
its ``/diagnostics`` status (and in its log), so after a failure the manager waits briefly
for that status and reports it with the node's name.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.context import Context
from rclpy.executors import Executor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from catheter_models.errors import CatheterError, GraphConflictError
from catheter_ros.dds_profile import use_loopback_profile

CONFIGURE = Transition.TRANSITION_CONFIGURE
ACTIVATE = Transition.TRANSITION_ACTIVATE
DEACTIVATE = Transition.TRANSITION_DEACTIVATE
_LABELS = {CONFIGURE: "configure", ACTIVATE: "activate", DEACTIVATE: "deactivate"}

SERVICE_WAIT_S = 60.0
"""How long a node's lifecycle services may take to appear: a process start (imports,
DDS discovery) on a busy 2-core machine took up to ~10 s; the margin is deliberate."""
TRANSITION_WAIT_S = 60.0
"""How long one transition may take (configure loads and hash-checks a model)."""
REASON_WAIT_S = 2.5
"""How long to wait for a failed node's /diagnostics status (published at 1 Hz)."""
ALONE_LOOK_S = 3.0
"""How long the manager has looked at the graph before it checks that the nodes it is about to
configure are the only ones of their names. Launchers look for another graph before they start
(catheter_control.graph_domain), but on a busy 2-core machine that 2 s look once missed a whole
running graph; by the time our own nodes offer their services the manager has usually watched
for far longer, and this floor covers a composed graph that comes up at once."""


class LifecycleError(CatheterError):
    """A managed node failed a transition (or never offered its services); names it and why."""


class LifecycleManager(Node):
    """Configures then activates ``managed`` (full node names) in order; deactivates on close.

    Args:
        managed: full names of the lifecycle nodes (``/catheter/compensator``), in start order.
        deactivate_first: those to deactivate on :meth:`close`, in that order (the
            compensator: its deactivate ramps the pressure down while the rig still runs).
        is_gone: given a node's full name, why it can no longer answer (its process exited)
            or None; checked while waiting, so a dead node fails fast.
        context: the rclpy context (None: the default one).
    """

    def __init__(
        self,
        managed: Sequence[str],
        deactivate_first: Sequence[str] = (),
        is_gone: Callable[[str], str | None] | None = None,
        context: Context | None = None,
    ) -> None:
        super().__init__("lifecycle_manager", context=context, start_parameter_services=False)
        self.managed = list(managed)
        self.deactivate_first = list(deactivate_first)
        self.is_gone = is_gone or (lambda _name: None)
        self._change_state: dict[str, Any] = {
            name: self.create_client(ChangeState, f"{name}/change_state") for name in managed
        }
        self._get_state: dict[str, Any] = {
            name: self.create_client(GetState, f"{name}/get_state") for name in managed
        }
        self._status: dict[str, tuple[int, str]] = {}
        self._born_s = time.monotonic()
        self.create_subscription(DiagnosticArray, "/diagnostics", self._on_diagnostics, 50)
        self.active: list[str] = []

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            self._status[status.name] = (int.from_bytes(status.level, "little"), status.message)

    def _spin(self, executor: Executor, until: Callable[[], bool], timeout_s: float) -> bool:
        end = time.monotonic() + timeout_s
        while not until():
            if time.monotonic() > end:
                return False
            executor.spin_once(timeout_sec=0.05)
        return True

    def _wait_for_services(self, executor: Executor, name: str, label: str) -> None:
        """Wait until ``name``'s lifecycle services are up; LifecycleError if it exits first."""
        client = self._change_state[name]
        getter = self._get_state[name]
        gone: list[str] = []

        def ready() -> bool:
            reason = self.is_gone(name)
            if reason and not gone:
                gone.append(reason)
            return bool(gone) or (client.service_is_ready() and getter.service_is_ready())

        if not self._spin(executor, ready, SERVICE_WAIT_S) or gone:
            why = gone[0] if gone else f"no {client.srv_name} service after {SERVICE_WAIT_S:g} s"
            raise LifecycleError(f"{name}: cannot {label}: {why}")

    def _refuse_another_graph(self, executor: Executor) -> None:
        """LifecycleError if a managed name is taken twice or is not ``unconfigured``."""
        end_s = self._born_s + ALONE_LOOK_S
        while time.monotonic() < end_s:
            executor.spin_once(timeout_sec=0.05)
        domain = f"ROS_DOMAIN_ID={self.context.get_domain_id()}"
        twice = self._twice(self.managed)
        if twice:
            raise GraphConflictError(
                f"another graph already runs in this ROS domain ({domain}): "
                f"{', '.join(twice)} {'are' if len(twice) > 1 else 'is'} there twice (or one "
                "killed in the last few seconds still shows); its nodes would answer this "
                "graph's transitions, so none was configured. Stop it, or start this graph in "
                "another domain (--domain-id auto)"
            )
        for name in self.managed:
            state = self.state_of(executor, name)
            if state and state != "unconfigured":
                raise GraphConflictError(
                    f"another graph already runs in this ROS domain ({domain}): {name} "
                    f"answers as {state!r}, not as a node just started; none was configured. "
                    "Stop that graph, or start this one in another domain (--domain-id auto)"
                )

    def _twice(self, names: list[str]) -> list[str]:
        """The names among ``names`` that another node in the domain also has.

        Three views of the graph, because they are discovered apart and a slow discovery may
        have brought one and not yet the others: node names (``ros_discovery_info``), and the
        servers of ``<name>/change_state`` and publishers of ``<name>/transition_event``
        (endpoint discovery). A clean-clone CI run on a busy machine saw the other graph's
        node names only after its first transition, and that graph's node answered it.
        """
        seen = [f"{ns.rstrip('/')}/{node}" for node, ns in self.get_node_names_and_namespaces()]
        return [
            name
            for name in names
            if seen.count(name) > 1
            or self.count_services(f"{name}/change_state") > 1
            or self.count_publishers(f"{name}/transition_event") > 1
        ]

    def _refuse_late_twin(self, name: str, label: str) -> None:
        """GraphConflictError if another graph's ``name`` has shown up since the first look."""
        if self._twice([name]):
            raise GraphConflictError(
                f"another graph already runs in this ROS domain "
                f"(ROS_DOMAIN_ID={self.context.get_domain_id()}): {name} is there twice, found "
                f"before its {label} (discovery was slow); its node would answer this graph's "
                "transitions. Stop it, or start this graph in another domain (--domain-id auto)"
            )

    def change_state(self, executor: Executor, name: str, transition: int) -> None:
        """Run one transition of node ``name``; raise LifecycleError naming it and why not.

        Raises:
            GraphConflictError: (configure, activate) a node of the same name in another graph
                was discovered since :meth:`bring_up` looked (before the transition, or as it
                failed).
        """
        label = _LABELS[transition]
        client = self._change_state[name]
        gone: list[str] = []

        def is_gone() -> bool:
            reason = self.is_gone(name)
            if reason and not gone:
                gone.append(reason)
            return bool(gone)

        self._wait_for_services(executor, name, label)
        # Bring-up only: winding down must go on whatever else runs (a deactivate is this
        # graph's ramp-down; a CI run's teardown was refused once a refused twin showed up).
        bring_up = transition in (CONFIGURE, ACTIVATE)
        if bring_up:
            self._refuse_late_twin(name, label)
        request = ChangeState.Request()
        request.transition.id = transition
        self._status.pop(name.lstrip("/"), None)  # a status from after the answer says why
        future = client.call_async(request)
        # A node may offer its services and still exit (a refused parameter is found once
        # it is built): watch for that while waiting for the answer, too.
        if not self._spin(executor, lambda: future.done() or is_gone(), TRANSITION_WAIT_S):
            client.remove_pending_request(future)
            raise LifecycleError(f"{name}: {label} did not answer within {TRANSITION_WAIT_S:g} s")
        if not future.done():
            client.remove_pending_request(future)
            raise LifecycleError(f"{name}: cannot {label}: {gone[0]}")
        response: Any = future.result()
        if response is None or not response.success:
            # The answer may have come from a twin discovered only now.
            if bring_up:
                self._refuse_late_twin(name, label)
            reason = self._reason(executor, name, label).removeprefix(f"{label} failed: ")
            raise LifecycleError(f"{name}: {label} failed: {reason}")
        self.get_logger().info(f"{name}: {label}d")

    def _reason(self, executor: Executor, name: str, label: str) -> str:
        key = name.lstrip("/")
        # The node's periodic status ("not configured: ...") may arrive before the one that
        # says why the transition failed: wait for that one, else take what came.
        self._spin(
            executor,
            lambda: key in self._status and self._status[key][1].startswith(f"{label} failed"),
            REASON_WAIT_S,
        )
        if key not in self._status:
            return self.is_gone(name) or "no reason on /diagnostics; see the node's log"
        return self._status[key][1]

    def bring_up(self, executor: Executor) -> None:
        """Configure every managed node, then activate each, in order (raises LifecycleError).

        Before the first transition, every node's services must be up and each name must be
        the only one of its kind in the domain, in state ``unconfigured``: a node of another
        graph answers the same ``change_state`` service, and configuring or activating it
        would make two graphs command each other's catheter.
        """
        for name in self.managed:
            self._wait_for_services(executor, name, _LABELS[CONFIGURE])
        self._refuse_another_graph(executor)
        for name in self.managed:
            self.change_state(executor, name, CONFIGURE)
        for name in self.managed:
            self.change_state(executor, name, ACTIVATE)
            self.active.append(name)

    def state_of(self, executor: Executor, name: str) -> str:
        """The node's lifecycle state label (``active``), or '' if it does not answer in 5 s."""
        client = self._get_state[name]
        if not client.service_is_ready():
            return ""
        future = client.call_async(GetState.Request())
        if not self._spin(executor, future.done, 5.0):
            client.remove_pending_request(future)
            return ""
        response: Any = future.result()
        return "" if response is None else str(response.current_state.label)

    def wind_down(self, executor: Executor) -> list[str]:
        """Deactivate ``deactivate_first`` nodes that are active; the failures, by name.

        Never raises: shutdown goes on (the drivers' watchdogs vent) whatever happens here.
        A node someone else deactivated meanwhile (``ros2 lifecycle set``) is left alone.
        """
        failures = []
        for name in self.deactivate_first:
            if name not in self.active or self.is_gone(name):
                continue
            if self.state_of(executor, name) != "active":
                self.active.remove(name)
                continue
            try:
                self.change_state(executor, name, DEACTIVATE)
                self.active.remove(name)
            except LifecycleError as exc:
                failures.append(str(exc))
                self.get_logger().error(str(exc))
        return failures

    # -- composed mode: one more node on run_nodes' executor ----------------------------
    def start(self) -> None:
        """Drive the managed nodes up on this node's executor (``run_nodes`` calls this)."""
        assert self.executor is not None, "add the manager to the nodes' executor first"
        self.bring_up(self.executor)

    def close(self) -> None:
        """Deactivate the ``deactivate_first`` nodes before ``run_nodes`` destroys them."""
        if self.executor is not None:
            self.wind_down(self.executor)


class ManagerContext:
    """A :class:`LifecycleManager` on its own rclpy context, for a launcher process.

    ``env`` is the environment the managed processes get: its ``ROS_DOMAIN_ID`` and
    ``ROS_AUTOMATIC_DISCOVERY_RANGE`` apply here too (they are read when the context
    initialises, so they are set for that moment only, as the tests' probe does).
    """

    def __init__(
        self,
        managed: Sequence[str],
        deactivate_first: Sequence[str],
        env: Mapping[str, str],
        is_gone: Callable[[str], str | None],
    ) -> None:
        keys = ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE", "FASTDDS_DEFAULT_PROFILES_FILE")
        env = dict(env)
        use_loopback_profile(env)  # the nodes' own choice (node_main), for this participant
        saved = {k: os.environ.get(k) for k in keys}
        self.context = Context()
        try:
            for key in keys:
                if key in env:
                    os.environ[key] = env[key]
            domain = env.get("ROS_DOMAIN_ID", "")
            rclpy.init(
                args=["lifecycle_manager"],  # not sys.argv: the launcher's own ROS arguments
                context=self.context,
                domain_id=int(domain) if domain.isdigit() else None,
                signal_handler_options=SignalHandlerOptions.NO,
            )
        finally:
            for key, value in saved.items():
                if value is None:
                    os.environ.pop(key, None)
                else:
                    os.environ[key] = value
        self.manager = LifecycleManager(managed, deactivate_first, is_gone, self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.manager)

    def bring_up(self) -> None:
        """Configure, then activate, every managed node (raises LifecycleError)."""
        self.manager.bring_up(self.executor)

    def wind_down(self) -> list[str]:
        """Deactivate the ``deactivate_first`` nodes; the failures."""
        return self.manager.wind_down(self.executor)

    def close(self) -> None:
        """Destroy the manager and shut its context down (idempotent)."""
        if not self.context.ok():
            return
        self.executor.shutdown(timeout_sec=2.0)
        self.manager.destroy_node()
        rclpy.shutdown(context=self.context)
