"""The interface contract (``docs/interfaces.md``) as constants.

Nodes, the recorder and the bag loader all read topic names, types and the joint name from
here, and so do the nodes, the simulated plant and model evaluation for the pressure limits,
the rates and the QoS numbers, so a change to the contract is one edit and a reviewer sees it
in one place. A limit that could be changed in one place and not in another would be a safety
defect; ``tests/test_one_source.py`` fails if one of these numbers is typed anywhere else.
"""

from __future__ import annotations

from typing import Final, NamedTuple

DEFAULT_NAMESPACE: Final = "/catheter"
BEND_JOINT: Final = "bend"
"""The one bending joint of the thesis's catheter. Multi-DOF catheters add names later."""

SENSOR_RATE_HZ: Final = 250.0
"""Laser (Baumer OADM) and pressure transmitter sampling rate of the thesis's rig."""
CONTROL_RATE_HZ: Final = 250.0
"""The compensator's and the valve driver's tick rate: one command per sensor sample."""

MAX_PRESSURE_PA: Final = 3.0e5
"""The safety ceiling on the muscle's gauge pressure (3 bar, the thesis's regulator span).

Every layer that can move the catheter clamps or refuses above its own ``max_pressure_pa``
parameter, and every such parameter defaults to this one value."""

MAX_SLEW_PA_PER_S: Final = 20.0e5
"""How fast a pressure command may change (20 bar/s: 0 to 3 bar in 0.15 s, faster than any
thesis trajectory asks). The compensator limits its command to it and the valve driver its
set-point, so a jump from a bad model or a bad message reaches the muscle as a ramp."""

COMMAND_TIMEOUT_S: Final = 0.1
"""The watchdog: a driver that has had no pressure command for this long vents to zero
(25 control periods at 250 Hz). The valve driver's ``watchdog_s`` and the simulated rig's
``command_timeout_s`` default to it."""

PRESSURE_LIMIT_HARD_PA: Final = 6.0e5
"""The highest value any ``max_pressure_pa`` parameter accepts (6 bar, twice the thesis's
span, the top of the 0-6 bar valve modules' range): beyond it a typo, not a choice."""

FEEDBACK_AUTHORITY_PA: Final = 0.5e5
"""How far feedback on the measured bend may move the command from the feedforward's by default
(``max_correction_pa``, 0.5 bar): a sixth of ``MAX_PRESSURE_PA``, about 7 deg of bend on the
simulated rig, so a laser that freezes at a plausible value cannot drive the catheter to the
clamp."""
FEEDBACK_MAX_AUTHORITY_PA: Final = 1.0e5
"""The safety envelope's bound on that authority (1 bar): any ``feedback.json``, sealed or not,
with more is refused. A third of ``MAX_PRESSURE_PA``'s span (15 deg at the rig's stiffest
15 deg/bar) is as far as a lying laser may bend the catheter from its plan; wider, the authority
stops being a bound and the clamp is all that is left."""
FEEDBACK_AUTHORITY_TIMEOUT_S: Final = 0.5
"""How long the feedback may press against its authority before the run ramps down, by default
(``authority_timeout_s``): the value the shipped gains have run with since feedback was added,
three times the 0.15 s the slew limit takes to cross the whole clamp."""
FEEDBACK_MAX_AUTHORITY_TIMEOUT_S: Final = 2.0
"""The safety envelope's bound on that timeout (2 s, four times the default): how long a catheter
may be held off its plan by a frozen laser before the run stops. Longer, and the authority check
is no check (a 10^6 s timeout never fires)."""


MAX_TRAJECTORY_DURATION_S: Final = 600.0
"""The longest trajectory (time of its last point) the compensator takes: 10 minutes.

The thesis's trajectories last 20-40 s; a long procedure is minutes. Beyond 10 minutes a plan is
more likely a unit slip (ms for s) than a procedure, and a hold or a new trajectory goes on."""
MAX_TRAJECTORY_POINTS: Final = 15_000
"""The most points one trajectory may have: 5 minutes of knots at 50 Hz, the thesis's knot rate
(its 20-40 s trajectories have 1,000-2,000), a minute at the control rate, or the longest
trajectory (``MAX_TRAJECTORY_DURATION_S``) knotted at 25 Hz.

The bound keeps taking a trajectory off the control loop's back: rclpy builds a Python object
per point, holding the GIL the loop thread needs, about 18 us a point on the busy 2-core test
machine. A 10^6-point message held it for 13 s (842 missed deadlines, the watchdog vented); one
of 30,000 points still put the loop 64 ms behind its deadline, close to the 0.1 s watchdog, so
the limit is half that."""
MAX_TRAJECTORY_MESSAGE_BYTES: Final = 1024 * 1024
"""The largest serialised ``trajectory`` message the compensator deserialises (1 MiB).

A point of the one joint is 32 bytes in CDR with a position, 48 with a velocity too and 64 with
an acceleration too (15,000 such points serialise to 960,036 bytes), so 1 MiB holds
``MAX_TRAJECTORY_POINTS`` of them; anything bigger is refused by its length, before rclpy
turns it into Python objects."""
MAX_TRAJECTORY_FILE_BYTES: Final = 2 * 1024 * 1024
"""The largest trajectory file (CSV/YAML) ``follow_trajectory --file`` reads (2 MiB): about 140
bytes a row for ``MAX_TRAJECTORY_POINTS`` rows, more than a CSV row (~25 bytes) or a YAML point
(~40 bytes) of the thesis's trajectories takes."""

