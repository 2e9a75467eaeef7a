"""Benchmark of the simulated rig: batch speed and streaming step latency.

The reference is the rig itself: it produces one sample every 4 ms (250 Hz, thesis ch. 3),
so "x real time" is simulated time per wall-clock time. The simulated hardware node needs
the streaming step far inside one period; offline data generation wants the batch path as
fast as possible. There is deliberately no pure-Python copy of the kernel to compare
against: hot loops are written once, so batch and streaming cannot disagree
(docs/simulated_rig.md).

Run with ``make bench`` (``.venv/bin/python bench/bench_plant.py``). Prints a table and
writes ``bench/results/plant.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numba
import numpy as np
import numpy.typing as npt

from catheter_models.plant import EFFECTS, Plant, PlantConfig
from catheter_models.signals import training_set

FloatArray = npt.NDArray[np.float64]

RESULTS_PATH = Path(__file__).resolve().parent / "results" / "plant.json"
BATCH_DURATION_S = 300.0
"""A 5-minute session, the length of a long recording on the rig."""


@dataclass(frozen=True)
class BatchResult:
    """Best-of-N wall time of one ``Plant.simulate`` over the whole signal."""

    config: str
    samples: int
    substeps_per_sample: int
    wall_s_best: float
    wall_s_median: float
    samples_per_s: float
    x_real_time: float


@dataclass(frozen=True)
class StreamResult:
    """Per-call time of ``Plant.step`` (kernel + sensor model + sample object)."""

    config: str
    calls: int
    p50_us: float
    p99_us: float
    max_us: float
    mean_us: float
    x_real_time: float
    budget_used_p99: float
    """p99 call time as a share of one sample period at the rig's rate [1]."""


def _configs() -> dict[str, PlantConfig]:
    every = PlantConfig.thesis_rig()
    for name in EFFECTS:
        every = every.with_effect(name)
    return {"thesis_rig (default)": PlantConfig.thesis_rig(), "all effects on": every}


def _session_command_pa(rate_hz: float, duration_s: float) -> FloatArray:
    """The thesis's 8 training signals (eqs. 4.1/4.2) back to back, tiled to the duration."""
    one_pass = np.concatenate([spec.generate(rate_hz).values_si for spec in training_set()])
    n = round(duration_s * rate_hz)
    out: FloatArray = np.resize(one_pass, n)
    return out


def bench_batch(
    name: str, config: PlantConfig, command_pa: FloatArray, repeats: int
) -> BatchResult:
    """Time ``simulate`` on a fresh plant; the first (compile/cache-load) run is not counted.

    Args:
        name: Label for the table.
        config: Plant configuration.
        command_pa: Command signal, gauge [Pa].
        repeats: Timed runs after the warm-up; the best one is reported.

    Returns:
        Timing of the batch path.
    """
    Plant(config).simulate(command_pa[:1000])  # warm-up: numba compile or cache load
    walls = []
    for _ in range(repeats):
        plant = Plant(config)
        t0 = time.perf_counter()
        plant.simulate(command_pa)
        walls.append(time.perf_counter() - t0)
    best = min(walls)
    period_s = 1.0 / config.rig["sample_rate_hz"]
    return BatchResult(
        config=name,
        samples=command_pa.size,
        substeps_per_sample=plant.substeps_per_sample,
        wall_s_best=best,
        wall_s_median=float(np.median(walls)),
        samples_per_s=command_pa.size / best,
        x_real_time=command_pa.size * period_s / best,
    )


