"""Each package.xml declares what its code imports, so ``rosdep install`` gives a working system.

Every module of a package (``src/<pkg>/<pkg>/**/*.py`` and its launch files) is read with
``ast``; every ``import`` in it, at module level or inside a function, must be covered:

* the standard library (``sys.stdlib_module_names``) needs nothing;
* another package of this workspace needs an ``<exec_depend>`` on it;
* a third-party root needs the rosdep key that :data:`ROSDEP_KEYS` maps it to;
* a root with no usable rosdep key is in :data:`PIP_ONLY`, with the reason, and
  docker/Dockerfile must pip-install it;
* an optional extra's root (:data:`EXTRAS`) is named in its package's ``extras_require``,
  locked for the tests, and kept out of the runtime lock and the image.

An import root in none of these fails the test: a new dependency cannot slip in unnoticed.
Imports under ``if TYPE_CHECKING:`` are skipped (they never run). The other direction is
checked too: a non-ROS ``<exec_depend>`` that no module imports is stale, and a key that is
not in the tables is refused until someone has checked that it exists.

Where the keys were checked: ros/rosdistro ``rosdep/python.yaml`` (python3-numpy, -scipy,
-matplotlib, -yaml, -tqdm, -sklearn, -serial, -can, -onnxruntime-pip); python3-numba
(all Ubuntu releases since ros/rosdistro#36477) and python3-rosbags-pip (ros/rosdistro#37795)
from the rosdistro pull requests that added them. The ROS names (rclpy, sensor_msgs, launch,
...) are packages of the ROS 2 Kilted distribution itself, all in ``ros-kilted-ros-base``.
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("catheter_models", "catheter_ros", "catheter_driver", "catheter_control")
DOCKERFILE = REPO / "docker" / "Dockerfile"
CONSTRAINTS = REPO / "docker" / "constraints.txt"

ROSDEP_KEYS: dict[str, str] = {
    # rosdep system keys (ros/rosdistro rosdep/python.yaml)
    "numpy": "python3-numpy",
    "scipy": "python3-scipy",
    "numba": "python3-numba",
    "matplotlib": "python3-matplotlib",
    "yaml": "python3-yaml",
    "tqdm": "python3-tqdm",
    "sklearn": "python3-sklearn",
    # threadpoolctl is scikit-learn's own dependency (Debian's python3-sklearn depends on
    # python3-threadpoolctl), so the sklearn key brings it.
    "threadpoolctl": "python3-sklearn",
    "serial": "python3-serial",
    "can": "python3-can",
    "rosbags": "python3-rosbags-pip",
    "onnxruntime": "python3-onnxruntime-pip",
    # packages of the ROS 2 distribution (resolved from its distribution.yaml)
    "rclpy": "rclpy",
    "builtin_interfaces": "builtin_interfaces",
    "std_msgs": "std_msgs",
    "std_srvs": "std_srvs",
    "sensor_msgs": "sensor_msgs",
    "trajectory_msgs": "trajectory_msgs",
    "diagnostic_msgs": "diagnostic_msgs",
    "rcl_interfaces": "rcl_interfaces",
    "lifecycle_msgs": "lifecycle_msgs",
    "action_msgs": "action_msgs",
    "ament_index_python": "ament_index_python",
    "launch": "launch",
    "launch_ros": "launch_ros",
    "control_msgs": "control_msgs",
    "tf2_msgs": "tf2_msgs",
    "geometry_msgs": "geometry_msgs",
}
"""Import root -> rosdep key. Check a new key in ros/rosdistro before adding it here."""

ROS_PACKAGES = frozenset(
    {
        "rclpy",
        "builtin_interfaces",
        "std_msgs",
        "std_srvs",
        "sensor_msgs",
        "trajectory_msgs",
        "diagnostic_msgs",
        "rcl_interfaces",
        "lifecycle_msgs",
        "action_msgs",
        "ament_index_python",
        "launch",
        "launch_ros",
        "control_msgs",
        "tf2_msgs",
        "geometry_msgs",
    }
)
"""Keys that are ROS packages. They may stand without an import (a message package a node
serves through rclpy, e.g. lifecycle_msgs), so the stale check leaves them alone."""

PIP_ONLY: dict[str, tuple[str, str]] = {
    "mcap": ("mcap", "no rosdep key for the mcap library (only mcap_vendor, which is C++)"),
    "onnx": ("onnx", "no rosdep key; used only to export trained networks"),
    "foxglove": ("foxglove-sdk", "no rosdep key; the live view's Foxglove server"),
    "torch": (
        "torch",
        "python3-torch has no Ubuntu 24.04 package and python3-pytorch-pip is an EOL alias; "
        "training only, and the image wants the pinned CPU wheel",
    ),
}
"""Import root -> (pip distribution, why not rosdep). Not in package.xml: docker/Dockerfile
pip-installs them, pinned by docker/constraints.txt (checked below), and the venv has them
from the lock."""

EXTRAS: dict[str, tuple[str, str, str]] = {
    "ray": ("catheter_models", "ray", "the lab's refits on a cluster (`--ray`); never the graph"),
}
"""Import root -> (package, extra, what for): an optional extra, imported inside the function
that needs it (which refuses by name without it). Not in package.xml, the image or the runtime
lock; in ``requirements-lock.txt`` so its tests run (checked below)."""


@dataclass(frozen=True)
class Import:
    """One imported top-level name and where."""

    root: str
    path: Path
    line: int
    statement: str

    def where(self) -> str:
        return f"{self.path.relative_to(REPO)}:{self.line}: {self.statement}"


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports_in(source: str, path: Path) -> list[Import]:
    """Absolute imports of a module, anywhere in it, except under ``if TYPE_CHECKING:``."""
    found: list[Import] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            for alias in node.names:
                found.append(
                    Import(alias.name.partition(".")[0], path, node.lineno, ast.unparse(node))
                )
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append(
                Import(node.module.partition(".")[0], path, node.lineno, ast.unparse(node))
            )
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(source, filename=str(path)))
    return found


def package_sources(pkg: str) -> list[Path]:
    """Every module of a package: its Python package and its launch files."""
    root = REPO / "src" / pkg
    return sorted((root / pkg).rglob("*.py")) + sorted((root / "launch").glob("*.py"))


def package_imports(pkg: str) -> list[Import]:
    return [imp for path in package_sources(pkg) for imp in imports_in(path.read_text(), path)]


def exec_depends(pkg: str) -> list[str]:
    root = ET.parse(REPO / "src" / pkg / "package.xml").getroot()
    tags = ("exec_depend", "depend")
    return [(el.text or "").strip() for el in root if el.tag in tags]


def _third_party(imp: Import, pkg: str) -> bool:
    return imp.root not in sys.stdlib_module_names and imp.root != pkg


@pytest.mark.parametrize("pkg", PACKAGES)
def test_every_import_has_an_exec_depend(pkg: str) -> None:
    declared = set(exec_depends(pkg))
    problems = []
    for imp in package_imports(pkg):
        if not _third_party(imp, pkg) or imp.root in PIP_ONLY:
            continue
        if imp.root in EXTRAS and EXTRAS[imp.root][0] == pkg:
            continue
        if imp.root in PACKAGES:
            needed = imp.root
        elif imp.root in ROSDEP_KEYS:
            needed = ROSDEP_KEYS[imp.root]
        else:
            problems.append(
                f"{imp.where()}\n    import root {imp.root!r} is not in ROSDEP_KEYS of "
                "tests/test_package_deps.py: add it there with its rosdep key (check that the "
                "key exists in ros/rosdistro rosdep/python.yaml or base.yaml), or to PIP_ONLY "
                "with the reason and a pip install in docker/Dockerfile"
            )
            continue
        if needed not in declared:
            problems.append(
                f"{imp.where()}\n    needs <exec_depend>{needed}</exec_depend> in "
                f"src/{pkg}/package.xml"
            )
    assert not problems, f"{pkg}: {len(problems)} import(s) not covered:\n" + "\n".join(problems)


LAYERS: dict[str, frozenset[str]] = {
    "catheter_models": frozenset(),
    "catheter_ros": frozenset({"catheter_models"}),
    "catheter_driver": frozenset({"catheter_models", "catheter_ros"}),
    "catheter_control": frozenset({"catheter_models", "catheter_ros"}),
}
"""Which workspace packages each may import. The driver and control sides never import each
other: they meet at the topic contract (``catheter_models.contract``), over DDS."""

LAUNCHES: dict[str, frozenset[str]] = {"catheter_control": frozenset({"catheter_driver"})}
"""Run-time dependencies without an import: ``bringup`` and the launch files start the driver
package's nodes as processes, by executable or module name."""


