"""Benchmark of the DRDPI identification: fast budget vs a long run of the same optimiser.

The thesis identified its DRDPI's 12 parameters (Table 5.1) on 26,798 samples with MATLAB's
genetic algorithm in about 3.5 h (sec. 5.3.2). Here the same objective (eq. 5.12) on the
simulated thesis training set (``simulate_recordings(training_set())``, 8 descending sines,
26,800 samples at 250 Hz) is minimised by differential evolution over a numba population
loss, then polished (``catheter_models.models.identify``). The baseline is the same
optimiser given 10x the generations and 4x the population: the fast run is good enough when
it reaches the same loss.

Also reported: the RMSE of both identified models on the four modelling test signals
(sec. 5.4.2), and, unless ``--no-tracking``, how each IDRDPI method tracks the four control
trajectories open loop on the simulated rig (``tracking_score``), next to two baselines:
no command at all, and the static inverse (``StaticMap``, no hysteresis compensation).

Run with ``.venv/bin/python bench/bench_drdpi_identification.py`` (a few minutes; ``--quick``
for a smoke run of seconds). Prints tables and writes ``bench/results/drdpi_identification.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numba
import numpy as np
import scipy

from catheter_models.metrics import compute_metrics
from catheter_models.models.base import Recording
from catheter_models.models.data import simulate_recordings
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.evaluate import modelling_score, run_compensator, tracking_score
from catheter_models.models.identify import Budget
from catheter_models.models.idrdpi import IDRDPI
from catheter_models.plant import Plant, PlantConfig
from catheter_models.signals import (
    TEST_PRESSURE_SIGNALS,
    TEST_TRAJECTORIES,
    get_preset,
    training_set,
)
from catheter_models.static_map import StaticMap
from catheter_models.units import rad_to_deg

RESULTS_PATH = Path(__file__).resolve().parent / "results" / "drdpi_identification.json"
THESIS_IDENTIFICATION_S = 3.5 * 3600.0
"""Sec. 5.3.2: the GA took about 3.5 h on an i7 @ 2.8 GHz."""
TEST_NOISE_SEED0 = 100
"""Test recordings get other laser-noise seeds than the training ones."""

IDRDPI_VARIANTS: tuple[tuple[str, str], ...] = (
    ("analytic", "inverse"),
    ("gpi", "inverse"),
    ("direct", "inverse"),
    ("gpi", "drdpi"),
    ("direct", "drdpi"),
)


def _fit_drdpi(recordings: list[Recording], budget: Budget) -> dict[str, Any]:
    model = DRDPI(budget=budget, seed=0).fit(recordings, progress=False)
    ident = model.fit_report_.extra["identification"]
    n = sum(len(r) for r in recordings)
    train_rmse = model.fit_report_.extra["train_rmse_deg"]
    overall = float(np.sqrt(sum(len(r) * train_rmse[r.name] ** 2 for r in recordings) / n))
    return {
        "model": model,
        "budget": budget.to_dict(),
        "wall_s": ident["duration_s"],
        "search_s": ident["search_s"],
        "generations": ident["generations"],
        "evaluations": ident["evaluations"],
        "stopped_by": ident["stopped_by"],
        "loss_deg2": ident["loss"],
        "train_rmse_deg": overall,
        "params": model.params_.to_dict(),
    }


def _test_rmse(model: DRDPI, tests: list[Recording]) -> dict[str, float]:
    return {r.name: float(rad_to_deg(modelling_score(model, r).metrics.rmse)) for r in tests}


class _StaticStream:
    """The static inverse as a stream (no state): the no-compensation baseline."""

    def __init__(self, static: StaticMap) -> None:
        self._static = static

    def reset(self) -> None:
        """Nothing to reset."""

    def step(self, value: float) -> float:
        return float(self._static.pressure(value))


class _ZeroStream:
    """No command at all."""

    def reset(self) -> None:
        """Nothing to reset."""

    def step(self, value: float) -> float:
        del value
        return 0.0


def _baseline_tracking(stream: Any, trajectory: str) -> dict[str, float]:
    rate_hz = float(PlantConfig.thesis_rig().rig["sample_rate_hz"])
    desired = np.asarray(get_preset(trajectory).generate(rate_hz).values_si)
    command = run_compensator(stream, desired, rate_hz=rate_hz)
    measured = np.asarray(Plant(PlantConfig.thesis_rig()).simulate(command).angle_rad)
    m = compute_metrics(measured, desired)
    return {"rmse_deg": float(rad_to_deg(m.rmse)), "mae_deg": float(rad_to_deg(m.mae))}


def _tracking(train: list[Recording], budget: Budget, quick: bool) -> dict[str, Any]:
    static = StaticMap.fit(
        np.concatenate([r.pressure_pa for r in train]),
        np.concatenate([r.angle_rad for r in train]),
    )
    out: dict[str, Any] = {
        "no_command": {t: _baseline_tracking(_ZeroStream(), t) for t in TEST_TRAJECTORIES},
        "static_inverse": {
            t: _baseline_tracking(_StaticStream(static), t) for t in TEST_TRAJECTORIES
        },
    }
    for method, structure in IDRDPI_VARIANTS:
        t0 = time.perf_counter()
        model = IDRDPI(
            method=method,  # type: ignore[arg-type]
            structure=structure,  # type: ignore[arg-type]
            budget=budget,
            gpi_budget=replace(budget, wall_time_s=min(budget.wall_time_s, 20.0)),
            virtual_samples=10_000 if quick else 50_000,
            seed=0,
        ).fit(train, progress=False)
        fit_s = time.perf_counter() - t0
        scores = {}
        for trajectory in TEST_TRAJECTORIES:
            m = tracking_score(model, trajectory).metrics
            scores[trajectory] = {
                "rmse_deg": float(rad_to_deg(m.rmse)),
                "mae_deg": float(rad_to_deg(m.mae)),
            }
        out[f"idrdpi_{method}_{structure}"] = {
            "fit_s": fit_s,
            "params": model.params_.to_dict(),
            **scores,
        }
        print(f"  fitted IDRDPI {method}/{structure} in {fit_s:.1f} s", flush=True)
    return out


def _machine() -> dict[str, str]:
    return {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "numba": numba.__version__,
        "numba_threads": str(numba.get_num_threads()),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": str(os.cpu_count()),
    }


def _print_identification(fast: dict[str, Any], ref: dict[str, Any], samples: int) -> None:
    print(f"\nDRDPI identification on {samples:,} samples (eq. 5.12 = sum of per-recording MSE)")
    cols = f"{'wall [s]':>10}{'gens':>7}{'evals':>9}{'loss [deg2]':>13}{'RMSE [deg]':>12}"
    header = f"{'run':<28}{cols}"
    print(header)
    print("-" * len(header))
    thesis = f"{THESIS_IDENTIFICATION_S:>10,.0f}{'>1000':>7}"
    print(f"{'thesis (MATLAB GA)':<28}{thesis}")
    for name, run in (("fast (default budget)", fast), ("reference (10x gen, 4x pop)", ref)):
        print(
            f"{name:<28}{run['wall_s']:>10.1f}{run['generations']:>7}{run['evaluations']:>9,}"
            f"{run['loss_deg2']:>13.4f}{run['train_rmse_deg']:>12.4f}"
        )


def _print_tests(fast: dict[str, float], ref: dict[str, float]) -> None:
    print("\nRMSE [deg] on the modelling test signals (sec. 5.4.2)")
    print(f"{'signal':<34}{'fast':>9}{'reference':>11}")
    for name, value in fast.items():
        print(f"{name:<34}{value:>9.3f}{ref[name]:>11.3f}")


def _print_tracking(tracking: dict[str, Any]) -> None:
    print("\nOpen-loop tracking on the simulated rig, RMSE / MAE [deg] (sec. 9.3)")
    short = ["descending_sine", "down_chirp", "up_chirp", "arbitrary"]
    print(f"{'compensator':<26}" + "".join(f"{s:>18}" for s in short))
    for name, scores in tracking.items():
        cells = "".join(
            f"{scores[t]['rmse_deg']:>10.3f} / {scores[t]['mae_deg']:<5.2f}"
            for t in TEST_TRAJECTORIES
        )
        print(f"{name:<26}{cells}")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the tables and write the JSON results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smoke run: tiny budgets")
    parser.add_argument("--no-tracking", action="store_true", help="skip the IDRDPI tracking")
    parser.add_argument("--out", type=Path, default=RESULTS_PATH, help="JSON results file")
    args = parser.parse_args(argv)

    train = simulate_recordings(training_set())
    tests = simulate_recordings(TEST_PRESSURE_SIGNALS, seed0=TEST_NOISE_SEED0)
    fast_budget = Budget()
    if args.quick:
        fast_budget = Budget(max_generations=20, popsize=5, wall_time_s=10.0, polish_max_evals=20)
    ref_budget = replace(
        fast_budget,
        max_generations=10 * fast_budget.max_generations,
        popsize=4 * fast_budget.popsize,
        wall_time_s=60.0 if args.quick else 3600.0,
        tol=0.0,
    )
    # Compile (or load from cache) every kernel before anything is timed.
    DRDPI(budget=Budget(max_generations=1, popsize=2, wall_time_s=5.0)).fit(
        train[:1], progress=False
    )

    fast = _fit_drdpi(train, fast_budget)
    print(f"  fast identification: {fast['wall_s']:.1f} s", flush=True)
    ref = _fit_drdpi(train, ref_budget)
    print(f"  reference identification: {ref['wall_s']:.1f} s", flush=True)
    samples = sum(len(r) for r in train)
    _print_identification(fast, ref, samples)
    fast_tests = _test_rmse(fast.pop("model"), tests)
    ref_tests = _test_rmse(ref.pop("model"), tests)
    _print_tests(fast_tests, ref_tests)

    results: dict[str, Any] = {
        "benchmark": "catheter_models.models.drdpi identification",
        "quick": args.quick,
        "training": {
            "signals": [r.name for r in train],
            "samples": samples,
            "rate_hz": train[0].rate_hz,
            "plant": "PlantConfig.thesis_rig(), laser noise seeds 0-7",
        },
        "baseline": {
            "name": "thesis: MATLAB GA, about 3.5 h (sec. 5.3.2)",
            "wall_s": THESIS_IDENTIFICATION_S,
        },
        "fast": {**fast, "test_rmse_deg": fast_tests},
        "reference": {**ref, "test_rmse_deg": ref_tests},
        "fast_over_reference_loss": fast["loss_deg2"] / ref["loss_deg2"],
        "machine": _machine(),
        "unix_time_s": time.time(),
    }
    if not args.no_tracking:
        print("\nIDRDPI methods (tracking)", flush=True)
        tracking = _tracking(train, fast_budget, args.quick)
        _print_tracking(tracking)
        results["tracking"] = tracking
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
