"""Over DDS: what a user chooses on the command line, a second graph in a busy domain, the
parameter types a node takes, and Ctrl-C during a run.

- a second ``follow_trajectory --sim`` or ``bringup`` in a domain where the graph runs exits 2
  naming the nodes and the domain, and leaves the running graph alone; a graph started with
  no look at all is refused by its lifecycle manager before any transition;
- ``-p control_rate_hz:=1000`` (an integer) is the 1 kHz loop; a string exits 2 with one line;
- ``bringup --compensator idrdpi`` runs the IDRDPI, and Ctrl-C stops it cleanly (exit 0);
- ``follow_trajectory --sim --model-dir <the shipped IDRDPI>`` runs the IDRDPI without
  ``--compensator``, and SIGINT mid-run ramps down, reports the run up to there and exits 130;
  SIGINT while the graph comes up stops it and exits 130. No traceback anywhere.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticArray
from graph_utils import SLACK_SENSOR_TIMEOUT_S, Children, Probe, diagnostic_values, node_argv

from catheter_control.bringup import sim_graph_specs
from catheter_control.follow_trajectory import EXIT_INTERRUPTED, EXIT_REFUSED
from catheter_control.models import shipped_model_dir
from catheter_models.contract import DIAGNOSTICS

pytestmark = [pytest.mark.slow]

FOLLOW = [sys.executable, "-m", "catheter_control.follow_trajectory"]
BRINGUP = [sys.executable, "-m", "catheter_control.bringup"]


def _wait_for_line(children: Children, name: str, text: str, timeout_s: float) -> bool:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if text in children.log(name):
            return True
        time.sleep(0.1)
    return False


def _compensator_report(probe: Probe, diagnostics: list, key: str, value: str) -> bool:
    def seen() -> bool:
        return any(
            status.name.endswith("compensator") and diagnostic_values(status).get(key) == value
            for m in diagnostics
            for status in m.msg.status
        )

    return probe.spin_until(seen, 30.0)


def _names_the_graph(said: str) -> bool:
    return "/catheter/compensator" in said or "/catheter/sim_hardware" in said


def test_a_second_graph_in_a_busy_domain_is_refused_naming_the_first(
    children: Children, tmp_path: Path
) -> None:
    graph = children.graph(sim_graph_specs(None))
    run_dir = tmp_path / "run"
    second = children.run(
        "follow_trajectory", [*FOLLOW, "--sim", "--out", str(run_dir), "--no-progress"], 90.0
    )
    assert second.returncode == EXIT_REFUSED, second.stdout + second.stderr
    # Discovery is gradual: the nodes found within the look are named, at least one of them.
    assert _names_the_graph(second.stderr), second.stderr
    assert f"ROS_DOMAIN_ID={children.domain_id}" in second.stderr
    assert "Traceback" not in second.stderr
    # Refused by the look before anything started or, where a busy machine made the look
    # miss the graph, by the lifecycle manager before any node was configured (the recorder,
    # not a lifecycle node, may have opened its bag by then): nothing was followed.
    assert "following '" not in second.stdout, second.stdout
    again = children.run("bringup", [*BRINGUP, "--no-tf"], 90.0)
    assert again.returncode == 2, again.stdout + again.stderr
    assert _names_the_graph(again.stderr), again.stderr
    assert f"ROS_DOMAIN_ID={children.domain_id}" in again.stderr
    # The running graph was not touched: nothing configured its nodes a second time.
    assert not graph.failed()
    assert children.log("compensator", "graph").count("compensator 'clstm' at") == 1


def test_a_graph_started_without_a_look_is_refused_by_its_manager_before_any_transition(
    children: Children,
) -> None:
    """The launchers' look can miss a graph on a busy machine; the manager must not."""
    from catheter_control.bringup import ProcessGraph
    from catheter_models.errors import GraphConflictError

    first = children.graph(sim_graph_specs(None))
    second = ProcessGraph(
        sim_graph_specs(None), "/catheter", children.log_dir / "second", children.env
    )
    with pytest.raises(GraphConflictError) as refused:
        second.start()  # no choose_domain here: only the manager stands in the way
    said = str(refused.value)
    assert "another graph already runs" in said
    assert _names_the_graph(said), said
    assert f"ROS_DOMAIN_ID={children.domain_id}" in said
    assert all(proc.poll() is not None for proc in second.procs.values()), "left running"
    # The first graph was never sent a transition: its nodes stay active, configured once.
    assert not first.failed()
    assert children.log("compensator", "graph").count("compensator 'clstm' at") == 1
    assert "Unable to start transition" not in children.log("sim_hardware", "graph")
    # The first graph winds down beside the refused one's traces (nodes that exited can show
    # for seconds): a deactivate, this graph's ramp-down, is never refused for a twin.
    assert first.stop(timeout_s=15.0) == {"compensator": 0, "sim_hardware": 0}


