"""The graph ``follow_trajectory --sim`` / ``--emulated-rig`` brings up before its run.

``--sim`` starts the recorder, the simulated rig and the compensator; ``--emulated-rig``
puts emulated devices (Keller transmitter, DAC bridge, laser ADC over pseudo-terminals)
around the simulated rig and runs the real ``valve_driver`` and ``laser_angle`` on them,
with a laser calibration written for the emulated laser. Without either flag
``follow_trajectory`` starts nothing and uses the nodes that are up. This is its own file
because setting up a local rig is a job of its own, apart from running and scoring the
trajectory.
"""

from __future__ import annotations

import argparse
import os
from dataclasses import dataclass
from pathlib import Path

from catheter_control.bringup import EmulatedDevices, driver_specs, sim_graph_specs
from catheter_control.graph_domain import choose_domain, default_domain_choice
from catheter_control.models import (
    SHIPPED,
    resolve_compensator,
    resolve_feedback,
    resolve_shaping,
    shaper_for,
)
from catheter_control.process_graph import ProcessGraph
from catheter_models.errors import CatheterError, GraphConflictError
from catheter_models.geometry import Calibration
from catheter_models.plant import PlantConfig

_LOOP_NODES = frozenset({"sim_hardware", "compensator", "valve_driver", "laser_angle"})
"""Nodes with deadline loops, which take ``rt_priority``."""


class LocalGraphError(CatheterError):
    """The local graph did not come up: the emulated devices or a node failed to start."""


@dataclass
class LocalGraph:
    """A started local graph: its nodes, and the emulated devices under them if any."""

    graph: ProcessGraph
    devices: EmulatedDevices | None

    def stop(self) -> None:
        """Stop the nodes, then the devices they were talking to."""
        self.graph.stop()
        if self.devices is not None:
            self.devices.stop()


def prepare_local_graph(args: argparse.Namespace) -> None:
    """Before anything starts: this host only, the compensator settled, the domain checked.

    ``args.compensator`` becomes the kind the graph runs (``--model-dir``'s manifest's, when
    no ``--compensator`` was given). ``--domain-id`` left out takes ROS_DOMAIN_ID when it is
    set (a person chose it; the integration tests give each test its own), and a domain of
    its own (``auto``) when it is not: unset means domain 0, every rig's and every ROS tool's
    default, and a simulated run must never reach a rig.

    Raises:
        CatheterError: the compensator and the model directory disagree, the directory is
            not a compensator's, or another graph runs in the namespace and domain.
    """
    # A local graph must never reach a real rig on the network.
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    args.compensator = resolve_compensator(args.compensator, args.model_dir)
    # A commissioned model directory runs with the feedback it was verified with.
    args.feedback = resolve_feedback(args.feedback, args.model_dir)
    args.feedforward_shaping = resolve_shaping(args.feedforward_shaping, args.model_dir)
    # The node would refuse it at configure, after the graph is up: refuse it now.
    shaper_for(args.feedforward_shaping, args.feedback_gains, args.model_dir)
    choose_domain(default_domain_choice(args.domain_id), args.namespace, "follow_trajectory")


def start_local_graph(
    args: argparse.Namespace,
    run_dir: Path,
    bag_path: Path,
    name: str,
    signal_params: dict[str, object],
) -> LocalGraph:
    """Start the graph ``args`` (follow_trajectory's command line) asks for, and say so.

    Args:
        args: follow_trajectory's parsed command line (``--sim`` or ``--emulated-rig``, the
            compensator and feedback, the rate, ``--rt-priority``, the namespace).
        run_dir: The run's directory: logs, and the emulated laser's calibration, go there.
        bag_path: Where the recorder writes the bag.
        name: The trajectory's name, for the bag's metadata.
        signal_params: The trajectory's parameters, for the bag's metadata.

    Raises:
        LocalGraphError: the devices or a node failed to start (the message says which).
    """
    # A local graph must never reach a real rig on the network (prepare_local_graph set it
    # already; a caller that skipped it still gets it).
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
        "model_dir": args.model_dir or f"shipped ({SHIPPED.get(args.compensator, 'none')})",
        "feedback": args.feedback,
        "feedback_gains": args.feedback_gains or "beside the model (or shipped)",
        "feedforward_shaping": args.feedforward_shaping,
        "plant": args.plant or "shipped",
    }
    run_dir.mkdir(parents=True, exist_ok=True)
    specs = sim_graph_specs(
        bag_path,
        custom,
        {"plant": args.plant} if args.plant else None,
        compensator_params={
            "control_rate_hz": args.control_rate_hz,
            "compensator": args.compensator,
            "model_dir": args.model_dir,
            "feedback": args.feedback,
            "feedback_gains": args.feedback_gains,
            "feedforward_shaping": args.feedforward_shaping,
            # The local rig has a laser: stop if it goes quiet (a patient's would not).
            "require_tip_angle": True,
            # Only when asked: the node's own default and bounds stay the one source.
            **(
                {"sensor_timeout_s": args.sensor_timeout_s}
                if getattr(args, "sensor_timeout_s", None) is not None
                else {}
            ),
        },
    )
    devices = None
    if args.emulated_rig:
        devices = EmulatedDevices(extra_args=["--plant", args.plant] if args.plant else ())
        try:
            ports = devices.start()
        except RuntimeError as exc:
            raise LocalGraphError(str(exc)) from exc
        except KeyboardInterrupt:
            devices.stop()
            raise
        # The emulated laser is taken as zeroed at the plant's straight-tip distance,
        # as ~/zero would measure it with the muscle vented.
        calibration = run_dir / "laser_calibration.json"
        straight_m = PlantConfig.thesis_rig().rig["straight_distance_m"]
        Calibration(straight_m, 0.0, 0, "emulated rig").save(calibration)
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
    except BaseException as exc:  # a node failed configure/activate or exited, or Ctrl-C
        # The graph stopped its own nodes; the emulated devices go too. Left running, the
        # rig process outlived follow_trajectory and held its output pipe open.
        if devices is not None:
            devices.stop()
        if isinstance(exc, GraphConflictError):
            raise  # a refusal: nothing of this run moved, and the other graph is left alone
        if isinstance(exc, CatheterError):
            raise LocalGraphError(str(exc)) from exc
        raise
    return LocalGraph(graph, devices)
