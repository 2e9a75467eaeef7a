"""The ``catheter-lab`` verbs that make things from data: bags, models, gains.

``bag info`` and ``bag repair`` read and recover bags; ``simulate`` writes the simulated rig's
bags; ``train`` fits a model from bags; ``tune`` (and ``--reseal``) makes feedback gains from
recorded steps; ``models`` lists the model kinds and their settings.

Apart from ``cli`` (which parses and dispatches) and ``cli_lab`` (the lab's verbs on a fitted
model) so each module has one job; ``cli`` imports these, never the other way round.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from catheter_models.errors import CatheterError

if TYPE_CHECKING:
    from catheter_models.plant import PlantConfig


EXIT_BAG_PROBLEM = 3
"""``bag info``: the bag is truncated, damaged, lost messages, its metadata.yaml disagrees or its
data is implausible (listed first). ``bag repair``: a new bag was written, but messages were
lost (counted, with when). A refusal (not a bag, nothing to recover) exits 2."""


def _bag_verb(args: argparse.Namespace, run: Any) -> int:
    """Run a bag verb; whatever a decoder raises becomes one line naming the bag, exit 2."""
    try:
        return int(run())
    except (CatheterError, OSError):
        raise
    except Exception as exc:
        # zstd, lz4, mcap and rosbags raise their own types for damaged bytes; a person gets
        # the bag and the reason, never a traceback.
        raise CatheterError(f"bag {args.bag} cannot be read: {type(exc).__name__}: {exc}") from None


def _cmd_bag_info(args: argparse.Namespace) -> int:
    from catheter_models.bag.info import inspect_bag

    def run() -> int:
        inspection = inspect_bag(args.bag)
        print(inspection.text)
        return EXIT_BAG_PROBLEM if inspection.problem else 0

    return _bag_verb(args, run)


def _cmd_bag_repair(args: argparse.Namespace) -> int:
    from catheter_models.bag import repair_bag

    def run() -> int:
        report = repair_bag(args.bag, args.output)
        print(report.describe())
        return EXIT_BAG_PROBLEM if report.lost_messages else 0

    return _bag_verb(args, run)


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


# Named groups of presets: the thesis's training sets and test signals.
SIGNAL_SETS = {
    "@training": "training_set",
    "@clstm_training": "clstm_training_set",
    "@model_tests": "TEST_PRESSURE_SIGNALS",
    "@lab_training": "lab_training_specs",
    "@lab_test": "lab_test_specs",
}


def _expand_signals(names: list[str]) -> list[str]:
    from catheter_models import signals
    from catheter_models.lab import signals as lab_signals

    out: list[str] = []
    for name in names:
        if name in SIGNAL_SETS:
            module = lab_signals if name.startswith("@lab") else signals
            group = getattr(module, SIGNAL_SETS[name])
            specs = group() if callable(group) else group
            out.extend(s if isinstance(s, str) else s.name for s in specs)
        else:
            out.append(name)
    return out


def _cmd_simulate(args: argparse.Namespace) -> int:
    from catheter_models.plant import PlantConfig

    names = _expand_signals(args.signal)
    config = PlantConfig.thesis_rig(seed=args.seed)
    for name, params in _parse_effects(args.effect).items():
        config = config.with_effect(name, enabled=True, **params)
    for name in args.no_effect:
        config = config.with_effect(name, enabled=False)
    if len(names) == 1:
        _simulate_one(names[0], config, args.output)
        return 0
    # Several signals: one bag each under the output directory, each run with its own noise.
    args.output.mkdir(parents=True, exist_ok=True)
    for i, name in enumerate(names):
        _simulate_one(name, replace(config, seed=args.seed + i), args.output / name)
    return 0


def _simulate_one(signal_name: str, config: PlantConfig, output: Path) -> None:
    import numpy as np

    from catheter_models.bag import write_bag_from_arrays
    from catheter_models.lab.signals import lab_spec
    from catheter_models.plant import Plant
    from catheter_models.signals import get_preset

    spec = lab_spec(signal_name) or get_preset(signal_name)
    if spec.kind != "pressure":
        raise CatheterError(f"{signal_name!r} is an angle trajectory; simulate drives pressure")
    signal = spec.generate(config.rig["sample_rate_hz"])
    out = Plant(config).simulate(signal.values_si)
    custom = {"signal": spec.name, "signal_params": repr(dict(spec.params())), "source": "simulate"}
    custom |= {f"plant.{k}": v for k, v in config.describe().items()}
    write_bag_from_arrays(
        output,
        np.asarray(out.t_s),
        out.pressure_command_pa,
        out.pressure_measured_pa,
        out.angle_rad,
        distance_m=out.distance_m,
        custom_data=custom,
        compression="zstd",
    )
    print(f"{spec.name}: {signal.duration_s:.1f} s simulated, bag written to {output}")


def _parse_settings(items: list[str]) -> dict[str, Any]:
    """``n_play=12`` ``form="windowed"`` -> {name: value}; values parse as JSON, else text."""
    out: dict[str, Any] = {}
    for item in items:
        key, eq, text = item.partition("=")
        if not eq or not key:
            raise CatheterError(f"--set {item!r}: expected NAME=VALUE")
        try:
            out[key] = json.loads(text)
        except json.JSONDecodeError:
            out[key] = text
    return out


def _cmd_train(args: argparse.Namespace) -> int:
    from catheter_models.models import model_class
    from catheter_models.models.data import recordings_from_bags
    from catheter_models.models.evaluate import modelling_score

    cls = model_class(args.kind)
    if args.output.exists() and any(args.output.iterdir()):
        raise CatheterError(f"{args.output} exists and is not empty; choose a new directory")
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        train = recordings_from_bags(
            args.train, rate_hz=args.rate_hz, accept_implausible=args.accept_implausible
        )
        validation = recordings_from_bags(
            args.validate, rate_hz=args.rate_hz, accept_implausible=args.accept_implausible
        )
    findings = _said_and_kept(seen)
    try:
        model = cls(**_parse_settings(args.set))
    except TypeError as exc:
        raise CatheterError(f"{args.kind}: {exc}; see `catheter-lab models`") from None
    n = sum(len(r) for r in train)
    print(f"{args.kind}: training on {len(train)} bag(s), {n} samples at {args.rate_hz:g} Hz")
    start = time.perf_counter()
    model.fit(train, validation, progress=not args.quiet)
    took_s = time.perf_counter() - start
    unit = "deg" if cls.direction == "forward" else "bar"
    metrics: dict[str, Any] = {"train_time_s": took_s}
    if findings:
        # What the plausibility check said about the bags this model learned from, accepted
        # refusals included, so the model's manifest carries it.
        metrics["bag_plausibility"] = findings
    for rec in validation:
        score = modelling_score(model, rec).metrics
        metrics[f"validation.{rec.name}"] = {
            "rmse": score.rmse,
            "mae": score.mae,
            "nrmse": score.nrmse,
        }
        print(f"  validation {rec.name}: {score.format(unit)}")
    model.save(args.output, training=train, metrics=metrics)
    print(f"{args.kind}: trained in {took_s:.1f} s, model written to {args.output}")
    return 0


def _said_and_kept(seen: list[warnings.WarningMessage]) -> dict[str, list[dict[str, Any]]]:
    """Say each caught warning again; keep the plausibility findings by bag name."""
    from catheter_models.bag.plausible import PlausibilityWarning

    kept: dict[str, list[dict[str, Any]]] = {}
    for w in seen:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if isinstance(w.message, PlausibilityWarning):
            entry = {**w.message.finding.to_dict(), "accepted": w.message.accepted}
            kept.setdefault(Path(str(w.message.bag)).name, []).append(entry)
    return kept


def _cmd_tune(args: argparse.Namespace) -> int:
    from catheter_models.feedback.report import write_tune_report
    from catheter_models.feedback.tune import design, identify, opening_pressure_pa
    from catheter_models.models.data import recordings_from_bags

    if args.reseal is not None:
        return _reseal(args)
    if not args.bags or args.output is None:
        from catheter_models.errors import ParameterError

        raise ParameterError("give BAG... and -o OUTPUT (or --reseal FILE --reason TEXT)")
    recordings = recordings_from_bags(
        args.bags, rate_hz=args.rate_hz, accept_implausible=args.accept_implausible
    )
    if args.chain is not None:
        model, gains, found, decided = _tune_on_chain(args, recordings)
    else:
        model = identify(recordings)
        print(f"loop model: {model.describe()}")
        gains, found = design(
            model,
            max_sensitivity=args.max_sensitivity,
            opening_pressure_pa=opening_pressure_pa(recordings),
        )
        decided = {}
    gains = replace(
        gains, tuning={**gains.tuning, **decided, "recordings": [r.name for r in recordings]}
    )
    notch = (
        f", notch at {gains.notch_frequency_hz:.2f} Hz" if gains.notch_frequency_hz > 0.0 else ""
    )
    print(
        f"PI: kp {gains.kp_pa_per_rad:.4g} Pa/rad, ki {gains.ki_pa_per_rad_s:.4g} Pa/(rad s)"
        f"{notch}; opening pressure {gains.opening_pressure_pa / 1e5:.2f} bar"
    )
    print(f"margins on the model: {found.describe()}")
    args.output.mkdir(parents=True, exist_ok=True)
    print(f"gains written to {gains.save(args.output)}")
    if args.report is not None:
        print(f"report: {write_tune_report(recordings, model, gains, found, args.report)}")
    return 0


def _tune_on_chain(args: argparse.Namespace, recordings: list[Any]) -> tuple[Any, ...]:
    """``tune --chain``: the loop's shape from the explained model, checked on the steps."""
    from catheter_models.errors import ParameterError
    from catheter_models.feedback.chain_loop import design_on_chain
    from catheter_models.feedback.tune import opening_pressure_pa
    from catheter_models.models import load_model
    from catheter_models.models.greybox import GreyBox

    chain = GreyBox.chain_of(load_model(args.chain))
    if chain is None:
        raise ParameterError(
            f"{args.chain} holds a black-box model: no chain to read the loop from "
            "(give the grey box catheter-lab explain or add wrote, or leave --chain out)"
        )
    tuned = design_on_chain(
        recordings,
        chain,
        max_sensitivity=args.max_sensitivity,
        opening_pressure_pa=opening_pressure_pa(recordings),
    )
    print(f"loop from the chain: {tuned.chain_loop.describe()}")
    print(f"loop from the steps: {tuned.steps_loop.describe()}")
    for said in tuned.disagreements:
        print(f"  disagreement: {said}")
    if not tuned.disagreements:
        print("  the chain and the recorded steps agree")
    whose = "the recorded steps'" if tuned.shape_from == "steps" else "the chain's"
    print(f"designed on {whose} loop")
    return tuned.model, tuned.gains, tuned.margins, {**tuned.record(), "chain": str(args.chain)}


