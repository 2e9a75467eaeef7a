"""The catheter's robot model (``urdf/catheter.urdf``) and its transforms from ``tip/angle``.

``tip_tf`` is the catheter's ``robot_state_publisher``: from each ``tip/angle`` sample
(``sensor_msgs/JointState``, joint ``bend``) it publishes

- ``joint_states``: the same joint, as a stock ``robot_state_publisher`` consumes it;
- ``/tf``: ``base_link`` -> ``bend_distal``, and ``/tf_static``: ``bend_distal`` -> ``tip``
  (only where ``tf2_msgs`` is importable: the ROS wheels here lack it; a stock
  ``robot_state_publisher`` fed ``joint_states`` and ``robot_description`` gives the same TF);
- ``robot_description`` (``std_msgs/String``, transient local): the URDF.

``joint_states`` and ``/tf`` are published at most ``max_rate_hz`` (50 Hz by default): a view
needs no more, and 250 Hz of TF would only load the machine beside the control loop. The
transforms are computed from the URDF's own joint origins, so TF and model cannot disagree.

    ros2 run catheter_control tip_tf --ros-args -r __ns:=/catheter
"""

from __future__ import annotations

import importlib.resources
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from functools import cache
from typing import Any, Final

from rclpy.node import Node
from sensor_msgs.msg import JointState

from catheter_models.contract import BEND_JOINT, TIP_ANGLE
from catheter_models.errors import ParameterError
from catheter_ros import qos
from catheter_ros.messages import angle_rad_from, ns_from_time
from catheter_ros.node_main import run_node_as_main
from catheter_ros.params import declare_plain

URDF_RESOURCE: Final = "urdf/catheter.urdf"
"""The model inside the ``catheter_control`` package (also installed to ``share/``)."""
URDF_PACKAGE_URL: Final = "package://catheter_control/urdf/catheter.urdf"
"""How ROS tools and Foxglove name the model (``share/catheter_control/urdf/catheter.urdf``)."""
BASE_FRAME: Final = "base_link"
DISTAL_FRAME: Final = "bend_distal"
TIP_FRAME: Final = "tip"
MAX_RATE_HZ: Final = 50.0


@cache
def urdf_text() -> str:
    """The catheter's URDF, as shipped in the package."""
    return importlib.resources.files("catheter_control").joinpath(URDF_RESOURCE).read_text("utf-8")


@dataclass(frozen=True)
class BendChain:
    """The planar chain of the URDF: ``base_link`` -bend-> ``bend_distal`` -fixed-> ``tip``.

    Attributes:
        pivot_m: from ``base_link`` to the ``bend`` joint along x [m].
        distal_m: from the joint to the tip along the distal link's x [m].
        lower_rad, upper_rad: the joint's limits [rad].
    """

    pivot_m: float
    distal_m: float
    lower_rad: float
    upper_rad: float

    @classmethod
    def from_urdf(cls, text: str) -> BendChain:
        """Read the chain from URDF text; refuses a model that is not the planar chain.

        Raises:
            ParameterError: naming what is missing or not as expected.
        """
        root = ET.fromstring(text)
        joints = {j.get("name"): j for j in root.iter("joint")}
        bend = joints.get(BEND_JOINT)
        if bend is None or bend.get("type") != "revolute":
            raise ParameterError(f"URDF: no revolute joint named {BEND_JOINT!r}")
        tips = [j for j in joints.values() if _child(j) == TIP_FRAME]
        if len(tips) != 1 or tips[0].get("type") != "fixed":
            raise ParameterError(f"URDF: link {TIP_FRAME!r} must hang on one fixed joint")
        tip = tips[0]
        expected = {
            BEND_JOINT: (bend, BASE_FRAME, DISTAL_FRAME),
            str(tip.get("name")): (tip, DISTAL_FRAME, TIP_FRAME),
        }
        for name, (joint, parent, child) in expected.items():
            if _parent(joint) != parent or _child(joint) != child:
                raise ParameterError(f"URDF: joint {name!r} must link {parent!r} -> {child!r}")
        if _floats(bend.find("axis"), "xyz", "0 0 1") != [0.0, 0.0, 1.0]:
            raise ParameterError(f"URDF: joint {BEND_JOINT!r} must turn about z")
        pivot, distal = (_x_offset(j) for j in (bend, tip))
        limit = bend.find("limit")
        lower, upper = (_floats(limit, k, "nan")[0] for k in ("lower", "upper"))
        if not (lower < 0.0 < upper):
            raise ParameterError(f"URDF: joint {BEND_JOINT!r} needs limits lower < 0 < upper")
        return cls(pivot, distal, lower, upper)

    def transforms(self, angle_rad: float) -> dict[tuple[str, str], tuple[Translation, Quat]]:
        """Parent->child transforms at a bend angle [rad]: translation [m], quaternion xyzw."""
        half = 0.5 * angle_rad
        return {
            (BASE_FRAME, DISTAL_FRAME): (
                (self.pivot_m, 0.0, 0.0),
                (0.0, 0.0, math.sin(half), math.cos(half)),
            ),
            (DISTAL_FRAME, TIP_FRAME): ((self.distal_m, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0)),
        }

    def tip_xy_m(self, angle_rad: float) -> tuple[float, float]:
        """The tip's position in ``base_link`` [m]."""
        return (
            self.pivot_m + self.distal_m * math.cos(angle_rad),
            self.distal_m * math.sin(angle_rad),
        )


