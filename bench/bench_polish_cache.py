"""What keeping the core's output during a joint polish saves, beside the polish without it.

``explain`` refits the chain with each candidate block, warm from the chain it has; each
refit ends in a joint least-squares polish of the core and the blocks by finite differences,
one coordinate at a time. Where the coordinate moved is an output block's, or a Bouc-Wen
core's output weight, the core's output (nearly all of a residual's cost) is the one of the
point being differenced: the polish now keeps it (``Core.polish_runners``,
``greybox_fit._NonlinearFitter.polish``) instead of running the core again.

This runs the same warm refits both ways in one process, on a foreign plant of
``tests/support`` (development seed 5 by default: no held-out seed is needed, the chain must
come out equal to the last bit) and reports processor seconds (``time.process_time``: the
figure a busy machine disturbs least) and whether the chains are equal.

    .venv/bin/python bench/bench_polish_cache.py                        # ~4 min
    .venv/bin/python bench/bench_polish_cache.py --cores boucwen --plant duhem

Writes ``bench/results/polish_cache.json``.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))

from foreign_plants import PLANTS  # noqa: E402
from foreign_plants.cases import draw_case  # noqa: E402

from catheter_models.models.cores import base as core_base  # noqa: E402
from catheter_models.models.greybox import GreyBox  # noqa: E402

EFFECTS = ("tip_dynamics", "creep", "drift", "transport_delay", "pneumatic_lag")


@contextmanager
def nothing_kept() -> Iterator[None]:
    """The baseline: the polish as it was before it kept the core's output (no budget)."""
    budget = core_base.POLISH_CACHE_BYTES
    core_base.POLISH_CACHE_BYTES = 0  # type: ignore[misc]
    try:
        yield
    finally:
        core_base.POLISH_CACHE_BYTES = budget  # type: ignore[misc]


def refit(base: GreyBox, effect: str, train: list[Any]) -> tuple[float, dict[str, Any]]:
    """Processor seconds of one warm refit with ``effect``, and the chain it gives."""
    model = base.with_effect(effect)
    start = time.process_time()
    model.fit(train, progress=False)
    seconds = time.process_time() - start
    return seconds, {"blocks": model.block_values(), "core": model.core_.values()}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--plant", default="maxwell_slip", choices=sorted(PLANTS))
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--cores", nargs="+", default=["boucwen", "drdpi"])
    parser.add_argument("--effects", nargs="+", default=list(EFFECTS), choices=EFFECTS)
    parser.add_argument("--out", type=Path, default=REPO / "bench/results/polish_cache.json")
    args = parser.parse_args()

    rows = []
    for core in args.cores:
        for effect in args.effects:
            # Each effect's own case, so that the block has the excitation it needs.
            case = draw_case(PLANTS[args.plant], [effect], args.seed)
            base = GreyBox(effects=[], core=core).fit([case.train], progress=False)
            ours_s, ours = refit(base, effect, [case.train])
            with nothing_kept():
                before_s, before = refit(base, effect, [case.train])
            row = {
                "core": core,
                "effect": effect,
                "ours_cpu_s": ours_s,
                "baseline_cpu_s": before_s,
                "saved_share": 1.0 - ours_s / before_s,
                "same_chain": ours == before,
            }
            rows.append(row)
            print(
                f"{core:8s} + {effect:16s} kept {ours_s:6.2f} s, not kept {before_s:6.2f} s "
                f"({100 * row['saved_share']:+5.1f} % saved), same chain: {row['same_chain']}",
                flush=True,
            )
    result = {
        "benchmark": "polish_cache",
        "command": "python bench/bench_polish_cache.py " + " ".join(sys.argv[1:]),
        "plant": args.plant,
        "seed": args.seed,
        "machine": {"platform": platform.platform(), "python": platform.python_version()},
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0 if all(r["same_chain"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
