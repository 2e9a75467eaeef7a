"""Write generated text into a markdown file between two marker comments."""

from __future__ import annotations

from pathlib import Path


def write_between(doc: Path, begin: str, end: str, text: str) -> None:
    """Replace what lies between ``begin`` and ``end`` in ``doc`` with ``text``.

    Raises:
        SystemExit: the file lacks either marker (names both).
    """
    content = doc.read_text()
    if begin not in content or end not in content:
        raise SystemExit(f"{doc} has no {begin} ... {end} markers")
    head, rest = content.split(begin, 1)
    _, tail = rest.split(end, 1)
    doc.write_text(f"{head}{begin}\n{text}{end}{tail}")
