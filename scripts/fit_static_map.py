"""Fit the shipped static-inverse model (compensator ``none``) from a training bag.

    python scripts/fit_static_map.py [--bag bags/training] \
        [--out src/catheter_control/catheter_control/data/static_map]
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

from catheter_models.bag import load_bag
from catheter_models.model_dir import sha256_file
from catheter_models.static_map import StaticMap

DEFAULT_OUT = Path("src/catheter_control/catheter_control/data/static_map")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bag", type=Path, default=Path("bags/training"))
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    series = load_bag(args.bag).aligned()
    static = StaticMap.fit(series.pressure_command_pa, series.angle_rad)
    if args.out.exists():
        shutil.rmtree(args.out)
    mcaps = sorted(args.bag.glob("*.mcap"))
    static.save(
        args.out,
        training_bags={str(p): sha256_file(p) for p in mcaps},
        metrics={"knots": len(static.pressure_pa)},
    )
    print(f"static map with {len(static.pressure_pa)} knots written to {args.out}")


if __name__ == "__main__":
    main()
