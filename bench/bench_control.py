"""Thesis Tables 11.1-11.4 redone on the simulated rig: IDRDPI and c-LSTM as compensators.

Same protocol as the thesis (ch. 9-11): each compensator is identified from recordings,
then runs open loop, one sample at a time through its streaming form (as the compensator
node runs it, with the node's pressure clamp and slew limit), on the four test trajectories
with the simulated plant in the loop. Scored by RMSE, maximum absolute error (eq. 5.13) and
NRMSE of the laser's angle against the desired angle, beside the thesis's real-rig numbers.
The baseline ``none`` is the static inverse of the quasi-static curve: no hysteresis
compensation at all.

Training data, as bags (playback for training):
* IDRDPI: ``bags/training`` (the DRDPI training set, recorded by the real node graph);
  all three IDRDPI forms (analytic inverse, the thesis's GPI route, direct) are measured.
* c-LSTM: the thesis's c-LSTM set (40 descending sines, eqs. 4.1/4.2, f 0.2-0.8 Hz,
  tau 0.02-0.2), simulated into bags with ``catheter-lab simulate @clstm_training``.

    .venv/bin/python bench/bench_control.py                   # trains everything (~12 min)
    .venv/bin/python bench/bench_control.py --clstm-model DIR # score a trained c-LSTM
    .venv/bin/python bench/bench_control.py --quick           # smoke run, small budgets

Writes ``bench/results/control.json`` and ``docs/figures/benchmarks/control_*.png``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from thesis_tables import CONTROL, TRAINING_TIME_S

from catheter_control.control_core import StaticInverseCompensator
from catheter_control.models import shipped_model_dir
from catheter_models.cli import main as lab_main
from catheter_models.models import Model, load_model, model_class
from catheter_models.models.data import recording_from_bag, recordings_from_bags
from catheter_models.models.evaluate import TrackingResult, track, tracking_score
from catheter_models.signals import TEST_TRAJECTORIES
from catheter_models.static_map import StaticMap

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results" / "control.json"
FIGURES = REPO / "docs" / "figures" / "benchmarks"
IDRDPI_METHODS = ("analytic", "gpi", "direct")


def static_inverse_score(trajectory: str) -> TrackingResult:
    """The baseline: the shipped static inverse (no hysteresis compensation) on the plant."""
    stream = StaticInverseCompensator(StaticMap.load(shipped_model_dir("static_map")))
    return track(stream, trajectory)


def train_clstm(quick: bool) -> tuple[Model, float]:
    """Simulate the c-LSTM training set into bags, then train from those bags."""
    with tempfile.TemporaryDirectory(prefix="clstm_bags_") as tmp:
        bag_root = Path(tmp)
        sets = ["@training"] if quick else ["@clstm_training"]
        try:
            lab_main(["simulate", *sets, "-o", str(bag_root), "--seed", "100"])
        except SystemExit as exc:
            if exc.code:
                raise
        bags = sorted(p for p in bag_root.iterdir() if p.is_dir())
        recordings = recordings_from_bags(bags)
    # The shipped model's own settings (its manifest), so a fresh run retrains exactly it.
    settings = load_model(shipped_model_dir("clstm")).settings()
    if quick:
        settings["time_budget_s"] = 30.0
    model = model_class("clstm")(**settings)
    n = sum(len(r) for r in recordings)
    print(f"\n== clstm: training on {len(recordings)} bags, {n} samples ...", flush=True)
    start = time.perf_counter()
    model.fit(recordings, progress=True)
    return model, time.perf_counter() - start


def _plot(runs: dict[str, dict[str, TrackingResult]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    FIGURES.mkdir(parents=True, exist_ok=True)
    for trajectory, by_label in runs.items():
        fig, (ax, ax_err) = plt.subplots(2, 1, figsize=(12, 6), sharex=True, height_ratios=[2, 1])
        first = next(iter(by_label.values()))
        ax.plot(first.t_s, np.degrees(first.desired_rad), color="black", lw=1.3, label="desired")
        for label, res in by_label.items():
            rmse = np.degrees(res.metrics.rmse)
            ax.plot(
                res.t_s, np.degrees(res.measured_rad), lw=0.9, label=f"{label} (RMSE {rmse:.2f}°)"
            )
            ax_err.plot(res.t_s, np.degrees(res.measured_rad - res.desired_rad), lw=0.8)
        ax.set(ylabel="bend [deg]", title=f"{trajectory}: open-loop compensation on the plant")
        ax_err.set(xlabel="time [s]", ylabel="error [deg]")
        ax.legend(fontsize=8)
        for a in (ax, ax_err):
            a.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(FIGURES / f"control_{trajectory}.png", dpi=110)
        plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small budgets: a smoke run")
    parser.add_argument(
        "--clstm-model",
        type=Path,
        default=None,
        help="score this c-LSTM model directory instead of training one",
    )
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()

    models: dict[str, Model] = {}
    fit: dict[str, Any] = {}
    train = [recording_from_bag(REPO / "bags" / "training")]
    for method in IDRDPI_METHODS:
        settings: dict[str, Any] = {"method": method}
        if args.quick:
            settings["budget"] = {"max_generations": 20, "popsize": 5}
        model = model_class("idrdpi")(**settings)
        print(f"\n== idrdpi ({method}): identifying on {len(train[0])} samples ...", flush=True)
        start = time.perf_counter()
        model.fit(train, progress=True)
        took = time.perf_counter() - start
        models[f"idrdpi ({method})"] = model
        fit[f"idrdpi ({method})"] = {
            "fit_time_s": took,
            "thesis_fit_time_s": TRAINING_TIME_S["idrdpi"],
        }
        print(f"   identified in {took:.1f} s")
    if args.clstm_model is not None:
        models["clstm"] = load_model(args.clstm_model)
        fit["clstm"] = {"model_dir": str(args.clstm_model)}
    else:
        clstm, took = train_clstm(args.quick)
        models["clstm"] = clstm
        fit["clstm"] = {
            "fit_time_s": took,
            "thesis_fit_time_s": TRAINING_TIME_S["clstm"],
            "target_s": 600.0,
            "met": took <= 600.0,
        }
        print(f"   trained in {took / 60:.1f} min (target <= 10 min; thesis 2.25 h on a GPU)")

    runs: dict[str, dict[str, TrackingResult]] = {}
    results: dict[str, dict[str, Any]] = {}
    for trajectory in TEST_TRAJECTORIES:
        runs[trajectory] = {"none (static inverse)": static_inverse_score(trajectory)}
        for label, model in models.items():
            runs[trajectory][label] = tracking_score(model, trajectory)
        results[trajectory] = {}
        for label, res in runs[trajectory].items():
            kind = label.split(" ")[0]
            m = res.metrics
            results[trajectory][label] = {
                "ours": {
                    "rmse_deg": float(np.degrees(m.rmse)),
                    "mae_deg": float(np.degrees(m.mae)),
                    "nrmse": m.nrmse,
                },
                "thesis": CONTROL[trajectory][kind]._asdict()
                if kind in CONTROL[trajectory]
                else None,
            }

    print("\nOpen-loop tracking on the simulated rig (ours) vs the thesis's rig; deg, NRMSE %")
    header = f"{'trajectory':32s} {'compensator':24s} {'RMSE':>13s} {'MAE':>13s} {'NRMSE':>13s}"
    print(header + "\n" + "-" * len(header))
    for trajectory, by_label in results.items():
        for label, row in by_label.items():
            o, t = (
                row["ours"],
                row["thesis"] or {"rmse_deg": np.nan, "mae_deg": np.nan, "nrmse": np.nan},
            )
            print(
                f"{trajectory:32s} {label:24s} {o['rmse_deg']:6.3f}/{t['rmse_deg']:6.2f} "
                f"{o['mae_deg']:6.3f}/{t['mae_deg']:6.2f} "
                f"{100 * (o['nrmse'] or 0):5.2f}/{100 * t['nrmse']:5.2f}"
            )
    best_idrdpi = min(
        (label for label in models if label.startswith("idrdpi")),
        key=lambda lb: float(np.mean([results[t][lb]["ours"]["rmse_deg"] for t in results])),
    )
    targets = {}
    for trajectory, by_label in results.items():
        c = by_label["clstm"]["ours"]["rmse_deg"]
        i = by_label[best_idrdpi]["ours"]["rmse_deg"]
        targets[trajectory] = {
            "clstm_rmse_deg": c,
            "best_idrdpi": best_idrdpi,
            "idrdpi_rmse_deg": i,
            "reduction": 1.0 - c / i,
            "met_rmse_0p5": c <= 0.5,
            "met_75pct_below_idrdpi": c <= 0.25 * i,
        }
        print(
            f"target {trajectory}: c-LSTM {c:.3f} deg (<= 0.5: "
            f"{'met' if c <= 0.5 else 'NOT met'}), {100 * (1 - c / i):.0f}% below "
            f"{best_idrdpi} (>= 75%: {'met' if c <= 0.25 * i else 'NOT met'})"
        )
    if not args.quick:  # a smoke run must not overwrite the documented figures
        _plot(runs)
    payload = {
        "benchmark": "open-loop control (thesis tables 11.1-11.4) on the simulated rig",
        "command": "python bench/bench_control.py" + (" --quick" if args.quick else ""),
        "fit": fit,
        "results": results,
        "targets": targets,
        "machine": {"python": platform.python_version(), "cores": os.cpu_count()},
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(payload, indent=2) + "\n")
    print(f"\nwrote {args.out}" + ("" if args.quick else f" and {FIGURES}/control_*.png"))


if __name__ == "__main__":
    main()
