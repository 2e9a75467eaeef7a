"""How well can the lab's lag family, given the muscle's pressure itself, follow a foreign fill?

The lab's worst held-out case (docs/lab_validation.md) is the Maxwell-slip catheter with a
pneumatic lag: the loop ends about ten times above its twin with nothing hidden. That plant
fills its muscle through an orifice (choked flow at large pressure ratios, subsonic near equal
pressures) into a volume that grows as the muscle contracts. This benchmark separates the lag
from everything else: it fits the ``pneumatic_lag`` block (``catheter_models.models.blocks``)
directly to the plant's **muscle pressure** (which only a simulator can give), from the valve
command, so what remains is what the family cannot express, whatever the core does.

Forms, in the same run:

* ``earlier``: the lab's family before it grew a flow knee and an upstream share (its five
  parameters: filling's time constant, venting's ratio, the flow limit, venting's limit
  ratio, the pressure exponent);
* ``family``: the lab's family now, the seven (``flow_knee``: the flow bends gradually to its
  limit; ``upstream_share``: the limit grows with the absolute pressure pushing the air, so
  the flow saturates at a pressure ratio across the tube);
* and three generalisations written here before the family grew, as candidates, each
  defined by a signature rather than by the plant's law: ``smooth``, a limit at
  ``L tanh(step / L)``; ``upstream``, a limit growing as a free power of the upstream
  absolute pressure; ``smooth+upstream``, both.

Each form is fitted by bounded least squares from the same grid of starts on the training
recording and scored on the held-out one; errors are in bar and in degrees at the plant's
static sensitivity at mid-range (what a pressure error costs the bend). Development seeds
by default (below 1000); the lab's held-out seeds are not for tuning.

    .venv/bin/python bench/bench_lag_family.py                 # seeds 5 6 7, about 10 min
    .venv/bin/python bench/bench_lag_family.py --seeds 5 --out /tmp/lag.json

Writes ``bench/results/lag_family.json``.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Final

import numpy as np
from numba import njit
from scipy import optimize

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))

from foreign_plants.cases import RATE_HZ, draw_twin_case  # noqa: E402
from foreign_plants.maxwell_slip import MaxwellSlipPlant  # noqa: E402
from provenance import commit  # noqa: E402

from catheter_models.models.blocks import FORMS, block  # noqa: E402
from catheter_models.models.greybox_fit import _Unit  # noqa: E402  (the polish's own box)
from catheter_models.units import pa_to_bar  # noqa: E402

FloatArray = np.ndarray
AMBIENT_BAR: Final = 1.01325
REFERENCE_BAR: Final = 1.5
CANDIDATES: Final = ("smooth", "upstream", "smooth+upstream")
FORM_NAMES: Final = ("earlier", "family", *CANDIDATES)


@njit(cache=True)
def _candidate(  # noqa: PLR0917
    x: FloatArray,
    dt_s: float,
    fill_s: float,
    vent_s: float,
    fill_limit_bar_per_s: float,
    vent_limit_bar_per_s: float,
    upstream_exponent: float,
    smooth: bool,
    pressure_exponent: float,
) -> FloatArray:  # pragma: no cover - compiled
    """A candidate lag over a signal from rest at its first sample [bar]."""
    out = np.empty_like(x)
    p = x[0]
    for k in range(x.size):
        err = x[k] - p
        rising = err >= 0.0
        tau = fill_s if rising else vent_s
        limit = (fill_limit_bar_per_s if rising else vent_limit_bar_per_s) * dt_s
        upstream = (x[k] if rising else p) + AMBIENT_BAR
        limit *= (max(upstream, 1e-3) / (REFERENCE_BAR + AMBIENT_BAR)) ** upstream_exponent
        speed = ((max(p, 0.0) + AMBIENT_BAR) / (REFERENCE_BAR + AMBIENT_BAR)) ** pressure_exponent
        linear = (1.0 - math.exp(-dt_s * speed / tau)) * err
        p += limit * math.tanh(linear / limit) if smooth else min(max(linear, -limit), limit)
        out[k] = p
    return out


def _fit(
    run: Callable[[FloatArray, FloatArray], FloatArray],
    box: _Unit,
    starts: list[FloatArray],
    x: FloatArray,
    p: FloatArray,
) -> FloatArray:
    """The best of a bounded least-squares fit from each start."""
    best: tuple[float, FloatArray] | None = None
    for v0 in starts:
        result = optimize.least_squares(
            lambda u: run(x, box.from_unit(u)) - p,
            box.to_unit(v0),
            bounds=(_Unit.LOW, _Unit.HIGH),
            diff_step=1e-3,
            max_nfev=80,
        )
        if best is None or result.cost < best[0]:
            best = (float(result.cost), box.from_unit(result.x))
    assert best is not None
    return best[1]


def _family(
    earlier: bool,
) -> tuple[Callable[[FloatArray, FloatArray], FloatArray], _Unit, list[FloatArray]]:
    """The lab's ``pneumatic_lag`` block, its bounds, and starts over its grid's corners.

    ``earlier``: the block's form before the flow knee and the upstream share (both held at
    0, their ``absent`` values), the five parameters the lab fitted until 2026-11-29.
    """
    lag = block("pneumatic_lag")
    params = FORMS["pneumatic_lag"].params
    free = params[:5] if earlier else params
    box = _Unit(np.array([q.low for q in free]), np.array([q.high for q in free]))
    starts = [
        np.array([tau, 1.0, rate, 1.0, exponent, *([] if earlier else [0.5, 0.5])])
        for tau, rate, exponent in itertools.product((0.03, 0.1), (3e5, 1e6, 9.9e7), (0.0, 1.0))
    ]
    held = [float(q.absent or 0.0) for q in params[len(free) :]]
    return (lambda x, v: lag.apply(x, RATE_HZ, [*(float(a) for a in v), *held])), box, starts


def _candidate_form(
    name: str,
) -> tuple[Callable[[FloatArray, FloatArray], FloatArray], _Unit, list[FloatArray]]:
    """A candidate: fill and vent time constants and limits, upstream and pressure exponents."""
    smooth, upstream = "smooth" in name, "upstream" in name
    low = np.array([0.002, 0.002, 0.2, 0.2, 0.0, -1.0])
    high = np.array([0.5, 0.5, 1000.0, 1000.0, 2.0 if upstream else 1e-12, 2.0])
    box = _Unit(low, high)
    starts = [
        np.array([tau, tau, rate, rate, 1.0 if upstream else 0.0, exponent])
        for tau, rate, exponent in itertools.product((0.03, 0.1), (3.0, 10.0, 990.0), (0.0, 1.0))
    ]

    def run(x: FloatArray, v: FloatArray) -> FloatArray:
        fill_s, vent_s, fill_limit, vent_limit, upstream_exponent, exponent = (float(a) for a in v)
        kernel: Callable[..., FloatArray] = _candidate  # numba's dispatcher, untyped
        return kernel(
            np.ascontiguousarray(x),
            1.0 / RATE_HZ,
            fill_s,
            vent_s,
            fill_limit,
            vent_limit,
            upstream_exponent,
            smooth,
            exponent,
        )

    return run, box, starts


def run_seed(seed: int) -> dict[str, Any]:
    """Every form on one development case of the Maxwell-slip catheter's lag."""
    case = draw_twin_case(MaxwellSlipPlant, ["pneumatic_lag"], seed)
    plant = case.plant
    assert isinstance(plant, MaxwellSlipPlant)
    deg_per_bar = math.degrees((plant.static_bend_rad(1.6e5) - plant.static_bend_rad(1.4e5)) / 0.2)
    data = {}
    for part, rec in (("train", case.train), ("test", case.test)):
        _, muscle_pa = plant.simulate_clean(rec.pressure_pa, RATE_HZ, case.effects)
        data[part] = (pa_to_bar(rec.pressure_pa), pa_to_bar(muscle_pa))
    row: dict[str, Any] = {
        "seed": seed,
        "variant": plant.variant,
        "time_constant_s": dict(case.effects[0].params)["time_constant_s"],
        "deg_per_bar": deg_per_bar,
        "forms": {},
    }
    for name in FORM_NAMES:
        t0 = time.perf_counter()
        if name in ("earlier", "family"):
            run, box, starts = _family(earlier=name == "earlier")
        else:
            run, box, starts = _candidate_form(name)
        values = _fit(run, box, starts, *data["train"])
        errors = {
            part: float(np.sqrt(np.mean((run(x, values) - p) ** 2)))
            for part, (x, p) in data.items()
        }
        row["forms"][name] = {
            "train_bar": errors["train"],
            "test_bar": errors["test"],
            "test_deg_equivalent": errors["test"] * deg_per_bar,
            "values": [float(v) for v in values],
            "seconds": time.perf_counter() - t0,
        }
        print(
            f"seed {seed} {name:16s} train {errors['train']:.4f} bar, held out "
            f"{errors['test']:.4f} bar ({errors['test'] * deg_per_bar:.3f} deg)",
            flush=True,
        )
    return row


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[5, 6, 7])
    parser.add_argument("--out", type=Path, default=REPO / "bench/results/lag_family.json")
    args = parser.parse_args(argv)
    source = commit()  # the code the rows come from, whatever is committed meanwhile
    rows = [run_seed(s) for s in args.seeds]
    summary = {
        name: float(np.median([r["forms"][name]["test_bar"] for r in rows])) for name in FORM_NAMES
    }
    print("median held-out RMS of the muscle pressure [bar]:")
    for name, value in summary.items():
        print(f"  {name:16s} {value:.4f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "command": " ".join(["bench/bench_lag_family.py", *(argv or sys.argv[1:])]),
                "commit": source,
                "plant": "maxwell_slip",
                "rows": rows,
                "median_test_bar": summary,
            },
            indent=2,
        )
        + "\n"
    )
    print(f"results: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
