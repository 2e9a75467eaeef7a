"""No two modules of the four packages import each other, directly or around a ring.

A cycle makes the import order decide what works (a name is missing while its module is half
run), and it hides which module is the lower layer. The emulated rig and its device emulators,
and the LSTM and its trainer, each had one, dodged by imports inside functions; so imports
inside functions count here too. Only those under ``if TYPE_CHECKING:`` do not (they never
run).
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("catheter_models", "catheter_ros", "catheter_driver", "catheter_control")


def _modules() -> dict[str, Path]:
    found = {}
    for pkg in PACKAGES:
        root = REPO / "src" / pkg
        for path in (root / pkg).rglob("*.py"):
            parts = path.relative_to(root).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _type_checking_only(tree: ast.Module) -> set[int]:
    """ids of the nodes under ``if TYPE_CHECKING:`` (they never run)."""
    skip: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            skip.update(id(sub) for sub in ast.walk(node))
    return skip


def import_graph(modules: dict[str, Path]) -> dict[str, set[str]]:
    """Module -> the workspace modules its imports name, inside functions too."""
    graph = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        skip = _type_checking_only(tree)
        named: set[str] = set()
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                named.update(a.name for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                submodules = {f"{node.module}.{a.name}" for a in node.names} & modules.keys()
                named.update(submodules)
                # ``from catheter_models.plant import kernel`` imports the submodule; only
                # names defined in the package itself make the package a dependency.
                if len(submodules) < len(node.names):
                    named.add(node.module)
        graph[name] = {n for n in named if n in modules and n != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_no_module_is_in_an_import_cycle() -> None:
    found = cycles(import_graph(_modules()))
    assert not found, "modules that import each other:\n" + "\n".join(map(str, found))


def test_a_cycle_is_found() -> None:
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(graph) == [["a", "b", "c"]]


def test_the_models_never_import_the_lab() -> None:
    """The lab sits above the models: a core, a block or a grey-box chain is a model anyone
    (the compensator, the tuner) uses without the lab's workflow coming with it."""
    graph = import_graph(_modules())
    upward = {
        (module, named)
        for module, names in graph.items()
        if module.startswith("catheter_models.models")
        for named in names
        if named.startswith("catheter_models.lab")
    }
    assert not upward, sorted(upward)
