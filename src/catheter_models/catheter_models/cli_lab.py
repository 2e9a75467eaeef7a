"""The ``catheter-lab`` verbs of the lab's loop on a fitted model (docs/lab.md).

``compare`` it with bags, ``diagnose`` what it lacks, ``add`` an effect or change its ``core``
(refit, history kept), ``explain`` it step by step, show the ``history``; and ``effects``, the
catalogue ``add`` takes from.

Apart from ``cli`` (which parses and dispatches) and ``cli_data`` (bags, simulation, training,
tuning) so each module has one job; ``cli`` imports these, never the other way round.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from catheter_models.errors import CatheterError


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


def _cmd_diagnose(args: argparse.Namespace) -> int:
    """Residual tests, then a refit per missing effect; ranked, or 'adequate'."""
    import json

    from catheter_models.lab.diagnose import diagnose, plot_diagnosis
    from catheter_models.lab.residuals import plot_residual_tests
    from catheter_models.models import load_model

    model = load_model(args.model)
    train, test = _train_and_test(args, model.fitted_rate_hz)
    result = diagnose(
        model,
        train,
        test,
        effects=args.effect or None,
        cores=args.core,
        reference=False if args.no_reference else args.reference,
        workers=args.workers,
        ray=args.ray,
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


def _train_and_test(args: argparse.Namespace, rate_hz: float) -> tuple[list[Any], list[Any]]:
    """``--train`` and ``--test`` bags as recordings at the model's rate (``--test`` optional)."""
    from catheter_models.models.data import recordings_from_bags

    def read(bags: list[Path] | None) -> list[Any]:
        return recordings_from_bags(
            bags or [], rate_hz=rate_hz, accept_implausible=args.accept_implausible
        )

    return read(args.train), read(args.test)


def _change(args: argparse.Namespace, change: str, make: Any) -> int:
    """Refit ``make(model)``, save it, record parent and child in the lab's history."""
    from catheter_models.lab import history

    if args.output.exists():
        raise CatheterError(f"{args.output} exists; choose a new model directory")
    model = _greybox_of(args.model)
    train, test = _train_and_test(args, model.fitted_rate_hz)
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

    if args.output.exists():
        raise CatheterError(f"{args.output} exists; choose a new directory")
    model = load_model(args.model)
    train, test = _train_and_test(args, model.fitted_rate_hz)
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
        model,
        train,
        test,
        max_steps=args.max_steps,
        on_step=on_step,
        workers=args.workers,
        reference=args.reference,
        ray=args.ray,
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
