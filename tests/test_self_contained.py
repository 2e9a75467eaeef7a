"""The repository stands on its own: every document it sends a reader to is in the clone.

A newcomer reads a docstring that says "see docs/effects.md" and finds no such file, or a
README that points at a directory beside the clone that only its authors had. Scans every
text file the repository tracks (or, outside a git checkout, every file under the source,
test, bench and docs trees) for paths of the form ``docs/<name>.md`` and for ``../shared``.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DOC_PATH = re.compile(r"\bdocs/[A-Za-z0-9_./-]+\.md\b")
TEXT_SUFFIXES = {".py", ".md", ".txt", ".toml", ".cfg", ".yaml", ".yml", ".json", ".sh", ""}
_THIS = Path(__file__).resolve()


def _text_files() -> list[Path]:
    try:
        names = subprocess.run(
            ["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True, timeout=60
        ).stdout.split()
        files = [REPO / n for n in names]
    except (OSError, subprocess.SubprocessError):
        files = [
            p
            for top in ("src", "tests", "bench", "docs", "scripts")
            for p in (REPO / top).rglob("*")
        ] + [REPO / "README.md", REPO / "Makefile"]
    return [
        p
        for p in files
        if p.is_file() and p.suffix in TEXT_SUFFIXES and p.stat().st_size < 2_000_000
    ]


def _read(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        return ""


def test_every_docs_page_a_file_names_exists() -> None:
    missing = sorted(
        f"{path.relative_to(REPO)}: {ref}"
        for path in _text_files()
        if path.resolve() != _THIS
        for ref in set(DOC_PATH.findall(_read(path)))
        if not (REPO / ref).is_file()
    )
    assert not missing, "pages named but not in the repository:\n" + "\n".join(missing)


def test_nothing_points_outside_the_clone() -> None:
    outside = sorted(
        str(path.relative_to(REPO))
        for path in _text_files()
        if path.resolve() != _THIS and "../shared" in _read(path)
    )
    assert not outside, f"files that send the reader outside the repository: {outside}"
