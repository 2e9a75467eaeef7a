"""``bringup``: start a whole simulated graph for the main job.

Separate processes by default (what a lab runs, and what the integration tests check), or
composed in one process with ``--compose`` (one executor, less start-up cost). The graph is
``sim_hardware``, ``compensator`` and, given a bag path, ``recorder``, all in one namespace.

The rig and the compensator are lifecycle nodes: once their processes are up, ``bringup``
configures each, then activates each, in start order, through their ``change_state``
services (catheter_ros.lifecycle_client); a failed transition stops the graph and is
reported with the node's name and its reason.

Shutdown order matters for safety and for the record: the compensator is deactivated first
(it ramps the pressure down while the rig still runs), then every node is stopped in reverse
start order: the rig, and the recorder last so the bag holds the ramp-down and is closed
cleanly.

ROS arguments after ``--ros-args`` go to every node (``-r __ns:=/x`` sets the namespace), and
every node refuses a parameter it does not have: the compensator's choices are ``bringup``'s own
flags (``--compensator``, ``--model-dir``, ``--feedback``, ``--feedback-gains``,
``--feedforward-shaping``), the simulated rig's are ``--sim-param`` and ``--plant``.

Before anything starts, ``bringup`` looks for nodes already in its namespace on its ROS domain
(:data:`catheter_control.local_graph.DISCOVERY_WAIT_S`) and refuses to start a second graph
beside them (exit code 2, naming them): its lifecycle manager would configure theirs.
``--domain-id auto`` starts the graph in a domain of its own instead and prints which.

Exit codes: 0 after Ctrl-C (SIGINT) or SIGTERM, the graph stopped in order; 1 when a node
exited on its own (named); 2 when the graph was refused before it started (a compensator that
contradicts its model directory, another graph in the namespace) or a node failed its
start-up (named, with its reason).
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

from catheter_control.graph_description import SIM_COMPENSATOR_PARAMS, graph_nodes
from catheter_control.process_graph import NodeSpec, Params, ProcessGraph, run_composed
from catheter_models.contract import DEFAULT_NAMESPACE
from catheter_models.errors import CatheterError

__all__ = [
    "EmulatedDevices",
    "NodeSpec",
    "ProcessGraph",
    "driver_specs",
    "main",
    "parse_args",
    "sim_graph_specs",
]


def sim_graph_specs(
    bag_path: Path | None = None,
    custom_data: Mapping[str, str] | None = None,
    sim_params: Params | None = None,
    compensator_params: Params | None = None,
    *,
    with_compensator: bool = True,
    with_tf: bool = False,
) -> list[NodeSpec]:
    """The simulated graph, in start order: recorder, rig, compensator, and ``tip_tf``.

    The order and the nodes are graph_description.GRAPH's (its ``sim`` graph).

    ``tip_tf`` (the robot model and its transforms, for RViz or Foxglove) is what a person
    at the rig looks at; runs that only score or record leave it out (``with_tf=False``),
    since it is one more process beside the control loop.
    """
    params: dict[str, Params | None] = {
        "sim_hardware": sim_params,
        "compensator": compensator_params,
        "tip_tf": None,
    }
    if bag_path is not None:
        custom = json.dumps(dict(custom_data or {}))
        params["recorder"] = {"bag_path": str(bag_path), "custom_data": custom}
    if not with_compensator:
        del params["compensator"]
    if not with_tf:
        del params["tip_tf"]
    return [NodeSpec.of(n.name, params[n.name]) for n in graph_nodes("sim") if n.name in params]


class EmulatedDevices:
    """The emulated rig (``catheter_driver.emulators.rig``) as a child process.

    It wraps the simulated plant behind pseudo-terminals that speak the real wire protocols
    (Keller transmitter, DAC bridge valve, laser ADC bridge), so the real driver nodes run
    unchanged. :attr:`ports` holds what the emulator printed: backend name -> options.

    Args:
        env: extra environment for the child.
        extra_args: more CLI arguments, e.g. ``["--plant-param", "pneumatic_lag.enabled=true"]``.
        timeout_s: how long to wait for the emulator to report its ports.
    """

    def __init__(
        self,
        env: Mapping[str, str] | None = None,
        extra_args: Sequence[str] = (),
        timeout_s: float = 20.0,
    ) -> None:
        self.env = {**os.environ, **(env or {})}
        self.args = [
            sys.executable,
            "-m",
            "catheter_driver.emulators.rig",
            "--keller-pty",
            "--dac-pty",
            "--adc-pty",
            *extra_args,
        ]
        self.timeout_s = timeout_s
        self.proc: subprocess.Popen[bytes] | None = None
        self.ports: dict[str, dict[str, object]] = {}

    def start(self) -> dict[str, dict[str, object]]:
        """Start the emulator and return its ports (raises RuntimeError if it does not say)."""
        # Its own session, as the nodes (ProcessGraph.spawn): Ctrl-C goes to the launcher,
        # which stops the drivers before the devices they talk to.
        self.proc = subprocess.Popen(
            self.args,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            env=self.env,
            start_new_session=True,
        )
        assert self.proc.stdout is not None
        import selectors

        sel = selectors.DefaultSelector()
        sel.register(self.proc.stdout, selectors.EVENT_READ)
        if not sel.select(self.timeout_s):
            self.stop()
            raise RuntimeError(f"the emulated rig printed no ports within {self.timeout_s:g} s")
        line = self.proc.stdout.readline()
        try:
            self.ports = json.loads(line)
        except ValueError:
            self.stop()
            raise RuntimeError(f"the emulated rig printed {line!r}, not its ports") from None
        return self.ports

    def stop(self, timeout_s: float = 5.0) -> None:
        """SIGINT, then SIGKILL after ``timeout_s``."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


