"""An output block on the core's columns: the compiled row-by-row pass against ``lfilter``.

A linear core's fit applies every output block to every column of its design matrix
(samples x columns, row-major), for every trial of the block's parameters: on a
``free_pi -> creep`` chain that filtering was most of a diagnosis step. The baseline is the
form the blocks had before, ``scipy.signal.lfilter`` along the first axis; ours is
``Creep.apply_columns`` / ``OutputLag.apply_columns`` (one numba pass, columns innermost).
Both run on the same matrices in one run, and their outputs are checked equal.

    NUMBA_NUM_THREADS=1 .venv/bin/python bench/bench_lab_columns.py

Shapes are a 5-minute 250 Hz session (75,000 samples) with the grey box's 32 reduced
columns plus the offset, and the full design of 65 columns. Writes
``bench/results/lab_columns.json``.
"""

from __future__ import annotations

import json
import math
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from scipy import signal as sps

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_plant import _machine

from catheter_models.models.blocks import block

RATE_HZ = 250.0
REPEATS = 20
CASES: dict[str, list[float]] = {
    "creep": [0.15, 1.5, 4.0],  # fraction, time constant [s], spread
    "output_lag": [0.06],  # time constant [s]
}


def _lfilter_form(effect: str, m: np.ndarray, values: list[float]) -> np.ndarray:
    """The blocks' column form before this change (the baseline)."""
    if effect == "creep":
        fraction, tau, spread = values
        root = math.sqrt(spread)
        creeping = np.zeros_like(m)
        for t in (tau / root, tau * root):
            a = math.exp(-1.0 / (RATE_HZ * t))
            lag, _ = sps.lfilter([1.0 - a], [1.0, -a], m, axis=0, zi=a * m[:1, :])
            creeping += 0.5 * lag
        out: np.ndarray = (1.0 - fraction) * m + fraction * creeping
        return out
    a = math.exp(-1.0 / (RATE_HZ * values[0]))
    lag, _ = sps.lfilter([1.0 - a], [1.0, -a], m, axis=0, zi=a * m[:1, :])
    return np.asarray(lag)


def _best_of(fn: Callable[[], np.ndarray]) -> float:
    fn()  # compile / warm the caches
    times = []
    for _ in range(REPEATS):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> int:
    rng = np.random.default_rng(0)
    rows: list[dict[str, Any]] = []
    for columns in (33, 65):
        m = np.cumsum(rng.normal(0.0, 0.1, (75_000, columns)), axis=0)
        ref = m[:, :-1].mean(axis=1)
        for effect, values in CASES.items():
            b = block(effect)
            ours = b.apply_columns(m, RATE_HZ, values, ref)
            base = _lfilter_form(effect, m, values)
            diff = float(np.max(np.abs(ours - base)))
            t_base = _best_of(partial(_lfilter_form, effect, m, values))
            t_ours = _best_of(partial(b.apply_columns, m, RATE_HZ, values, ref))
            row = {
                "effect": effect,
                "shape": [int(s) for s in m.shape],
                "lfilter_ms": 1e3 * t_base,
                "numba_ms": 1e3 * t_ours,
                "speed_up": t_base / t_ours,
                "max_abs_difference": diff,
            }
            rows.append(row)
            print(
                f"{effect:<11} {m.shape[0]} x {m.shape[1]:<3} lfilter (baseline) "
                f"{row['lfilter_ms']:7.2f} ms   numba {row['numba_ms']:6.2f} ms   "
                f"x{row['speed_up']:.1f}   max |diff| {diff:.1e}"
            )
            if diff > 1e-9:
                raise SystemExit(f"{effect}: the two forms differ by {diff:g}")
    out = Path(__file__).resolve().parent / "results" / "lab_columns.json"
    out.write_text(
        json.dumps(
            {"rows": rows, "repeats": REPEATS, "timing": "best of repeats", **_machine()},
            indent=1,
        )
        + "\n"
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
