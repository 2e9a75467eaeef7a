"""The lab's worked example (docs/lab.md), made from the simulated rig with real bags.

    .venv/bin/python scripts/lab_worked_example.py [--out build/lab_example] [--docs]

A plant with a pneumatic lag of 0.2 s that nobody told the model about:

1. simulate the lab's training and held-out signal sets into bags (the lag switched on);
2. ``catheter-lab train drdpi``: the thesis's DRDPI (version 1);
3. ``catheter-lab compare``: where it fails;
4. ``catheter-lab diagnose``: which physical effect is missing;
5. ``catheter-lab add pneumatic_lag``: the grey-box chain with the lag, refitted (version 2);
6. ``catheter-lab compare`` again and ``catheter-lab history``: the error falling.

With ``--docs`` the figures are copied to ``docs/figures/lab/`` (what docs/lab.md shows).
Takes about two minutes on 2 cores.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from catheter_models.cli import main as lab

REPO = Path(__file__).resolve().parents[1]
HIDDEN = ["pneumatic_lag.time_constant_s=0.2"]


def run(*argv: str) -> None:
    """One ``catheter-lab`` command; stops the example if it fails."""
    print(f"\n$ catheter-lab {' '.join(argv)}", flush=True)
    try:
        lab(list(argv))
    except SystemExit as exc:
        if exc.code:
            raise SystemExit(f"catheter-lab {argv[0]} failed ({exc.code})") from None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=REPO / "build" / "lab_example")
    parser.add_argument("--docs", action="store_true", help="copy figures to docs/figures/lab")
    args = parser.parse_args(argv)
    out: Path = args.out
    if out.exists():
        shutil.rmtree(out)
    train_dir, test_dir, lab_dir = out / "train", out / "test", out / "lab"
    effects = [a for h in HIDDEN for a in ("--effect", h)]
    run("simulate", "@lab_training", "-o", str(train_dir), *effects, "--seed", "1")
    run("simulate", "@lab_test", "-o", str(test_dir), *effects, "--seed", "51")
    train = sorted(str(p) for p in train_dir.iterdir())
    test = sorted(str(p) for p in test_dir.iterdir())
    v1, v2 = out / "v1_drdpi", out / "v2_drdpi_lag"
    run("train", "drdpi", "--train", *train, "-o", str(v1))
    run("compare", str(v1), *test, "-o", str(out / "compare_v1"))
    run("diagnose", str(v1), "--train", *train, "--test", *test, "-o", str(out / "diagnose_v1"))
    run(
        "add",
        "pneumatic_lag",
        str(v1),
        "-o",
        str(v2),
        "--train",
        *train,
        "--test",
        *test,
        "--lab",
        str(lab_dir),
        "--no-progress",
    )
    run("compare", str(v2), *test, "-o", str(out / "compare_v2"))
    run("history", "--lab", str(lab_dir), "-o", str(out / "history.png"))

    diagnosis = json.loads((out / "diagnose_v1" / "diagnosis.json").read_text())
    summary = {
        "hidden": HIDDEN,
        "verdict": diagnosis["verdict"],
        "ranked": [
            (c["effect"], c["display"], round(c["measured_reduction"], 3))
            for c in diagnosis["candidates"]
        ],
        "rmse_test_deg": {
            "v1": json.loads((out / "compare_v1" / "comparison.json").read_text())["overall"],
            "v2": json.loads((out / "compare_v2" / "comparison.json").read_text())["overall"],
        },
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary, indent=2))
    if args.docs:
        figures = REPO / "docs" / "figures" / "lab"
        figures.mkdir(parents=True, exist_ok=True)
        picks = {
            out / "diagnose_v1" / "diagnosis.png": "example_diagnosis.png",
            out / "diagnose_v1" / "residual_tests.png": "example_residual_tests.png",
            out / "history.png": "example_history.png",
        }
        for which in ("v1", "v2"):
            loops = sorted((out / f"compare_{which}").glob("*_loops.png"))
            if loops:
                picks[loops[0]] = f"example_loops_{which}.png"
        for src, name in picks.items():
            shutil.copyfile(src, figures / name)
            print(f"figure: {figures / name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
