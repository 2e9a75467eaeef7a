"""The fault table of docs/reliability.md from a fault-suite run (``make faults``).

    FAULT_REPORT=bench/results/faults.json .venv/bin/pytest -m fault tests/integration
    .venv/bin/python scripts/fault_table.py bench/results/faults.json --docs docs/reliability.md

Prints the table (faults tried, survived, time to a safe state, invariants checked) and, with
``--docs``, writes it into the file between the markers ``<!-- faults:begin -->`` and
``<!-- faults:end -->``. A fault whose test failed is listed as not survived, with the first
invariant that broke.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from doc_markers import write_between

BEGIN, END = "<!-- faults:begin -->", "<!-- faults:end -->"
CATEGORIES = {
    "graph": "Simulated graph (separate processes over DDS)",
    "drivers": "Real drivers against the emulated devices (real wire protocols over ptys)",
    "offline": "Files: bags given to the lab",
    "input": "Input to the tools and the network: trajectory files, settings, DDS sockets",
}


def _time(row: dict[str, Any]) -> str:
    t = row.get("time_to_safe_s")
    if t is None:
        return "—"
    if t == 0.0:
        return "never left it"
    return f"{t * 1e3:.0f} ms" if t < 2.0 else f"{t:.1f} s"


def _checks(row: dict[str, Any]) -> str:
    names = []
    for check in row["checks"]:
        mark = "" if check["ok"] else " **(broke: " + check["detail"] + ")**"
        if check["name"] not in names:
            names.append(check["name"] + mark)
    return "; ".join(names) or "—"


def table(rows: list[dict[str, Any]]) -> str:
    """Markdown: a summary line, then one table per category."""
    survived = sum(r["outcome"] == "passed" for r in rows)
    lines = [f"**{len(rows)} faults tried, {survived} survived.**", ""]
    for category, title in CATEGORIES.items():
        chosen = [r for r in rows if r["category"] == category]
        if not chosen:
            continue
        lines += [
            f"{title}:",
            "",
            "| fault injected | safe state | time to safe state | invariants checked | survived |",
            "|---|---|---|---|---|",
        ]
        for r in chosen:
            ok = "yes" if r["outcome"] == "passed" else f"**no** ({r['outcome']})"
            lines.append(f"| {r['fault']} | {r['safe']} | {_time(r)} | {_checks(r)} | {ok} |")
        lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("report", type=Path, help="JSON written by the suite (FAULT_REPORT)")
    parser.add_argument("--docs", type=Path, help="markdown file to write the table into")
    args = parser.parse_args(argv)
    if not args.report.is_file():
        print(f"fault_table: {args.report} does not exist; run the suite first", file=sys.stderr)
        return 2
    rows = json.loads(args.report.read_text())["faults"]
    text = table(rows)
    print(text)
    if args.docs:
        write_between(args.docs, BEGIN, END, text)
        print(f"written into {args.docs}")
    return 0 if all(r["outcome"] == "passed" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
