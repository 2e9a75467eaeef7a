"""The hash-checked locks say what requirements*.txt say.

scripts/setup_env.sh installs only from the locks, so a pin edited in a requirements file and
not re-locked (`make lock`) would silently not take effect. Each pin of an input must be in its
lock, with hashes; the distro lock and docker/constraints.txt must hold Ubuntu 24.04's versions.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PIN = re.compile(r"^([A-Za-z0-9][A-Za-z0-9._-]*)(?:\[[^\]]*\])?==([^\s;\\]+)")


def _name(raw: str) -> str:
    return re.sub(r"[-_.]+", "-", raw).lower()


def input_pins(path: Path) -> dict[str, str]:
    """name -> version of a requirements file and the files it includes with ``-r``."""
    pins: dict[str, str] = {}
    for raw in path.read_text().splitlines():
        line = raw.strip()
        if line.startswith("-r "):
            pins.update(input_pins(path.parent / line[3:].strip()))
        elif match := PIN.match(line):
            pins[_name(match[1])] = match[2]
    return pins


def lock_pins(path: Path) -> dict[str, str]:
    """name -> version of a lock, refusing a pin without hashes."""
    text = path.read_text()
    pins: dict[str, str] = {}
    for block in re.split(r"\n(?=[A-Za-z0-9])", text):
        if match := PIN.match(block):
            assert "--hash=sha256:" in block, f"{path.name}: {match[1]} has no hash"
            pins[_name(match[1])] = match[2]
    return pins


def _same(locked: str | None, wanted: str) -> bool:
    # torch==2.13.0 resolves to the CPU index's 2.13.0+cpu: the local label is the build.
    return locked is not None and locked.partition("+")[0] == wanted.partition("+")[0]


@pytest.mark.parametrize(
    ("inputs", "lock"),
    [
        (("requirements-dev.txt",), "requirements-lock.txt"),
        (("requirements.txt",), "requirements-runtime-lock.txt"),
        (("requirements-distro.txt",), "requirements-distro-lock.txt"),
    ],
)
def test_every_input_pin_is_locked(inputs: tuple[str, ...], lock: str) -> None:
    locked = lock_pins(REPO / lock)
    stale = [
        f"{name}=={version} (lock: {locked.get(name)})"
        for name_file in inputs
        for name, version in input_pins(REPO / name_file).items()
        if not _same(locked.get(name), version)
    ]
    assert not stale, f"{lock} is behind its inputs, run `make lock`: {', '.join(stale)}"


def test_the_runtime_lock_has_no_training_extra() -> None:
    locked = lock_pins(REPO / "requirements-runtime-lock.txt")
    assert not {"torch", "onnx"} & set(locked), "the runtime must not need torch or onnx"
    assert lock_pins(REPO / "requirements-lock.txt")["torch"].endswith("+cpu")


def test_the_image_constraints_hold_the_distribution_versions() -> None:
    constraints = dict(
        (_name(m[1]), m[2])
        for line in (REPO / "docker" / "constraints.txt").read_text().splitlines()
        if (m := PIN.match(line))
    )
    for name, version in input_pins(REPO / "requirements-distro.txt").items():
        assert constraints.get(name) == version, f"docker/constraints.txt: {name}"
    assert not [n for n in constraints if n.startswith("ros-")], "the image's ROS is apt's"
