"""A parameter given with another type than it has: what a person means, or a one-line refusal.

``-p control_rate_hz:=1000`` is a person asking for 1 kHz; ROS reads ``1000`` as an integer,
and rclpy refused it for the double parameter with a traceback. An integer is taken as the
double; a string (or a bool, a list) for a double is refused at start-up with exit code 2 and
one line naming the parameter, its type and what was given.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from typing import Any

import pytest
import rclpy
from rclpy.context import Context
from rclpy.node import Node

from catheter_models.errors import ParameterError
from catheter_models.limits import BoundedParam
from catheter_ros.params import declare_float, declare_int, declare_plain

RATE = BoundedParam("control_rate_hz", 250.0, 10.0, 2000.0, "control loop rate [Hz]")


@pytest.fixture
def node_with() -> Iterator[Any]:
    """Build a node on its own context with the given ``-p`` overrides."""
    made: list[tuple[Node, Context]] = []

    def build(*overrides: str) -> Node:
        context = Context()
        args = ["t", "--ros-args", *(a for o in overrides for a in ("-p", o))]
        rclpy.init(args=args, context=context)
        node = Node("param_probe", context=context, enable_rosout=False)
        made.append((node, context))
        return node

    yield build
    for node, context in made:
        node.destroy_node()
        context.try_shutdown()


def test_an_integer_for_a_double_is_taken_as_the_double(node_with: Any) -> None:
    node = node_with("control_rate_hz:=1000")
    value = declare_float(node, "control_rate_hz", RATE)
    assert value == 1000.0 and isinstance(value, float)
    assert node.get_parameter("control_rate_hz").value == 1000.0


def test_an_integer_out_of_range_is_still_refused_with_the_range(node_with: Any) -> None:
    node = node_with("control_rate_hz:=5000")
    with pytest.raises(ParameterError, match=r"\[10, 2000\]"):
        declare_float(node, "control_rate_hz", RATE)


@pytest.mark.parametrize(
    ("given", "said"),
    [
        ("abc", "'abc' (a string)"),
        ("true", "True (a bool)"),
        ("[1.0,2.0]", "[1.0, 2.0]"),
    ],
)
def test_another_type_for_a_double_is_refused_naming_name_type_and_value(
    node_with: Any, given: str, said: str
) -> None:
    node = node_with(f"control_rate_hz:={given}")
    with pytest.raises(ParameterError) as err:
        declare_float(node, "control_rate_hz", RATE)
    message = str(err.value)
    assert "\n" not in message
    assert "'control_rate_hz'" in message and "a double" in message and said in message


def test_a_double_for_an_integer_and_a_string_for_a_bool_are_refused(node_with: Any) -> None:
    node = node_with("rt_priority:=50.5", "autostart:=yes_please")
    with pytest.raises(ParameterError, match=r"'rt_priority'.*an integer.*50\.5"):
        declare_int(node, "rt_priority", 50, low=0, high=98, doc="priority")
    with pytest.raises(ParameterError, match=r"'autostart'.*a bool.*'yes_please'"):
        declare_plain(node, "autostart", False, "autostart")


def _run_compensator(*params: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "ROS_DOMAIN_ID": "218", "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    argv = [sys.executable, "-m", "catheter_control.compensator_node", "--ros-args"]
    for param in params:
        argv += ["-p", param]
    return subprocess.run(argv, env=env, capture_output=True, text=True, timeout=120, check=False)


def test_a_node_given_a_string_for_a_double_exits_2_with_one_line_and_no_traceback() -> None:
    result = _run_compensator("control_rate_hz:=fast")
    out = result.stdout + result.stderr
    assert result.returncode == 2, out
    assert "Traceback" not in out
    (line,) = [line for line in out.splitlines() if "control_rate_hz" in line]
    assert "expects a double" in line and "'fast' (a string)" in line
