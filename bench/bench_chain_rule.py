"""``tune --chain``'s rule, offline: when does the lab's chain shape the feedback loop?

``catheter-lab tune --chain`` (and ``commission``) take the loop's dead time, lag and tip from
the lab's explained chain where that chain predicts the recorded steps at least as well as
the steps' own shape predicts a step left out of its fit
(``catheter_models.feedback.chain_loop.fits_steps``). Until 2026-11-29 the rule was "the
chain's residual on the steps within twice the steps' in-sample residual, plus a point". This
benchmark runs both rules on the same cases, in one run:

* **the plant's own physics as the chain**: the foreign plants of ``tests/support``
  (Maxwell-slip, Bouc-Wen, Duhem laws) with a transport delay, a pneumatic lag or a ringing
  tip hidden, and the chain holding exactly that effect at the value the case drew. A rule
  may prefer either shape here (the hidden effect alone is not the whole loop: the valve and
  the plant's own dynamics are in the steps too); what it must not do is choose gains that
  ring on the other shape's account of the loop. Reported: which shape each rule chose, the
  largest Ms of the chosen gains on either loop, and their integral gain against the gains
  designed on the steps' loop.
* **wrong chains**: a lab that took a lag up partly as a delay (what the live
  ``maxwell_slip_lag`` commissioning of 2026-11-28 held: a delay of 0.57 and a lag of 1.23
  times the plant's lag) and one that took it up wholly as a delay (3x the lag). A rule must
  turn these away; where it does not, the gains run slower than the loop allows (the
  chosen integral gain against the steps').

Seeds below 1000 are the ones the rule was developed on; 1000 and up are held out (nobody
looked at them while choosing the rule) and are reported apart.

    .venv/bin/python bench/bench_chain_rule.py                         # ~10 min on 2 cores
    .venv/bin/python bench/bench_chain_rule.py --seeds 1 1000 --out /tmp/rule.json

Writes ``bench/results/chain_rule.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))

from foreign_plants import PLANTS  # noqa: E402
from foreign_plants.cases import HELD_OUT_SEED0, Case, draw_case  # noqa: E402
from lab_chains import Blocks, chain, lag_block, true_blocks  # noqa: E402

from catheter_models.feedback.chain_loop import (  # noqa: E402
    CHECK_SENSITIVITY_FACTOR,
    design_on_chain,
)
from catheter_models.feedback.law import FeedbackGains  # noqa: E402
from catheter_models.feedback.tune import LoopModel, design, margins, plainly_stable  # noqa: E402

PLANT_NAMES: Final = ("maxwell_slip", "boucwen", "duhem")
EFFECTS: Final = ("transport_delay", "pneumatic_lag", "tip_dynamics")
MAX_SENSITIVITY: Final = 1.6
RING_MS: Final = CHECK_SENSITIVITY_FACTOR * MAX_SENSITIVITY
"""Chosen gains 'ring' on a loop where its Ms exceeds this (gain margin under 2)."""
OLD_RESIDUAL_FACTOR: Final = 2.0
OLD_RESIDUAL_ALLOWANCE: Final = 0.01
"""The rule before 2026-11-29 (git 36a54b3^): chain fit <= 2 x steps' in-sample fit + 1 %."""

TRUE: Final = "true chain"


WRONG: Final[dict[str, Callable[[float], Blocks]]] = {
    "delay+longer lag": lambda lag_s: {
        "transport_delay": [0.57 * lag_s],
        "pneumatic_lag": lag_block(1.23 * lag_s),
    },
    "all delay": lambda lag_s: {"transport_delay": [3.0 * lag_s]},
}


@dataclass(frozen=True)
class Choice:
    """What one rule chose and what its gains do on both loops."""

    shape_from: str
    gains: FeedbackGains

    def record(
        self, chain_loop: LoopModel, steps_loop: LoopModel, steps_ki: float, chain_is_true: bool
    ) -> dict[str, Any]:
        """The choice, its gains' Ms on each loop, and whether they ring where it matters.

        Where the chain is the plant's own physics, both loops are accounts of the plant and
        the gains must hold on each; a wrong chain is no account of it, so only the steps'
        loop (what was measured) counts there.
        """
        ms_steps, ms_chain = (_ms(loop, self.gains) for loop in (steps_loop, chain_loop))
        judged = max(ms_steps, ms_chain) if chain_is_true else ms_steps
        return {
            "shape_from": self.shape_from,
            "ms_on_steps": ms_steps,
            "ms_on_chain": ms_chain,
            "worst_ms": judged,
            "rings": judged > RING_MS,
            "ki_over_steps": self.gains.ki_pa_per_rad_s / steps_ki,
            "crossover_hz_on_steps": margins(steps_loop, self.gains).crossover_hz,
        }


def _ms(loop: LoopModel, gains: FeedbackGains) -> float:
    """Ms of these gains on this loop (inf: not plainly stable)."""
    if not plainly_stable(loop, gains):
        return float("inf")
    return margins(loop, gains).max_sensitivity


def old_rule(chain_loop: LoopModel, steps_loop: LoopModel) -> Choice:
    """The rule before 2026-11-29, with today's stability check after it."""
    fits = chain_loop.fit_nrmse <= (
        OLD_RESIDUAL_FACTOR * steps_loop.fit_nrmse + OLD_RESIDUAL_ALLOWANCE
    )
    if fits:
        gains, _ = design(chain_loop, MAX_SENSITIVITY)
        if plainly_stable(steps_loop, gains) and (
            margins(steps_loop, gains).max_sensitivity <= RING_MS
        ):
            return Choice("chain", gains)
    return Choice("steps", design(steps_loop, MAX_SENSITIVITY)[0])


