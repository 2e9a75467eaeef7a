"""The models import along one direction: no module of ``catheter_models.models`` takes part in
an import cycle, and training (``lstm_train``) depends on the graph contract, not on inference."""

from __future__ import annotations

import ast
from pathlib import Path

import catheter_models

PACKAGE_DIR = Path(catheter_models.__file__).parent


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(tree: ast.Module, *, top_level_only: bool) -> set[str]:
    """Workspace modules named by the file's imports (only those run at import time if asked)."""
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    names: set[str] = set()
    for node in nodes:
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return {n for n in names if n.startswith("catheter_models")}


def _graph(*, top_level_only: bool) -> dict[str, set[str]]:
    files = {_module_name(p): p for p in PACKAGE_DIR.rglob("*.py")}
    return {
        name: _imports(ast.parse(path.read_text()), top_level_only=top_level_only) & set(files)
        for name, path in files.items()
    }


def _reaches(graph: dict[str, set[str]], start: str, goal: str) -> bool:
    seen: set[str] = set()
    todo = [start]
    while todo:
        node = todo.pop()
        for nxt in graph.get(node, set()):
            if nxt == goal:
                return True
            if nxt not in seen:
                seen.add(nxt)
                todo.append(nxt)
    return False


def test_no_models_module_is_in_an_import_cycle_at_import_time() -> None:
    graph = _graph(top_level_only=True)
    models = [m for m in graph if m.startswith("catheter_models.models")]
    cyclic = [m for m in models if _reaches(graph, m, m)]
    assert not cyclic, f"modules in an import cycle: {cyclic}"


def test_training_does_not_import_inference() -> None:
    graph = _graph(top_level_only=False)
    assert "catheter_models.models.lstm" not in graph["catheter_models.models.lstm_train"]
    top = _graph(top_level_only=True)
    assert "catheter_models.models.lstm_train" not in top["catheter_models.models.lstm"]
