"""What ``bringup`` and ``follow_trajectory --sim`` run, chosen on their command lines (no DDS).

The compensator, its model directory (whose manifest names its kind), the feedback, the plant
and the ROS domain: a choice that contradicts the model, or a node parameter given after
``--ros-args`` where it would reach every node, is refused before anything starts.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

import pytest

from catheter_control import bringup, follow_trajectory, graph_domain, local_graph
from catheter_control.models import compensator_of_model_dir, resolve_compensator, shipped_model_dir
from catheter_models.errors import ParameterError
from catheter_models.model_dir import ModelDirError, write_model_dir

IDRDPI = str(shipped_model_dir("idrdpi"))
CLSTM = str(shipped_model_dir("clstm"))


def _forward_model(path: Path) -> str:
    """A sealed model directory of the forward DRDPI kind (its weights do not matter here)."""
    write_model_dir(path, "drdpi", {"pressure": "Pa"}, {"angle": "rad"}, {"w.json": b"{}"})
    return str(path)


def test_a_model_directory_alone_names_its_compensator() -> None:
    assert compensator_of_model_dir(IDRDPI) == "idrdpi"
    assert compensator_of_model_dir(CLSTM) == "clstm"
    assert compensator_of_model_dir(str(shipped_model_dir("static_map"))) == "none"
    assert resolve_compensator(None, IDRDPI) == "idrdpi"
    assert resolve_compensator(None, "") == "clstm"
    assert resolve_compensator("none", "") == "none"


def test_a_compensator_that_contradicts_the_manifest_is_refused_with_both_named() -> None:
    with pytest.raises(ParameterError) as err:
        resolve_compensator("clstm", IDRDPI)
    assert "'clstm'" in str(err.value) and "'idrdpi'" in str(err.value)
    assert IDRDPI in str(err.value)
    assert resolve_compensator("idrdpi", IDRDPI) == "idrdpi"


def test_a_forward_model_is_refused_naming_its_kind(tmp_path: Path) -> None:
    forward = _forward_model(tmp_path / "drdpi")
    with pytest.raises(ParameterError, match=r"'drdpi' forward model.*not a compensator"):
        resolve_compensator(None, forward)
    with pytest.raises(ParameterError, match="'drdpi'"):
        resolve_compensator("idrdpi", forward)


def test_a_directory_that_is_no_model_or_was_tampered_with_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ModelDirError, match=r"no manifest\.json"):
        resolve_compensator(None, str(tmp_path))
    forward = Path(_forward_model(tmp_path / "m"))
    manifest = json.loads((forward / "manifest.json").read_text())
    manifest["kind"] = "idrdpi"  # a forward model relabelled: its seal no longer matches
    (forward / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ModelDirError, match="sha256"):
        resolve_compensator(None, str(forward))


def test_bringup_passes_its_choices_to_the_compensator_and_the_plant_to_the_rig() -> None:
    args, ros_args = bringup.parse_args(
        ["--model-dir", IDRDPI, "--feedback", "pi", "--plant", "my_lab.rod:make_plant"]
    )
    assert ros_args == []
    params = bringup.compensator_choice(args)
    assert params == {"compensator": "idrdpi", "model_dir": IDRDPI, "feedback": "pi"}
    assert args.plant == "my_lab.rod:make_plant"
    assert args.domain_id == "env"
    # Nothing given: the node's own defaults, nothing passed.
    plain, _ = bringup.parse_args([])
    assert bringup.compensator_choice(plain) == {}
    explicit, _ = bringup.parse_args(["--compensator", "idrdpi"])
    assert bringup.compensator_choice(explicit) == {"compensator": "idrdpi"}


def test_bringup_refuses_a_contradicting_compensator_before_anything_starts(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[bringup.ProcessGraph] = []
    monkeypatch.setattr(bringup.ProcessGraph, "start", _record_into(started))
    with pytest.raises(SystemExit) as stop:
        bringup.main(["--compensator", "clstm", "--model-dir", IDRDPI])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "'clstm'" in err and "'idrdpi'" in err
    assert not started


@pytest.mark.parametrize("tool", ["bringup", "follow_trajectory"])
@pytest.mark.parametrize(
    ("param", "flag"),
    [("compensator:=idrdpi", "--compensator idrdpi"), ("model_dir:=/m", "--model-dir /m")],
)
def test_a_node_parameter_after_ros_args_is_refused_naming_the_flag(
    tool: str, param: str, flag: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["--ros-args", "-p", param]
    with pytest.raises(SystemExit) as stop:
        if tool == "bringup":
            bringup.parse_args(argv)
        else:
            follow_trajectory._parse(["--sim", *argv])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert f"use {flag}" in err and "every node" in err


def test_other_ros_arguments_still_reach_every_node() -> None:
    _, ros_args = bringup.parse_args(["--ros-args", "-p", "use_sim_time:=false"])
    assert ros_args == ["-p", "use_sim_time:=false"]


@pytest.mark.parametrize("value", ["auto", "env", "0", "42", "232"])
def test_domain_ids_accepted(value: str) -> None:
    args, _ = bringup.parse_args(["--domain-id", value])
    assert args.domain_id == value


@pytest.mark.parametrize("value", ["233", "-1", "random", ""])
def test_domain_ids_refused(value: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        bringup.parse_args(["--domain-id", value])
    assert "--domain-id" in capsys.readouterr().err


def test_a_graph_s_nodes_in_the_namespace_are_told_apart_from_tools_and_other_graphs() -> None:
    nodes = [
        "/catheter/compensator",
        "/catheter/sim_hardware",
        "/catheter/compensator_action",  # the compensator's own helper, named with it
        "/catheter/follow_trajectory",  # a client of the graph, not a graph
        "/catheter/test_probe",
        "/catheter2/compensator",
        "/catheter/sub/compensator",
        "/compensator",
    ]
    assert graph_domain.in_namespace(nodes, "/catheter") == [
        "/catheter/compensator",
        "/catheter/sim_hardware",
    ]


def _record_into(started: list[bringup.ProcessGraph]) -> object:
    """A stand-in for ProcessGraph.start that keeps the graph instead of starting it."""

    def start(self: bringup.ProcessGraph) -> None:
        started.append(self)

    return start


def _forget_domain(monkeypatch: pytest.MonkeyPatch) -> None:
    """No ROS_DOMAIN_ID, and whatever the code under test sets is undone afterwards."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "0")
    monkeypatch.delenv("ROS_DOMAIN_ID")
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET")


