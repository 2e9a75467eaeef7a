"""Run the same ``catheter-lab`` commands on two revisions and compare what they write.

    .venv/bin/python scripts/same_outputs.py BEFORE AFTER [--out DIR]

A restructuring (modules moved, a table turned into classes) must not change what a user
gets: the bags ``simulate`` writes, the models ``train`` fits, the diagnosis ``diagnose``
prints and saves. Each revision is checked out as a git worktree, and the commands run with
that worktree's packages first on ``PYTHONPATH`` (this venv's dependencies for both). Every
file the commands write and everything they print is compared byte for byte. Where the bytes
differ, the file is compared again without what records the run rather than its result, and
said so ("identical but the run record"): wall-clock durations and creation times in
manifests and bag metadata and the hashes that seal them, the work directory in paths, a fit's
"trained in 13.7 s", and a simulated bag's wall-clock stamps (its streams are then compared
as the lab reads them: stamps from the bag's start, and values). Progress bars are off.

Prints a table and saves ``same_outputs.json`` in ``--out``. Exit 0 when everything else is
identical, 1 when anything differs.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("catheter_models", "catheter_ros", "catheter_driver", "catheter_control")

# Keys that record the run (when, how long, on what), not its result; and the seal over them.
RUN_RECORD_KEYS = frozenset(
    {
        "created",
        "created_utc",
        "fit_seconds",
        "duration_s",
        "wall_s",
        "seconds",
        "elapsed_s",
        "sha256",
        "manifest_sha256",
        "search_s",
        "train_time_s",
        "nanoseconds_since_epoch",
        "hashes",
        "files",
        "seal",
        "library",
    }
)


def commands(out: Path) -> list[tuple[str, list[str]]]:
    """The commands, each writing under ``out`` (same relative paths on both revisions)."""
    bags = REPO / "bags"
    return [
        ("simulate", ["simulate", "lab_steps_7", "--seed", "3", "-o", str(out / "sim_steps")]),
        (
            "train drdpi",
            [
                "train",
                "drdpi",
                "--quiet",
                "--train",
                str(bags / "training"),
                "-o",
                str(out / "drdpi"),
            ],
        ),
        (
            "train idrdpi",
            [
                "train",
                "idrdpi",
                "--quiet",
                "--train",
                str(bags / "training"),
                "-o",
                str(out / "idrdpi"),
            ],
        ),
        (
            "compare",
            [
                "compare",
                str(out / "drdpi"),
                str(bags / "model_test_descending_sine"),
                "-o",
                str(out / "compare"),
            ],
        ),
        (
            "diagnose",
            [
                "diagnose",
                str(out / "drdpi"),
                "--train",
                str(bags / "training"),
                "--test",
                str(bags / "model_test_descending_sine"),
                str(bags / "model_test_arbitrary_plateaus"),
                "--effect",
                "pneumatic_lag",
                "--effect",
                "creep",
                "--core",
                "free_pi",
                "--no-reference",
                "--workers",
                "1",
                "-o",
                str(out / "diag"),
            ],
        ),
        ("tune", ["tune", str(out / "sim_steps"), "-o", str(out / "tune")]),
    ]


def _strip(value: Any) -> Any:
    """``value`` without the run-record keys, at any depth."""
    if isinstance(value, dict):
        return {k: _strip(v) for k, v in value.items() if k not in RUN_RECORD_KEYS}
    if isinstance(value, list):
        return [_strip(v) for v in value]
    return value


def _json_paths(a: Any, b: Any, at: str = "") -> list[str]:
    """Where two JSON values differ (key paths; at most 10)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out: list[str] = []
        for k in sorted(set(a) | set(b)):
            out += _json_paths(a.get(k), b.get(k), f"{at}/{k}")
        return out[:10]
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        out = []
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            out += _json_paths(x, y, f"{at}[{i}]")
        return out[:10]
    return [] if a == b else [at or "/"]


def _first_difference(a: str, b: str) -> str:
    """The first line that differs, before and after."""
    for x, y in zip(a.splitlines(), b.splitlines(), strict=False):
        if x != y:
            return f"{x!r} -> {y!r}"
    return "one is longer"


def _where(a: Path, b: Path) -> str:
    """What differs between two files, briefly."""
    if a.suffix == ".json":
        try:
            return ", ".join(_json_paths(json.loads(a.read_bytes()), json.loads(b.read_bytes())))
        except ValueError:
            pass
    try:
        return _first_difference(a.read_text(), b.read_text())
    except UnicodeDecodeError:
        data_a, data_b = a.read_bytes(), b.read_bytes()
        first = next(
            (i for i, (x, y) in enumerate(zip(data_a, data_b, strict=False)) if x != y), None
        )
        return f"{len(data_a)} vs {len(data_b)} bytes, first difference at byte {first}"


def _timeless(printed: dict[str, Any]) -> dict[str, Any]:
    """What a command printed, with its wall times ("trained in 13.7 s") left out."""
    return {**printed, "output": re.sub(r"\bin \d+(\.\d+)? s\b", "in <t> s", printed["output"])}


def _bag_series(path: Path) -> dict[str, Any]:
    """The bag's streams as the lab reads them: stamps from the bag's start and values.

    Not the raw messages: a simulated bag is stamped from the wall clock when it was made.
    """
    from catheter_models.bag import load_bag

    bag = load_bag(path.parent)
    out: dict[str, Any] = {}
    for name in ("pressure_command", "pressure_measured", "tip_angle", "tip_distance"):
        series = getattr(bag, name, None)
        if series is not None:
            out[name] = (series.t_s.tobytes(), series.values.tobytes())
    return out


