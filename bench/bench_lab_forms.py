"""A block's current form beside its earlier one, on foreign plants: held-out RMSE per case.

Where a block gained parameters (``BlockParam.absent``: the value that gives the earlier
form), this fits the block both ways on the same chain and scores both on held-out data, so
that a new form is judged in one run beside the old. Each case is a foreign plant
(``tests/support/foreign_plants``) with one effect hidden: 5 minutes of training and
2 minutes held out. The chain is what the lab's loop reaches first on these plants, the
``free_pi`` core fitted on the training recording; the block is then refitted on it.

Where the block has a rival on the core's other side (the pneumatic lag's ``output_lag``,
creep's ``slow_fill``), the rival is fitted too: a more flexible block must not win where the
effect is the rival's (``--hidden sensor_lag`` and ``--hidden slow_lag`` are the cases to
check).

    NUMBA_NUM_THREADS=1 .venv/bin/python bench/bench_lab_forms.py --effect pneumatic_lag \\
        --hidden pneumatic_lag --seeds 2 3 4 --jobs 2
    NUMBA_NUM_THREADS=1 .venv/bin/python bench/bench_lab_forms.py --effect creep --hidden creep

Writes ``bench/results/lab_forms_<effect>_<hidden>.json`` and prints a table. Seeds below 1000
are the development part; from 1000 on, held out.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_plant import _machine  # noqa: E402
from foreign_plants import PLANTS  # noqa: E402
from foreign_plants.cases import draw_case  # noqa: E402

from catheter_models.models import blocks as lab_blocks  # noqa: E402
from catheter_models.models.drdpi import DRDPI  # noqa: E402
from catheter_models.models.evaluate import pooled_rmse  # noqa: E402
from catheter_models.models.greybox import GreyBox  # noqa: E402


def earlier_form(current: type[lab_blocks.Block]) -> type[lab_blocks.Block]:
    """The block with every parameter that has an ``absent`` value held at it."""
    kept = [i for i, p in enumerate(current.params) if p.absent is None]
    full = [p.absent for p in current.params]

    def widen(values: Sequence[float]) -> list[float]:
        out = [float(v) if v is not None else 0.0 for v in full]
        for i, v in zip(kept, values, strict=True):
            out[i] = float(v)
        return out

    class Earlier(current):  # type: ignore[misc, valid-type]
        params: ClassVar[tuple[lab_blocks.BlockParam, ...]] = tuple(current.params[i] for i in kept)

        def apply(self, x: Any, rate_hz: float, values: Sequence[float]) -> Any:
            return super().apply(x, rate_hz, widen(values))

        def apply_columns(
            self, m: Any, rate_hz: float, values: Sequence[float], reference: Any
        ) -> Any:
            return super().apply_columns(m, rate_hz, widen(values), reference)

        def streamer(self, rate_hz: float, values: Sequence[float]) -> Any:
            return super().streamer(rate_hz, widen(values))

        def unlike_effect(self, values: Sequence[float]) -> list[str]:
            return super().unlike_effect(widen(values))

    return Earlier


def _deg(model: GreyBox, recordings: Sequence[Any]) -> float:
    """Held-out (or training) RMSE in degrees."""
    return float(np.degrees(pooled_rmse(model, recordings)))


def run_case(job: tuple[str, str, str, int]) -> dict[str, Any]:
    """Fit the chain, then the block in both forms (and its rival); score them held out."""
    plant, hidden, effect, seed = job
    case = draw_case(PLANTS[plant], [hidden], seed)
    drdpi = DRDPI().fit([case.train], progress=False)
    core = GreyBox.from_drdpi(drdpi).with_core("free_pi").fit([case.train], progress=False)
    row: dict[str, Any] = {
        "plant": plant,
        "hidden": hidden,
        "strengths": dict(case.effects[0].params),
        "seed": seed,
        "effect": effect,
        "noise_true_deg": float(np.degrees(case.plant.noise_std_rad)),
        "core_test_deg": _deg(core, [case.test]),
    }
    current = lab_blocks.FORMS[effect]
    for name, form in (("current", current), ("earlier", earlier_form(current))):
        lab_blocks.FORMS[effect] = form  # type: ignore[index]  # this process only
        try:
            t0 = time.perf_counter()
            fitted = core.with_effect(effect).fit([case.train], progress=False)
            row[f"{name}_s"] = time.perf_counter() - t0
        finally:
            lab_blocks.FORMS[effect] = current  # type: ignore[index]
        row[f"{name}_test_deg"] = _deg(fitted, [case.test])
        row[f"{name}_train_deg"] = _deg(fitted, [case.train])
        names = [p.name for p in form.params]
        row[f"{name}_values"] = dict(zip(names, fitted.blocks_[effect], strict=True))
    rival = current.rival
    if rival:
        row["rival"] = rival
        rival_fit = core.with_effect(rival).fit([case.train], progress=False)
        row["rival_test_deg"] = _deg(rival_fit, [case.test])
    print(
        f"{plant} {hidden} seed {seed}: core {row['core_test_deg']:.3f}, {effect} earlier "
        f"{row['earlier_test_deg']:.3f}, current {row['current_test_deg']:.3f} deg"
        + (f", {rival} {row['rival_test_deg']:.3f}" if rival else ""),
        flush=True,
    )
    return row


def table(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown: one row per case."""
    rival = next((r["rival"] for r in rows if "rival" in r), "")
    head = "| plant | hidden (strength) | seed | core alone | earlier form | current form |"
    lines = [head + (f" {rival} |" if rival else ""), "|---" * (6 + bool(rival)) + "|"]
    for r in rows:
        strength = ", ".join(f"{k} {v:.3g}" for k, v in r["strengths"].items())
        line = (
            f"| {r['plant']} | {r['hidden']} ({strength}) | {r['seed']} | "
            f"{r['core_test_deg']:.3f}° | {r['earlier_test_deg']:.3f}° | "
            f"{r['current_test_deg']:.3f}° |"
        )
        if rival:
            line += f" {r['rival_test_deg']:.3f}° |"
        lines.append(line)
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--effect", required=True, choices=list(lab_blocks.BLOCKS))
    parser.add_argument("--hidden", default=None, help="the effect hidden (default: --effect)")
    parser.add_argument("--seeds", nargs="+", type=int, default=[2, 3, 4])
    parser.add_argument("--plants", nargs="+", default=sorted(PLANTS))
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    hidden = args.hidden or args.effect
    if all(p.absent is None for p in lab_blocks.BLOCKS[args.effect].params):
        parser.error(f"{args.effect} has no earlier form (no parameter with an 'absent' value)")
    jobs = [(p, hidden, args.effect, s) for s in args.seeds for p in args.plants]
    t0 = time.perf_counter()
    if args.jobs > 1:
        with multiprocessing.get_context("spawn").Pool(args.jobs) as pool:
            rows = pool.map(run_case, jobs)
    else:
        rows = [run_case(j) for j in jobs]
    text = table(rows)
    print(text)
    out = args.out or REPO / "bench" / "results" / f"lab_forms_{args.effect}_{hidden}.json"
    out.write_text(
        json.dumps(
            {
                "rows": rows,
                "table": text,
                "seconds": time.perf_counter() - t0,
                "machine": _machine(),
                "unix_time_s": time.time(),
            },
            indent=1,
        )
    )
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
