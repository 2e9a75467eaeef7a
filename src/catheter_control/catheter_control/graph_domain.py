"""Which ROS domain a launcher starts its graph in, and whether another graph is there already.

Two graphs in one namespace and domain configure and activate each other's lifecycle nodes,
and each compensator takes the other's trajectories: both runs fail, with messages that blame
the watchdog or a missing tip angle, and a simulated run could command a rig's compensator.
So ``bringup`` and ``follow_trajectory --sim`` / ``--emulated-rig`` look before they start
(:func:`choose_domain`), and refuse a namespace where nodes already run, naming them and the
domain; or they take a domain of their own (``--domain-id auto``).
"""

from __future__ import annotations

import argparse
import os
import random
import time
from collections.abc import Sequence

from catheter_control.graph_description import GRAPH_NODES
from catheter_models.errors import GraphConflictError

__all__ = [
    "GraphConflictError",
    "choose_domain",
    "default_domain_choice",
    "domain_id_argument",
    "nodes_in_domain",
]


DISCOVERY_WAIT_S = 2.0
"""How long a look for nodes already in a domain lasts before a graph is started there. A new
DDS participant announces itself at once and the others answer it; the node names follow on
``ros_discovery_info``, participant by participant. On an idle host that takes a few hundred
ms; on our busy 2-core test machine 1.5 s saw one node of a running graph and not the other,
so a look that short could miss a whole graph. Every start pays it once. Commission's look at
a running rig (``commission_rig._LOOK_S``) lasts longer, since there a node missed is a
compensator the excitations fight. A graph started after the look is not seen; it makes its
own look."""

AUTO_DOMAIN_RANGE = (1, 99)
"""Where ``--domain-id auto`` looks for a domain: not 0 (every ROS tool's and rig's default),
and below the integration tests' 100-230, within the ids ROS 2 documents as safe on Linux (their
ports stay below the ephemeral range)."""

_AUTO_TRIES = 5


def domain_id_argument(value: str) -> str:
    """``--domain-id``: ``auto``, ``env`` (ROS_DOMAIN_ID as it is) or a number 0-232."""
    if value in {"auto", "env"} or (value.isdigit() and 0 <= int(value) <= 232):
        return value
    raise argparse.ArgumentTypeError(
        f"{value!r}: give auto (a domain with nobody in it), env (ROS_DOMAIN_ID as set) or 0-232"
    )


def default_domain_choice(given: str | None) -> str:
    """``--domain-id`` as given, else what a tool that starts its own graph defaults to.

    ``env`` where ROS_DOMAIN_ID is set (a person chose a domain), else ``auto``: ROS's default
    domain 0 is where a rig and every ROS tool run, so a simulated graph goes elsewhere.
    """
    return given or ("env" if os.environ.get("ROS_DOMAIN_ID") else "auto")


def nodes_in_domain(domain_id: int, wait_s: float = DISCOVERY_WAIT_S) -> list[str]:
    """Full names of the nodes seen in ``domain_id`` over ``wait_s`` (this probe left out).

    Discovery follows ``ROS_AUTOMATIC_DISCOVERY_RANGE`` as this process has it, so the probe
    sees what a graph started from here would reach.
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions

    from catheter_ros.dds_profile import use_loopback_profile

    use_loopback_profile()
    probe = f"_catheter_graph_probe_{os.getpid()}"
    context = Context()
    rclpy.init(
        args=["graph_probe"],  # not sys.argv: the tool's own ROS arguments are its node's
        context=context,
        domain_id=domain_id,
        signal_handler_options=SignalHandlerOptions.NO,
    )
    try:
        node = Node(probe, context=context, enable_rosout=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        # The whole window, always: a node found late is still a node.
        end_s = time.monotonic() + wait_s
        while time.monotonic() < end_s:
            executor.spin_once(timeout_sec=0.1)
        found = {
            f"{ns.rstrip('/')}/{name}"
            for name, ns in node.get_node_names_and_namespaces()
            if name != probe
        }
        # Node names arrive on ros_discovery_info, apart from the endpoints; a busy machine
        # once showed neither graph node's name within the look. Every rclpy node serves
        # ``<node>/get_parameters`` and every lifecycle node publishes
        # ``<node>/transition_event``, so the endpoints name the nodes too.
        for service, _types in node.get_service_names_and_types():
            if service.endswith("/get_parameters") and f"/{probe}/" not in service:
                found.add(service.removesuffix("/get_parameters"))
        for topic, _types in node.get_topic_names_and_types():
            if topic.endswith("/transition_event"):
                found.add(topic.removesuffix("/transition_event"))
        executor.remove_node(node)
        node.destroy_node()
    finally:
        context.try_shutdown()
    return sorted(found)


def in_namespace(nodes: Sequence[str], namespace: str) -> list[str]:
    """The graph's nodes (:data:`GRAPH_NODES`) among ``nodes`` (full names) in ``namespace``.

    Another graph's nodes are what clash (its lifecycle nodes would be configured twice, its
    compensator take our trajectories); a tool in the namespace (a probe, ``follow_trajectory``
    on a running graph, Foxglove's bridge) does not.
    """
    ns = namespace.rstrip("/")
    return [n for n in nodes if n.rsplit("/", 1)[0] == ns and n.rsplit("/", 1)[1] in GRAPH_NODES]


def current_domain_id() -> int:
    """ROS_DOMAIN_ID as this process has it (0, ROS's default, when unset or empty)."""
    value = os.environ.get("ROS_DOMAIN_ID", "")
    return int(value) if value.isdigit() else 0


def choose_domain(choice: str, namespace: str, who: str) -> int:
    """Set ROS_DOMAIN_ID for what this process starts, after checking no graph runs there.

    ``choice`` is ``--domain-id``: ``env`` keeps ROS_DOMAIN_ID (0 if unset); a number takes
    that domain; ``auto`` takes a domain in :data:`AUTO_DOMAIN_RANGE` where no node is seen.
    The domain is printed, so a person can attach tools to it.

    Raises:
        GraphConflictError: nodes run in ``namespace`` in the chosen domain (named, with the
            domain), or ``auto`` found no empty domain in :data:`_AUTO_TRIES` tries.
    """
    if choice == "auto":
        low, high = AUTO_DOMAIN_RANGE
        busy: dict[int, int] = {}
        for domain_id in random.sample(range(low, high + 1), _AUTO_TRIES):
            seen = nodes_in_domain(domain_id)
            if not seen:
                os.environ["ROS_DOMAIN_ID"] = str(domain_id)
                print(
                    f"{who}: ROS_DOMAIN_ID={domain_id} (a domain of its own: nobody else was "
                    f"there); attach tools with ROS_DOMAIN_ID={domain_id}"
                )
                return domain_id
            busy[domain_id] = len(seen)
        raise GraphConflictError(
            "no empty ROS domain found for --domain-id auto: "
            + ", ".join(f"{d} ({n} nodes)" for d, n in busy.items())
            + "; give one with --domain-id N"
        )
    if choice != "env":
        os.environ["ROS_DOMAIN_ID"] = choice
    domain_id = current_domain_id()
    others = in_namespace(nodes_in_domain(domain_id), namespace)
    if others:
        raise GraphConflictError(
            f"another graph already runs in {namespace} on ROS_DOMAIN_ID={domain_id}: "
            f"{', '.join(others)}; a second one would configure and command its nodes. Stop "
            "it, or start this one elsewhere (--domain-id auto, or --namespace)"
        )
    print(f"{who}: ROS_DOMAIN_ID={domain_id}")
    return domain_id