def _same_file(a: Path, b: Path, work_a: Path, work_b: Path) -> tuple[bool, bool]:
    """(identical, identical once the run record is left out).

    The run record: JSON keys in :data:`RUN_RECORD_KEYS`, the two work directories in text,
    and in an MCAP bag when it was recorded (every stream's stamps from the bag's start and
    values must be equal).
    """
    data_a, data_b = a.read_bytes(), b.read_bytes()
    if data_a == data_b:
        return True, True
    if a.suffix == ".mcap":
        return False, _bag_series(a) == _bag_series(b)
    try:
        text_a = data_a.decode().replace(str(work_a), "<work>")
        text_b = data_b.decode().replace(str(work_b), "<work>")
    except UnicodeDecodeError:
        return False, False
    if a.suffix in {".json", ".yaml"}:
        import yaml

        try:
            return False, _strip(yaml.safe_load(text_a)) == _strip(yaml.safe_load(text_b))
        except yaml.YAMLError:
            return False, False
    return False, text_a == text_b


def run(rev: str, work: Path) -> dict[str, Any]:
    """Check ``rev`` out, run every command; returns what each printed and its exit code."""
    tree = work / "tree"
    subprocess.run(
        ["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), rev],
        check=True,
        capture_output=True,
    )
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join(str(tree / "src" / p) for p in PACKAGES),
        "PYTHONHASHSEED": "0",
    }
    printed: dict[str, Any] = {}
    try:
        # The venv's editable installs must not win over the worktree's packages.
        where = subprocess.run(
            [
                sys.executable,
                "-c",
                "import catheter_models, catheter_control; "
                "print(catheter_models.__file__); print(catheter_control.__file__)",
            ],
            env=env,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split()
        if not all(Path(w).is_relative_to(tree) for w in where):
            raise SystemExit(f"{rev}: the packages load from {where}, not from {tree}")
        out = work / "out"
        for label, argv in commands(out):
            done = subprocess.run(
                [sys.executable, "-c", "from catheter_models.cli import main; main()", *argv],
                check=False,
                env=env,
                capture_output=True,
                text=True,
                cwd=work,
            )
            # Paths differ between the two runs by their work directory only.
            text = (done.stdout + done.stderr).replace(str(work), "<work>")
            printed[label] = {"rc": done.returncode, "output": text}
            print(f"  {rev[:10]} {label}: rc {done.returncode}", flush=True)
    finally:
        subprocess.run(
            ["git", "-C", str(REPO), "worktree", "remove", "--force", str(tree)],
            check=False,
            capture_output=True,
        )
    return printed


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "results")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        works = {k: Path(tmp) / k for k in ("before", "after")}
        printed = {}
        for key, rev in (("before", args.before), ("after", args.after)):
            works[key].mkdir()
            printed[key] = run(rev, works[key])
        rows: list[dict[str, Any]] = []
        for label in printed["before"]:
            a, b = printed["before"][label], printed["after"][label]
            rows.append(
                {
                    "what": f"{label}: printed",
                    "identical": a == b,
                    "identical_but_run_record": _timeless(a) == _timeless(b),
                    "where": "" if a == b else _first_difference(a["output"], b["output"]),
                    **({} if _timeless(a) == _timeless(b) else {"before": a, "after": b}),
                }
            )
        files_a = {
            p.relative_to(works["before"] / "out")
            for p in (works["before"] / "out").rglob("*")
            if p.is_file()
        }
        files_b = {
            p.relative_to(works["after"] / "out")
            for p in (works["after"] / "out").rglob("*")
            if p.is_file()
        }
        for rel in sorted(files_a | files_b):
            if rel not in files_a or rel not in files_b:
                rows.append(
                    {"what": str(rel), "identical": False, "identical_but_run_record": False}
                )
                continue
            same, same_result = _same_file(
                works["before"] / "out" / rel,
                works["after"] / "out" / rel,
                works["before"],
                works["after"],
            )
            before, after = works["before"] / "out" / rel, works["after"] / "out" / rel
            rows.append(
                {
                    "what": str(rel),
                    "identical": same,
                    "identical_but_run_record": same_result,
                    "where": "" if same else _where(before, after),
                }
            )
    width = max(len(r["what"]) for r in rows)
    for r in rows:
        verdict = (
            "identical"
            if r["identical"]
            else ("identical but the run record" if r["identical_but_run_record"] else "DIFFERS")
        )
        print(f"{r['what']:<{width}}  {verdict}")
        if r.get("where") and not r["identical_but_run_record"]:
            print(f"{'':<{width}}    {r['where'][:300]}")
    differ = [r["what"] for r in rows if not r["identical_but_run_record"]]
    result = {
        "before": args.before,
        "after": args.after,
        "command": "python scripts/same_outputs.py " + " ".join([args.before, args.after]),
        "files_and_outputs": len(rows),
        "identical": sum(r["identical"] for r in rows),
        "identical_but_run_record": sum(
            r["identical_but_run_record"] and not r["identical"] for r in rows
        ),
        "differ": differ,
        "rows": rows,
    }
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "same_outputs.json").write_text(json.dumps(result, indent=2) + "\n")
    print(
        f"{result['identical']} of {len(rows)} identical, {result['identical_but_run_record']} "
        f"differ only in the run record, {len(differ)} differ"
    )
    return 1 if differ else 0


if __name__ == "__main__":
    raise SystemExit(main())
