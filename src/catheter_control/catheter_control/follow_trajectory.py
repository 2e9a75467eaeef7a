"""``follow_trajectory``: send a desired-angle trajectory, watch it run, report how well it went.

    ros2 run catheter_control follow_trajectory --preset traj_descending_sine
    follow_trajectory --sim --preset traj_up_chirp        # bring up the simulated rig first
    follow_trajectory --file my_path.csv                  # columns t_s, angle_deg

It validates the trajectory before anything moves, sends it to the compensator as a
``follow_joint_trajectory`` goal (control_msgs/FollowJointTrajectory), shows progress from the
goal's feedback, takes a refusal or an early stop from the goal's result, then prints RMSE,
MAE (maximum absolute error) and NRMSE of ``tip/angle`` against ``angle/desired``, saves a
plot, and says where the bag is. A trajectory that does not start straight is preceded by a
1 s move from rest and a 1 s hold (``--lead-in-s``), which are not scored, as in the
benchmarks.
"""

from __future__ import annotations

import argparse
import datetime as dt
import math
import os
import sys
import time
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from catheter_control.live_view import LiveViewProcess, parse_port
from catheter_control.models import COMPENSATORS, DEFAULT_COMPENSATOR, FEEDBACKS, SHIPPED
from catheter_control.trajectory import (
    TrajectoryLimits,
    TrajectoryPlan,
    load_trajectory_file,
    preset_knots,
    with_lead_in,
)
from catheter_models.contract import ANGLE_DESIRED, DEFAULT_NAMESPACE, TIP_ANGLE
from catheter_models.errors import CatheterError, ParameterError
from catheter_models.gaps import find_gaps, say_gaps
from catheter_models.geometry import Calibration
from catheter_models.signals import TEST_TRAJECTORIES, get_preset

_PLANT_STRAIGHT_DISTANCE_M = 0.065
"""The simulated rig's laser distance with the tip straight (plant rig parameter default)."""

_LOOP_NODES = frozenset({"sim_hardware", "compensator", "valve_driver", "laser_angle"})
"""Nodes with deadline loops, which take ``rt_priority``."""

EXIT_REFUSED = 2
EXIT_GRAPH = 3
EXIT_STOPPED = 4
"""The compensator stopped the run part-way (a stale sensor, a failed model): it ramped the
pressure down and said why; the partial run is still reported."""
_START_TIMEOUT_S = 8.0
"""The compensator holds a plan up to 5 s for its valve driver; allow for that and more."""