def _follow_args(*argv: str) -> argparse.Namespace:
    return follow_trajectory._parse(["--sim", *argv])


@pytest.mark.parametrize(
    ("environment", "expected"), [({"ROS_DOMAIN_ID": "17"}, "env"), ({}, "auto")]
)
def test_a_sim_run_takes_a_domain_of_its_own_unless_one_was_chosen(
    environment: dict[str, str], expected: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    _forget_domain(monkeypatch)
    for key, value in environment.items():
        monkeypatch.setenv(key, value)
    chosen: list[tuple[str, str]] = []
    monkeypatch.setattr(
        local_graph, "choose_domain", lambda choice, ns, who: chosen.append((choice, ns))
    )
    args = _follow_args("--model-dir", IDRDPI)
    assert args.compensator is None
    local_graph.prepare_local_graph(args)
    assert chosen == [(expected, "/catheter")]
    assert args.compensator == "idrdpi"
    # The look for other graphs, and the graph, are on this host only.
    assert os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    explicit = _follow_args("--domain-id", "5")
    local_graph.prepare_local_graph(explicit)
    assert chosen[-1] == ("5", "/catheter")


def test_follow_trajectory_refuses_a_contradicting_compensator_with_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    _forget_domain(monkeypatch)
    monkeypatch.setattr(local_graph, "choose_domain", lambda *a: pytest.fail("looked"))
    code = follow_trajectory.main(
        ["--sim", "--compensator", "clstm", "--model-dir", IDRDPI, "--out", str(tmp_path / "r")]
    )
    assert code == follow_trajectory.EXIT_REFUSED == 2
    err = capsys.readouterr().err
    assert "'clstm'" in err and "'idrdpi'" in err


def test_a_busy_namespace_is_refused_naming_the_nodes_and_the_domain(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    _forget_domain(monkeypatch)
    monkeypatch.setenv("ROS_DOMAIN_ID", "33")
    monkeypatch.setattr(
        graph_domain,
        "nodes_in_domain",
        lambda domain_id, wait_s=0.0: ["/catheter/compensator", "/elsewhere/x"],
    )
    with pytest.raises(graph_domain.GraphConflictError) as err:
        graph_domain.choose_domain("env", "/catheter", "test")
    assert "/catheter/compensator" in str(err.value) and "ROS_DOMAIN_ID=33" in str(err.value)
    assert "/elsewhere/x" not in str(err.value)
    # Another namespace in the same domain is no conflict.
    assert graph_domain.choose_domain("env", "/catheter2", "test") == 33


def test_auto_takes_a_domain_nobody_is_in_and_says_which(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    _forget_domain(monkeypatch)
    looked: list[int] = []

    def nodes(domain_id: int, wait_s: float = 0.0) -> list[str]:
        looked.append(domain_id)
        return ["/someone/else"] if len(looked) == 1 else []

    monkeypatch.setattr(graph_domain, "nodes_in_domain", nodes)
    domain_id = graph_domain.choose_domain("auto", "/catheter", "test")
    low, high = graph_domain.AUTO_DOMAIN_RANGE
    assert looked[-1] == domain_id and len(looked) == 2 and low <= domain_id <= high
    assert os.environ["ROS_DOMAIN_ID"] == str(domain_id)
    assert f"ROS_DOMAIN_ID={domain_id}" in capsys.readouterr().out


def test_auto_gives_up_naming_the_busy_domains(monkeypatch: pytest.MonkeyPatch) -> None:
    _forget_domain(monkeypatch)
    monkeypatch.setattr(graph_domain, "nodes_in_domain", lambda d, wait_s=0.0: ["/x/y"])
    with pytest.raises(graph_domain.GraphConflictError, match="--domain-id N"):
        graph_domain.choose_domain("auto", "/catheter", "test")


@pytest.mark.parametrize("rig", ["--sim", "--emulated-rig"])
def test_the_plant_reaches_sim_hardware_or_the_emulated_rig(
    rig: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[bringup.ProcessGraph] = []
    device_args: list[list[str]] = []
    monkeypatch.setattr(bringup.ProcessGraph, "start", _record_into(started))

    def fake_devices(self: bringup.EmulatedDevices) -> dict[str, dict[str, object]]:
        device_args.append(self.args)
        return {k: {"port": f"/dev/{k}"} for k in ("keller_serial", "dac_serial", "adc_serial")}

    monkeypatch.setattr(bringup.EmulatedDevices, "start", fake_devices)
    _forget_domain(monkeypatch)
    args = follow_trajectory._parse([rig, "--plant", "my_lab.rod:make_plant"])
    args.compensator = "clstm"
    local = local_graph.start_local_graph(args, tmp_path, tmp_path / "bag", "t", {})
    (graph,) = started
    assert local.graph is graph
    specs = {s.name: s for s in graph.specs}
    if rig == "--sim":
        assert specs["sim_hardware"].params["plant"] == "my_lab.rod:make_plant"
        assert not device_args
    else:
        (argv,) = device_args
        assert argv[argv.index("--plant") + 1] == "my_lab.rod:make_plant"
        assert "sim_hardware" not in specs
    assert "my_lab.rod:make_plant" in specs["recorder"].params["custom_data"]  # type: ignore[operator]
