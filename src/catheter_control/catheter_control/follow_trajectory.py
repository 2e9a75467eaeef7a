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

With a bag (``--sim``, ``--emulated-rig``) the run is refused before anything starts when the
bag's disk lacks room for what it will write (:mod:`catheter_models.bag.space`), and
report.json and tracking.png get their space then (a disk that fills mid-run cannot keep them
from being written). During the run the recorder is watched
(:mod:`catheter_control.recording_watch`): if it exits or reports that it cannot write, the
run stops as the compensator's own stops do (ramped down, scored up to there, exit 4), or
with ``--continue-without-bag`` goes on; either way it says how many seconds went
unrecorded, from when.

This file is the command line: its arguments, the order of the steps and the exit codes.
The steps are their own modules: bringing up a local rig (:mod:`catheter_control.local_graph`),
the run on ROS (:mod:`catheter_control.trajectory_client`, with
:mod:`catheter_control.progress_bar`), and the score and report
(:mod:`catheter_control.tracking_report`).
"""

from __future__ import annotations

import argparse
import datetime as dt
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from catheter_control.bringup import (
    add_graph_choices,
    namespace_from_ros_args,
    refuse_node_params,
    split_ros_args,
)
from catheter_control.live_view import LiveViewProcess, parse_port
from catheter_control.local_graph import (
    LocalGraph,
    LocalGraphError,
    prepare_local_graph,
    start_local_graph,
)
from catheter_control.trajectory import (
    TrajectoryLimits,
    TrajectoryPlan,
    lead_in_knots,
    load_trajectory_file,
    preset_trajectory,
    with_lead_in,
)
from catheter_models.bag.space import (
    check_free_space,
    contract_streams,
    need_for,
)
from catheter_models.contract import CONTROL_RATE_HZ, DEFAULT_NAMESPACE
from catheter_models.errors import CatheterError, GraphConflictError, ParameterError
from catheter_models.signals import TEST_TRAJECTORIES, get_preset

if TYPE_CHECKING:
    from catheter_control.tracking_report import ReservedFile, RunRecord

EXIT_REFUSED = 2
"""Refused before anything moved: the trajectory (by this tool's checks, or by the
compensator), a compensator that contradicts its model directory or a model directory that is
not a compensator's, or (``--sim``/``--emulated-rig``) a namespace and domain where another
graph already runs, or a disk without room for the run's bag (the figures and the path are
named)."""
EXIT_GRAPH = 3
"""The graph did not come up, or never started the trajectory."""
EXIT_STOPPED = 4
"""The run stopped part-way: the compensator stopped it (a stale sensor, a failed model), or,
with a bag, the recorder died or cannot write (unless ``--continue-without-bag``); the
pressure was ramped down, the reason said, and the partial run is still reported."""
EXIT_INTERRUPTED = 130
"""A person interrupted the run (Ctrl-C, SIGINT; SIGTERM alike): the goal was cancelled and a
started graph stopped (the compensator ramps down), and the partial run is reported when there
is anything to score. Not EXIT_STOPPED: that says the rig or the model failed, which a script
(commission) acts on; an interrupt says nothing about the rig. 130 is what shells report for a
command that SIGINT ended (128 + 2), so a script that runs this tool sees what it would see for
any other command a person interrupted."""


START_STOP_S = 30.0
"""What a recorded run records beyond its trajectory, for the free-space check [s]: the
graph coming up and the recorder hearing every stream (5-15 s on a busy host), the ramp-down
and the last reports (3.5 s), and the stop."""
LOG_BYTES = 1_000_000
"""Room for the started nodes' logs in the run directory [bytes] (a normal run: 10-50 kB)."""


