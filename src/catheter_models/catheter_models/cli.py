"""``catheter-lab``: the lab's command line.

    catheter-lab bag info BAG              what a bag holds (topics, rates, metadata), what is
                                           damaged or lost, whether its data is plausible
    catheter-lab bag repair BAG [-o OUT]   recover a truncated or damaged bag into a new one
    catheter-lab simulate SIGNAL... -o BAG offline data: thesis signals through the
                                           simulated rig, written as contract bags
    catheter-lab effects                   the physical effects the plant and lab know
    catheter-lab train KIND --train BAG... -o DIR
                                           identify a thesis model from bags (playback
                                           for training) into a model directory
    catheter-lab models                    the model kinds and their settings
    catheter-lab compare MODEL BAG... [-o OUT]
                                           a fitted model against measured bags: metrics
                                           per regime, worst segments, an HTML report

    catheter-lab diagnose MODEL --train BAG... --test BAG...
                                          which physical effect the model lacks (ranked,
                                          or "adequate"), with the residual tests
    catheter-lab add EFFECT MODEL -o NEW --train BAG...
                                          add an effect block and refit (history kept)
    catheter-lab core NAME MODEL -o NEW --train BAG...
                                          change the hysteresis core, keep the blocks
    catheter-lab explain MODEL --train BAG... --test BAG... -o DIR
                                          the whole loop: diagnose, make the best change,
                                          again, until nothing earns its place
    catheter-lab history [--lab DIR]      model versions and the error across them

The lab's guide: docs/lab.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from catheter_models.contract import SENSOR_RATE_HZ
from catheter_models.errors import CatheterError
from catheter_models.gaps import BagGapWarning

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


def _accept_implausible_argument(parser: argparse.ArgumentParser) -> None:
    from catheter_models.bag.plausible import ACCEPT_FLAG

    parser.add_argument(
        ACCEPT_FLAG,
        dest="accept_implausible",
        action="store_true",
        help="go on with bags whose data fails the plausibility check (values against the "
        "contract, stamps, non-finite share); each finding is still printed (and, for train, "
        "recorded in the model's manifest)",
    )


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
    model = identify(recordings)
    print(f"loop model: {model.describe()}")
    gains, found = design(
        model,
        max_sensitivity=args.max_sensitivity,
        opening_pressure_pa=opening_pressure_pa(recordings),
    )
    gains = replace(gains, tuning={**gains.tuning, "recordings": [r.name for r in recordings]})
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


def _cmd_effects(_args: argparse.Namespace) -> int:
    """Each effect as the simulated plant has it and as the lab identifies it.

    Read from the two catalogues (the plant's ``EFFECTS`` and the lab's blocks, which name
    their plant counterpart), so what ``effects`` offers is what ``add`` takes.
    """
    from catheter_models.lab.residuals import TEST_LABELS
    from catheter_models.models.blocks import BLOCKS, CHECKS, DEFAULT_CHAIN_EFFECTS
    from catheter_models.plant.config import EFFECTS

    lab_of = {b.plant_effect: b for b in BLOCKS.values() if b.plant_effect}
    for name, spec in EFFECTS.items():
        state = "on" if spec.enabled_in_thesis_rig else "off"
        print(f"{name}  (thesis rig: {state})\n    {spec.physics}")
        for p in spec.params:
            print(f"    {p.name} = {p.default:g}  in [{p.low:g}, {p.high:g}]  {p.doc}")
        block = lab_of.get(name)
        if name in DEFAULT_CHAIN_EFFECTS:
            print("    lab: part of the hysteresis core (the DRDPI carries it)")
        elif block is not None:
            print(
                f"    lab: block {block.effect!r} ({block.side} side; catheter-lab add "
                f"{block.effect}); evidence: {TEST_LABELS[block.evidence_test]}; "
                f"shows in: {', '.join(block.regimes)}"
            )
        else:
            print("    lab: no block (the lab cannot name it)")
    for block in BLOCKS.values():
        if block.plant_effect not in EFFECTS:  # an effect the simulated plant does not have
            print(
                f"{block.effect}  (lab only: the simulated plant has no such effect)\n"
                f"    {block.__doc__.splitlines()[0] if block.__doc__ else ''}\n"
                f"    lab: block {block.effect!r} ({block.side} side; catheter-lab add "
                f"{block.effect}); evidence: {TEST_LABELS[block.evidence_test]}; "
                f"shows in: {', '.join(block.regimes)}"
            )
    for block in CHECKS.values():
        print(
            f"{block.effect}  (lab only: a side check, never named by a diagnosis)\n"
            f"    {block.stands_for}\n    lab: block {block.effect!r} ({block.side} side; "
            f"catheter-lab add {block.effect})"
        )
    return 0


def _cmd_compare(args: argparse.Namespace) -> int:
    """Compare a model directory with bags; every refusal is one line naming the problem.

    Bags are resampled at the model's own rate unless ``--rate-hz`` asks for another, which
    the comparison then refuses: a model only means something at the rate it was fitted at.
    """
    from datetime import datetime

    from catheter_models.lab.compare import compare, write_report
    from catheter_models.models import RateMismatchError, load_model
    from catheter_models.models.data import recordings_from_bags

    if args.output is not None and args.output.exists() and any(args.output.iterdir()):
        raise CatheterError(f"{args.output} exists and is not empty; choose a new directory")
    model = load_model(args.model)
    rate_hz = model.fitted_rate_hz if args.rate_hz is None else args.rate_hz
    recordings = recordings_from_bags(
        args.bags, rate_hz=rate_hz, accept_implausible=args.accept_implausible
    )
    try:
        result = compare(model, recordings, n_worst=args.worst, window_s=args.window_s)
    except RateMismatchError as exc:
        hint = "; or drop --rate-hz: bags are resampled at the model's rate by default"
        raise RateMismatchError(f"{exc}{hint}") from None
    print(result.text())
    stamp = datetime.now().strftime("%Y%m%d-%H%M%S")
    out_dir = args.output or Path("lab") / f"compare-{args.model.resolve().name}-{stamp}"
    names = ", ".join(r.name for r in recordings)
    index = write_report(result, out_dir, title=f"{model.kind} ({args.model}) vs {names}")
    print(f"report: {index}")
    return 0


def _workers(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"--workers must be a whole number >= 1, not {text!r}")
    return n


def _workers_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--workers",
        type=_workers,
        default=None,
        help="processes for the refits, which are independent (default: one per core; "
        "1: this process only)",
    )


def _cmd_diagnose(args: argparse.Namespace) -> int:
    """Residual tests, then a refit per missing effect; ranked, or 'adequate'."""
    import json

    from catheter_models.lab.diagnose import diagnose, plot_diagnosis
    from catheter_models.lab.residuals import plot_residual_tests
    from catheter_models.models import load_model
    from catheter_models.models.data import recordings_from_bags

    model = load_model(args.model)
    train = recordings_from_bags(
        args.train, rate_hz=model.fitted_rate_hz, accept_implausible=args.accept_implausible
    )
    test = recordings_from_bags(
        args.test, rate_hz=model.fitted_rate_hz, accept_implausible=args.accept_implausible
    )
    result = diagnose(
        model,
        train,
        test,
        effects=args.effect or None,
        cores=args.core,
        reference=not args.no_reference,
        workers=args.workers,
    )
    print(result.text())
    if args.output is not None:
        args.output.mkdir(parents=True, exist_ok=True)
        (args.output / "diagnosis.json").write_text(
            json.dumps(result.to_dict(), indent=2, default=float) + "\n"
        )
        plot_residual_tests(result.residual_report, args.output / "residual_tests.png")
        if result.candidates:
            plot_diagnosis(result, args.output / "diagnosis.png")
        print(f"figures and diagnosis.json: {args.output}")
    return 0


def _greybox_of(model_dir: Path) -> Any:
    """The grey-box model in ``model_dir`` (a DRDPI is the default chain); refused otherwise."""
    from catheter_models.models import load_model
    from catheter_models.models.greybox import GreyBox

    model = load_model(model_dir)
    chain = GreyBox.chain_of(model)
    if chain is None:
        raise CatheterError(
            f"{model_dir} holds a {model.kind} model: effects and cores are changed on "
            "grey-box models (or a DRDPI, the default chain)"
        )
    return chain


def _change(args: argparse.Namespace, change: str, make: Any) -> int:
    """Refit ``make(model)``, save it, record parent and child in the lab's history."""
    from catheter_models.lab import history
    from catheter_models.models.data import recordings_from_bags

    if args.output.exists():
        raise CatheterError(f"{args.output} exists; choose a new model directory")
    model = _greybox_of(args.model)
    train = recordings_from_bags(
        args.train, rate_hz=model.fitted_rate_hz, accept_implausible=args.accept_implausible
    )
    test = recordings_from_bags(
        args.test or [], rate_hz=model.fitted_rate_hz, accept_implausible=args.accept_implausible
    )
    new = make(model).fit(train, progress=not args.no_progress)
    new.save(args.output, training=train)
    print(f"{' -> '.join(new.chain)}: {new.block_values() or new.core_name}")
    print(f"model: {args.output}")
    versions = history.load_history(args.lab)
    parent = history.find(versions, args.model)
    if parent is None:
        parent = history.record(args.lab, args.model, model, train=train, test=test)
    child = history.record(
        args.lab, args.output, new, train=train, test=test, added=change, parent=parent.version
    )
    print(history.history_text(history.load_history(args.lab)))
    print(f"history: {args.lab / history.HISTORY_FILE} (version {child.version})")
    return 0