def driver_specs(
    ports: Mapping[str, Mapping[str, object]], calibration_file: Path
) -> list[NodeSpec]:
    """The real driver nodes pointed at the emulated rig's ports."""
    keller = ports["keller_serial"]
    valve: dict[str, object] = {
        "valve.backend": "dac_serial",
        "valve.port": str(ports["dac_serial"]["port"]),
        "transmitter.backend": "keller_serial",
        "transmitter.port": str(keller["port"]),
        "transmitter.baudrate": 115200,
    }
    for key in ("address", "reference"):
        if key in keller:
            valve[f"transmitter.{key}"] = keller[key]
    laser: dict[str, object] = {
        "adc.backend": "adc_serial",
        "adc.port": str(ports["adc_serial"]["port"]),
        "calibration_file": str(calibration_file),
    }
    return [NodeSpec.of("valve_driver", valve), NodeSpec.of("laser_angle", laser)]


def split_ros_args(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """``(own arguments, ROS arguments)``: what follows ``--ros-args`` (up to ``--``) is ROS's.

    The ROS arguments are returned without the ``--ros-args`` flag; an empty list if none.
    """
    own: list[str] = []
    ros: list[str] = []
    in_ros = False
    for arg in argv:
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--" and in_ros:
            in_ros = False
        elif in_ros:
            ros.append(arg)
        else:
            own.append(arg)
    return own, ros


def namespace_from_ros_args(ros_args: Sequence[str], default: str) -> str:
    """The namespace ``-r __ns:=/x`` (or ``--remap __ns:=/x``) sets, else ``default``."""
    namespace = default
    for flag, value in itertools.pairwise(ros_args):
        if flag in {"-r", "--remap"} and value.startswith("__ns:="):
            namespace = value.split(":=", 1)[1]
    return namespace


def parse_args(argv: Sequence[str]) -> tuple[argparse.Namespace, list[str]]:
    """Parse ``bringup``'s command line; returns its options and the ROS arguments for the nodes.

    ``-r __ns:=/x`` after ``--ros-args`` sets the namespace (as ``--namespace /x``); the other
    ROS arguments are passed to every node.
    """
    own, ros_args = split_ros_args(argv)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, help="record to this new bag directory")
    parser.add_argument("--namespace", default=DEFAULT_NAMESPACE)
    parser.add_argument("--compose", action="store_true", help="all nodes in one process")
    parser.add_argument("--no-compensator", action="store_true", help="rig (and recorder) only")
    parser.add_argument(
        "--no-tf",
        action="store_true",
        help="leave out tip_tf (robot_description, joint_states and /tf from tip/angle)",
    )
    parser.add_argument(
        "--sim-param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="sim_hardware parameter, e.g. effects.pneumatic_lag.enabled=true",
    )
    add_graph_choices(parser, domain_default="env")
    args = parser.parse_args(own)
    args.namespace = namespace_from_ros_args(ros_args, args.namespace)
    ros_args = [
        a
        for i, a in enumerate(ros_args)
        if not a.startswith("__ns:=")
        and not (
            a in {"-r", "--remap"}
            and i + 1 < len(ros_args)
            and ros_args[i + 1].startswith("__ns:=")
        )
    ]
    refuse_node_params(ros_args)
    return args, ros_args