@dataclass(frozen=True)
class _Trajectory:
    """The trajectory to follow, checked, and where it came from (for the bag's metadata)."""

    plan: TrajectoryPlan
    name: str
    signal_params: dict[str, object]
    lead_s: float
    """The unscored lead-in at its start [s] (0: none)."""


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
    # With --sim/--emulated-rig: what the started graph runs, and in which ROS domain
    # (default: ROS_DOMAIN_ID if set, else auto; see local_graph.prepare_local_graph).
    add_graph_choices(parser, domain_default=None)
    parser.add_argument("--out", type=Path, help="run directory (default runs/<time>-<name>)")
    parser.add_argument("--namespace", default=DEFAULT_NAMESPACE)
    parser.add_argument("--control-rate-hz", type=float, default=CONTROL_RATE_HZ)
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
    parser.add_argument(
        "--sensor-timeout-s",
        type=float,
        default=None,
        help="with --sim/--emulated-rig: the compensator ramps down when a sensor it needs is "
        "silent this long (its sensor_timeout_s; default: the node's, 0.1 s). A host too busy "
        "to publish every 100 ms stops runs otherwise; a rig keeps the default",
    )
    parser.add_argument(
        "--continue-without-bag",
        action="store_true",
        help="with --sim/--emulated-rig: if the recorder dies or cannot write (disk full), go "
        "on with the run instead of stopping it (the report still says what went unrecorded)",
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
    own, ros_args = split_ros_args(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(own)
    args.namespace = namespace_from_ros_args(ros_args, args.namespace)
    args.ros_args = ros_args
    refuse_node_params(ros_args)
    return args


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the process exit code."""
    args = _parse(argv)
    try:
        # Refuse a bad trajectory here, before any node starts or anything moves.
        trajectory = _load(args)
    except CatheterError as exc:
        print(f"follow_trajectory: trajectory refused: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    run_dir = args.out or Path("runs") / f"{dt.datetime.now():%Y%m%d-%H%M%S}-{trajectory.name}"
    # A graph this tool starts is recorded; one already running records (or not) as it was
    # launched.
    bag_path = run_dir / "bag" if args.sim or args.emulated_rig else None
    local = None
    reserved: dict[str, ReservedFile] = {}
    report_bytes = 0
    if bag_path is not None:
        try:
            prepare_local_graph(args)
            report_bytes = _check_room(args, trajectory, bag_path)
        except CatheterError as exc:
            print(f"follow_trajectory: {exc}", file=sys.stderr)
            return EXIT_REFUSED
        except KeyboardInterrupt:
            print("follow_trajectory: interrupted before anything started", file=sys.stderr)
            return EXIT_INTERRUPTED
        try:
            local = start_local_graph(
                args, run_dir, bag_path, trajectory.name, trajectory.signal_params
            )
        except GraphConflictError as exc:
            print(f"follow_trajectory: {exc}", file=sys.stderr)
            return EXIT_REFUSED
        except LocalGraphError as exc:
            print(f"follow_trajectory: {exc}", file=sys.stderr)
            return EXIT_GRAPH
        except KeyboardInterrupt:
            # ProcessGraph.start stopped what it had started (the compensator first).
            print(
                "follow_trajectory: interrupted while the graph came up; it is stopped, "
                "nothing ran",
                file=sys.stderr,
            )
            return EXIT_INTERRUPTED
    # From here a SIGINT (or SIGTERM) is a request: the run cancels its goal, the graph stops
    # in order and what ran is reported. As KeyboardInterrupt it tore through rclpy's spin
    # and lost the run.
    interrupt = threading.Event()
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}

    def on_signal(_signum: int, _frame: object) -> None:
        if interrupt.is_set():
            print("follow_trajectory: stopping, please wait", file=sys.stderr)
        interrupt.set()

    for sig in previous:
        signal.signal(sig, on_signal)
    live = None
    try:
        if args.live is not None:
            try:
                live = LiveViewProcess(args.live, args.namespace).start()
            except ParameterError as exc:  # the port is taken or not allowed
                print(f"follow_trajectory: {exc}", file=sys.stderr)
                return EXIT_GRAPH
            print(f"follow_trajectory: live view: Foxglove -> Open connection -> {live.url}")
        if bag_path is not None:
            try:
                reserved = _reserve(run_dir, report_bytes)
            except OSError as exc:
                print(f"follow_trajectory: cannot write in {run_dir}: {exc}", file=sys.stderr)
                return EXIT_REFUSED
        return _run(args, trajectory, run_dir, bag_path, local, interrupt=interrupt, files=reserved)
    finally:
        for held in reserved.values():
            held.discard()  # a run that ended before its report leaves no placeholder
        if live is not None:
            print(live.stop())
        if local is not None:
            local.stop()
        if bag_path is not None and bag_path.exists():
            print(f"Bag: {bag_path}")
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _check_room(args: argparse.Namespace, trajectory: _Trajectory, bag_path: Path) -> int:
    """Refuse a disk without room for the run's bag, report and plot; report.json's share.

    Raises:
        DiskSpaceError: the disk lacks room (the figures and the path are named).
    """
    from catheter_control import tracking_report as report  # loaded with the run, see _run

    duration_s = trajectory.plan.duration_s + START_STOP_S
    report_bytes = report.REPORT_RESERVE_BYTES + int(report.REPORT_BYTES_PER_S * duration_s)
    need = need_for(
        bag_path,
        duration_s,
        contract_streams(control_rate_hz=args.control_rate_hz),
        extra_bytes=report_bytes + report.PLOT_RESERVE_BYTES + LOG_BYTES,
    )
    check_free_space(need)
    return report_bytes


def _reserve(run_dir: Path, report_bytes: int) -> dict[str, ReservedFile]:
    """Hold report.json's and the plot's space now, so that a disk full later keeps them."""
    from catheter_control import tracking_report as report

    return {
        "report": report.ReservedFile(run_dir / "report.json", report_bytes),
        "plot": report.ReservedFile(run_dir / "tracking.png", report.PLOT_RESERVE_BYTES),
    }


def _load(args: argparse.Namespace) -> _Trajectory:
    """The preset or file, after the lead-in, checked against the compensator's limits.

    Raises:
        CatheterError: the trajectory cannot be read or is not one the rig can follow.
    """
    if args.file is not None:
        name = args.file.stem
        t_s, angle_rad = load_trajectory_file(args.file)
        signal_params: dict[str, object] = {"file": str(args.file)}
    else:
        name = args.preset
        # With its rate and acceleration at the knots: joined by quintic segments, the plan
        # is the preset itself, not a polyline.
        knots = preset_trajectory(name)
        if args.lead_in_s > 0.0:
            knots = lead_in_knots(knots, args.lead_in_s, args.lead_in_s)
        plan = knots.plan(TrajectoryLimits(), args.control_rate_hz, name)
        return _Trajectory(plan, name, dict(get_preset(name).params()), knots.lead_s)
    lead_s = 0.0
    if args.lead_in_s > 0.0:
        t_s, angle_rad, lead_s = with_lead_in(t_s, angle_rad, args.lead_in_s, args.lead_in_s)
    plan = TrajectoryPlan.from_knots(t_s, angle_rad, TrajectoryLimits(), args.control_rate_hz, name)
    return _Trajectory(plan, name, signal_params, lead_s)


def _run(
    args: argparse.Namespace,
    trajectory: _Trajectory,
    run_dir: Path,
    bag_path: Path | None,
    local: LocalGraph | None,
    *,
    interrupt: threading.Event,
    files: dict[str, ReservedFile],
) -> int:
    """Follow the trajectory, then score and report it; the exit code."""
    # Imported here, not at the top: the run loads the report's matplotlib (about 2 s),
    # which a refused trajectory, or a local graph that fails to start, should not wait for.
    from catheter_control.recording_watch import RecordingWatch
    from catheter_control.tracking_report import RunRecord
    from catheter_control.trajectory_client import (
        GoalRefusedError,
        GraphNotReadyError,
        RunInterruptedError,
        follow,
    )

    record = RunRecord()
    watch = None
    if bag_path is not None:
        watch = RecordingWatch(
            bag_path,
            local.graph if local is not None else None,
            record,
            continue_without_bag=args.continue_without_bag,
        )
    try:
        follow(
            trajectory.plan,
            namespace=args.namespace,
            ros_args=args.ros_args,
            timeout_s=args.timeout_s,
            graph=local.graph if local is not None else None,
            wait_for_recorder=bag_path is not None,
            show_progress=not args.no_progress,
            lead_s=trajectory.lead_s,
            interrupt=interrupt,
            watch=watch.check if watch is not None else None,
            record=record,
        )
    except RunInterruptedError as exc:
        print(f"follow_trajectory: {exc}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except GoalRefusedError as exc:
        print(f"follow_trajectory: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    except GraphNotReadyError as exc:
        print(f"follow_trajectory: {exc}", file=sys.stderr)
        return EXIT_GRAPH
    if watch is not None:
        now_ns, now_s = time.time_ns(), time.monotonic()
        start_ns = (
            None
            if record.started_at_s is None
            else now_ns - int((now_s - record.started_at_s) * 1e9)
        )
        record.recording = watch.finish(now_ns, start_ns)
    return _report(record, trajectory, run_dir, bag_path, files)


def _write_out(path: Path, data: bytes, reserved: ReservedFile | None) -> str:
    """Write a run file (into its reserved space if it has one); '' or what went wrong."""
    if reserved is not None:
        return reserved.write(data)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data)
    except OSError as exc:
        return f"could not write {path}: {exc.strerror or exc}"
    return ""


def _report(
    record: RunRecord,
    trajectory: _Trajectory,
    run_dir: Path,
    bag_path: Path | None,
    files: dict[str, ReservedFile] | None = None,
) -> int:
    """Score the run, print the report, save report.json and the plot; the exit code.

    report.json is written whatever the run came to (with null metrics when nothing could be
    scored); neither file failing to write (a full disk) changes the exit code: it is said.
    """
    from catheter_control import tracking_report as report  # loaded with the run, see _run

    files = files or {}
    plan, lead_s = trajectory.plan, trajectory.lead_s
    result = None
    unscored = ""
    try:
        result = report.score_record(record, plan.duration_s, lead_s)
    except report.TrackingError as exc:
        unscored = str(exc)
        print(f"follow_trajectory: cannot score the run: {exc}", file=sys.stderr)
    if result is not None:
        print(result.text(plan.name))
    summary = report.RunSummary.of(record)
    print(report.timing_text(summary.timing))
    controller = summary.controller_text()
    if controller is not None:
        print(controller)
    losses = report.sample_losses(record, bag_path)
    for line in losses.said:
        print(line, file=sys.stderr)
    facts = report.run_facts(
        record, summary, losses, trajectory=plan.name, bag_path=bag_path, lead_s=lead_s
    )
    if unscored:
        facts["unscored"] = unscored
    text = report.report_json(result, facts)
    json_path = run_dir / "report.json"
    problem = _write_out(json_path, text.encode(), files.get("report"))
    if problem:
        # Nothing lost without a word: the report goes to the terminal instead.
        print(f"follow_trajectory: {problem}; the report follows:\n{text}", file=sys.stderr)
    else:
        print(f"Report: {json_path}")
    plot_path = run_dir / "tracking.png"
    if result is None:
        print("follow_trajectory: no plot: nothing was scored", file=sys.stderr)
    else:
        try:
            png = report.plot_png(result, f"{plan.name}: desired vs measured")
        except (OSError, ValueError) as exc:
            problem = f"could not draw the plot: {exc}"
        else:
            problem = _write_out(plot_path, png, files.get("plot"))
        if problem:
            print(f"follow_trajectory: {problem} (report.json has the scores)", file=sys.stderr)
        else:
            print(f"Plot: {plot_path}")
    if result is None and not (record.interrupted or record.stopped):
        return EXIT_GRAPH
    if record.interrupted:
        print(f"follow_trajectory: {record.interrupted} (scored up to there)", file=sys.stderr)
        return EXIT_INTERRUPTED
    if record.stopped:
        print(
            f"follow_trajectory: the run stopped part-way: {record.stopped} (scored up to there)",
            file=sys.stderr,
        )
        return EXIT_STOPPED
    return 0


def entry() -> None:
    """Console-script wrapper that turns the return code into the exit status."""
    sys.exit(main())


if __name__ == "__main__":
    entry()
