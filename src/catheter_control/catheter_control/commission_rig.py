"""The rig ``commission`` drives: one it starts (``--sim``, ``--emulated-rig``) or one running.

Commissioning needs the hardware side of the graph (the valve and the laser, or what stands
in for them) to stay up through every step, while the parts on top come and go: a recorder
and ``excite`` for each excitation, then a compensator per candidate for the trajectories.
So the hardware is one :class:`~catheter_control.process_graph.ProcessGraph` (or the drivers a
person started on the rig), and each step starts and stops its own nodes on it, exactly the
processes a person would start by hand (docs/commissioning.md lists them).

A recording is watched as ``follow_trajectory``'s is
(:class:`~catheter_control.recording_watch.RecordingWatch`): a recorder that exits or reports
ERROR (it cannot write) stops ``excite`` at once (it ramps the pressure down) and fails the
step with the reason and the seconds that went unrecorded from when. There is no going on
without a bag here: a recording step's bag is all it is for.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from catheter_control.bringup import EmulatedDevices, driver_specs, sim_graph_specs
from catheter_control.process_graph import NodeSpec, ProcessGraph
from catheter_control.progress_bar import ProgressBar
from catheter_control.recording_watch import RecordingWatch
from catheter_control.tracking_report import RunRecord
from catheter_control.trajectory import TrajectoryPlan
from catheter_models.bag import load_bag
from catheter_models.bag.space import SpaceNeed, contract_streams, need_for
from catheter_models.contract import (
    CONTROL_RATE_HZ,
    PRESSURE_MEASURED,
    SENSOR_RATE_HZ,
    TIP_ANGLE,
)
from catheter_models.errors import CatheterError, GraphConflictError
from catheter_models.geometry import Calibration
from catheter_models.lab.signals import lab_spec
from catheter_models.plant import PlantConfig
from catheter_models.signals import get_preset

RIG_MODES = ("sim", "emulated", "running")

_EXCITE_LEAD_IN_S = 0.5
_EXCITE_TAIL_S = 1.0
_EXCITE_START_WAIT_S = 30.0
"""How long ``excite`` waits for the rig and the recorder to subscribe (discovery on a busy
host can take seconds; a rig that never listens is named after this)."""
_MOVING_PA = 1.0e3
"""A command above this has left rest [Pa] (excite's lead-in sends zeros)."""
_TAKES_PER_SPIN = 8
"""Callbacks a watching listener runs after each wait: the newest sample of the three streams
it watches and the /diagnostics reports that came in (one a second from each node)."""
_UNKNOWN = "_UNKNOWN_"
"""What rclpy names a publisher's node and namespace before their names are discovered."""
_LOOK_S = 10.0
"""How long a look at a running graph lasts (unless a node commanding the valve is found
first): DDS discovery on one idle host takes well under a second, on a busy one several,
and a node found late would be a node that fights the excitations."""
_SETTLE_S = 2.0
"""Rest between runs: the muscle empties and the tip comes back before the next one starts."""

# What a recording must show for the rig to count as responding. A valve that moves follows
# its set-point within its own accuracy (the Keller transmitter reads 0.1 % of its span);
# a catheter that bends moves its tip by tens of degrees over 3 bar. These bounds sit far
# below both and far above noise (0.05 deg, a few hundred Pa), so a working rig never trips
# them and a frozen one always does.
MIN_COMMAND_SPAN_PA = 0.5e5
"""A recording whose command spans less than this says nothing about the rig."""
MIN_PRESSURE_FOLLOW = 0.2
"""The measured pressure must span at least this share of the commanded span."""
MIN_BEND_SPAN_DEG = 1.0
"""The bend must span at least this much when the pressure spans a bar or more."""
LIVE_VALVE_COMMAND_SPAN_BAR = 1.0
"""The live watch judges the valve once the command has spanned this much."""
LIVE_TIP_PRESSURE_SPAN_BAR = 1.5
"""... and the tip once the measured pressure has spanned this much (half the range)."""
LIVE_GRACE_S = 2.0
"""... this long after each, so a slow tube or tip has followed."""
LIVE_MIN_SAMPLES = 20
"""Samples of each stream the live watch needs before it judges anything."""
LIVE_SAMPLE_S = 0.2
"""The live watch takes the newest sample of each stream this often: a few callbacks a
second, where taking every sample (750 a second) would load the host the recording needs."""
MAX_COMMANDS_LOST_SHARE = 0.05
"""Past this share of the excitation's commands missing from the recording, it is not used.

A command missing from the bag is a tick ``excite`` skipped (the plant then held the one
before, which the resampling's hold reproduces) or one DDS lost on its way to the recorder
(the plant got it, the bag holds the one before): either way the models learn from a held
command. A few are harmless; a fifth (seen on a foreign plant, a pure-Python plugin in a
real-time ``sim_hardware`` on two busy cores) is a host too busy to record on."""


class RigError(CatheterError):
    """The rig did not come up, or does not respond (frozen laser, valve that does not move)."""


@dataclass(frozen=True)
class RigChoice:
    """Which rig commission drives.

    Attributes:
        mode: ``sim`` (commission starts ``sim_hardware``), ``emulated`` (emulated devices
            and the real drivers), or ``running`` (drivers already up in ``namespace``).
        plant: ``module:factory`` of the plant behind ``sim``/``emulated`` ('' = ours).
        namespace: The graph's namespace.
    """

    mode: str
    plant: str
    namespace: str
    domain: str = "env"
    """``--domain-id`` for a rig commission starts (auto, env, N); a running rig's is env."""

    def describe(self) -> str:
        """One line for the terminal and the report."""
        plant = self.plant or "the shipped simulated rig"
        if self.mode == "sim":
            return f"simulated rig (sim_hardware), plant: {plant}"
        if self.mode == "emulated":
            return f"emulated devices and the real drivers, plant: {plant}"
        return f"the drivers already running in {self.namespace}"

    def to_dict(self) -> dict[str, str]:
        """For commission.json: a directory is commissioned on one rig (any domain)."""
        return {"mode": self.mode, "plant": self.plant, "namespace": self.namespace}


@dataclass(frozen=True)
class Candidate:
    """A compensator with the tuned feedback, as the node will host it.

    Attributes:
        name: The candidate's label (``idrdpi+pi``).
        compensator: The node's ``compensator`` parameter.
        model_dir: Its model directory.
        feedback: ``pi`` or ``none``.
        feedback_gains: The ``feedback.json`` that ``catheter-lab tune`` wrote.
        feedforward_shaping: ``none``, or ``zvd`` when the tuned loop has a ringing tip.
    """

    name: str
    compensator: str
    model_dir: Path
    feedback: str
    feedback_gains: Path
    feedforward_shaping: str = "none"

    def params(self, control_rate_hz: float) -> dict[str, object]:
        """The compensator node's parameters."""
        return {
            "control_rate_hz": control_rate_hz,
            "compensator": self.compensator,
            "model_dir": str(self.model_dir),
            "feedback": self.feedback,
            "feedback_gains": str(self.feedback_gains),
            "feedforward_shaping": self.feedforward_shaping,
            # The rig has a laser: stop if it goes quiet, as follow_trajectory --sim does.
            "require_tip_angle": True,
        }


def signal_duration_s(signals: Sequence[str], rate_hz: float = CONTROL_RATE_HZ) -> float:
    """About how long ``excite`` takes to send ``signals`` [s]: for the progress bar only.

    Lead-in, each signal and its tail; the ramp down after a signal that ends above zero
    (at most a second or so) is left out.
    """
    total = _EXCITE_LEAD_IN_S
    for name in signals:
        spec = lab_spec(name) or get_preset(name)
        total += spec.generate(rate_hz).values_si.size / rate_hz + _EXCITE_TAIL_S
    return total


RECORDING_START_STOP_S = 60.0
"""What a recording records beyond its excitation, for the free-space check [s]: the recorder
and excite finding the rig (up to _EXCITE_START_WAIT_S), and the stop."""


def recording_need(bags_dir: Path, recordings: Sequence[Sequence[str]]) -> SpaceNeed:
    """The free space the recordings (each a list of signals) take in ``bags_dir``."""
    duration_s = sum(signal_duration_s(s) + RECORDING_START_STOP_S for s in recordings)
    return need_for(bags_dir, duration_s, contract_streams())


class CommissionRig:
    """The hardware side of the graph, up for the whole commissioning.

    Args:
        choice: Which rig.
        log_dir: Where every started node logs.
        timeout_s: How long the graph may take to come up.
    """

    def __init__(self, choice: RigChoice, log_dir: Path, timeout_s: float = 60.0) -> None:
        self.choice = choice
        self.log_dir = log_dir
        self.timeout_s = timeout_s
        self._graph: ProcessGraph | None = None
        self._devices: EmulatedDevices | None = None

    # -- the hardware ---------------------------------------------------------------------
    def start(self) -> None:
        """Bring the hardware up (or check the running drivers).

        Raises:
            RigError: a node or the emulated devices failed to start, or (``running``) no
                driver publishes in the namespace, or a compensator already runs there.
            GraphConflictError: (``sim``, ``emulated``) another graph runs in the domain.
        """
        from catheter_control.graph_domain import choose_domain

        choice = self.choice
        if choice.mode in ("sim", "emulated"):
            # A local rig must never reach a real one on the network, nor a graph running in
            # its domain (GraphConflictError names it).
            os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
            choose_domain(choice.domain, choice.namespace, "commission")
        if choice.mode == "running":
            self._check_running()
            return
        sim_params: dict[str, object] = {"plant": choice.plant} if choice.plant else {}
        specs = sim_graph_specs(None, None, sim_params, with_compensator=False)
        if choice.mode == "emulated":
            self._devices = EmulatedDevices(
                extra_args=["--plant", choice.plant] if choice.plant else ()
            )
            try:
                ports = self._devices.start()
            except RuntimeError as exc:
                raise RigError(str(exc)) from exc
            # Zeroed at the simulated straight-tip distance, as ~/zero would measure it.
            calibration = self.log_dir / "laser_calibration.json"
            self.log_dir.mkdir(parents=True, exist_ok=True)
            straight_m = PlantConfig.thesis_rig().rig["straight_distance_m"]
            Calibration(straight_m, 0.0, 0, "emulated rig").save(calibration)
            specs = driver_specs(ports, calibration)
        graph = ProcessGraph(specs, choice.namespace, log_dir=self.log_dir)
        try:
            graph.start()
        except GraphConflictError:
            self.stop()
            raise  # a refusal (commission exits 2), not a rig that failed to come up
        except CatheterError as exc:
            self.stop()
            raise RigError(f"the rig did not come up: {exc}") from exc
        self._graph = graph

    def stop(self) -> None:
        """Stop what this rig started (nothing for a running one)."""
        if self._graph is not None:
            self._graph.stop()
            self._graph = None
        if self._devices is not None:
            self._devices.stop()
            self._devices = None

    def _check_running(self) -> None:
        """Drivers publish in the namespace and nothing else commands the valve."""
        import rclpy
        from rclpy.node import Node

        from catheter_ros.dds_profile import use_loopback_profile

        ns = self.choice.namespace.rstrip("/")
        sensors = [f"{ns}/pressure/measured", f"{ns}/tip/angle"]
        command = f"{ns}/pressure/command"
        start = time.monotonic()
        use_loopback_profile()
        with rclpy.init(args=["commission"]):
            node = Node("commission_probe")

            def commanding() -> list[str]:
                return sorted(
                    f"{info.node_namespace.rstrip('/')}/{info.node_name}"
                    for info in node.get_publishers_info_by_topic(command)
                )

            # Discovery is gradual, and slow on a busy machine: a clean-clone CI run beside a
            # benchmark had found the drivers but not yet the compensator 2 s in, and excited
            # beside it. So the look lasts its whole window (a few seconds of a commissioning
            # that takes minutes) unless a commanding node shows up first.
            # A publisher is announced before its node's name (ros_discovery_info follows):
            # look on until the names are known too, to refuse the node by name.
            commanders: list[str] = []
            while time.monotonic() - start < min(self.timeout_s, _LOOK_S) and not (
                commanders and not any(_UNKNOWN in c for c in commanders)
            ):
                rclpy.spin_once(node, timeout_sec=0.2)
                commanders = commanding()
            topics = {name for name, _ in node.get_topic_names_and_types()}
            node.destroy_node()
        commanders = [
            "a node whose name was not yet discovered" if _UNKNOWN in c else c for c in commanders
        ]
        missing = [t for t in sensors if t not in topics]
        if missing:
            raise RigError(
                f"no {', '.join(missing)} in this ROS domain "
                f"(ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}): start the rig's "
                "drivers first (docs/rig.md), or use --sim / --emulated-rig"
            )
        if commanders:
            raise RigError(
                f"{', '.join(commanders)} is running and publishes {command}: it would fight the "
                "excitations; start the drivers without it (commission starts its own "
                "compensator)"
            )

    # -- steps on top of it ---------------------------------------------------------------
    def record(
        self,
        signals: Sequence[str],
        bag_path: Path,
        custom_data: Mapping[str, str],
        *,
        show_progress: bool,
    ) -> None:
        """Record ``excite`` sending ``signals`` open loop into a new bag at ``bag_path``.

        Raises:
            RigError: the recorder or ``excite`` failed (the log's last lines say why), or
                the rig never listened.
        """
        recorder = NodeSpec(
            "recorder",
            "catheter_control.recorder_node",
            {"bag_path": str(bag_path), "custom_data": json.dumps(dict(custom_data))},
        )
        graph = ProcessGraph([recorder], self.choice.namespace, log_dir=self.log_dir)
        graph.start()
        excite_log = self.log_dir / f"excite-{bag_path.name}.log"
        argv = [
            sys.executable,
            "-m",
            "catheter_control.excite_node",
            "--ros-args",
            "-r",
            f"__ns:={self.choice.namespace}",
            "-p",
            f"signal:={','.join(signals)}",
            # The rig (or valve driver) and the recorder: a recording needs both listening.
            "-p",
            "min_subscribers:=2",
            "-p",
            f"wait_for_subscriber_s:={_EXCITE_START_WAIT_S}",
            "-p",
            f"lead_in_s:={_EXCITE_LEAD_IN_S}",
            "-p",
            f"tail_s:={_EXCITE_TAIL_S}",
        ]
        duration_s = signal_duration_s(signals)
        bar = ProgressBar(duration_s, show_progress)
        heard = RunRecord()  # the recorder's /diagnostics land here
        response = LiveResponse()
        not_moving = ""
        watch = RecordingWatch(
            bag_path,
            graph,
            heard,
            tool="commission",
            stopping="stopping excite (it ramps the pressure down) and the step",
        )
        failed = ""
        start_ns = time.time_ns()
        try:
            with (
                excite_log.open("wb") as log,
                _DiagnosticsListener(self.choice.namespace, heard, response) as listener,
            ):
                # Discovery is pairwise: the rig's sensors may reach excite and not yet the
                # recorder. Excited before the recorder hears them, the bag began 2.7 s into
                # the excitation, mid-motion, once, and the lab fitted from a wrong rest.
                self._wait_until_recorder_hears(listener, heard)
                proc = subprocess.Popen(argv, stdout=log, stderr=subprocess.STDOUT)
                start = time.monotonic()
                limit_s = duration_s + _EXCITE_START_WAIT_S + 30.0
                try:
                    while proc.poll() is None:
                        listener.spin(LIVE_SAMPLE_S)
                        bar.show(time.monotonic() - start)
                        self._check_alive()
                        failed = watch.check()
                        if failed:
                            break  # excite is stopped below: it ramps the pressure down
                        not_moving = response.problem(time.monotonic())
                        if not_moving:
                            moving_s = time.monotonic() - start
                            break
                        if time.monotonic() - start > limit_s:
                            raise RigError(
                                f"excite did not finish {signals} within {limit_s:.0f} s"
                            )
                finally:
                    if proc.poll() is None:
                        proc.terminate()  # excite ramps down before it exits
                        proc.wait(10.0)
        finally:
            bar.close()
            if failed:
                facts = watch.finish(time.time_ns(), start_ns)
            graph.stop()
        if failed:
            raise RigError(
                f"{bag_path.name}: {failed}; excite was stopped and ramped the pressure down; "
                f"{facts['unrecorded_s']:.1f} s of the excitation went unrecorded from "
                f"{facts['unrecorded_from']}; the step is to be run again (rerun the command)"
            )
        if not_moving:
            raise RigError(
                f"{bag_path.name}: {not_moving}; seen {moving_s:.0f} s into the excitation of "
                f"about {duration_s:.0f} s, so excite was stopped there (it ramps the pressure "
                "down)"
            )
        if proc.returncode != 0:
            tail = "\n".join(excite_log.read_text(errors="replace").splitlines()[-5:])
            raise RigError(f"excite ended with code {proc.returncode}:\n{tail}")

    def _wait_until_recorder_hears(self, listener: _DiagnosticsListener, heard: RunRecord) -> None:
        """Until the recorder reports a publisher on each sensor stream (its /diagnostics).

        Raises:
            RigError: it hears none on one of them within the start wait.
        """
        ns = self.choice.namespace.rstrip("/")
        streams = [f"{ns}/{name}" for name in (PRESSURE_MEASURED.name, TIP_ANGLE.name)]

        def unheard() -> list[str]:
            return [t for t in streams if int(heard.recorder.get(f"publishers {t}", "0")) < 1]

        until = time.monotonic() + _EXCITE_START_WAIT_S
        while unheard() and time.monotonic() < until:
            listener.spin(0.1)
            self._check_alive()
        if unheard():
            raise RigError(
                f"the recorder hears no publisher on {', '.join(unheard())} after "
                f"{_EXCITE_START_WAIT_S:g} s; nothing was excited"
            )

    def _check_alive(self, extra: ProcessGraph | None = None) -> None:
        for graph in (self._graph, extra):
            if graph is not None and (dead := graph.failed()):
                name = next(iter(dead))
                raise RigError(
                    f"{name} exited (code {dead[name]}) during commissioning; its log ends:\n"
                    f"{graph.log_tail(name, 8)}"
                )

    def follow(
        self,
        plan: TrajectoryPlan,
        candidate: Candidate,
        lead_s: float,
        *,
        control_rate_hz: float,
        show_progress: bool,
    ) -> RunRecord:
        """Start the candidate's compensator, follow ``plan`` as follow_trajectory does, stop it.

        Raises:
            RigError: the compensator did not come up, or the rig died.
            GoalRefusedError, GraphNotReadyError: as ``follow_trajectory``'s run.
        """
        from catheter_control.trajectory_client import follow

        self._check_alive()
        spec = NodeSpec(
            "compensator",
            "catheter_control.compensator_node",
            candidate.params(control_rate_hz),
        )
        graph = ProcessGraph([spec], self.choice.namespace, log_dir=self.log_dir)
        try:
            graph.start()
        except CatheterError as exc:
            raise RigError(f"{candidate.name}: the compensator did not come up: {exc}") from exc
        try:
            return follow(
                plan,
                namespace=self.choice.namespace,
                ros_args=[],
                timeout_s=self.timeout_s,
                graph=graph,
                wait_for_recorder=False,
                show_progress=show_progress,
                lead_s=lead_s,
            )
        finally:
            graph.stop()  # deactivates the compensator first: it ramps the pressure down
            time.sleep(_SETTLE_S)


class _DiagnosticsListener:
    """A node that keeps the recorder's newest /diagnostics report in ``record``."""

    def __init__(
        self, namespace: str, record: RunRecord, response: LiveResponse | None = None
    ) -> None:
        self.namespace = namespace
        self.record = record
        self.response = response

    def __enter__(self) -> _DiagnosticsListener:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
        from rclpy.node import Node
        from rclpy.signals import SignalHandlerOptions

        from catheter_models.contract import DIAGNOSTICS
        from catheter_ros.dds_profile import use_loopback_profile

        use_loopback_profile()
        self._rclpy = rclpy
        # Python's own SIGINT handling stays: Ctrl-C is commission's KeyboardInterrupt.
        self._context = rclpy.init(
            args=["commission", "--ros-args", "-r", f"__ns:={self.namespace}"],
            signal_handler_options=SignalHandlerOptions.NO,
        )
        self._context.__enter__()
        self.node = Node("commission_recording_watch")
        record = self.record

        def on_diag(msg: DiagnosticArray) -> None:
            for status in msg.status:
                if status.name.endswith("recorder"):
                    record.recorder = {kv.key: kv.value for kv in status.values}
                    error = status.level == DiagnosticStatus.ERROR
                    record.recorder_error = status.message if error else ""

        self.node.create_subscription(DiagnosticArray, DIAGNOSTICS.name, on_diag, 10)
        if self.response is not None:
            self._watch_streams(self.response)
        return self

    def _watch_streams(self, response: LiveResponse) -> None:
        from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import FluidPressure, JointState

        from catheter_models.contract import PRESSURE_COMMAND
        from catheter_ros.messages import angle_rad_from

        # The newest sample only, best effort: it matches any publisher, and what is not
        # taken is overwritten below Python, at no cost to the host.
        newest = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT
        )
        self.node.create_subscription(
            FluidPressure,
            PRESSURE_COMMAND.name,
            lambda m: response.command_pa.append(float(m.fluid_pressure)),
            newest,
        )
        self.node.create_subscription(
            FluidPressure,
            PRESSURE_MEASURED.name,
            lambda m: response.measured_pa.append(float(m.fluid_pressure)),
            newest,
        )
        self.node.create_subscription(
            JointState,
            TIP_ANGLE.name,
            lambda m: response.angle_rad.append(angle_rad_from(m)),
            newest,
        )

    def spin(self, timeout_s: float) -> None:
        """Take what arrived, waiting up to ``timeout_s``."""
        if self.response is None:
            self._rclpy.spin_once(self.node, timeout_sec=timeout_s)
            return
        # With the streams watched, a wait would end at every one of their 750 samples a
        # second: wait out the time instead, then take the newest of each (and the reports).
        time.sleep(timeout_s)
        for _ in range(_TAKES_PER_SPIN):
            self._rclpy.spin_once(self.node, timeout_sec=0.0)

    def __exit__(self, *exc: object) -> None:
        self.node.destroy_node()
        self._context.__exit__(None, None, None)