@pytest.mark.parametrize("pkg", PACKAGES)
def test_packages_import_only_down_their_layers(pkg: str) -> None:
    problems = [
        f"{imp.path.relative_to(REPO)}:{imp.line}: imports {imp.root}"
        for imp in package_imports(pkg)
        if imp.root in PACKAGES and imp.root != pkg and imp.root not in LAYERS[pkg]
    ]
    assert not problems, (
        f"{pkg} may import only {sorted(LAYERS[pkg]) or 'no workspace package'}:\n"
        + "\n".join(problems)
    )


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_stale_or_unknown_exec_depend(pkg: str) -> None:
    used = set(LAUNCHES.get(pkg, ()))
    for imp in package_imports(pkg):
        if imp.root in PACKAGES:
            used.add(imp.root)
        elif imp.root in ROSDEP_KEYS:
            used.add(ROSDEP_KEYS[imp.root])
    known = set(ROSDEP_KEYS.values()) | set(PACKAGES)
    problems = []
    for key in exec_depends(pkg):
        if key not in known:
            problems.append(
                f"{key}: not a key this test knows; check it exists in ros/rosdistro and add "
                "its import root to ROSDEP_KEYS (or drop it)"
            )
        elif key not in ROS_PACKAGES and key not in used:
            problems.append(f"{key}: no module of {pkg} imports it (stale)")
    assert not problems, f"src/{pkg}/package.xml:\n" + "\n".join(problems)


