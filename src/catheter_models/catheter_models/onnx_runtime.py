"""ONNX Runtime, imported in one place, with its telemetry switched off before it starts.

The official Linux wheels (onnxruntime 1.31) carry Microsoft's 1DS telemetry, on by default.
In every process that imports it (the compensator, which moves the catheter, included) it
starts an uploader thread, writes a device id and queued events under
``~/.cache/Microsoft/DeveloperTools/.onnxruntime`` and sends them when it can reach the
network. A control node must not do that unasked. ONNX Runtime reads its switch,
``ORT_DISABLE_TELEMETRY``, once, when it is first imported: set afterwards it changes
nothing. So every module of this project takes ONNX Runtime from here, and a user who set
the variable themselves keeps their setting (docs/deployment.md, "What runs inside").
"""

from __future__ import annotations

import os
from typing import Final

TELEMETRY_ENV: Final = "ORT_DISABLE_TELEMETRY"
"""ONNX Runtime's own switch ("1": no uploader, no device id, no event cache)."""

os.environ.setdefault(TELEMETRY_ENV, "1")

import onnxruntime as ort  # noqa: E402  (after the switch, which it reads at import)

__all__ = ["TELEMETRY_ENV", "ort"]
