"""node_main's process set-up: what every node process does before its loops start."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

# A node whose start() reports how many objects the collector has been told to ignore: the
# loops start after this, so it is what a loop thread lives with.
PROGRAM = """
import gc, os
from rclpy.node import Node
from catheter_ros.node_main import run_nodes

class Probe(Node):
    def __init__(self):
        super().__init__("gc_probe")
        self.junk = [[i] for i in range(10000)]  # start-up objects, as a model load makes
    def start(self):
        print("frozen", gc.get_freeze_count(), flush=True)

raise SystemExit(run_nodes([Probe], until=lambda nodes: True))
"""


@pytest.mark.parametrize(("setting", "frozen"), [(None, True), ("0", False)])
def test_start_up_objects_are_frozen_out_of_the_collector_before_the_loops_start(
    setting: str | None, frozen: bool
) -> None:
    env = {**os.environ, "ROS_DOMAIN_ID": "219", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    env.pop("CATHETER_GC_FREEZE", None)
    if setting is not None:
        env["CATHETER_GC_FREEZE"] = setting
    result = subprocess.run(
        [sys.executable, "-c", PROGRAM],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    count = int(result.stdout.split("frozen", 1)[1].split()[0])
    # Frozen: everything built so far, the probe's 10,000 lists included.
    assert (count > 10000) if frozen else (count == 0), count


# A node's main as every node writes it: run_node_as_main, with a node that starts and stops
# at once, or one whose start-up is refused (as a refused parameter or a bad model is).
MAIN_PROGRAM = """
import sys
from rclpy.node import Node
from catheter_models.errors import ParameterError
from catheter_ros.node_main import run_node_as_main

class Probe(Node):
    def __init__(self):
        if sys.argv[1] == "refused":
            raise ParameterError("probe.limit_pa = -1.0 is outside its range")
        super().__init__("main_probe")

run_node_as_main(Probe, until=lambda node: True)
print("returned", flush=True)
"""


@pytest.mark.parametrize(("case", "code"), [("clean", 0), ("refused", 2)])
def test_a_node_main_exits_0_after_a_clean_run_and_2_when_start_up_is_refused(
    case: str, code: int
) -> None:
    env = {**os.environ, "ROS_DOMAIN_ID": "219", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    result = subprocess.run(
        [sys.executable, "-c", MAIN_PROGRAM, case],
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert result.returncode == code, result.stderr
    # A clean run returns from main (a console script then exits 0); a refused one leaves
    # through SystemExit, after saying why.
    assert ("returned" in result.stdout) == (code == 0)
    if code:
        assert "probe.limit_pa = -1.0 is outside its range" in result.stderr