STREAM_DEPTH: Final = 500
"""Samples a stream's publisher keeps for re-sending, and a keeping subscriber queues: 2 s at
250 Hz, 0.5 s at 1 kHz (longer than any stall measured on a busy machine)."""


class QosSpec(NamedTuple):
    """One QoS profile of the contract as plain data.

    Both rclpy's profiles (``catheter_ros.qos``) and a bag's ``metadata.yaml``
    (``catheter_models.bag.metadata``) are built from these, so they cannot disagree. Every
    profile of the contract keeps the last ``depth`` samples (history keep-last).
    """

    depth: int
    reliable: bool
    """Reliable (re-sent if lost) rather than best effort."""
    transient_local: bool
    """Transient-local (a late subscriber still gets the last ``depth``) rather than volatile."""


QOS_STREAM: Final = QosSpec(depth=STREAM_DEPTH, reliable=True, transient_local=False)
"""What every sensor and command stream offers (``catheter_ros.qos.STREAM``)."""
QOS_KEEP_EVERY_SAMPLE: Final = QosSpec(depth=STREAM_DEPTH, reliable=False, transient_local=False)
"""Best effort with a deep queue (``catheter_ros.qos.KEEP_EVERY_SAMPLE``): matches any publisher
and keeps every sample that reaches the listener."""
QOS_RECORD: Final = QosSpec(depth=STREAM_DEPTH, reliable=True, transient_local=False)
"""The recorder's request (``catheter_ros.qos.RECORD``): every sample, re-sent if lost."""
QOS_TRAJECTORY: Final = QosSpec(depth=1, reliable=True, transient_local=True)
"""``trajectory`` (``catheter_ros.qos.TRAJECTORY``): latched, so a late subscriber still gets it."""
QOS_SENSOR_DATA: Final = QosSpec(depth=5, reliable=False, transient_local=False)
"""rclpy's ``qos_profile_sensor_data`` (``catheter_ros.qos.SENSOR``): what a controller asks of
a stream, and what the streams offered before they were reliable (older bags record it)."""


class TopicSpec(NamedTuple):
    """One topic of the contract: its name relative to the namespace and its ROS type."""

    name: str
    msgtype: str


PRESSURE_COMMAND: Final = TopicSpec("pressure/command", "sensor_msgs/msg/FluidPressure")
PRESSURE_MEASURED: Final = TopicSpec("pressure/measured", "sensor_msgs/msg/FluidPressure")
TIP_DISTANCE: Final = TopicSpec("tip/distance", "sensor_msgs/msg/Range")
TIP_ANGLE: Final = TopicSpec("tip/angle", "sensor_msgs/msg/JointState")
ANGLE_DESIRED: Final = TopicSpec("angle/desired", "sensor_msgs/msg/JointState")
TRAJECTORY: Final = TopicSpec("trajectory", "trajectory_msgs/msg/JointTrajectory")
DIAGNOSTICS: Final = TopicSpec("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")

RECORDED_TOPICS: Final = (
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_DISTANCE,
    TIP_ANGLE,
    ANGLE_DESIRED,
    TRAJECTORY,
)
"""What the recorder writes by default (diagnostics are not science data)."""

SENSOR_STREAMS: Final = (PRESSURE_MEASURED, TIP_DISTANCE, TIP_ANGLE)
"""Published every sample for as long as the driver runs: any silence in them is lost data."""

RUN_STREAMS: Final = (PRESSURE_COMMAND, ANGLE_DESIRED)
"""Published every tick while a run lasts, and silent between runs (see ``gaps.PAUSE_S``)."""

REQUIRED_BAG_TOPICS: Final = (PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE)
"""A bag holds at least these; tools that read a bag name anything missing and stop."""


def qualify(topic: TopicSpec | str, namespace: str = DEFAULT_NAMESPACE) -> str:
    """Full topic name: absolute names stay, relative ones go under ``namespace``."""
    name = topic.name if isinstance(topic, TopicSpec) else topic
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"