def test_a_twin_found_late_stops_the_bring_up_but_never_the_wind_down(
    children: Children, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str]
) -> None:
    """Discovery can bring another graph's node after the manager's first look (a CI run:
    after configure). Before each configure or activate the manager looks again and refuses;
    its deactivate (the ramp-down) goes on whatever it sees. The twin is simulated here
    (``_twice``), so both paths run every time rather than when discovery happens to be slow.
    """
    from catheter_control.process_graph import ProcessGraph
    from catheter_models.errors import GraphConflictError
    from catheter_ros.lifecycle_client import LifecycleManager

    looks: list[list[str]] = []

    def twin_after_the_first_look(self: LifecycleManager, names: list[str]) -> list[str]:
        looks.append(list(names))
        return [] if len(looks) == 1 else list(names)

    monkeypatch.setattr(LifecycleManager, "_twice", twin_after_the_first_look)
    late = ProcessGraph(sim_graph_specs(None), "/catheter", children.log_dir / "late", children.env)
    with pytest.raises(GraphConflictError) as refused:
        late.start()
    assert "found before its configure (discovery was slow)" in str(refused.value)
    assert "configured" not in capfd.readouterr().err  # refused before the first transition
    monkeypatch.undo()

    graph = children.graph(sim_graph_specs(None))
    monkeypatch.setattr(LifecycleManager, "_twice", lambda self, names: list(names))
    assert graph.stop(timeout_s=15.0) == {"compensator": 0, "sim_hardware": 0}
    assert "/catheter/compensator: deactivated" in capfd.readouterr().err


def test_an_integer_for_the_rate_is_the_1_khz_loop_and_a_string_is_refused(
    children: Children,
) -> None:
    params = {"require_pressure_measured": False, "control_rate_hz": 1000}
    argv = node_argv("catheter_control.compensator_node", params)
    assert "control_rate_hz:=1000" in argv  # an integer on the command line, as typed
    with Probe(children.domain_id) as probe:
        diagnostics = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        children.start("compensator", argv)
        assert _compensator_report(probe, diagnostics, "control_rate_hz", "1000"), children.log(
            "compensator"
        )
    bad = children.run(
        "compensator_string",
        node_argv("catheter_control.compensator_node", {"control_rate_hz": "fast"}),
        60.0,
    )
    out = bad.stdout + bad.stderr
    assert bad.returncode == 2, out
    assert "Traceback" not in out
    (line,) = [x for x in out.splitlines() if "control_rate_hz" in x]
    assert "expects a double" in line and "'fast' (a string)" in line


def test_bringup_runs_the_compensator_it_is_given_and_stops_cleanly_on_ctrl_c(
    children: Children,
) -> None:
    with Probe(children.domain_id) as probe:
        diagnostics = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        proc = children.start("bringup", [*BRINGUP, "--no-tf", "--compensator", "idrdpi"])
        assert _wait_for_line(children, "bringup", "graph up in /catheter", 90.0), children.log(
            "bringup"
        )
        assert _compensator_report(probe, diagnostics, "compensator", "idrdpi"), children.log(
            "bringup"
        )
    proc.send_signal(signal.SIGINT)
    assert proc.wait(30.0) == 0, children.log("bringup")
    log = children.log("bringup")
    assert "Traceback" not in log and "KeyboardInterrupt" not in log
    assert "/catheter/compensator: deactivated" in log, log


