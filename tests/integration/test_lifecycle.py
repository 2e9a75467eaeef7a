"""bringup drives the lifecycle nodes over DDS: up through configure and activate, down with the
compensator deactivated first, and a failed transition reported by node and reason."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from graph_utils import (
    SLACK_SENSOR_TIMEOUT_S,
    Children,
    Probe,
    diagnostic_values,
    gauge_pa,
    statuses,
    trajectory_msg,
)
from sensor_msgs.msg import JointState

from catheter_control.bringup import sim_graph_specs
from catheter_ros import qos
from catheter_ros.lifecycle_client import LifecycleError

pytestmark = pytest.mark.slow


def test_composed_bringup_activates_every_node_in_the_ros_args_namespace(
    children: Children,
) -> None:
    bringup = [sys.executable, "-m", "catheter_control.bringup", "--compose"]
    proc = children.start("bringup", [*bringup, "--ros-args", "-r", "__ns:=/x"])
    with Probe(children.domain_id) as probe:
        angles = probe.subscribe(JointState, "/x/tip/angle", qos.KEEP_EVERY_SAMPLE)
        # tip_tf, which bringup starts beside the graph for a person watching in RViz.
        joints = probe.subscribe(JointState, "/x/joint_states", qos.KEEP_EVERY_SAMPLE)
        diags = probe.subscribe(DiagnosticArray, "/diagnostics", 50)

        def compensator_armed() -> bool:
            values = [diagnostic_values(s) for s in statuses(diags, "x/compensator")]
            # Only an active compensator reports its loop's ticks.
            return bool(values) and "ticks" in values[-1]

        # Start-up on a busy 2-core machine: imports, model load, discovery.
        assert probe.spin_until(
            lambda: len(angles) > 50 and len(joints) > 5 and compensator_armed(), 90.0
        ), (
            f"{len(angles)} tip/angle samples, {len(joints)} joint_states; compensator statuses "
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


def test_deactivating_the_compensator_mid_run_ramps_the_pressure_down(
    children: Children,
) -> None:
    from lifecycle_msgs.msg import Transition
    from lifecycle_msgs.srv import ChangeState
    from sensor_msgs.msg import FluidPressure
    from trajectory_msgs.msg import JointTrajectory

    from catheter_models.contract import PRESSURE_COMMAND, TRAJECTORY

    # This test is about the deactivation, not the sensor timeout: beside two busy loops the
    # node's 0.1 s default saw pressure/measured quiet for 104 ms and ended the run first.
    children.graph(sim_graph_specs(compensator_params={"sensor_timeout_s": SLACK_SENSOR_TIMEOUT_S}))
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, qos.RECORD)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        assert probe.spin_until(lambda: pub.get_subscription_count() > 0, 30.0)
        # Up to 20 deg and hold: a run that would last 12 s.
        pub.publish(trajectory_msg([(0.0, 0.0), (2.0, 20.0), (12.0, 20.0)]))
        # Wait for the hold, not the ramp: on a busy machine 1 bar was reached mid-ramp and
        # the command then still rose ~250 Pa a tick while the request travelled.
        assert probe.spin_until(
            lambda: (
                len(commands) > 25
                and gauge_pa(commands[-25:]).min() > 1.0e5
                and np.ptp(gauge_pa(commands[-25:])) < 250.0
            ),
            20.0,
        ), f"{len(commands)} commands, last {gauge_pa(commands[-25:])}"

        client = probe.node.create_client(ChangeState, "/catheter/compensator/change_state")
        assert client.wait_for_service(timeout_sec=10.0)
        request = ChangeState.Request()
        request.transition.id = Transition.TRANSITION_DEACTIVATE
        n_before = len(commands)
        future = client.call_async(request)
        assert probe.spin_until(future.done, 30.0)
        assert future.result().success
        probe.spin_for(0.5)
        sent = gauge_pa(commands[n_before - 1 :])
        steps = np.diff(sent)
        falling = int(np.flatnonzero(steps < -1.0e3)[0])
        # Holding 20 deg until the request; the answer comes once the command is down: at
        # the slew limit (20 bar/s, 8000 Pa per 4 ms tick), never up, ending at zero; then
        # the loop is stopped and silent.
        assert np.all(np.abs(sent[: falling + 1] - sent[0]) < 1.0e3), sent[: falling + 1]
        assert np.all((steps[falling:] <= 1e-6) & (steps[falling:] >= -8.0e3 - 1e-6)), steps
        assert sent[-1] == 0.0, sent[-5:]
        silent_from = len(commands)
        probe.spin_for(0.5)
        assert len(commands) == silent_from, "a deactivated compensator still commands"