OWN_FLAGS = {
    "compensator": "--compensator",
    "model_dir": "--model-dir",
    "feedback": "--feedback",
    "feedback_gains": "--feedback-gains",
    "feedforward_shaping": "--feedforward-shaping",
    "plant": "--plant",
}
"""Node parameters a launcher takes as its own flags: given after ``--ros-args`` they would
reach every node, and each node without them refuses to start."""


def refuse_node_params(ros_args: Sequence[str]) -> None:
    """Refuse ``-p compensator:=...`` (and the like) after ``--ros-args``, naming the flag.

    Raises:
        SystemExit: 2, with the flag to use (argparse's code for a bad command line).
    """
    for flag, value in itertools.pairwise(ros_args):
        name = value.split(":=", 1)[0]
        if flag in {"-p", "--param"} and name in OWN_FLAGS:
            print(
                f"{sys.argv[0].rsplit('/', 1)[-1]}: -p {value} after --ros-args would reach every "
                f"node (and the nodes without {name!r} refuse to start): use "
                f"{OWN_FLAGS[name]} {value.split(':=', 1)[-1]}",
                file=sys.stderr,
            )
            raise SystemExit(2)


def add_graph_choices(parser: argparse.ArgumentParser, *, domain_default: str | None) -> None:
    """The flags ``bringup`` and ``follow_trajectory --sim`` share (controller, plant, domain)."""
    from catheter_control.graph_domain import domain_id_argument
    from catheter_control.models import COMPENSATORS, DEFAULT_COMPENSATOR, FEEDBACKS
    from catheter_models.shaping import SHAPERS

    parser.add_argument(
        "--compensator",
        choices=COMPENSATORS,
        default=None,
        help="the compensator the graph hosts (clstm: the shipped c-LSTM; idrdpi: the shipped "
        "inverse DRDPI; none: static inverse); default: the kind --model-dir holds, else "
        f"{DEFAULT_COMPENSATOR}",
    )
    parser.add_argument(
        "--model-dir",
        default="",
        help="model directory for the compensator ('' = shipped); alone, its manifest says "
        "which compensator it is",
    )
    parser.add_argument(
        "--feedback",
        choices=FEEDBACKS,
        default=None,
        help="feedback on the measured bend beside the compensator (pi: gains from "
        "--feedback-gains); default: what a commissioned --model-dir was verified with, "
        "else none",
    )
    parser.add_argument(
        "--feedback-gains",
        default="",
        help="feedback.json written by catheter-lab tune ('' = the one in --model-dir, or the "
        "shipped one, tuned on the simulated rig)",
    )
    parser.add_argument(
        "--feedforward-shaping",
        choices=SHAPERS,
        default=None,
        help="input shaping of the compensator's pressure (zvd: does not ring the tip mode "
        "that --feedback-gains' tuning identified); default: what a commissioned --model-dir "
        "was verified with, else none",
    )
    parser.add_argument(
        "--plant",
        default="",
        metavar="MODULE:FACTORY",
        help="a simulated catheter of your own behind the rig (docs/simulated_rig.md)",
    )
    parser.add_argument(
        "--domain-id",
        type=domain_id_argument,
        default=domain_default,
        metavar="auto|env|N",
        help="ROS domain of the graph: auto = one where nobody is (printed), env = "
        "ROS_DOMAIN_ID as set, N = that one"
        + (f" (default: {domain_default})" if domain_default else ""),
    )


