"""Train the compensators shipped in ``catheter_control/data`` (IDRDPI and c-LSTM), from bags.

This is the recipe behind the shipped models, using only the public tools a researcher uses:

1. ``catheter-lab simulate @clstm_training`` writes the thesis's c-LSTM training set (40
   descending sines, thesis sec. 10.3.1) as bags from the simulated rig (``build/``);
2. ``catheter-lab train clstm`` trains the c-LSTM from those bags;
3. ``catheter-lab train idrdpi`` identifies the IDRDPI from ``bags/training`` (recorded by
   the real node graph, the DRDPI training set of thesis sec. 5.3.2);
4. both are scored on the four test trajectories with the plant in the loop.

    .venv/bin/python scripts/train_shipped_models.py            # both, about 10 minutes
    .venv/bin/python scripts/train_shipped_models.py --only idrdpi
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import numpy as np

from catheter_models.cli import main as lab
from catheter_models.models import load_model
from catheter_models.models.evaluate import tracking_score
from catheter_models.signals import TEST_TRAJECTORIES

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "src" / "catheter_control" / "catheter_control" / "data"
BAGS = REPO / "build" / "clstm_training_bags"

# The settings the benchmarks chose (docs/models.md says why).
IDRDPI_SETTINGS: list[str] = []  # the default, method=analytic, tracks best
# 2 x 64 rather than the thesis's 2 x 128: within a 10-minute CPU budget the smaller network
# trains further and tracked better in every comparison we ran (docs/models.md).
CLSTM_SETTINGS: list[str] = [
    "hidden_size=64",
    "chunk_samples=125",
    "batch_size=8",
    "learning_rate=0.002",
    "time_budget_s=540",
    "max_epochs=2000",
    "patience_epochs=80",
    "input_smoothing_hz=20",
    "rest_weight=0.1",
    "num_threads=2",
]


def _lab(argv: list[str]) -> None:
    try:
        lab(argv)
    except SystemExit as exc:
        if exc.code:
            sys.exit(f"catheter-lab {' '.join(argv[:2])} failed (exit {exc.code})")


def _settings(items: list[str]) -> list[str]:
    return [arg for item in items for arg in ("--set", item)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", nargs="*", choices=["idrdpi", "clstm"], default=None)
    parser.add_argument("--out", type=Path, default=DATA, help="where the model dirs go")
    args = parser.parse_args()
    kinds = args.only or ["idrdpi", "clstm"]
    tests = [str(REPO / "bags" / n) for n in ("model_test_descending_sine",)]
    for kind in kinds:
        out = args.out / kind
        if out.exists():
            shutil.rmtree(out)
        if kind == "clstm":
            if BAGS.exists():
                shutil.rmtree(BAGS)
            _lab(["simulate", "@clstm_training", "-o", str(BAGS), "--seed", "100"])
            bags = [str(p) for p in sorted(BAGS.iterdir())]
            _lab(["train", "clstm", "--train", *bags, "-o", str(out), *_settings(CLSTM_SETTINGS)])
        else:
            train = [str(REPO / "bags" / "training")]
            _lab(
                [
                    "train",
                    "idrdpi",
                    "--train",
                    *train,
                    "--validate",
                    *tests,
                    "-o",
                    str(out),
                    *_settings(IDRDPI_SETTINGS),
                ]
            )
        model = load_model(out)
        for trajectory in TEST_TRAJECTORIES:
            m = tracking_score(model, trajectory).metrics
            print(
                f"{kind} on {trajectory}: RMSE {np.degrees(m.rmse):.3f} deg, "
                f"MAE {np.degrees(m.mae):.3f} deg, NRMSE {100 * (m.nrmse or 0):.2f} %"
            )


if __name__ == "__main__":
    main()
