"""Every command-line tool takes ``--ros-args`` as ``ros2 run`` passes it (parsers only, no DDS)."""

from __future__ import annotations

from pathlib import Path

import pytest

from catheter_control import bag_play, bringup, follow_trajectory


def test_bringup_takes_its_namespace_from_ros_args_and_passes_the_rest_to_every_node() -> None:
    args, ros_args = bringup.parse_args(
        ["--bag", "b", "--ros-args", "-r", "__ns:=/x", "--log-level", "debug"]
    )
    assert args.namespace == "/x"
    assert args.bag == Path("b")
    assert ros_args == ["--log-level", "debug"]
    spec = bringup.sim_graph_specs()[0]
    argv = spec.argv(args.namespace, ros_args)
    assert argv[argv.index("-r") + 1] == "__ns:=/x"
    assert argv[-2:] == ["--log-level", "debug"]


def test_bringup_without_ros_args_is_unchanged() -> None:
    args, ros_args = bringup.parse_args(["--compose"])
    assert args.compose and args.namespace == "/catheter" and ros_args == []


def test_follow_trajectory_accepts_ros_args_and_runs_its_node_there() -> None:
    args = follow_trajectory._parse(
        ["--sim", "--preset", "traj_descending_sine", "--ros-args", "-r", "__ns:=/x"]
    )
    assert args.namespace == "/x"
    assert args.sim and args.preset == "traj_descending_sine"
    assert args.ros_args == ["-r", "__ns:=/x"]


def test_follow_trajectory_still_refuses_its_own_unknown_options() -> None:
    with pytest.raises(SystemExit):
        follow_trajectory._parse(["--sim", "--bogus", "--ros-args", "-r", "__ns:=/x"])


def test_bag_play_leaves_ros_args_to_rclpy(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # A missing bag is refused by bag_play itself (exit 2, its own message), which shows the
    # ROS arguments reached neither argparse ("unrecognized arguments") nor the bag lookup.
    missing = tmp_path / "nope"
    code = bag_play.main([str(missing), "--rate", "2", "--ros-args", "-r", "__ns:=/x"])
    err = capsys.readouterr().err
    assert code == bag_play.EXIT_REFUSED
    assert err.startswith("bag_play:") and str(missing) in err
    assert "unrecognized arguments" not in err
