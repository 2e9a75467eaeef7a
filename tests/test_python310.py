"""The packages say they run on Python 3.10 (setup.py ``python_requires``): hold them to it.

The venv runs 3.11, so nothing else would notice a 3.11-only name imported at run time (eight
modules imported ``typing.Self``, an ImportError on 3.10) or 3.11-only syntax.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
NEW_IN_TYPING = {
    "Self",
    "Never",
    "LiteralString",
    "assert_never",
    "assert_type",
    "reveal_type",
    "Required",
    "NotRequired",
    "TypeVarTuple",
    "Unpack",
    "dataclass_transform",
}
"""``typing`` names added in Python 3.11."""
SOURCES = sorted(SRC.rglob("*.py"))


def _runtime_typing_imports(tree: ast.Module) -> list[tuple[int, str]]:
    """3.11-only ``typing`` names imported outside ``if TYPE_CHECKING:``."""
    guarded: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            guarded.update(id(child) for child in ast.walk(node))
    return [
        (node.lineno, alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module == "typing" and id(node) not in guarded
        for alias in node.names
        if alias.name in NEW_IN_TYPING
    ]


@pytest.mark.parametrize("path", SOURCES, ids=lambda p: str(p.relative_to(SRC)))
def test_a_module_parses_and_imports_as_python_3_10_allows(path: Path) -> None:
    tree = ast.parse(path.read_text(), filename=str(path), feature_version=(3, 10))
    assert not _runtime_typing_imports(tree), (
        f"{path}: 3.11-only typing names imported at run time: {_runtime_typing_imports(tree)}; "
        "import them under `if TYPE_CHECKING:` (annotations are strings here)"
    )


def test_the_check_sees_a_runtime_import_and_lets_a_guarded_one_pass() -> None:
    bare = ast.parse("from typing import Any, Self\n")
    guarded = ast.parse(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from typing import Self\n"
    )
    assert _runtime_typing_imports(bare) == [(1, "Self")]
    assert _runtime_typing_imports(guarded) == []