Translation = tuple[float, float, float]
Quat = tuple[float, float, float, float]


def _parent(joint: ET.Element) -> str | None:
    el = joint.find("parent")
    return None if el is None else el.get("link")


def _child(joint: ET.Element) -> str | None:
    el = joint.find("child")
    return None if el is None else el.get("link")


def _floats(el: ET.Element | None, key: str, default: str) -> list[float]:
    return [float(v) for v in (default if el is None else el.get(key, default)).split()]


def _x_offset(joint: ET.Element) -> float:
    origin = joint.find("origin")
    x, y, z = _floats(origin, "xyz", "0 0 0")
    if y or z or any(_floats(origin, "rpy", "0 0 0")):
        raise ParameterError(
            f"URDF: joint {joint.get('name')!r} must sit on its parent's x axis, unrotated"
        )
    return x


@cache
def chain() -> BendChain:
    """The shipped model's chain."""
    return BendChain.from_urdf(urdf_text())


def tf2_available() -> bool:
    """Whether ``tf2_msgs`` can be imported (the pip ROS wheels used here lack it)."""
    try:
        import tf2_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


class TipTf:
    """Publishes ``joint_states``, TF and ``robot_description`` for ``node`` from ``tip/angle``.

    Call :meth:`on_angle` with each ``tip/angle`` sample; :attr:`last` holds the newest
    transforms for anyone else (the live view) that shows them.
    """

    def __init__(self, node: Any, max_rate_hz: float = MAX_RATE_HZ) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import String

        if not (math.isfinite(max_rate_hz) and max_rate_hz > 0.0):
            raise ParameterError(f"tip_tf: max_rate_hz must be > 0, got {max_rate_hz!r}")
        self.node = node
        self.chain = chain()
        self.min_interval_ns = round(1e9 / max_rate_hz)
        latched = QoSProfile(
            depth=1,
            reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
        )
        node.create_publisher(String, "robot_description", latched).publish(
            String(data=urdf_text())
        )
        self._joint_states = node.create_publisher(JointState, "joint_states", 10)
        self._tf: Any = None
        self.tf_published = tf2_available()
        if self.tf_published:
            from tf2_msgs.msg import TFMessage

            self._tf = node.create_publisher(TFMessage, "/tf", 100)
            static = node.create_publisher(TFMessage, "/tf_static", latched)
            static.publish(self._tf_message(0, [(DISTAL_FRAME, TIP_FRAME)], 0.0))
        self._last_ns: int | None = None
        self.angle_rad: float | None = None

    def on_angle(self, stamp_ns: int, angle_rad: float) -> bool:
        """One ``tip/angle`` sample; True if it was published (not thinned by the rate)."""
        from sensor_msgs.msg import JointState

        self.angle_rad = angle_rad
        if self._last_ns is not None and 0 <= stamp_ns - self._last_ns < self.min_interval_ns:
            return False
        self._last_ns = stamp_ns
        msg = JointState()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
        msg.name = [BEND_JOINT]
        msg.position = [angle_rad]
        self._joint_states.publish(msg)
        if self._tf is not None:
            self._tf.publish(self._tf_message(stamp_ns, [(BASE_FRAME, DISTAL_FRAME)], angle_rad))
        return True

    def _tf_message(self, stamp_ns: int, pairs: list[tuple[str, str]], angle_rad: float) -> Any:
        from geometry_msgs.msg import TransformStamped
        from tf2_msgs.msg import TFMessage

        out = TFMessage()
        poses = self.chain.transforms(angle_rad)
        for parent, child in pairs:
            (x, y, z), (qx, qy, qz, qw) = poses[(parent, child)]
            t = TransformStamped()
            t.header.stamp.sec, t.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
            t.header.frame_id = parent
            t.child_frame_id = child
            t.transform.translation.x, t.transform.translation.y = x, y
            t.transform.translation.z = z
            t.transform.rotation.x, t.transform.rotation.y = qx, qy
            t.transform.rotation.z, t.transform.rotation.w = qz, qw
            out.transforms.append(t)
        return out


class TipTfNode(Node):
    """``tip_tf`` as a node: ``tip/angle`` in, :class:`TipTf`'s topics out."""

    def __init__(self) -> None:
        super().__init__("tip_tf")
        # Through params: an integer (max_rate_hz:=30) is taken as the double it means.
        rate = float(
            declare_plain(
                self, "max_rate_hz", MAX_RATE_HZ, "most tip/angle samples a second", False
            )
        )
        self.tf = TipTf(self, rate)
        self.bad_samples = 0
        self.create_subscription(JointState, TIP_ANGLE.name, self._on_angle, qos.SENSOR)
        if not self.tf.tf_published:
            self.get_logger().warning(
                "tf2_msgs is not installed: publishing joint_states and robot_description "
                "only (a robot_state_publisher turns them into /tf)"
            )

    def _on_angle(self, msg: JointState) -> None:
        try:
            angle_rad = angle_rad_from(msg)
        except ValueError as exc:
            # Someone else's driver may name its joints differently: say so, once.
            if not self.bad_samples:
                self.get_logger().error(f"tip/angle: {exc}; no TF from such samples")
            self.bad_samples += 1
            return
        self.tf.on_angle(ns_from_time(msg.header.stamp), angle_rad)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control tip_tf``."""
    run_node_as_main(TipTfNode, args)


if __name__ == "__main__":
    main()
