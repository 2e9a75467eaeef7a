"""bringup drives the lifecycle nodes over DDS: up through configure and activate, down with the
compensator deactivated first, and a failed transition reported by node and reason."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from graph_utils import Children, Probe, diagnostic_values, statuses
from sensor_msgs.msg import JointState

from catheter_control import qos
from catheter_control.bringup import sim_graph_specs
from catheter_control.lifecycle_client import LifecycleError

pytestmark = pytest.mark.slow


def test_composed_bringup_activates_every_node_in_the_ros_args_namespace(
    children: Children,
) -> None:
    bringup = [sys.executable, "-m", "catheter_control.bringup", "--compose"]
    proc = children.start("bringup", [*bringup, "--ros-args", "-r", "__ns:=/x"])
    with Probe(children.domain_id) as probe:
        angles = probe.subscribe(JointState, "/x/tip/angle", qos.KEEP_EVERY_SAMPLE)
        diags = probe.subscribe(DiagnosticArray, "/diagnostics", 50)

        def compensator_armed() -> bool:
            values = [diagnostic_values(s) for s in statuses(diags, "x/compensator")]
            # Only an active compensator reports its loop's ticks.
            return bool(values) and "ticks" in values[-1]

        # Start-up on a busy 2-core machine: imports, model load, discovery.
        assert probe.spin_until(lambda: len(angles) > 50 and compensator_armed(), 90.0), (
            f"{len(angles)} tip/angle samples; compensator statuses "
            f"{[s.message for s in statuses(diags, 'x/compensator')][-3:]}"
        )
    proc.send_signal(signal.SIGINT)
    assert proc.wait(30.0) == 0
    log = children.log("bringup")
    # The compensator is deactivated (ramp-down) before anything is destroyed.
    assert "/x/compensator: deactivated" in log, log[-2000:]


def test_a_failed_configure_stops_the_graph_and_names_the_node_and_why(
    children: Children, tmp_path: Path
) -> None:
    not_a_model = tmp_path / "empty"
    not_a_model.mkdir()
    specs = sim_graph_specs(compensator_params={"model_dir": str(not_a_model)})
    with pytest.raises(LifecycleError) as err:
        children.graph(specs)
    message = str(err.value)
    assert message.startswith("/catheter/compensator: configure failed:"), message
    assert str(not_a_model) in message and "manifest.json" in message, message
    # Every process of the graph is stopped with it.
    graph = children.graphs[-1]
    assert all(p.poll() is not None for p in graph.procs.values())
    assert not any(p.returncode == -signal.SIGKILL for p in graph.procs.values())