def _reseal(args: argparse.Namespace) -> int:
    """``tune --reseal FILE``: keep a deliberate edit of a gains file, after checking it."""
    from catheter_models.errors import ParameterError
    from catheter_models.feedback.reseal import reseal

    if args.bags or args.output is not None:
        raise ParameterError("--reseal takes a gains file alone (no BAG, no -o)")
    path, gains, found = reseal(args.reseal, args.reason or "")
    print(
        f"kp {gains.kp_pa_per_rad:.4g} Pa/rad, ki {gains.ki_pa_per_rad_s:.4g} Pa/(rad s); on the "
        f"recorded loop: {found.describe()}"
    )
    print(f"resealed {path} ({args.reason.strip()})")
    return 0


def _cmd_models(_args: argparse.Namespace) -> int:
    import inspect

    from catheter_models.models import MODEL_KINDS, model_class

    for kind in MODEL_KINDS:
        cls = model_class(kind)
        doc = (cls.__doc__ or "").strip().splitlines()[0]
        print(f"{kind}  ({cls.direction}) {doc}")
        for name, param in inspect.signature(cls.__init__).parameters.items():
            if name == "self" or param.kind in (param.VAR_KEYWORD, param.VAR_POSITIONAL):
                continue
            default = "" if param.default is param.empty else f" = {param.default!r}"
            print(f"    {name}{default}")
    return 0