def _cmd_add(args: argparse.Namespace) -> int:
    """Add an effect block to a grey-box (or DRDPI) model, refit it, record both versions."""
    return _change(args, args.effect, lambda m: m.with_effect(args.effect))


def _cmd_core(args: argparse.Namespace) -> int:
    """Change a grey-box (or DRDPI) model's core, refit it, record both versions."""
    return _change(args, f"core:{args.name}", lambda m: m.with_core(args.name))


def _cmd_explain(args: argparse.Namespace) -> int:
    """The whole loop, each version saved and recorded, the history plotted with floors."""
    from catheter_models.lab import history
    from catheter_models.lab.diagnose import plot_diagnosis
    from catheter_models.lab.explain import Step, explain
    from catheter_models.models import load_model
    from catheter_models.models.data import recordings_from_bags

    if args.output.exists():
        raise CatheterError(f"{args.output} exists; choose a new directory")
    model = load_model(args.model)
    train = recordings_from_bags(
        args.train, rate_hz=model.fitted_rate_hz, accept_implausible=args.accept_implausible
    )
    test = recordings_from_bags(
        args.test, rate_hz=model.fitted_rate_hz, accept_implausible=args.accept_implausible
    )
    args.output.mkdir(parents=True)
    parent: list[int | None] = [None]

    def on_step(step: Step) -> None:
        d = step.diagnosis
        where = args.model
        if step.change is not None:
            where = args.output / f"step{sum(1 for _ in args.output.glob('step*')) + 1}"
            step.model.save(where, training=train)
        version = history.record(
            args.output,
            where,
            step.model,
            train=train,
            test=test,
            added=step.change,
            parent=parent[0],
            floors=(d.floors.noise_deg, d.floors.reference_deg),
        )
        parent[0] = version.version
        print(
            f"step {version.version - 1}: {' -> '.join(d.chain)}: held-out "
            f"{d.rmse_test_deg:.3f} deg; verdict {d.verdict}",
            flush=True,
        )

    result = explain(
        model, train, test, max_steps=args.max_steps, on_step=on_step, workers=args.workers
    )
    print()
    print(result.text())
    (args.output / "explanation.json").write_text(
        json.dumps(result.to_dict(), indent=2, default=float) + "\n"
    )
    history.plot_history(history.load_history(args.output), args.output / "history.png")
    if result.final.candidates:
        plot_diagnosis(result.final, args.output / "diagnosis.png")
    print(f"versions, history.png, diagnosis.png and explanation.json: {args.output}")
    return 0


