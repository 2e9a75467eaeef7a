"""Reading a bag for playback: its messages in log-time order, with each topic's offered QoS.

The ROS side (``catheter_control.bag_play``) publishes what this yields; reading the bag is
this package's business, as every other bag reader is.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rosbags.highlevel import AnyReader, AnyReaderError
from rosbags.rosbag2 import ReaderError

from catheter_models.bag.messages import kilted_typestore
from catheter_models.bag.metadata import locate_bag
from catheter_models.errors import BagError, ParameterError
from catheter_models.units import ns_to_s, s_to_ns


@dataclass(frozen=True)
class PlayedTopic:
    """One topic as played."""

    name: str
    """As recorded."""
    out: str
    """As published (after ``--remap``)."""
    msgtype: str
    qos: dict[str, Any]
    """Offered QoS as recorded: reliability, durability, depth."""


def _qos_dict(profiles: Sequence[Any]) -> dict[str, Any]:
    """The first offered profile as plain values (rosbags' Qos objects)."""
    if not profiles:
        # A bag without offered QoS (some writers leave it out): what our streams offer.
        return {"reliability": "reliable", "durability": "volatile", "depth": 500}
    q = profiles[0]
    return {
        "reliability": q.reliability.name.lower(),
        "durability": q.durability.name.lower(),
        "depth": max(1, int(q.depth)),
    }


def _select(connections: Sequence[Any], wanted: Sequence[str] | None) -> list[Any]:
    if wanted is None:
        return list(connections)
    chosen = []
    names = sorted({c.topic for c in connections})
    for w in wanted:
        hits = [c for c in connections if c.topic == w or c.topic.endswith("/" + w.lstrip("/"))]
        if not hits:
            raise BagError(f"the bag has no topic {w!r}; it has {', '.join(names)}")
        chosen += [c for c in hits if c not in chosen]
    return chosen


class Player:
    """Reads a bag's messages in log-time order, with each topic's offered QoS.

    Args:
        bag: bag directory or ``.mcap`` file.
        topics: only these (full or namespace-relative names); None: all.
        remap: recorded name -> published name.
    """

    def __init__(
        self,
        bag: Path,
        topics: Sequence[str] | None = None,
        remap: dict[str, str] | None = None,
    ) -> None:
        self.layout = locate_bag(bag)
        self._reader_path = self.layout.reader_path()
        remap = remap or {}
        try:
            with AnyReader([self._reader_path], default_typestore=kilted_typestore()) as reader:
                self.connections = _select(reader.connections, topics)
                self.topics = {
                    c.topic: PlayedTopic(
                        c.topic,
                        remap.get(c.topic, c.topic),
                        c.msgtype,
                        _qos_dict(getattr(c.ext, "offered_qos_profiles", [])),
                    )
                    for c in self.connections
                }
                self.count = sum(c.msgcount for c in self.connections)
                self.start_ns = reader.start_time
                self.end_ns = reader.end_time
        except (AnyReaderError, ReaderError) as exc:
            raise BagError(f"bag {self.layout.path} cannot be read: {exc}") from None
        unknown = set(remap) - set(self.topics)
        if unknown:
            raise ParameterError(
                f"--remap names {', '.join(sorted(unknown))}, not among the topics played: "
                f"{', '.join(sorted(self.topics))}"
            )

    @property
    def duration_s(self) -> float:
        """From the first to the last log time [s]."""
        return ns_to_s(self.end_ns - self.start_ns)

    def messages(self, start_offset_s: float = 0.0) -> Iterator[tuple[str, int, bytes]]:
        """(recorded topic, log time [ns], serialized message), in log-time order."""
        first_ns = self.start_ns + s_to_ns(start_offset_s)
        with AnyReader([self._reader_path], default_typestore=kilted_typestore()) as reader:
            wanted = [c for c in reader.connections if c.topic in self.topics]
            for conn, log_ns, raw in reader.messages(connections=wanted, start=first_ns):
                yield conn.topic, log_ns, bytes(raw)
