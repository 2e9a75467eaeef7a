"""rosbag2 ``metadata.yaml`` (version 9), offered-QoS profiles, and where a bag's files are.

A rosbag2 bag is a directory holding ``metadata.yaml`` beside one or more storage files.
``ros2 bag info``/``play`` and the ``rosbags`` reader both read ``metadata.yaml`` first, so the
writer, the repair tool and the loader build and read it here, in one place.

Two details matter for interoperability:

* In version 9, ``offered_qos_profiles`` is a YAML *list* in ``metadata.yaml`` but a YAML *string*
  in each MCAP channel's metadata. The ``rosbags`` reader matches the two by value and silently
  ignores a topic whose two copies differ, so both are produced from the same profile list.
* ``custom_data`` is a string-to-string map (rosbag2 decodes it as such); the experiment's
  description lives there.

The offered profiles of the contract's topics come from its QoS specs
(``catheter_models.contract.QOS_*``), the same numbers ``catheter_ros.qos`` builds rclpy's
profiles from, so a bag records what the nodes really offer.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader

from catheter_models.contract import QOS_SENSOR_DATA, QOS_STREAM, QOS_TRAJECTORY, QosSpec
from catheter_models.errors import BagError, ParameterError

METADATA_FILE: Final = "metadata.yaml"
METADATA_VERSION: Final = 9
"""rosbag2 metadata version written (Jazzy, Kilted). Readers accept older versions."""
ROS_DISTRO: Final = "kilted"

RMW_DURATION_INFINITE_NS: Final = 9_223_372_036_854_775_807
"""What rmw reports for an unset deadline/lifespan/lease; real recordings carry this value."""

_HISTORY: Final = frozenset({"system_default", "keep_last", "keep_all", "unknown"})
_RELIABILITY: Final = frozenset(
    {"system_default", "reliable", "best_effort", "unknown", "best_available"}
)
_DURABILITY: Final = frozenset(
    {"system_default", "transient_local", "volatile", "unknown", "best_available"}
)
_LIVELINESS: Final = frozenset(
    {"system_default", "automatic", "manual_by_topic", "unknown", "best_available"}
)


def dump_yaml(data: object) -> str:
    """Block-style YAML in the given key order, as rosbag2 writes it."""
    return str(yaml.safe_dump(data, default_flow_style=False, sort_keys=False))


def _duration_yaml(duration_ns: int) -> dict[str, int]:
    sec, nsec = divmod(duration_ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


@dataclass(frozen=True)
class QosProfile:
    """One QoS profile a publisher offered, as rosbag2 records it (strings as in rmw).

    Durations are in nanoseconds; the default is rmw's "infinite", which is what a publisher
    with no deadline/lifespan/lease reports.
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int = RMW_DURATION_INFINITE_NS
    lifespan_ns: int = RMW_DURATION_INFINITE_NS
    liveliness: str = "automatic"
    liveliness_lease_duration_ns: int = RMW_DURATION_INFINITE_NS
    avoid_ros_namespace_conventions: bool = False

    def __post_init__(self) -> None:
        """Refuse policy names rmw does not know, so a bag never carries one."""
        for name, value, allowed in (
            ("history", self.history, _HISTORY),
            ("reliability", self.reliability, _RELIABILITY),
            ("durability", self.durability, _DURABILITY),
            ("liveliness", self.liveliness, _LIVELINESS),
        ):
            if value not in allowed:
                msg = f"QoS {name} {value!r} is unknown to rmw; expected one of {sorted(allowed)}"
                raise ParameterError(msg)
        if self.depth < 0:
            msg = f"QoS depth {self.depth} is negative; expected >= 0"
            raise ParameterError(msg)

    def to_yaml_dict(self) -> dict[str, Any]:
        """The profile in rosbag2's version-9 YAML form (policy names as strings)."""
        return {
            "history": self.history,
            "depth": self.depth,
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": _duration_yaml(self.deadline_ns),
            "lifespan": _duration_yaml(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": _duration_yaml(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": self.avoid_ros_namespace_conventions,
        }


def offered_qos(spec: QosSpec) -> QosProfile:
    """How ``metadata.yaml`` records a publisher offering one of the contract's QoS specs."""
    return QosProfile(
        history="keep_last",
        depth=spec.depth,
        reliability="reliable" if spec.reliable else "best_effort",
        durability="transient_local" if spec.transient_local else "volatile",
    )


SENSOR_DATA_QOS: Final = offered_qos(QOS_SENSOR_DATA)
"""rclpy's ``qos_profile_sensor_data``: what the streams offered before they were reliable."""
STREAM_QOS: Final = offered_qos(QOS_STREAM)
"""What the contract's sensor and command streams offer (``catheter_ros.qos.STREAM``)."""
LATCHED_QOS: Final = offered_qos(QOS_TRAJECTORY)
"""Reliable, transient-local: what the contract's ``trajectory`` topic offers."""


def qos_to_channel_string(profiles: Sequence[Mapping[str, Any]]) -> str:
    """Serialize profiles for an MCAP channel's ``offered_qos_profiles`` entry.

    rosbag2 stores a YAML document here; an empty list is written as ``"[]"`` like rosbag2's
    YAML emitter does (rosbag2 also accepts ``""``).
    """
    return dump_yaml([dict(p) for p in profiles]).strip()


def qos_from_channel_string(text: str, *, topic: str) -> list[dict[str, Any]]:
    """Parse an MCAP channel's ``offered_qos_profiles`` string back to a list of profiles.

    Raises:
        BagError: The string is not a YAML list of mappings.
    """
    if not text.strip():
        return []
    try:
        loaded = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        msg = f"offered_qos_profiles of topic {topic!r} is not valid YAML: {exc}"
        raise BagError(msg) from None
    if loaded is None:
        return []
    if not isinstance(loaded, list) or not all(isinstance(p, dict) for p in loaded):
        msg = (
            f"offered_qos_profiles of topic {topic!r} is {type(loaded).__name__}; "
            "expected a YAML list of QoS mappings"
        )
        raise BagError(msg)
    return [dict(p) for p in loaded]


@dataclass(frozen=True)
class TopicSummary:
    """One ``topics_with_message_count`` entry of ``metadata.yaml``."""

    name: str
    msgtype: str
    message_count: int
    offered_qos: tuple[Mapping[str, Any], ...] = ()
    type_description_hash: str = ""
    serialization_format: str = "cdr"


@dataclass(frozen=True)
class BagSummary:
    """Everything ``metadata.yaml`` says about a bag with one storage file.

    Times are log times in nanoseconds since the Unix epoch.
    """

    relative_file_path: str
    topics: tuple[TopicSummary, ...]
    start_time_ns: int
    end_time_ns: int
    custom_data: Mapping[str, str] = field(default_factory=dict)
    ros_distro: str = ROS_DISTRO
    storage_identifier: str = "mcap"

    @property
    def message_count(self) -> int:
        """Messages in the bag, over all topics."""
        return sum(t.message_count for t in self.topics)

    def to_yaml_dict(self) -> dict[str, Any]:
        """The ``rosbag2_bagfile_information`` mapping, version 9."""
        count = self.message_count
        start_ns = self.start_time_ns if count else 0
        duration_ns = max(0, self.end_time_ns - self.start_time_ns) if count else 0
        return {
            "version": METADATA_VERSION,
            "storage_identifier": self.storage_identifier,
            "duration": {"nanoseconds": duration_ns},
            "starting_time": {"nanoseconds_since_epoch": start_ns},
            "message_count": count,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": t.name,
                        "type": t.msgtype,
                        "serialization_format": t.serialization_format,
                        "offered_qos_profiles": [dict(p) for p in t.offered_qos],
                        "type_description_hash": t.type_description_hash,
                    },
                    "message_count": t.message_count,
                }
                for t in self.topics
            ],
            # Chunk compression inside MCAP is invisible here; these name file/message
            # compression, which this stack never uses.
            "compression_format": "",
            "compression_mode": "",
            "relative_file_paths": [self.relative_file_path],
            "files": [
                {
                    "path": self.relative_file_path,
                    "starting_time": {"nanoseconds_since_epoch": start_ns},
                    "duration": {"nanoseconds": duration_ns},
                    "message_count": count,
                }
            ],
            "custom_data": dict(self.custom_data),
            "ros_distro": self.ros_distro,
        }

    def to_yaml(self) -> str:
        """The whole ``metadata.yaml`` text."""
        return dump_yaml({"rosbag2_bagfile_information": self.to_yaml_dict()})