def test_sigint_mid_run_reports_the_run_up_to_there_and_exits_130(
    children: Children, tmp_path: Path
) -> None:
    """Also: ``--model-dir`` alone runs the compensator its manifest names (the IDRDPI)."""
    run_dir = tmp_path / "run"
    # About the interrupt, not a sensor's silence: a loaded run saw tip/angle quiet for 100 ms
    # 1.3 s in, and the run stopped (exit 4) before the interrupt came.
    slack = ["--sensor-timeout-s", str(SLACK_SENSOR_TIMEOUT_S)]
    argv = [*FOLLOW, "--sim", *slack, "--model-dir", str(shipped_model_dir("idrdpi"))]
    proc = children.start("follow_trajectory", [*argv, "--out", str(run_dir), "--no-progress"])
    assert _wait_for_line(children, "follow_trajectory", "following", 90.0), children.log(
        "follow_trajectory"
    )
    time.sleep(5.0)  # into the 20 s trajectory
    proc.send_signal(signal.SIGINT)
    assert proc.wait(60.0) == EXIT_INTERRUPTED, children.log("follow_trajectory")
    log = children.log("follow_trajectory")
    assert "Traceback" not in log and "KeyboardInterrupt" not in log
    said = [x for x in log.splitlines() if "interrupted (SIGINT)" in x]
    assert len(said) == 1 and "s into the trajectory" in said[0], log
    assert "the compensator ramped down" in said[0], said
    report = json.loads((run_dir / "report.json").read_text())
    assert report["interrupted"] == said[0].split("follow_trajectory: ", 1)[1].split(" (scored")[0]
    assert report["controller"]["compensator"] == "idrdpi", report["controller"]
    # Scored up to the interrupt: a few seconds of the 20 s trajectory's 5,000 set-points.
    assert 250 < report["overall"]["n_samples"] < 3750, report["overall"]
    assert (run_dir / "tracking.png").exists()
    # The graph was stopped in order: the compensator deactivated (ramp-down) first.
    assert "/catheter/compensator: deactivated" in log


def test_sigint_while_the_graph_comes_up_stops_it_and_exits_130(
    children: Children, tmp_path: Path
) -> None:
    run_dir = tmp_path / "run"
    proc = children.start(
        "follow_trajectory", [*FOLLOW, "--sim", "--out", str(run_dir), "--no-progress"]
    )
    assert _wait_for_line(children, "follow_trajectory", "starting the simulated rig", 60.0)
    time.sleep(0.5)
    proc.send_signal(signal.SIGINT)
    assert proc.wait(60.0) == EXIT_INTERRUPTED, children.log("follow_trajectory")
    log = children.log("follow_trajectory")
    assert "Traceback" not in log and "KeyboardInterrupt" not in log
    assert "interrupted while the graph came up" in log, log


def test_the_compensator_node_takes_its_kind_from_the_model_directory(
    children: Children,
) -> None:
    """``model_dir`` alone runs the kind its manifest names; a ``compensator`` given beside it
    that contradicts the manifest stops the node at configure naming both (exit 2)."""
    idrdpi = str(shipped_model_dir("idrdpi"))
    base = {"require_pressure_measured": False, "model_dir": idrdpi}
    proc = children.start("alone", node_argv("catheter_control.compensator_node", base))
    assert _wait_for_line(children, "alone", "compensator 'idrdpi' at", 60.0), children.log("alone")
    proc.send_signal(signal.SIGINT)
    assert proc.wait(30.0) == 0, children.log("alone")
    contradicting = children.run(
        "contradicting",
        node_argv("catheter_control.compensator_node", {**base, "compensator": "clstm"}),
        60.0,
    )
    out = contradicting.stdout + contradicting.stderr
    assert contradicting.returncode == 2, out
    assert "'clstm'" in out and "'idrdpi'" in out and "Traceback" not in out