def unresponsive(
    command_span_bar: float, measured_span_bar: float, bend_span_deg: float, *, judge_tip: bool
) -> str:
    """'' if the valve follows its command (and the tip bends, if ``judge_tip``), else what not.

    One judgement for the whole recording afterwards and for the live watch during it.
    """
    if measured_span_bar < MIN_PRESSURE_FOLLOW * command_span_bar:
        return (
            f"the valve does not move: pressure/measured spans {measured_span_bar:.3f} bar "
            f"while pressure/command spans {command_span_bar:.2f} bar (valve, supply, or "
            "transmitter?)"
        )
    if judge_tip and bend_span_deg < MIN_BEND_SPAN_DEG:
        return (
            f"the tip does not move: tip/angle spans {bend_span_deg:.2f} deg while the "
            f"pressure spans {measured_span_bar:.2f} bar (a frozen laser, a laser off its "
            "marker, or a catheter that does not bend)"
        )
    return ""


def _span(values: Sequence[float] | np.ndarray) -> float:
    """5th to 95th percentile: a spike or a glitch does not count as motion."""
    low, high = np.percentile(np.asarray(values, dtype=float), [5.0, 95.0])
    return float(high - low)


@dataclass
class LiveResponse:
    """The rig's response while a recording runs, from a sample of the streams it hears.

    The recording is checked whole afterwards (:func:`check_response`); this watch stops a
    rig that does not respond seconds into the motion instead of after the whole excitation
    (minutes in the full protocol), while the pressure is still low. It judges as the check
    does, with the same bounds, but only once the motion leaves no doubt: the valve once the
    command has spanned :data:`LIVE_VALVE_COMMAND_SPAN_BAR`, the tip once the measured
    pressure has spanned :data:`LIVE_TIP_PRESSURE_SPAN_BAR` (a muscle's dead band keeps a
    working tip still over the first bar or so), each :data:`LIVE_GRACE_S` later (a long
    tube's lag, the tip's own).
    """

    command_pa: list[float] = field(default_factory=list)
    measured_pa: list[float] = field(default_factory=list)
    angle_rad: list[float] = field(default_factory=list)
    _valve_from_s: float | None = None
    _tip_from_s: float | None = None

    def problem(self, now_s: float) -> str:
        """'' while the rig responds or it is too early to say, else what does not move."""
        if min(len(self.command_pa), len(self.measured_pa), len(self.angle_rad)) < (
            LIVE_MIN_SAMPLES
        ):
            return ""
        command_bar = _span(self.command_pa) / 1e5
        measured_bar = _span(self.measured_pa) / 1e5
        if self._valve_from_s is None and command_bar >= LIVE_VALVE_COMMAND_SPAN_BAR:
            self._valve_from_s = now_s
        if self._tip_from_s is None and measured_bar >= LIVE_TIP_PRESSURE_SPAN_BAR:
            self._tip_from_s = now_s
        valve = self._valve_from_s is not None and now_s - self._valve_from_s >= LIVE_GRACE_S
        tip = self._tip_from_s is not None and now_s - self._tip_from_s >= LIVE_GRACE_S
        if not valve:
            return ""
        return unresponsive(
            command_bar, measured_bar, math.degrees(_span(self.angle_rad)), judge_tip=tip
        )


