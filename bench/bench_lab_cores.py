"""The lab's hysteresis cores on foreign plants with nothing hidden: held-out RMSE per core.

The core is the part of a grey-box chain that carries the loop shape. Before any effect is
looked for, it must fit a plant whose law it was not written for. Each case is a foreign
plant (``tests/support/foreign_plants``) with nothing hidden: 5 minutes of training,
2 minutes held out. Every core is identified on the training recording and scored on the
held-out one, beside the sensor's true noise and the black-box reference
(``FilterBankReference``). ``free_pi (fixed)`` is the ``free_pi`` core with thresholds that
do not grow with the pressure: the baseline for the tension-scaled thresholds.

    NUMBA_NUM_THREADS=1 .venv/bin/python bench/bench_lab_cores.py --seeds 1 2

Writes ``bench/results/lab_cores.json`` and prints the table that docs/lab.md shows. Seeds
below 1000 are the development part; pass seeds from 1000 on for the held-out part.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_plant import _machine  # noqa: E402
from foreign_plants import PLANTS  # noqa: E402
from foreign_plants.cases import draw_case  # noqa: E402
from tqdm import tqdm  # noqa: E402

from catheter_models.lab.floors import FilterBankReference  # noqa: E402
from catheter_models.models.evaluate import pooled_rmse  # noqa: E402
from catheter_models.models.greybox import GreyBox  # noqa: E402

CORES: dict[str, dict[str, Any]] = {
    "drdpi": {"core": "drdpi"},
    "gpi": {"core": "gpi"},
    "boucwen": {"core": "boucwen"},
    "free_pi (fixed)": {"core": "free_pi", "core_settings": {"tension_shares": [0.0]}},
    "free_pi": {"core": "free_pi"},
}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", nargs="+", type=int, default=[1, 2])
    parser.add_argument("--plants", nargs="+", default=sorted(PLANTS))
    parser.add_argument("--cores", nargs="+", default=list(CORES), choices=list(CORES))
    parser.add_argument("--out", type=Path, default=REPO / "bench" / "results" / "lab_cores.json")
    args = parser.parse_args(argv)
    rows: list[dict[str, Any]] = []
    jobs = [(p, s) for p in args.plants for s in args.seeds]
    bar = tqdm(total=len(jobs) * (len(args.cores) + 1), desc="cores", unit="fit")
    t0 = time.perf_counter()
    for plant, seed in jobs:
        case = draw_case(PLANTS[plant], [], seed)
        row: dict[str, Any] = {
            "plant": plant,
            "variant": case.plant.variant,
            "seed": seed,
            "held_out": case.held_out,
            "noise_deg": math.degrees(case.plant.noise_std_rad),
            "test_deg": {},
            "fit_s": {},
        }
        start = time.perf_counter()
        row["reference_deg"] = FilterBankReference().fit([case.train]).rmse_deg([case.test])
        row["fit_s"]["reference"] = time.perf_counter() - start
        bar.update()
        for name in args.cores:
            start = time.perf_counter()
            model = GreyBox(**CORES[name]).fit([case.train], progress=False)
            row["fit_s"][name] = time.perf_counter() - start
            row["test_deg"][name] = math.degrees(pooled_rmse(model, [case.test]))
            if name == "free_pi":
                row["free_pi_values"] = {
                    k: v for k, v in model.core_.values().items() if k != "weights"
                }
            bar.update()
        rows.append(row)
    bar.close()
    header = "| plant, variant (seed) | noise | " + " | ".join(f"`{c}`" for c in args.cores)
    lines = [header + " | black box |", "|---|---|" + "---|" * (len(args.cores) + 1)]
    for r in rows:
        best = min(r["test_deg"].values())
        cells = [f"**{v:.3f}°**" if v == best else f"{v:.3f}°" for v in r["test_deg"].values()]
        lines.append(
            f"| {r['plant']} {r['variant']} ({r['seed']}) | {r['noise_deg']:.3f}° | "
            + " | ".join(cells)
            + f" | {r['reference_deg']:.3f}° |"
        )
    table = "\n".join(lines)
    print(table)
    result = {
        "rows": rows,
        "table": table,
        "seconds": time.perf_counter() - t0,
        "machine": _machine(),
        "unix_time_s": time.time(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2, default=float) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
