"""The graph runs without the training extra: no node, and no shipped compensator, needs torch.

requirements.txt (the runtime) leaves torch and onnx out, and `make demo` runs on it; the
training extra (requirements-train.txt) brings them for `catheter-lab train` and export only.
This test proves the split holds without building a second environment: a child interpreter
refuses every import of torch or onnx (as a runtime-only venv would), then imports every
executable's module and steps each shipped compensator once. A module that grows a
module-level ``import torch`` on this path fails here with the import chain that pulled it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

CHILD = textwrap.dedent(
    """
    import importlib, importlib.abc, math, sys

    BLOCKED = ("torch", "onnx")

    class NoTraining(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.partition(".")[0] in BLOCKED:
                raise ModuleNotFoundError(
                    f"{name} is training-only (requirements-train.txt); the runtime path "
                    "imported it", name=name)
            return None

    sys.meta_path.insert(0, NoTraining())

    # Every console script of the three packages (setup.py entry points).
    for module in (
        "catheter_driver.sim_hardware_node",
        "catheter_driver.valve_driver_node",
        "catheter_driver.laser_angle_node",
        "catheter_control.compensator_node",
        "catheter_control.recorder_node",
        "catheter_control.excite_node",
        "catheter_control.follow_trajectory",
        "catheter_control.bringup",
        "catheter_control.bag_play",
    ):
        importlib.import_module(module)

    from catheter_control.models import SHIPPED, load_compensator

    # The grey box's inverse is a user's model (none shipped): its modules load here too.
    importlib.import_module("catheter_models.models.greybox_inverse")
    for kind in SHIPPED:
        compensator = load_compensator(kind, "")
        command_pa = compensator.step(math.radians(5.0))
        if not math.isfinite(command_pa):
            sys.exit(f"shipped {kind} compensator gave {command_pa} Pa")

    leaked = sorted(m for m in sys.modules if m.partition(".")[0] in BLOCKED)
    if leaked:
        sys.exit(f"training modules loaded anyway: {leaked}")
    print("runtime path is torch-free")
    """
)


def test_nodes_and_shipped_compensators_load_without_torch_or_onnx() -> None:
    # A child of this (bootstrapped) interpreter inherits the ROS library path as it is.
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1"}
    result = subprocess.run(
        [sys.executable, "-c", CHILD],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
        check=False,
    )
    assert result.returncode == 0, (
        "the runtime path needs a training-only module:\n" + result.stderr[-4000:]
    )
    assert "runtime path is torch-free" in result.stdout