def compensator_choice(args: argparse.Namespace) -> dict[str, object]:
    """The compensator's parameters from the command line, its kind checked against the model.

    The kind is passed only when given or read from ``--model-dir`` (the node's default is
    the same ``clstm``).

    Raises:
        CatheterError: the compensator and the model directory disagree, or the directory is
            not a compensator's (both named), or ``--feedback-gains`` is refused (named).
    """
    from catheter_control.models import resolve_compensator

    params: dict[str, object] = {}
    if args.compensator is not None or args.model_dir:
        params["compensator"] = resolve_compensator(args.compensator, args.model_dir)
    if args.model_dir:
        params["model_dir"] = str(args.model_dir)
    if args.feedback is not None:
        params["feedback"] = args.feedback
    if args.feedback_gains:
        from catheter_models.feedback import FeedbackGains

        # The node checks the file again at configure; checked here, a file that fails its
        # seal, its tuned range or the envelope stops bringup (exit 2) before any node starts.
        FeedbackGains.load(args.feedback_gains)
        params["feedback_gains"] = str(args.feedback_gains)
    if args.feedforward_shaping is not None:
        from catheter_control.models import shaper_for

        # Checked here too: a loop with no tip to shape stops bringup before any node starts.
        shaper_for(args.feedforward_shaping, args.feedback_gains, args.model_dir)
        params["feedforward_shaping"] = args.feedforward_shaping
    return params


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``ros2 run catheter_control bringup``."""
    args, ros_args = parse_args(sys.argv[1:] if argv is None else argv)
    from catheter_control.graph_domain import choose_domain

    sim_params: dict[str, object] = {}
    for item in args.sim_param:
        key, _, raw = item.partition("=")
        sim_params[key] = json.loads(raw) if raw not in {"true", "false"} else raw == "true"
    if args.plant:
        sim_params["plant"] = args.plant
    try:
        compensator_params = {**SIM_COMPENSATOR_PARAMS, **compensator_choice(args)}
        # Refused before anything starts: a second graph's manager would configure the
        # first one's nodes, and its compensator take the same trajectories.
        choose_domain(args.domain_id, args.namespace, "bringup")
    except CatheterError as exc:
        print(f"bringup: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        return  # Ctrl-C during the look: nothing started
    specs = sim_graph_specs(
        args.bag,
        {"source": "bringup"},
        sim_params,
        compensator_params,
        with_compensator=not args.no_compensator,
        with_tf=not args.no_tf,
    )
    if args.compose:
        code = run_composed(specs, args.namespace, ros_args)
        if code:
            raise SystemExit(code)
        return
    # SIGTERM (a supervisor, docker stop) stops the graph in order, as Ctrl-C does.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    graph = ProcessGraph(specs, args.namespace, ros_args=ros_args)
    try:
        graph.start()
    except CatheterError as exc:
        print(f"bringup: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    except KeyboardInterrupt:
        print("bringup: interrupted while the graph came up; stopped it", file=sys.stderr)
        return  # start() has stopped the nodes already
    print(f"bringup: graph up in {args.namespace}; Ctrl-C stops it (compensator ramped down first)")
    code = 0
    try:
        while not graph.failed():
            time.sleep(0.2)
        print(f"bringup: a node exited: {graph.failed()}", file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        print("bringup: stopping (the compensator ramps down first)", file=sys.stderr)
    finally:
        # A second Ctrl-C must not cut the ordered stop short (or end in a traceback).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        graph.stop()
    if code:
        raise SystemExit(code)


if __name__ == "__main__":
    main()
