"""Nothing in the packages can load a pickle: a model or bag file must never run code.

Scans every module under src/ with ``ast`` for the ways Python deserialises objects: the
pickle family of modules, ``torch.load`` (pickle underneath), ``np.load``/``numpy.load``
without ``allow_pickle=False``, and ``yaml.load``/``yaml.unsafe_load`` (``safe_load`` only).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PICKLING_MODULES = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "joblib", "shelve"}


def _modules() -> list[Path]:
    return sorted(p for p in SRC.rglob("*.py") if "egg-info" not in str(p))


def _call_name(node: ast.Call) -> str:
    parts = []
    target: ast.expr = node.func
    while isinstance(target, ast.Attribute):
        parts.append(target.attr)
        target = target.value
    if isinstance(target, ast.Name):
        parts.append(target.id)
    return ".".join(reversed(parts))


def _violations(path: Path, root: Path = SRC) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        where = f"{path.relative_to(root)}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.Import):
            found += [f"{where} imports {a.name}" for a in node.names if a.name in PICKLING_MODULES]
        elif isinstance(node, ast.ImportFrom) and (node.module or "") in PICKLING_MODULES:
            found.append(f"{where} imports from {node.module}")
        elif isinstance(node, ast.Call):
            name = _call_name(node)
            if name in {"torch.load", "yaml.load", "yaml.unsafe_load", "yaml.full_load"}:
                found.append(f"{where} calls {name}")
            elif name in {"np.load", "numpy.load"}:
                safe = any(
                    k.arg == "allow_pickle"
                    and isinstance(k.value, ast.Constant)
                    and k.value.value is False
                    for k in node.keywords
                )
                if not safe:
                    found.append(f"{where} calls {name} without allow_pickle=False")
    return found


def test_the_scan_sees_what_it_looks_for(tmp_path: Path) -> None:
    bad = tmp_path / "probe.py"
    bad.write_text(
        "import pickle\nimport numpy as np\nimport torch, yaml\n"
        "np.load('w.npy')\ntorch.load('m.pt')\nyaml.load(open('c'))\n"
        "np.load('ok.npy', allow_pickle=False)\nyaml.safe_load(open('c'))\n"
    )
    assert _violations(bad, tmp_path) == [
        "probe.py:1 imports pickle",
        "probe.py:4 calls np.load without allow_pickle=False",
        "probe.py:5 calls torch.load",
        "probe.py:6 calls yaml.load",
    ]


@pytest.mark.parametrize("path", _modules(), ids=lambda p: str(p.relative_to(SRC)))
def test_no_module_can_load_a_pickle(path: Path) -> None:
    assert not _violations(path)
