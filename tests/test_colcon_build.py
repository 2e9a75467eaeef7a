"""``colcon build`` of a scratch copy of ros2_ws installs what ``ros2 run`` needs: every console
script under ``lib/<package>/``, the ament index entries, and a working installed entry point;
and what ``ros2 launch`` needs: the launch files and the drivers' parameter files under
``share/``. No launch package is installed here, so the launch files are compiled and read, not
run: each defines ``generate_launch_description``, and every node and parameter file it names
is installed."""

from __future__ import annotations

import ast
import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("catheter_models", "catheter_ros", "catheter_driver", "catheter_control")
LIBRARIES = ("catheter_ros",)
"""Packages with no executable of their own (the plumbing the nodes share)."""
VENV_BIN = Path(sys.executable).parent
IGNORE = shutil.ignore_patterns("__pycache__", "*.egg-info", "build", "install", "log")


def console_scripts(setup_py: Path) -> dict[str, str]:
    """``console_scripts`` of a setup.py, read with ``ast`` (name -> ``module:function``)."""
    tree = ast.parse(setup_py.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == "entry_points":
            entry_points = ast.literal_eval(node.value)
            scripts = {}
            for spec in entry_points.get("console_scripts", []):
                name, _, target = spec.partition("=")
                scripts[name.strip()] = target.strip()
            return scripts
    return {}


def _site_packages(install: Path) -> list[str]:
    found = sorted(str(p) for p in install.glob("*/lib/python3*/site-packages"))
    assert len(found) == len(PACKAGES), found
    return found


def test_colcon_build_installs_every_executable(tmp_path: Path) -> None:
    # A scratch copy of the workspace: ros2_ws/src is a symlink to ../src, so copy the real
    # packages under the copy's src/ (without build products of the checkout).
    ws = tmp_path / "ros2_ws"
    shutil.copytree(REPO / "ros2_ws", ws, symlinks=True, ignore=IGNORE)
    if (ws / "src").is_symlink():
        (ws / "src").unlink()
    (ws / "src").mkdir(exist_ok=True)
    for pkg in PACKAGES:
        shutil.copytree(REPO / "src" / pkg, ws / "src" / pkg, ignore=IGNORE)

    env = {
        **os.environ,
        "PATH": f"{VENV_BIN}{os.pathsep}{os.environ.get('PATH', '')}",
        "COLCON_HOME": str(tmp_path / "colcon_home"),  # no user defaults
    }
    env.pop("AMENT_PREFIX_PATH", None)
    env.pop("COLCON_PREFIX_PATH", None)
    try:
        build = subprocess.run(
            [str(VENV_BIN / "colcon"), "build", "--event-handlers", "console_direct-"],
            cwd=ws,
            env=env,
            capture_output=True,
            text=True,
            timeout=180.0,
            check=False,
        )
    except subprocess.TimeoutExpired as exc:
        raise AssertionError(f"colcon build took over 180 s:\n{exc.stdout}\n{exc.stderr}") from None
    assert build.returncode == 0, f"{build.stdout}\n{build.stderr}"
    assert f"{len(PACKAGES)} packages finished" in build.stdout, build.stdout

    install = ws / "install"
    for pkg in PACKAGES:
        scripts = console_scripts(ws / "src" / pkg / "setup.py")
        assert scripts or pkg in LIBRARIES, f"{pkg} declares no console scripts"
        lib = install / pkg / "lib" / pkg
        for name in scripts:
            exe = lib / name
            assert exe.is_file(), f"{pkg}: {name} not installed in {lib}: {sorted(lib.iterdir())}"
            assert os.access(exe, os.X_OK), f"{exe} is not executable"

    _check_launch_files(ws, install)

    # What `ros2 run` does: find each package through the ament index.
    site_packages = _site_packages(install)
    run_env = {
        **env,
        "AMENT_PREFIX_PATH": os.pathsep.join(str(install / pkg) for pkg in PACKAGES),
        "PYTHONPATH": os.pathsep.join(site_packages),
    }
    probe = (
        "import json, sys\n"
        "from ament_index_python.packages import get_package_prefix, "
        "get_package_share_directory\n"
        "import catheter_control.models as models\n"
        "out = {p: [get_package_prefix(p), get_package_share_directory(p)] for p in sys.argv[1:]}\n"
        "models.load_compensator('none', '')\n"
        "out['models_file'] = models.__file__\n"
        "print(json.dumps(out))\n"
    )
    found = subprocess.run(
        [sys.executable, "-c", probe, *PACKAGES],
        env=run_env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60.0,
        check=False,
    )
    assert found.returncode == 0, found.stderr
    located = json.loads(found.stdout.strip().splitlines()[-1])
    for pkg in PACKAGES:
        prefix, share = (Path(p) for p in located[pkg])
        assert prefix == install / pkg
        assert (share / "package.xml").is_file(), f"{share} has no package.xml"
    # The installed packages (not the checkout) were imported, with the shipped model inside.
    assert Path(located["models_file"]).is_relative_to(install), located["models_file"]

    # An installed entry point runs from the install alone.
    effects = subprocess.run(
        [str(install / "catheter_models" / "lib" / "catheter_models" / "catheter-lab"), "effects"],
        env=run_env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=60.0,
        check=False,
    )
    assert effects.returncode == 0, f"{effects.stdout}\n{effects.stderr}"
    assert "pneumatic_lag" in effects.stdout, effects.stdout


def _check_launch_files(ws: Path, install: Path) -> None:
    """Launch files and parameter files are installed, compile, and name installed things."""
    config_src = sorted((ws / "src" / "catheter_driver" / "config").glob("*.yaml"))
    assert config_src, "catheter_driver has no config/*.yaml"
    config_share = install / "catheter_driver" / "share" / "catheter_driver" / "config"
    for src in config_src:
        installed = config_share / src.name
        assert installed.is_file(), f"{src.name} not installed in {config_share}"
        assert installed.read_bytes() == src.read_bytes()

    launch_src = sorted((ws / "src" / "catheter_control" / "launch").glob("*.launch.py"))
    assert {p.name for p in launch_src} >= {"sim.launch.py", "rig.launch.py"}, launch_src
    launch_share = install / "catheter_control" / "share" / "catheter_control" / "launch"
    # The nodes both launch files start are built in catheter_control.launch_common: the
    # installed copy is checked with each file.
    (common,) = install.glob(
        "catheter_control/lib/python3*/site-packages/catheter_control/launch_common.py"
    )
    common_tree = ast.parse(common.read_text())
    for src in launch_src:
        installed = launch_share / src.name
        assert installed.is_file(), f"{src.name} not installed in {launch_share}"
        source = installed.read_text()
        compile(source, str(installed), "exec")  # a SyntaxError fails the test
        tree = ast.parse(source)
        assert any(
            isinstance(node, ast.FunctionDef) and node.name == "generate_launch_description"
            for node in tree.body
        ), f"{src.name} defines no generate_launch_description()"
        nodes = [
            {kw.arg: kw.value for kw in call.keywords}
            for t in (tree, common_tree)
            for call in ast.walk(t)
            if isinstance(call, ast.Call)
            and getattr(call.func, "id", "") in {"Node", "LifecycleNode"}
        ]
        assert nodes, f"{src.name} starts no Node"
        for kwargs in nodes:
            package = ast.literal_eval(kwargs["package"])
            executable = ast.literal_eval(kwargs["executable"])
            exe = install / package / "lib" / package / executable
            assert exe.is_file(), f"{src.name}: Node({package}, {executable}): no {exe}"
        for name in re.findall(r"\"(\w+\.yaml)\"", source):
            assert (config_share / name).is_file(), f"{src.name} names {name}, not installed"