class _Series:
    """Stamps [s] and values of one topic, packed: 16 bytes a sample.

    A run keeps every sample to score it; as a list of tuples (~120 bytes a sample) the
    10-minute soak at 1 kHz grew 10 MB a minute.
    """

    def __init__(self) -> None:
        self.t_s = array("d")
        self.values = array("d")

    def append(self, t_s: float, value: float) -> None:
        self.t_s.append(t_s)
        self.values.append(value)

    def clear(self) -> None:
        self.t_s = array("d")
        self.values = array("d")

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass
class _Collected:
    desired: _Series = field(default_factory=_Series)
    measured: _Series = field(default_factory=_Series)
    refusal: str = ""
    stopped: str = ""
    recorder: dict[str, str] = field(default_factory=dict)
    # (monotonic receipt [s], status values) of the compensator and the commanded driver.
    compensator: list[tuple[float, dict[str, str]]] = field(default_factory=list)
    driver: list[tuple[float, dict[str, str]]] = field(default_factory=list)


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="follow_trajectory", description="Follow a desired-angle trajectory and report."
    )
    src = parser.add_mutually_exclusive_group()
    src.add_argument(
        "--preset",
        default="traj_descending_sine",
        help=f"thesis trajectory (sec. 9.3): {', '.join(TEST_TRAJECTORIES)}",
    )
    src.add_argument("--file", type=Path, help="CSV (t_s, angle_deg|angle_rad) or YAML trajectory")
    rig = parser.add_mutually_exclusive_group()
    rig.add_argument("--sim", action="store_true", help="bring up the simulated rig first")
    rig.add_argument(
        "--emulated-rig",
        action="store_true",
        help="bring up emulated devices and the real valve_driver and laser_angle first",
    )
    parser.add_argument(
        "--compensator",
        choices=COMPENSATORS,
        default=DEFAULT_COMPENSATOR,
        help="with --sim/--emulated-rig: the compensator the started graph hosts "
        "(clstm: the shipped c-LSTM; idrdpi: the shipped inverse DRDPI; none: static inverse)",
    )
    parser.add_argument(
        "--model-dir", default="", help="model directory for the compensator ('' = shipped)"
    )
    parser.add_argument(
        "--feedback",
        choices=FEEDBACKS,
        default="none",
        help="with --sim/--emulated-rig: feedback on the measured bend beside the compensator "
        "(pi: gains from --feedback-gains)",
    )
    parser.add_argument(
        "--feedback-gains",
        default="",
        help="feedback.json written by catheter-lab tune ('' = the one in --model-dir, or the "
        "shipped one, tuned on the simulated rig)",
    )
    parser.add_argument("--out", type=Path, help="run directory (default runs/<time>-<name>)")
    parser.add_argument("--namespace", default=DEFAULT_NAMESPACE)
    parser.add_argument("--control-rate-hz", type=float, default=250.0)
    parser.add_argument(
        "--timeout-s", type=float, default=60.0, help="wait for the graph this long"
    )
    parser.add_argument(
        "--lead-in-s",
        type=float,
        default=1.0,
        help="for a trajectory that does not start straight: move there from rest over this "
        "long, then hold as long again; not scored (0: start with the step)",
    )
    parser.add_argument(
        "--rt-priority",
        type=int,
        choices=range(99),
        metavar="0..98",
        help="with --sim/--emulated-rig: SCHED_FIFO priority of the started nodes' loops "
        "(0: normal scheduling; default: the nodes' own, 50)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument(
        "--live",
        nargs="?",
        const=8765,
        type=parse_port,
        metavar="PORT",
        help="stream the run to Foxglove on ws://localhost:PORT (8765 if not given; binds "
        "127.0.0.1 only); see docs/deployment.md, Live view",
    )
    # ROS arguments (after --ros-args) are rclpy's: -r __ns:=/x sets the namespace, and all
    # of them go to this tool's own node.
    from catheter_control.bringup import namespace_from_ros_args, split_ros_args

    own, ros_args = split_ros_args(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(own)
    args.namespace = namespace_from_ros_args(ros_args, args.namespace)
    args.ros_args = ros_args
    return args


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    args = _parse(argv)
    limits = TrajectoryLimits()
    try:
        if args.file is not None:
            name = args.file.stem
            t_s, angle_rad = load_trajectory_file(args.file)
            signal_params: dict[str, object] = {"file": str(args.file)}
        else:
            name = args.preset
            t_s, angle_rad = preset_knots(name)
            signal_params = dict(get_preset(name).params())
        lead_s = 0.0
        if args.lead_in_s > 0.0:
            t_s, angle_rad, lead_s = with_lead_in(t_s, angle_rad, args.lead_in_s, args.lead_in_s)
        # Refuse a bad trajectory here, before any node starts or anything moves.
        plan = TrajectoryPlan.from_knots(t_s, angle_rad, limits, args.control_rate_hz, name)
    except CatheterError as exc:
        print(f"follow_trajectory: trajectory refused: {exc}", file=sys.stderr)
        return EXIT_REFUSED

    run_dir = args.out or Path("runs") / f"{dt.datetime.now():%Y%m%d-%H%M%S}-{name}"
    local = args.sim or args.emulated_rig
    bag_path = run_dir / "bag" if local else None
    graph = None
    devices = None
    if local:
        from catheter_control.bringup import (
            EmulatedDevices,
            ProcessGraph,
            driver_specs,
            sim_graph_specs,
        )

        # A local graph must never reach a real rig on the network.
        os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        hardware = (
            "simulated thesis rig (catheter_driver sim_hardware)"
            if args.sim
            else "emulated devices (Keller, DAC bridge, laser ADC over ptys) around the "
            "simulated rig, real valve_driver and laser_angle"
        )
        custom = {
            "signal": name,
            "signal_params": repr(signal_params),
            "hardware": hardware,
            "compensator": args.compensator,
            "model_dir": args.model_dir or f"shipped ({SHIPPED[args.compensator]})",
            "feedback": args.feedback,
            "feedback_gains": args.feedback_gains or "beside the model (or shipped)",
        }
        run_dir.mkdir(parents=True, exist_ok=True)
        specs = sim_graph_specs(
            bag_path,
            custom,
            compensator_params={
                "control_rate_hz": args.control_rate_hz,
                "compensator": args.compensator,
                "model_dir": args.model_dir,
                "feedback": args.feedback,
                "feedback_gains": args.feedback_gains,
                # The local rig has a laser: stop if it goes quiet (a patient's would not).
                "require_tip_angle": True,
            },
        )
        if args.emulated_rig:
            devices = EmulatedDevices()
            try:
                ports = devices.start()
            except RuntimeError as exc:
                print(f"follow_trajectory: {exc}", file=sys.stderr)
                return EXIT_GRAPH
            # The emulated laser is taken as zeroed at the plant's straight-tip distance,
            # as ~/zero would measure it with the muscle vented.
            calibration = run_dir / "laser_calibration.json"
            Calibration(_PLANT_STRAIGHT_DISTANCE_M, 0.0, 0, "emulated rig").save(calibration)
            recorder, _sim, compensator = specs
            specs = [recorder, *driver_specs(ports, calibration), compensator]
        if args.rt_priority is not None:
            for spec in specs:
                if spec.name in _LOOP_NODES:
                    spec.params["rt_priority"] = args.rt_priority
        graph = ProcessGraph(specs, args.namespace, log_dir=run_dir / "logs")
        what = "simulated rig" if args.sim else "emulated devices and the real drivers"
        print(f"follow_trajectory: starting the {what} (logs in {run_dir / 'logs'})")
        try:
            graph.start()
        except CatheterError as exc:  # a node failed configure/activate, or exited
            print(f"follow_trajectory: {exc}", file=sys.stderr)
            return EXIT_GRAPH
    live = None
    try:
        if args.live is not None:
            try:
                live = LiveViewProcess(args.live, args.namespace).start()
            except ParameterError as exc:  # the port is taken or not allowed
                print(f"follow_trajectory: {exc}", file=sys.stderr)
                return EXIT_GRAPH
            print(f"follow_trajectory: live view: Foxglove -> Open connection -> {live.url}")
        return _run(args, plan, run_dir, bag_path, graph, lead_s=lead_s)
    finally:
        if live is not None:
            print(live.stop())
        if graph is not None:
            graph.stop()
        if devices is not None:
            devices.stop()
        if bag_path is not None and bag_path.exists():
            print(f"Bag: {bag_path}")


def _run(
    args: argparse.Namespace,
    plan: TrajectoryPlan,
    run_dir: Path,
    bag_path: Path | None,
    graph: object,
    *,
    lead_s: float,
) -> int:
    import rclpy
    from action_msgs.msg import GoalStatus
    from control_msgs.action import FollowJointTrajectory
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.action.client import ActionClient, ClientGoalHandle
    from rclpy.node import Node
    from rclpy.task import Future
    from sensor_msgs.msg import JointState
    from tqdm import tqdm
    from trajectory_msgs.msg import JointTrajectoryPoint

    from catheter_control.bringup import ProcessGraph
    from catheter_control.tracking_report import (
        TrackingError,
        save_json,
        save_plot,
        score_run,
        timing_summary,
        timing_text,
    )
    from catheter_control.trajectory_action import ACTION_NAME
    from catheter_models.contract import (
        ANGLE_DESIRED,
        BEND_JOINT,
        DIAGNOSTICS,
        PRESSURE_COMMAND,
        PRESSURE_MEASURED,
        TIP_ANGLE,
    )
    from catheter_ros import qos
    from catheter_ros.messages import angle_rad_from, ns_from_time

    data = _Collected()
    with rclpy.init(
        args=["follow_trajectory", "--ros-args", "-r", f"__ns:={args.namespace}", *args.ros_args]
    ):
        node = Node("follow_trajectory")

        def on_desired(msg: JointState) -> None:
            data.desired.append(ns_from_time(msg.header.stamp) * 1e-9, angle_rad_from(msg))

        def on_measured(msg: JointState) -> None:
            data.measured.append(ns_from_time(msg.header.stamp) * 1e-9, angle_rad_from(msg))

        def on_diag(msg: DiagnosticArray) -> None:
            now = time.monotonic()
            for status in msg.status:
                values = {kv.key: kv.value for kv in status.values}
                if status.name.endswith("compensator"):
                    data.compensator.append((now, values))
                elif status.name.endswith(("sim_hardware", "valve_driver")):
                    data.driver.append((now, values))
                elif status.name.endswith("recorder"):
                    data.recorder = values

        # Our compensator's stream: reliable, so the score misses nothing on a busy host. The
        # sensor may be anyone's driver: best effort matches whatever it offers.
        node.create_subscription(JointState, ANGLE_DESIRED.name, on_desired, qos.RECORD)
        node.create_subscription(JointState, TIP_ANGLE.name, on_measured, qos.KEEP_EVERY_SAMPLE)
        node.create_subscription(DiagnosticArray, DIAGNOSTICS.name, on_diag, 10)
        action: ActionClient[Any, Any, Any] = ActionClient(node, FollowJointTrajectory, ACTION_NAME)

        # Wait for the graph: measurements flowing and the compensator listening.
        deadline = time.monotonic() + args.timeout_s
        while time.monotonic() < deadline:
            rclpy.spin_once(node, timeout_sec=0.1)
            if isinstance(graph, ProcessGraph) and graph.failed():
                dead = graph.failed()
                for n in dead:
                    print(f"--- {n} log ---\n{graph.log_tail(n)}", file=sys.stderr)
                print(f"follow_trajectory: node(s) exited during start-up: {dead}", file=sys.stderr)
                return EXIT_GRAPH
            if data.measured and action.server_is_ready():
                break
        else:
            missing = []
            if not data.measured:
                missing.append(f"no {node.resolve_topic_name(TIP_ANGLE.name)} samples")
            if not action.server_is_ready():
                # Actions resolve like topics: the namespace applies.
                missing.append(f"no action server {node.resolve_topic_name(ACTION_NAME)}")
            print(
                f"follow_trajectory: graph not ready after {args.timeout_s:g} s: "
                + "; ".join(missing),
                file=sys.stderr,
            )
            return EXIT_GRAPH
        if bag_path is not None:
            # Discovery is pairwise: that we see the recorder does not mean it has matched
            # the compensator. Wait until it reports a publisher on every stream, or the bag
            # would miss the start of the run.
            streams = [
                node.resolve_topic_name(t.name)
                for t in (PRESSURE_COMMAND, ANGLE_DESIRED, TIP_ANGLE, PRESSURE_MEASURED)
            ]

            def unheard() -> list[str]:
                return [t for t in streams if int(data.recorder.get(f"publishers {t}", "0")) < 1]

            while unheard() and time.monotonic() < deadline:
                rclpy.spin_once(node, timeout_sec=0.05)
            if unheard():
                print(
                    "follow_trajectory: the recorder hears no publisher on "
                    + ", ".join(unheard())
                    + f" after {args.timeout_s:g} s",
                    file=sys.stderr,
                )
                return EXIT_GRAPH

        goal = FollowJointTrajectory.Goal()
        goal.trajectory.joint_names = [BEND_JOINT]
        for t, a in zip(plan.t_s, plan.angle_rad, strict=True):
            point = JointTrajectoryPoint()
            point.positions = [float(a)]
            point.time_from_start.sec = math.floor(t)
            point.time_from_start.nanosec = round((t - math.floor(t)) * 1e9) % 1_000_000_000
            goal.trajectory.points.append(point)
        data.desired.clear()
        plan_time_s = [0.0]  # of the newest feedback: the bar shows the compensator's clock

        def on_feedback(msg: Any) -> None:
            elapsed = msg.feedback.desired.time_from_start
            plan_time_s[0] = elapsed.sec + elapsed.nanosec * 1e-9

        sending: Future[ClientGoalHandle[Any, Any, Any]] = action.send_goal_async(
            goal, feedback_callback=on_feedback
        )
        result_future: Future[Any] | None = None
        finished = False
        sent_at = time.monotonic()
        print(f"follow_trajectory: following {plan.name!r} ({plan.duration_s:.1f} s)")
        if lead_s:
            print(
                f"follow_trajectory: the first {lead_s:g} s move from rest to "
                f"{math.degrees(plan.desired_at(lead_s)):.1f} deg and hold (not scored)"
            )
        bar = tqdm(
            total=round(plan.duration_s, 1),
            unit="s",
            # None: show on a terminal only; piped output gets no stream of redraws.
            disable=True if args.no_progress else None,
            mininterval=0.5,
            bar_format="{l_bar}{bar}| {n:.1f}/{total:.1f} s",
        )
        # Run through the trajectory and the ramp-down after it, timed from the first
        # set-point: the compensator starts once its valve driver listens, not on receipt.
        started_at: float | None = None
        while started_at is None or time.monotonic() - started_at < plan.duration_s + 1.0:
            rclpy.spin_once(node, timeout_sec=0.05)
            now = time.monotonic()
            if started_at is None and data.desired:
                started_at = now
            if started_at is not None:
                done_s = round(min(plan_time_s[0], plan.duration_s), 1)
                if done_s > bar.n:
                    bar.update(done_s - bar.n)
            if result_future is None and sending.done():
                handle = sending.result()
                if handle is None or not handle.accepted:
                    data.refusal = "the goal was rejected"
                else:
                    result_future = handle.get_result_async()
            if result_future is not None and result_future.done() and not finished:
                finished = True
                response = result_future.result()
                status = GoalStatus.STATUS_UNKNOWN if response is None else response.status
                outcome = (response and response.result.error_string) or f"status {status}"
                if status != GoalStatus.STATUS_SUCCEEDED:
                    # Aborted before a set-point went out: refused (the compensator's
                    # reason); after: cut short, and the compensator ramped down.
                    if started_at is None:
                        data.refusal = outcome
                    else:
                        data.stopped = f"stopped: {outcome}; ramped down"
            if data.refusal:
                bar.close()
                print(
                    f"follow_trajectory: the compensator refused the trajectory: {data.refusal}",
                    file=sys.stderr,
                )
                return EXIT_REFUSED
            if data.stopped:
                break
            if started_at is None and now - sent_at > _START_TIMEOUT_S:
                bar.close()
                print(
                    f"follow_trajectory: the compensator sent no set-points within "
                    f"{_START_TIMEOUT_S:g} s of the trajectory",
                    file=sys.stderr,
                )
                return EXIT_GRAPH
        bar.close()
        if data.stopped:
            print(f"follow_trajectory: compensator: {data.stopped}", file=sys.stderr)
        # One more report from each node after the run, so its counters span all of it.
        end_s = time.monotonic()
        until = end_s + 2.5
        while time.monotonic() < until and not (
            data.compensator
            and data.compensator[-1][0] > end_s
            and data.driver
            and data.driver[-1][0] > end_s
        ):
            rclpy.spin_once(node, timeout_sec=0.05)
        node.destroy_node()

    start = data.desired.t_s[0]
    try:
        result = score_run(
            data.desired.t_s,
            data.desired.values,
            data.measured.t_s,
            data.measured.values,
            window_s=(start + lead_s, start + plan.duration_s),
        )
    except TrackingError as exc:
        print(f"follow_trajectory: cannot score the run: {exc}", file=sys.stderr)
        return EXIT_STOPPED if data.stopped else EXIT_GRAPH
    print(result.text(plan.name))
    # Reports from the last one before the first set-point to the first after the end (the
    # loop above only ends with set-points received, so started_at is set).
    run_start_s = started_at if started_at is not None else sent_at
    first = max([t for t, _ in data.compensator if t <= run_start_s], default=run_start_s)
    timing = timing_summary(
        [v for t, v in data.compensator if t >= first],
        [v for t, v in data.driver if t >= first],
    )
    print(timing_text(timing))
    # What the compensator says it ran, from its last report of the run.
    last = next((v for t, v in reversed(data.compensator) if t >= first), {})
    controller = {
        k: last[k]
        for k in (
            "compensator",
            "feedback",
            "feedback_untrusted_samples",
            "feedback_saturated_ticks",
            "feedback_integral_pa",
        )
        if k in last
    }
    if controller:
        print("Controller: " + ", ".join(f"{k} {v}" for k, v in controller.items()))
    losses = _losses(data, bag_path)
    for line in losses["said"]:
        print(line, file=sys.stderr)
    run_dir.mkdir(parents=True, exist_ok=True)
    plot = save_plot(result, run_dir / "tracking.png", f"{plan.name}: desired vs measured")
    save_json(
        result,
        run_dir / "report.json",
        {
            "trajectory": plan.name,
            "bag": str(bag_path or ""),
            # Why the compensator stopped part-way ('' if the run went to its end).
            "stopped": data.stopped,
            "lead_in_s": lead_s,
            "controller": controller,
            "timing": timing,
            # Samples missing from the bag (the recorder's counts, by topic) and from the
            # streams this run was scored on (from their stamps).
            "bag_samples_lost": losses["bag"],
            "scored_samples_lost": losses["scored"],
            # How far the recorder's writer fell behind its intake (messages queued at worst,
            # and at its last report): a queue that only grows would end in drops.
            "recorder_queue": {
                k: int(data.recorder[k])
                for k in ("queue", "queue_max")
                if str(data.recorder.get(k, "")).isdigit()
            },
            # The compensator's 1 Hz reports over the run: where in it deadlines were missed,
            # how far behind its loop fell and how long each sensor it needs went quiet.
            "timing_series": [
                {
                    "t_s": round(t - run_start_s, 3),
                    **{
                        k: v.get(k, "")
                        for k in (
                            "state",
                            "ticks",
                            "missed_deadlines",
                            "lateness_p99_ms",
                            "compute_p99_ms",
                            "behind_max_ms",
                            *(k for k in v if k.endswith("_longest_silence_ms")),
                        )
                    },
                }
                for t, v in data.compensator
                if t >= first
            ],
            # The driver's (the sensors' producer) beside it: a sensor silence with the
            # driver's loop on time was lost on the way, one with it behind was never sent.
            "driver_timing_series": [
                {
                    "t_s": round(t - run_start_s, 3),
                    **{k: v.get(k, "") for k in ("missed_deadlines", "behind_max_ms")},
                }
                for t, v in data.driver
                if t >= first
            ],
        },
    )
    print(f"Plot: {plot}")
    print(f"Report: {run_dir / 'report.json'}")
    if data.stopped:
        print(
            f"follow_trajectory: the run stopped part-way: {data.stopped} (scored up to there)",
            file=sys.stderr,
        )
        return EXIT_STOPPED
    return 0


def _losses(data: _Collected, bag_path: Path | None) -> dict[str, Any]:
    """What the bag and the score lack: counts by topic, and lines for a person.

    The bag's counts are the recorder's at its last report (1 Hz); the bag's own
    ``custom_data`` has the final ones.
    """
    said: list[str] = []
    bag: dict[str, int] = {}
    if bag_path is not None:
        prefix = "lost "
        bag = {k[len(prefix) :]: int(v) for k, v in data.recorder.items() if k.startswith(prefix)}
        if not data.recorder:
            said.append("follow_trajectory: no report from the recorder; the bag is unchecked")
        elif any(bag.values()):
            said.append(
                "follow_trajectory: the bag lacks samples: "
                + ", ".join(f"{n} of {t}" for t, n in bag.items() if n)
                + " (in the command streams these include ticks the compensator skipped, "
                "commands that never existed)"
            )
    scored: dict[str, int] = {}
    for name, series, pauses in (
        (ANGLE_DESIRED.name, data.desired, True),
        (TIP_ANGLE.name, data.measured, False),
    ):
        t_s = np.frombuffer(series.t_s, dtype=float)
        period_s, found = find_gaps(t_s, pauses=pauses)
        scored[name] = sum(m for _, _, m in found)
        line = say_gaps(name, period_s, found, origin_s=float(t_s[0]) if t_s.size else 0.0)
        if line is not None:
            said.append(f"follow_trajectory: scored without them: {line}")
    return {"bag": bag, "scored": scored, "said": said}


def entry() -> None:
    """Console-script wrapper that turns the return code into the exit status."""
    sys.exit(main())


if __name__ == "__main__":
    entry()