@dataclass(frozen=True)
class ResponseCheck:
    """What one recording says about the rig: spans of command, measurement and bend."""

    bag: str
    command_span_bar: float
    measured_span_bar: float
    bend_span_deg: float
    duration_s: float
    samples: int
    commands_expected: int = 0
    commands_missing: int = 0
    late_sensor: str = ""
    """A sensor stream that begins after the excitation did ('' if none)."""
    late_by_s: float = 0.0
    """How long after the first command off zero it begins [s]."""

    @property
    def commands_missing_share(self) -> float:
        """Share of the excitation's commands (one per tick) the recording lacks."""
        return self.commands_missing / self.commands_expected if self.commands_expected else 0.0

    def problem(self) -> str:
        """'' for a rig that responds and a recording fit to learn from, else what is not."""
        if self.late_sensor:
            # The lab runs every model from rest at the bag's start: a bag that begins
            # mid-motion teaches it a wrong rest (once, a fit of 0.51 deg against 0.11 deg).
            return (
                f"{self.bag}: {self.late_sensor} begins {self.late_by_s:.2f} s after the "
                "excitation did (the recorder had not heard the rig yet), so the bag does not "
                "start at rest; the step is to be run again (rerun the command)"
            )
        if self.commands_missing_share > MAX_COMMANDS_LOST_SHARE:
            return (
                f"{self.bag}: {self.commands_missing} of {self.commands_expected} commands "
                f"({self.commands_missing_share:.1%}) are missing from the recording (limit "
                f"{MAX_COMMANDS_LOST_SHARE:.0%}): excite skipped its ticks or DDS dropped them, "
                "so the models would learn from held commands; the host is too busy to record "
                "on (what runs beside it?)"
            )
        if self.command_span_bar * 1e5 < MIN_COMMAND_SPAN_PA:
            return (
                f"{self.bag}: the command spans only {self.command_span_bar:.2f} bar; the "
                "excitation did not reach the valve"
            )
        judged = unresponsive(
            self.command_span_bar,
            self.measured_span_bar,
            self.bend_span_deg,
            judge_tip=self.command_span_bar >= 1.0,
        )
        return f"{self.bag}: {judged}" if judged else ""

    def to_dict(self) -> dict[str, object]:
        """For commission.json and the report."""
        return {
            "bag": self.bag,
            "command_span_bar": self.command_span_bar,
            "measured_span_bar": self.measured_span_bar,
            "bend_span_deg": self.bend_span_deg,
            "duration_s": self.duration_s,
            "samples": self.samples,
            "commands_expected": self.commands_expected,
            "commands_missing": self.commands_missing,
            "late_sensor": self.late_sensor,
            "late_by_s": self.late_by_s,
        }