def bench_stream(name: str, config: PlantConfig, command_pa: FloatArray) -> StreamResult:
    """Time every ``step`` call over ``command_pa``, after a warm-up of 500 untimed calls.

    Args:
        name: Label for the table.
        config: Plant configuration.
        command_pa: Command per call, gauge [Pa].

    Returns:
        Distribution of the per-call time.
    """
    plant = Plant(config)
    for c in command_pa[:500]:
        plant.step(float(c))
    calls = [float(c) for c in command_pa]
    times_ns = np.empty(len(calls))
    clock = time.perf_counter_ns
    for i, c in enumerate(calls):
        t0 = clock()
        plant.step(c)
        times_ns[i] = clock() - t0
    us = times_ns / 1e3
    period_us = 1e6 / config.rig["sample_rate_hz"]
    p99 = float(np.percentile(us, 99))
    return StreamResult(
        config=name,
        calls=len(calls),
        p50_us=float(np.percentile(us, 50)),
        p99_us=p99,
        max_us=float(us.max()),
        mean_us=float(us.mean()),
        x_real_time=period_us / float(us.mean()),
        budget_used_p99=p99 / period_us,
    )


def _machine() -> dict[str, str]:
    return {
        "python": sys.version.split()[0],
        "numpy": np.__version__,
        "numba": numba.__version__,
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": str(os.cpu_count()),
    }


def _print_table(rate_hz: float, batch: list[BatchResult], stream: list[StreamResult]) -> None:
    period_us = 1e6 / rate_hz
    print(f"\nSimulated rig vs the real rig ({rate_hz:g} Hz, one sample per {period_us:g} us)")
    header = f"{'path':<9}{'config':<22}{'speed':>24}{'x real time':>13}  {'detail'}"
    print(header)
    print("-" * (len(header) + 36))
    rows = [
        ("baseline", "the rig itself", f"{rate_hz:,.0f} samples/s", "1", "one sample per period")
    ]
    for b in batch:
        rows.append(
            (
                "batch",
                b.config,
                f"{b.samples_per_s:,.0f} samples/s",
                f"{b.x_real_time:,.0f}",
                f"best {b.wall_s_best * 1e3:.1f} ms for {b.samples:,} samples, "
                f"{1e6 / b.samples_per_s:.2f} us each ({b.substeps_per_sample} substeps)",
            )
        )
    for s in stream:
        rows.append(
            (
                "step",
                s.config,
                f"p50 {s.p50_us:.1f} us/call",
                f"{s.x_real_time:,.0f}",
                f"p99 {s.p99_us:.1f} us = {100 * s.budget_used_p99:.2f} % of a period",
            )
        )
    for path, config, speed, x_rt, detail in rows:
        print(f"{path:<9}{config:<22}{speed:>24}{x_rt:>13}  {detail}")


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table and write the JSON results."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=20, help="timed batch runs (best kept)")
    parser.add_argument(
        "--stream-calls", type=int, default=75_000, help="timed step() calls (75,000 = 5 min)"
    )
    parser.add_argument("--out", type=Path, default=RESULTS_PATH, help="JSON results file")
    args = parser.parse_args(argv)

    configs = _configs()
    rate_hz = next(iter(configs.values())).rig["sample_rate_hz"]
    command_pa = _session_command_pa(rate_hz, BATCH_DURATION_S)
    batch = [bench_batch(n, c, command_pa, args.repeats) for n, c in configs.items()]
    stream_cmd = np.resize(command_pa, args.stream_calls)
    stream = [bench_stream(n, c, stream_cmd) for n, c in configs.items()]
    _print_table(rate_hz, batch, stream)

    results = {
        "benchmark": "catheter_models.plant",
        "signal": (
            f"thesis training signals (eqs. 4.1/4.2, 0.2-0.8 Hz) back to back, "
            f"{BATCH_DURATION_S:g} s at {rate_hz:g} Hz"
        ),
        "baseline": {
            "name": "the thesis rig in real time",
            "rate_hz": rate_hz,
            "samples_per_s": rate_hz,
            "x_real_time": 1.0,
            "period_us": 1e6 / rate_hz,
        },
        "batch": [asdict(b) for b in batch],
        "stream": [asdict(s) for s in stream],
        "machine": _machine(),
        "unix_time_s": time.time(),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