def test_pip_only_imports_are_installed_by_the_image() -> None:
    dockerfile = DOCKERFILE.read_text()
    # Each command of a RUN on one line: continuations joined, `&&` and `;` split.
    commands = re.split(r"&&|;|\n", dockerfile.replace("\\\n", " "))
    pip_installs = " ".join(c for c in commands if "pip3 install" in c)
    pinned = dict(
        line.split("==", 1) for line in CONSTRAINTS.read_text().splitlines() if "==" in line
    )
    declared = {key for pkg in PACKAGES for key in exec_depends(pkg)}
    for root, (dist, reason) in PIP_ONLY.items():
        assert reason
        assert root not in ROSDEP_KEYS, f"{root} is both in ROSDEP_KEYS and PIP_ONLY"
        assert re.search(rf"(?<![\w-]){re.escape(dist)}(?![\w-])", pip_installs), (
            f"{root} has no rosdep key, so docker/Dockerfile must pip-install {dist}"
        )
        assert dist.lower() in pinned, (
            f"docker/constraints.txt does not pin {dist}: add it to requirements*.txt and run "
            "`make lock`"
        )
        guesses = {root, f"python3-{root}", f"python3-{root}-pip"} & declared
        assert not guesses, f"{root} has no usable rosdep key, yet package.xml names {guesses}"


@pytest.mark.parametrize("pkg", PACKAGES)
def test_package_xml_and_setup_py_agree(pkg: str) -> None:
    xml_root = ET.parse(REPO / "src" / pkg / "package.xml").getroot()
    tree = ast.parse((REPO / "src" / pkg / "setup.py").read_text())
    constants = {
        target.id: node.value.value
        for node in tree.body
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)
        for target in node.targets
        if isinstance(target, ast.Name)
    }
    setup_call = next(
        node
        for node in ast.walk(tree)
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "setup"
    )
    kwargs = {}
    for kw in setup_call.keywords:
        if isinstance(kw.value, ast.Constant):
            kwargs[kw.arg] = kw.value.value
        elif isinstance(kw.value, ast.Name) and kw.value.id in constants:
            kwargs[kw.arg] = constants[kw.value.id]
    assert xml_root.findtext("name") == pkg
    assert kwargs.get("name") == pkg, f"{pkg}/setup.py name={kwargs.get('name')!r}"
    assert kwargs.get("version") == xml_root.findtext("version"), (
        f"{pkg}: setup.py version {kwargs.get('version')!r} != package.xml "
        f"{xml_root.findtext('version')!r}"
    )
    assert xml_root.findtext("export/build_type") == "ament_python"
    assert (REPO / "src" / pkg / "resource" / pkg).is_file(), "ament resource marker missing"


def test_the_scanner_sees_function_level_imports_and_skips_type_checking() -> None:
    source = (
        "from __future__ import annotations\n"
        "from typing import TYPE_CHECKING\n"
        "import numpy as np, os.path\n"
        "if TYPE_CHECKING:\n"
        "    import torch\n"
        "else:\n"
        "    import yaml\n"
        "def f():\n"
        "    from sklearn.svm import SVR\n"
        "    from . import sibling\n"
        "    return SVR\n"
    )
    roots = [imp.root for imp in imports_in(source, REPO / "x.py")]
    assert roots == ["__future__", "typing", "numpy", "os", "yaml", "sklearn"]


@pytest.mark.parametrize("root", sorted(EXTRAS))
def test_an_optional_extra_is_declared_locked_for_tests_and_kept_out_of_the_runtime(
    root: str,
) -> None:
    pkg, extra, _ = EXTRAS[root]
    setup_py = (REPO / "src" / pkg / "setup.py").read_text()
    assert re.search(rf'extras_require=\{{[^}}]*"{extra}": \["{root}==', setup_py), (
        f"src/{pkg}/setup.py must offer {root} as the extra {extra!r}, pinned"
    )
    pin = re.search(rf'"{root}==([^"]+)"', setup_py)
    assert pin is not None
    assert f"{root}=={pin.group(1)} " in (REPO / "requirements-lock.txt").read_text(), (
        f"requirements-lock.txt must hold {root}=={pin.group(1)} so its tests run"
    )
    for runtime in (REPO / "requirements-runtime-lock.txt", CONSTRAINTS):
        assert f"\n{root}==" not in runtime.read_text(), f"{runtime.name} must not hold {root}"
    lazy = [
        imp
        for imp in package_imports(pkg)
        if imp.root == root and imp.statement == f"import {root}"
    ]
    assert lazy, f"{pkg} no longer imports {root}: drop it from EXTRAS and its setup.py extra"
    # Imported inside a function only: importing the package never needs the extra.
    for imp in lazy:
        line = imp.path.read_text().splitlines()[imp.line - 1]
        assert line.startswith(" "), f"{imp.where()}: import {root} at module level"
