"""Topics a deadline loop reads itself, instead of through executor callbacks.

Every executor callback in rclpy runs a few hundred microseconds of Python while holding the
GIL, and a loop thread that wakes meanwhile waits for it. A compensator that only needs to
know that ``tip/angle`` and ``pressure/measured`` keep arriving would pay that 500 times a
second; here the loop takes what arrived at each tick (a few microseconds when nothing did)
from subscriptions on a helper node that no executor spins.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import FluidPressure

from catheter_models.contract import PRESSURE_COMMAND
from catheter_ros.qos import KEEP_EVERY_SAMPLE


def _never_called(_msg: Any) -> None:
    """Subscriptions here are taken by :meth:`PolledTopics.poll`, never dispatched."""


class PolledTopics:
    """Subscriptions polled from the loop thread; :meth:`poll` names the topics that had news.

    Args:
        owner: the node the topics belong to (its context and namespace are used).
        topics: topic name -> message type.
        qos: QoS of every subscription (keep-last; the depth bounds the work per poll).
        raw: take serialized bytes (enough to know a message came); False for messages.
        suffix: the helper node's name is the owner's plus this (one helper per use).
    """

    def __init__(
        self,
        owner: Node,
        topics: Mapping[str, type],
        qos: QoSProfile,
        *,
        raw: bool = True,
        suffix: str = "_polled",
    ) -> None:
        self._raw = raw
        self.node = rclpy.create_node(
            f"{owner.get_name()}{suffix}",
            context=owner.context,
            namespace=owner.get_namespace(),
            enable_rosout=False,
            start_parameter_services=False,
        )
        # raw=True: the loop only needs to know a message came, not to deserialise it.
        self._subs = {
            name: self.node.create_subscription(msg_type, name, _never_called, qos, raw=raw)
            for name, msg_type in topics.items()
        }

    def poll(self) -> list[str]:
        """Take every message waiting; the topics that had at least one."""
        fresh = []
        for name, sub in self._subs.items():
            got = False
            with sub.handle:
                while sub.handle.take_message(sub.msg_type, True) is not None:
                    got = True
            if got:
                fresh.append(name)
        return fresh

    def take(self, name: str) -> list[Any]:
        """Every message of ``name`` waiting, oldest first (bytes if ``raw``)."""
        sub = self._subs[name]
        taken = []
        with sub.handle:
            while (got := sub.handle.take_message(sub.msg_type, self._raw)) is not None:
                taken.append(got[0])
        return taken

    def destroy(self) -> None:
        """Destroy the helper node and its subscriptions."""
        self.node.destroy_node()


class PressureCommands:
    """A driver's ``pressure/command`` input, taken by its loop at each tick.

    Every command is counted and every bad one refused, so none may drop from a short queue
    (``qos.KEEP_EVERY_SAMPLE``); and none may wait there: when the executor dispatched them,
    at 1 kHz beside two busy loops it fell behind and the rig applied commands up to 235 ms
    old (p99), one by one. The loop drains every waiting command each tick (each checked, the
    newest in force), so none waits longer than a tick.
    """

    def __init__(self, owner: Node) -> None:
        self._name = PRESSURE_COMMAND.name
        self._topics = PolledTopics(
            owner, {self._name: FluidPressure}, KEEP_EVERY_SAMPLE, raw=False, suffix="_commands"
        )

    def take(self) -> list[Any]:
        """Every command waiting, oldest first (``sensor_msgs/FluidPressure``)."""
        return self._topics.take(self._name)

    def destroy(self) -> None:
        """Destroy the subscription's helper node."""
        self._topics.destroy()
