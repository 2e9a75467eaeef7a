"""ONNX Runtime runs our networks without its telemetry (catheter_models.onnx_runtime)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

# A process that runs a one-node network through the project's import of ONNX Runtime.
_RUN_A_NETWORK = """
import os
from onnx import TensorProto, helper
from catheter_models.onnx_runtime import TELEMETRY_ENV, ort
x = helper.make_tensor_value_info("x", TensorProto.FLOAT, [1])
y = helper.make_tensor_value_info("y", TensorProto.FLOAT, [1])
graph = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "g", [x], [y])
model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], ir_version=9)
session = ort.InferenceSession(model.SerializeToString(), providers=["CPUExecutionProvider"])
import numpy as np
assert session.run(None, {"x": np.ones(1, np.float32)})[0][0] == 1.0
print(os.environ.get(TELEMETRY_ENV, "unset"))
"""


def _run(home: Path, **env: str) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in ("ORT_DISABLE_TELEMETRY", "CI")}
    result = subprocess.run(
        [sys.executable, "-c", _RUN_A_NETWORK],
        env={**clean, "HOME": str(home), **env},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout.strip().splitlines()[-1]


def test_a_network_run_leaves_no_device_id_and_no_event_cache(tmp_path: Path) -> None:
    # ONNX Runtime's 1DS telemetry writes its device id and event cache under the home
    # directory; a run through our import must leave the home untouched.
    setting = _run(tmp_path)
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert written == [], f"ONNX Runtime wrote under HOME: {written}"
    assert setting == "1"


@pytest.mark.parametrize("setting", ["0", "1"])
def test_a_users_own_setting_is_kept(tmp_path: Path, setting: str) -> None:
    assert _run(tmp_path, ORT_DISABLE_TELEMETRY=setting) == setting
