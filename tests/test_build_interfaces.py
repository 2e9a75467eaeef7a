"""scripts/build_interfaces.sh leaves the interface packages to a ROS 2 installation that has
them: with its prefix on AMENT_PREFIX_PATH, nothing is built or installed into the venv."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SCRIPT = REPO / "scripts" / "build_interfaces.sh"
PACKAGES = ("tf2_msgs", "control_msgs")


def test_a_sourced_ros_with_the_packages_skips_the_build(tmp_path: Path) -> None:
    ros = tmp_path / "opt_ros_kilted"
    index = ros / "share" / "ament_index" / "resource_index" / "packages"
    index.mkdir(parents=True)
    for pkg in PACKAGES:
        (index / pkg).touch()
    run = subprocess.run(
        ["bash", str(SCRIPT), sys.prefix],
        # FORCE: the venv's own up-to-date stamps must not be why nothing is built.
        env={**os.environ, "AMENT_PREFIX_PATH": str(ros), "FORCE": "1"},
        capture_output=True,
        text=True,
        timeout=120.0,
        check=False,
    )
    assert run.returncode == 0, run.stderr
    for pkg in PACKAGES:
        assert f"interfaces: {pkg} comes from {ros}, not built" in run.stdout, run.stdout
    assert "building" not in run.stdout + run.stderr