def run_case(case: Case, kind: str, blocks: Blocks) -> dict[str, Any]:
    """Both rules on one case."""
    tuned = design_on_chain([case.train], chain(blocks), max_sensitivity=MAX_SENSITIVITY)
    steps_gains, _ = design(tuned.steps_loop, MAX_SENSITIVITY)
    steps_ki = steps_gains.ki_pa_per_rad_s
    new = Choice(tuned.shape_from, tuned.gains)
    old = old_rule(tuned.chain_loop, tuned.steps_loop)
    chain_gains, _ = design(tuned.chain_loop, MAX_SENSITIVITY)
    return {
        "plant": case.plant.name,
        "hidden": [e.name for e in case.effects],
        "seed": case.seed,
        "held_out": case.held_out,
        "kind": kind,
        "chain_fit_nrmse": tuned.chain_loop.fit_nrmse,
        "steps_fit_nrmse": tuned.steps_loop.fit_nrmse,
        "steps_held_out_nrmse": tuned.steps_held_out_nrmse,
        "chain_loop": tuned.chain_loop.describe(),
        "steps_loop": tuned.steps_loop.describe(),
        "chain_gains_ki_over_steps": chain_gains.ki_pa_per_rad_s / steps_ki,
        "ours": new.record(tuned.chain_loop, tuned.steps_loop, steps_ki, kind == TRUE),
        "baseline": old.record(tuned.chain_loop, tuned.steps_loop, steps_ki, kind == TRUE),
    }


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts per part (development / held out) and kind, for both rules."""
    out: dict[str, Any] = {}
    for part, held in (("development", False), ("held_out", True)):
        for kind in (TRUE, *WRONG):
            sel = [r for r in rows if r["held_out"] == held and r["kind"] == kind]
            if not sel:
                continue
            key = f"{part}/{kind}"
            out[key] = {"cases": len(sel)}
            for rule in ("ours", "baseline"):
                chosen = [r[rule] for r in sel]
                out[key][rule] = {
                    "chain_chosen": sum(c["shape_from"] == "chain" for c in chosen),
                    "rings": sum(c["rings"] for c in chosen),
                    "worst_ms": max(c["worst_ms"] for c in chosen),
                    "min_ki_over_steps": min(c["ki_over_steps"] for c in chosen),
                }
    return out


def _print_row(i: int, n: int, row: dict[str, Any]) -> None:
    ours, base = row["ours"], row["baseline"]
    print(
        f"[{i:3d}/{n}] {row['plant']:12s} {row['hidden'][0]:15s} seed {row['seed']:4d} "
        f"{row['kind']:16s} chain {row['chain_fit_nrmse']:6.1%} held-out "
        f"{row['steps_held_out_nrmse']:6.1%} in {row['steps_fit_nrmse']:6.1%} | ours "
        f"{ours['shape_from']:5s} Ms {ours['worst_ms']:5.2f} ki x{ours['ki_over_steps']:4.2f} | "
        f"baseline {base['shape_from']:5s} Ms {base['worst_ms']:5.2f} "
        f"ki x{base['ki_over_steps']:4.2f}",
        flush=True,
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 1000, 1001, 1002])
    parser.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    parser.add_argument("--out", type=Path, default=REPO / "bench/results/chain_rule.json")
    args = parser.parse_args()

    jobs: list[tuple[Case, str, Blocks]] = []
    for seed in args.seeds:
        for plant in PLANT_NAMES:
            for effect in EFFECTS:
                case = draw_case(PLANTS[plant], [effect], seed)
                jobs.append((case, TRUE, true_blocks(case)))
                if effect == "pneumatic_lag":
                    lag_s = case.effects[0].params["time_constant_s"]
                    jobs.extend((case, kind, make(lag_s)) for kind, make in WRONG.items())

    started = time.monotonic()
    rows = []
    # Each case is independent and single-threaded: one per core.
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        futures = [pool.submit(run_case, *job) for job in jobs]
        for i, future in enumerate(futures, 1):
            row = future.result()
            rows.append(row)
            _print_row(i, len(jobs), row)
    summary = summarise(rows)
    print(
        f"\npart/kind: cases; ours / baseline: chain chosen, gains that ring (Ms > {RING_MS:.1f}"
        " on either loop for the true chain, on the steps' loop for a wrong one), worst Ms,"
        " least ki against the steps' design"
    )
    for key, s in summary.items():
        o, b = s["ours"], s["baseline"]
        print(
            f"  {key:28s} {s['cases']:2d}: ours {o['chain_chosen']:2d} chain, {o['rings']} ring,"
            f" Ms {o['worst_ms']:.2f}, ki x{o['min_ki_over_steps']:.2f} | baseline "
            f"{b['chain_chosen']:2d} chain, {b['rings']} ring, Ms {b['worst_ms']:.2f}, "
            f"ki x{b['min_ki_over_steps']:.2f}"
        )
    result = {
        "benchmark": "chain_rule",
        "command": "python bench/bench_chain_rule.py " + " ".join(sys.argv[1:]),
        "held_out_seed0": HELD_OUT_SEED0,
        "ring_ms": RING_MS,
        "wall_s": time.monotonic() - started,
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "summary": summary,
        "cases": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1, default=float) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