def _cmd_history(args: argparse.Namespace) -> int:
    """The lab's model versions and their errors; a plot of the error across versions."""
    from catheter_models.lab import history

    versions = history.load_history(args.lab)
    print(history.history_text(versions))
    if versions:
        out = args.output or args.lab / "history.png"
        history.plot_history(versions, out)
        print(f"plot: {out}")
    return 0


def _refit_arguments(p: argparse.ArgumentParser) -> None:
    """What ``add`` and ``core`` share: the model changed, where it goes, the data, the lab."""
    p.add_argument("model", type=Path, help="grey-box or DRDPI model directory")
    p.add_argument("-o", "--output", type=Path, required=True, help="new model directory")
    p.add_argument("--train", nargs="+", type=Path, required=True, help="training bags")
    p.add_argument("--test", nargs="+", type=Path, help="held-out bags scored in the history")
    p.add_argument("--lab", type=Path, default=Path("lab"), help="the lab's directory (lab)")
    p.add_argument("--no-progress", action="store_true")
    _accept_implausible_argument(p)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (separate so docs and tests can inspect it)."""
    parser = argparse.ArgumentParser(prog="catheter-lab", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    bag = sub.add_parser("bag", help="inspect or repair bags")
    bag_sub = bag.add_subparsers(dest="bag_command", required=True)
    info = bag_sub.add_parser(
        "info",
        help="what a bag holds, what is damaged or lost, whether its data is plausible",
        description="Exit 0: whole and plausible (warnings may be printed); 3: truncated, "
        "damaged, messages lost, metadata.yaml disagreeing or implausible data (said first); "
        "2: not a bag.",
    )
    info.add_argument("bag", type=Path)
    info.set_defaults(func=_cmd_bag_info)
    repair = bag_sub.add_parser(
        "repair",
        help="recover a truncated or damaged bag into a new bag",
        description="Copies every message that can be read whole into a new bag and says what "
        "was truncated, corrupt, unverifiable or lost. Exit 0: written, no message known lost; "
        "3: written, messages lost (counted, with when); 2: refused, nothing written (not a "
        "bag, 0 bytes, no header, nothing whole to recover, output exists).",
    )
    repair.add_argument("bag", type=Path)
    repair.add_argument("-o", "--output", type=Path, default=None, help="new bag directory")
    repair.set_defaults(func=_cmd_bag_repair)

    sim = sub.add_parser("simulate", help="a thesis pressure signal through the simulated rig")
    sim.add_argument(
        "signal",
        nargs="+",
        help="pressure preset(s), e.g. train_zero_f0.2, or a set: " + ", ".join(SIGNAL_SETS),
    )
    sim.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        help="new bag directory (several signals: a directory of bags, one per signal)",
    )
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

    train = sub.add_parser(
        "train",
        help="identify a model from bags into a model directory",
        description=(
            "Identify a thesis model (drdpi, gpi, idrdpi, svr, lstm, clstm) from recorded "
            "bags. Forward models learn pressure/command -> tip/angle; inverse models "
            "(idrdpi, clstm) learn tip/angle -> pressure/command. Settings are the model's "
            "constructor arguments (`catheter-lab models` lists them)."
        ),
    )
    train.add_argument("kind", help="model kind: drdpi, gpi, idrdpi, svr, lstm, clstm")
    train.add_argument("--train", nargs="+", type=Path, required=True, metavar="BAG")
    train.add_argument(
        "--validate",
        nargs="*",
        type=Path,
        default=[],
        metavar="BAG",
        help="held-out bags, scored after training and recorded in the manifest",
    )
    train.add_argument("-o", "--output", type=Path, required=True, help="new model directory")
    train.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a model setting (JSON value), e.g. --set n_play=12; repeatable",
    )
    train.add_argument("--rate-hz", type=float, default=SENSOR_RATE_HZ, help="resampling rate [Hz]")
    train.add_argument("--quiet", action="store_true", help="no progress bar")
    _accept_implausible_argument(train)
    train.set_defaults(func=_cmd_train)

    tune = sub.add_parser(
        "tune",
        help="feedback gains from recorded steps (docs/closed_loop.md)",
        description=(
            "Fit the loop (dead time, lag, a ringing tip) to the pressure steps of recorded "
            "bags, then choose the PI gains of largest integral gain whose loop keeps the "
            "maximum sensitivity under a bound. Writes feedback.json into OUTPUT (a model "
            "directory: the compensator node reads it from there with feedback:=pi), sealed "
            "with the loop it was tuned on and the range of gains it considers safe; an "
            "edited file is refused until re-tuned or resealed (--reseal)."
        ),
    )
    tune.add_argument("bags", nargs="*", type=Path, metavar="BAG", help="bags with fast steps")
    tune.add_argument("-o", "--output", type=Path, default=None, help="directory for feedback.json")
    tune.add_argument(
        "--reseal",
        type=Path,
        default=None,
        metavar="FILE",
        help="seal a deliberately edited feedback.json again, after checking its gains against "
        "the safety envelope, the tuned range and the margins on the recorded loop",
    )
    tune.add_argument(
        "--reason", default=None, help="with --reseal: why (kept in the file); required"
    )
    tune.add_argument(
        "--max-sensitivity",
        type=float,
        default=1.6,
        help="bound on Ms (1.6: gain margin >= 2.7, phase margin >= 36 deg)",
    )
    tune.add_argument("--report", type=Path, default=None, help="write an HTML report here")
    tune.add_argument("--rate-hz", type=float, default=SENSOR_RATE_HZ, help="resampling rate [Hz]")
    _accept_implausible_argument(tune)
    tune.set_defaults(func=_cmd_tune)

    models = sub.add_parser("models", help="list the model kinds and their settings")
    models.set_defaults(func=_cmd_models)

    comp = sub.add_parser(
        "compare",
        help="compare a fitted model with measured bags and locate where it fails",
        description=(
            "Run a model directory (any kind, forward or inverse) over bags from rest, print "
            "RMSE / MAE (maximum absolute error) / NRMSE overall and per motion regime and the "
            "worst segments (recording, time span, regime), and write an HTML report."
        ),
    )
    comp.add_argument("model", type=Path, metavar="MODEL_DIR", help="a model directory")
    comp.add_argument("bags", nargs="+", type=Path, metavar="BAG", help="measured bag(s)")
    comp.add_argument(
        "-o",
        "--output",
        type=Path,
        default=None,
        metavar="OUT_DIR",
        help="new report directory (default: lab/compare-<model dir name>-<timestamp>)",
    )
    comp.add_argument(
        "--worst", type=int, default=5, metavar="N", help="worst windows to report (default 5)"
    )
    comp.add_argument(
        "--window-s",
        type=float,
        default=1.0,
        help="window length [s] for locating the worst segments (default 1.0)",
    )
    comp.add_argument(
        "--rate-hz",
        type=float,
        default=None,
        help="resampling rate [Hz] (default: the rate the model was fitted at)",
    )
    _accept_implausible_argument(comp)
    comp.set_defaults(func=_cmd_compare)

    diag = sub.add_parser("diagnose", help="which physical effect does a model lack? (docs/lab.md)")
    diag.add_argument("model", type=Path, help="model directory")
    diag.add_argument("--train", nargs="+", type=Path, required=True, help="training bags")
    diag.add_argument("--test", nargs="+", type=Path, required=True, help="held-out bags")
    diag.add_argument(
        "--effect", action="append", help="test only this effect (repeatable; default: all)"
    )
    diag.add_argument(
        "--core",
        action="append",
        help="try only this core change (repeatable; default: every other core)",
    )
    diag.add_argument(
        "--no-reference",
        action="store_true",
        help="skip the black-box reference (the noise floor alone judges 'adequate')",
    )
    diag.add_argument("-o", "--output", type=Path, default=None, help="figures and JSON here")
    _workers_argument(diag)
    _accept_implausible_argument(diag)
    diag.set_defaults(func=_cmd_diagnose)

    core = sub.add_parser("core", help="change a grey-box model's hysteresis core and refit")
    core.add_argument("name", help="the new core (drdpi, free_pi, boucwen)")
    _refit_arguments(core)
    core.set_defaults(func=_cmd_core)

    expl = sub.add_parser(
        "explain", help="diagnose, make the best change, repeat until nothing helps"
    )
    expl.add_argument("model", type=Path, help="model directory to start from")
    expl.add_argument("--train", nargs="+", type=Path, required=True, help="training bags")
    expl.add_argument("--test", nargs="+", type=Path, required=True, help="held-out bags")
    expl.add_argument(
        "-o", "--output", type=Path, required=True, help="new directory: versions, figures"
    )
    expl.add_argument("--max-steps", type=int, default=4, help="changes at most (4)")
    _workers_argument(expl)
    _accept_implausible_argument(expl)
    expl.set_defaults(func=_cmd_explain)

    add = sub.add_parser("add", help="add an effect block to a grey-box model and refit")
    add.add_argument("effect", help="catalogue effect, e.g. pneumatic_lag (catheter-lab effects)")
    _refit_arguments(add)
    add.set_defaults(func=_cmd_add)

    hist = sub.add_parser("history", help="model versions and their errors, with a plot")
    hist.add_argument("--lab", type=Path, default=Path("lab"), help="the lab's directory (lab)")
    hist.add_argument("-o", "--output", type=Path, default=None, help="plot (lab/history.png)")
    hist.set_defaults(func=_cmd_history)
    return parser


def main(argv: list[str] | None = None) -> None:
    """Entry point of ``catheter-lab``; a refusal prints one line naming the command, exits 2.

    Unreadable bags and unwritable output directories (OSError) are refusals too: a person
    gets the path and the reason, not a traceback.
    """
    args = build_parser().parse_args(argv)
    command = " ".join(
        str(v) for v in (args.command, getattr(args, "bag_command", None)) if v is not None
    )

    def show(message: Warning | str, category: type[Warning], *_: object, **__: object) -> None:
        print(f"catheter-lab {command}: warning: {message}", file=sys.stderr)

    from catheter_models.bag.plausible import PlausibilityWarning

    with warnings.catch_warnings():
        # Every gap in every input is said, once per bag and stream, in the command's voice.
        warnings.simplefilter("always", BagGapWarning)
        warnings.simplefilter("always", PlausibilityWarning)
        warnings.showwarning = show
        try:
            code = args.func(args)
        except (CatheterError, OSError) as exc:
            print(f"catheter-lab {command}: {exc}", file=sys.stderr)
            code = 2
    sys.exit(code)