def check_response(bag_path: Path) -> ResponseCheck:
    """Spans (5th to 95th percentile, so a spike or a glitch does not count as motion)."""
    bag = load_bag(bag_path)
    series = bag.aligned(SENSOR_RATE_HZ)
    # excite stamps every command with its tick's deadline, so the stamps say how many ticks
    # the excitation had and which are missing.
    stamps_s = bag.pressure_command.t_s
    span_s = float(stamps_s[-1] - stamps_s[0]) if stamps_s.size else -1.0 / CONTROL_RATE_HZ
    expected = round(span_s * CONTROL_RATE_HZ) + 1

    # When the excitation left zero, and whether every sensor was heard by then.
    moving = np.flatnonzero(np.asarray(bag.pressure_command.values) > _MOVING_PA)
    excited_s = float(stamps_s[moving[0]]) if moving.size else float("inf")
    late_sensor, late_by_s = "", 0.0
    for name, stream in (
        ("tip/angle", bag.tip_angle),
        ("pressure/measured", bag.pressure_measured),
    ):
        first_s = float(stream.t_s[0]) if stream.t_s.size else float("inf")
        if first_s - excited_s > late_by_s:
            late_sensor, late_by_s = name, first_s - excited_s

    return ResponseCheck(
        bag=bag_path.name,
        command_span_bar=_span(series.pressure_command_pa) / 1e5,
        measured_span_bar=_span(series.pressure_measured_pa) / 1e5,
        bend_span_deg=math.degrees(_span(series.angle_rad)),
        duration_s=float(series.t_s[-1] - series.t_s[0]),
        samples=int(series.t_s.size),
        commands_expected=expected,
        commands_missing=max(expected - int(stamps_s.size), 0),
        late_sensor=late_sensor,
        late_by_s=late_by_s,
    )
