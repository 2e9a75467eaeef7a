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
import sys
import warnings
from pathlib import Path

# The verbs live in rooms of their own (cli_data: bags, simulation, training, tuning; cli_lab:
# the lab's loop on a fitted model); this module only parses and dispatches.
from catheter_models.cli_data import (
    EXIT_BAG_PROBLEM,
    SIGNAL_SETS,
    _cmd_bag_info,
    _cmd_bag_repair,
    _cmd_models,
    _cmd_simulate,
    _cmd_train,
    _cmd_tune,
)
from catheter_models.cli_lab import (
    _cmd_add,
    _cmd_compare,
    _cmd_core,
    _cmd_diagnose,
    _cmd_effects,
    _cmd_explain,
    _cmd_history,
)
from catheter_models.contract import SENSOR_RATE_HZ
from catheter_models.errors import CatheterError
from catheter_models.gaps import BagGapWarning

# EXIT_BAG_PROBLEM is this command line's promise (an exit code), so it is named here too.
__all__ = ["EXIT_BAG_PROBLEM", "build_parser", "main"]


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
    parser.add_argument(
        "--ray",
        metavar="ADDRESS",
        default=None,
        help="run the refits on a Ray cluster instead: 'auto' (the cluster this machine "
        "belongs to), ray://HOST:PORT, or 'local' (a Ray started for this run); the same "
        "answers; Ray is an optional extra: pip install 'catheter_models[ray]'",
    )


def _reference_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--reference",
        choices=("filter_bank", "recurrent", "stronger"),
        default="filter_bank",
        help="the black box the error is judged against: the filter bank (seconds, default), "
        "a recurrent network trained to convergence (minutes; needs torch), or both, the "
        "stronger one judging (docs/lab.md)",
    )


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
    tune.add_argument(
        "--chain",
        type=Path,
        default=None,
        metavar="MODEL_DIR",
        help="the lab's explained model (catheter-lab explain/add): the loop's dead time, lag "
        "and tip come from it, checked against the steps (each disagreement said)",
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
    _reference_argument(diag)
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
    _reference_argument(expl)
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