def write_metadata(bag_dir: Path, summary: BagSummary, *, fsync: bool = False) -> None:
    """Write ``<bag_dir>/metadata.yaml`` atomically.

    A reader (or a crash) sees either the previous file or the new one, never half of one:
    the text goes to a temporary file in the same directory, then ``os.replace`` swaps it in.

    Args:
        bag_dir: The bag directory.
        summary: What to write.
        fsync: Also force the file to disk before the swap (survives power loss, costs ms).
    """
    target = bag_dir / METADATA_FILE
    tmp = bag_dir / f".{METADATA_FILE}.tmp"
    with tmp.open("w", encoding="utf-8") as stream:
        stream.write(summary.to_yaml())
        stream.flush()
        if fsync:
            os.fsync(stream.fileno())
    tmp.replace(target)


def read_metadata(bag_dir: Path) -> dict[str, Any] | None:
    """The ``rosbag2_bagfile_information`` mapping of a bag directory, or None if it has none.

    Raises:
        BagError: ``metadata.yaml`` exists but is not a rosbag2 metadata file.
    """
    target = bag_dir / METADATA_FILE
    if not target.is_file():
        return None
    try:
        loaded = yaml.safe_load(target.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        msg = f"{target} is not valid YAML: {exc}"
        raise BagError(msg) from None
    info = loaded.get("rosbag2_bagfile_information") if isinstance(loaded, dict) else None
    if not isinstance(info, dict):
        msg = f"{target} has no 'rosbag2_bagfile_information' mapping; it is not rosbag2 metadata"
        raise BagError(msg)
    return info


def custom_data_of(info: Mapping[str, Any] | None) -> dict[str, str]:
    """The ``custom_data`` of a metadata mapping as ``str -> str`` (absent or null: empty)."""
    if info is None:
        return {}
    raw = info.get("custom_data")
    if not isinstance(raw, dict):
        return {}
    return {str(k): str(v) for k, v in raw.items()}


@dataclass(frozen=True)
class BagLayout:
    """Where a bag's pieces are on disk.

    Attributes:
        path: What the caller passed (a bag directory or one ``.mcap`` file).
        bag_dir: The bag directory, or None for a lone storage file outside one.
        storage_files: The storage files in playback order.
        metadata: The ``rosbag2_bagfile_information`` mapping, if ``metadata.yaml`` exists.
    """

    path: Path
    bag_dir: Path | None
    storage_files: tuple[Path, ...]
    metadata: Mapping[str, Any] | None

    @property
    def mcap_files(self) -> tuple[Path, ...]:
        """The storage files that are MCAP."""
        return tuple(f for f in self.storage_files if f.suffix == ".mcap")

    def reader_path(self) -> Path:
        """The path to hand to ``rosbags``: the directory if it has metadata, else the file.

        ``ros2 bag record`` writes ``metadata.yaml`` only when it stops, so a directory without
        one is common; its single storage file is still a complete bag if it has a footer.

        Raises:
            BagError: A directory without ``metadata.yaml`` holds several storage files, whose
                order and relation only the metadata records.
        """
        if self.metadata is not None or self.path.is_file():
            return self.path
        if len(self.storage_files) == 1:
            return self.storage_files[0]
        names = [f.name for f in self.storage_files]
        msg = (
            f"bag directory {self.path} has no metadata.yaml and {len(names)} storage files "
            f"{names}; rebuild the metadata with `ros2 bag reindex {self.path}` or load one file"
        )
        raise BagError(msg)


def locate_bag(path: Path | str) -> BagLayout:
    """Find the storage files and metadata of a bag directory or a lone ``.mcap`` file.

    Raises:
        BagError: The path does not exist, is neither a directory nor an ``.mcap``/``.db3``
            file, or a directory holds no storage file.
    """
    path = Path(path)
    if not path.exists():
        msg = f"bag {path} does not exist; expected a rosbag2 directory or an .mcap file"
        raise BagError(msg)
    if path.is_file():
        if path.suffix not in {".mcap", ".db3"}:
            msg = f"{path} is not a bag: expected a rosbag2 directory or an .mcap file"
            raise BagError(msg)
        info = read_metadata(path.parent)
        listed = _listed_files(path.parent, info)
        # The sibling metadata describes this file only if it lists it.
        in_dir = path.resolve() in {f.resolve() for f in listed}
        return BagLayout(
            path=path,
            bag_dir=path.parent if in_dir else None,
            storage_files=(path,),
            metadata=info if in_dir else None,
        )
    info = read_metadata(path)
    files = _listed_files(path, info) if info is not None else ()
    if not files:
        files = tuple(sorted(path.glob("*.mcap"))) or tuple(sorted(path.glob("*.db3")))
    if not files:
        msg = f"bag directory {path} holds no .mcap or .db3 storage file"
        raise BagError(msg)
    return BagLayout(path=path, bag_dir=path, storage_files=files, metadata=info)


def _listed_files(bag_dir: Path, info: Mapping[str, Any] | None) -> tuple[Path, ...]:
    if info is None:
        return ()
    names = info.get("relative_file_paths") or []
    # rosbag2 < version 4 stored paths including the directory; only the name counts.
    return tuple(bag_dir / Path(str(n)).name for n in names)


def bag_custom_data(layout: BagLayout) -> dict[str, str]:
    """A bag's ``custom_data``: from ``metadata.yaml``, else from inside a lone MCAP file.

    rosbag2 (and ``BagRecorder``) also store the metadata in an MCAP metadata record named
    ``rosbag2`` when closing, so a complete ``.mcap`` copied out of its directory keeps it.

    Raises:
        BagError: The embedded metadata cannot be read.
    """
    if layout.metadata is not None:
        return custom_data_of(layout.metadata)
    mcap_file = next(iter(layout.mcap_files), None)
    if mcap_file is None:
        return {}
    try:
        with mcap_file.open("rb") as stream:
            for record in make_reader(stream).iter_metadata():
                if record.name == "rosbag2" and "serialized_metadata" in record.metadata:
                    info = yaml.safe_load(record.metadata["serialized_metadata"])
                    return custom_data_of(info if isinstance(info, dict) else None)
    except (McapError, yaml.YAMLError) as exc:
        msg = f"{mcap_file}: cannot read its embedded rosbag2 metadata: {exc}"
        raise BagError(msg) from None
    return {}
