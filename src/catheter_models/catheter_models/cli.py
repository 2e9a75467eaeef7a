"""``catheter-lab``: the lab's command line.

    catheter-lab bag info BAG              what a bag holds (topics, rates, metadata)
    catheter-lab bag repair BAG [-o OUT]   recover a bag whose recorder was killed
    catheter-lab simulate SIGNAL -o BAG    offline data: a thesis signal through the
                                           simulated rig, written as a contract bag
    catheter-lab effects                   the physical effects the plant and lab know

The training, comparison and diagnosis commands join with the models and lab issues.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from catheter_models.errors import CatheterError


def _cmd_bag_info(args: argparse.Namespace) -> int:
    from catheter_models.bag import bag_info

    print(bag_info(args.bag))
    return 0


def _cmd_bag_repair(args: argparse.Namespace) -> int:
    from catheter_models.bag import repair_bag

    report = repair_bag(args.bag, args.output)
    print(report.describe())
    return 0


def _parse_effects(items: list[str]) -> dict[str, dict[str, float]]:
    """``pneumatic_lag`` or ``pneumatic_lag.time_constant_s=0.1`` -> {effect: {param: value}}."""
    out: dict[str, dict[str, float]] = {}
    for item in items:
        name, _, assignment = item.partition(".")
        params = out.setdefault(name, {})
        if assignment:
            key, eq, value = assignment.partition("=")
            if not eq:
                raise CatheterError(f"--effect {item!r}: expected EFFECT or EFFECT.PARAM=VALUE")
            params[key] = float(value)
    return out


def _cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from catheter_models.bag import write_bag_from_arrays
    from catheter_models.plant import Plant, PlantConfig
    from catheter_models.signals import get_preset

    spec = get_preset(args.signal)
    if spec.kind != "pressure":
        raise CatheterError(f"{args.signal!r} is an angle trajectory; simulate drives pressure")
    config = PlantConfig.thesis_rig(seed=args.seed)
    for name, params in _parse_effects(args.effect).items():
        config = config.with_effect(name, enabled=True, **params)
    for name in args.no_effect:
        config = config.with_effect(name, enabled=False)
    signal = spec.generate(config.rig["sample_rate_hz"])
    out = Plant(config).simulate(signal.values_si)
    custom = {"signal": spec.name, "signal_params": repr(dict(spec.params())), "source": "simulate"}
    custom |= {f"plant.{k}": v for k, v in config.describe().items()}
    write_bag_from_arrays(
        args.output,
        np.asarray(out.t_s),
        out.pressure_command_pa,
        out.pressure_measured_pa,
        out.angle_rad,
        distance_m=out.distance_m,
        custom_data=custom,
        compression="zstd",
    )
    print(f"{spec.name}: {signal.duration_s:.1f} s simulated, bag written to {args.output}")
    return 0


def _cmd_effects(_args: argparse.Namespace) -> int:
    from catheter_models.plant.config import EFFECTS

    for name, spec in EFFECTS.items():
        state = "on" if spec.enabled_in_thesis_rig else "off"
        print(f"{name}  (thesis rig: {state})\n    {spec.physics}")
        for p in spec.params:
            print(f"    {p.name} = {p.default:g}  in [{p.low:g}, {p.high:g}]  {p.doc}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (separate so docs and tests can inspect it)."""
    parser = argparse.ArgumentParser(prog="catheter-lab", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    bag = sub.add_parser("bag", help="inspect or repair bags")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True)
    info = bag_sub.add_parser("info", help="what a bag holds")
    info.add_argument("bag", type=Path)
    info.set_defaults(func=_cmd_bag_info)
    repair = bag_sub.add_parser("repair", help="recover a bag whose recorder was killed")
    repair.add_argument("bag", type=Path)
    repair.add_argument("-o", "--output", type=Path, default=None, help="new bag directory")
    repair.set_defaults(func=_cmd_bag_repair)

    sim = sub.add_parser("simulate", help="a thesis pressure signal through the simulated rig")
    sim.add_argument("signal", help="pressure preset, e.g. train_zero_f0.2")
    sim.add_argument("-o", "--output", type=Path, required=True, help="new bag directory")
    sim.add_argument("--seed", type=int, default=0)
    sim.add_argument(
        "--effect",
        action="append",
        default=[],
        metavar="NAME[.PARAM=VALUE]",
        help="switch an effect on (and size it); repeatable",
    )
    sim.add_argument(
        "--no-effect",
        action="append",
        default=[],
        metavar="NAME",
        help="switch an effect off; repeatable",
    )
    sim.set_defaults(func=_cmd_simulate)

    effects = sub.add_parser("effects", help="list the physical effects and their parameters")
    effects.set_defaults(func=_cmd_effects)
    return parser


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``catheter-lab``; errors print one line and exit 2."""
    args = build_parser().parse_args(argv)
    try:
        code = args.func(args)
    except CatheterError as exc:
        print(f"catheter-lab: {exc}", file=sys.stderr)
        code = 2
    sys.exit(code)
