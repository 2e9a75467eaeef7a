"""``commission``: a new catheter from its first recording to closed-loop tracking, in one command.

    ros2 run catheter_control commission -o runs/cath7 --sim                 # simulated rig
    commission -o runs/cath7 --sim --plant my_lab.rod:make_plant             # your simulator
    commission -o runs/cath7 --emulated-rig                                   # real drivers
    commission -o runs/cath7                     # drivers already running on the real rig

The steps, each of which a person can also run by hand (docs/commissioning.md gives the
commands, and the report shows each one as it was run):

1. ``record_train``, ``record_test``: the lab's excitations, open loop (``excite`` with the
   recorder on), the training set with its fast steps, and a held-out set; each recording is
   checked for a rig that responds (a frozen laser, a valve that does not move stop here,
   before anything is fitted).
2. ``explain``: the thesis's DRDPI, then the lab's loop (``catheter-lab explain``): which
   hysteresis law and which physical effects this catheter shows.
3. ``idrdpi``, ``clstm``, ``greybox``: the compensators (the c-LSTM only with
   ``--clstm-budget-s``; the explained chain run backwards where its core is invertible).
4. ``tune``: the PI on the measured bend, from the recorded steps, for margins it reports.
5. ``follow:<candidate>:<trajectory>``: each compensator with the tuned PI on the four
   thesis trajectories, on the rig: every one on the first, then the best of them on the
   rest first, each cut short once it can no longer be chosen.
6. ``select``: the best candidate is written, with its gains, as one model directory
   (``OUT/model``) that ``follow_trajectory --model-dir OUT/model`` and the launch files
   take as it is; ``OUT/report/index.html`` says what was done and how well it tracks.

A step already done (``OUT/commission.json``) is not redone when the command is run again;
delete its outputs (or the entry) to redo it. Nothing is written as commissioned unless every
step before ``select`` succeeded.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from catheter_control.commission_rig import (
    MAX_COMMANDS_LOST_SHARE,
    Candidate,
    CommissionRig,
    RigChoice,
    RigError,
    check_response,
    recording_need,
)
from catheter_control.commission_steps import (
    PROTOCOLS,
    State,
    StepError,
    StepRecord,
    protocol_signals,
    run_lab,
)
from catheter_control.control_core import is_sensor_silence
from catheter_control.graph_domain import (
    GraphConflictError,
    default_domain_choice,
    domain_id_argument,
)
from catheter_control.models import COMMISSIONED_FILE
from catheter_control.trajectory import (
    TrajectoryLimits,
    lead_in_knots,
    preset_trajectory,
)
from catheter_models.bag.space import DiskSpaceError, check_free_space
from catheter_models.contract import CONTROL_RATE_HZ, DEFAULT_NAMESPACE, SENSOR_RATE_HZ
from catheter_models.errors import CatheterError
from catheter_models.feedback import FeedbackGains
from catheter_models.signals import TEST_TRAJECTORIES

EXIT_REFUSED = 2
"""The command line or the output directory was refused (the reason is named), or the
output directory's disk lacks room for the recordings still to make (the figures named)."""
EXIT_GRAPH = 3
"""The rig did not come up."""
EXIT_STOPPED = 4
"""A step failed or the rig does not respond: stopped with the reason, nothing commissioned.
This includes a recording whose recorder died or could not write (excite is stopped, the
pressure ramped down, the seconds unrecorded said): a rerun records it again."""
EXIT_BELOW_TARGET = 5
"""Commissioned (the best candidate is written), but it misses the tracking target on at
least one trajectory; the report names where."""
EXIT_INTERRUPTED = 130
"""Ctrl-C: what was done is kept (a rerun goes on from there), nothing is commissioned."""

MODEL_DIR = "model"
TARGET_RMSE_DEG = 0.3
"""The tracking each thesis trajectory should reach with feedback (issue's target)."""
LEAD_IN_S = 1.0
"""As follow_trajectory: a trajectory that does not start straight is approached from rest."""


def _dead_time_of(loop: dict[str, Any]) -> float:
    """A tuned loop's dead time plus lag [s] (0 for a loop not identified)."""
    return float(loop.get("delay_s", 0.0)) + float(loop.get("time_constant_s", 0.0))


@dataclass
class Commission:
    """One commissioning: its directory, its rig, its settings, and the state of its steps."""

    out_dir: Path
    choice: RigChoice
    protocol: str
    clstm_budget_s: float
    explain_steps: int
    workers: int | None
    control_rate_hz: float
    show_progress: bool
    trajectories: tuple[str, ...] = TEST_TRAJECTORIES
    every_run: bool = False
    """Follow every candidate on every trajectory, also those that can no longer be chosen."""
    state: State = field(init=False)
    rig: CommissionRig = field(init=False)
    _rig_up: bool = field(default=False, init=False)
    _chain_dead_times: dict[tuple[Path, int], float | None] = field(
        default_factory=dict, init=False, repr=False
    )

    def __post_init__(self) -> None:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.state = State(self.out_dir, self.choice, self.protocol)
        self.state.save()  # the directory belongs to this rig from now on
        self.rig = CommissionRig(self.choice, self.out_dir / "logs")

    # -- paths ----------------------------------------------------------------------------
    def bag(self, name: str) -> Path:
        """A recording's bag directory."""
        return self.out_dir / "bags" / name

    @property
    def tune_dir(self) -> Path:
        """Where ``catheter-lab tune`` writes feedback.json and its report."""
        return self.out_dir / "tune"

    def candidate_dir(self, kind: str) -> Path:
        """A compensator's model directory."""
        return self.out_dir / "candidates" / kind

    def tuned_loop(self) -> dict[str, Any]:
        """The loop ``catheter-lab tune`` identified ({} before tuning).

        Read through :meth:`FeedbackGains.load`, as the compensator node reads it, so a file
        whose seal does not match is refused here too, by name, not used.
        """
        return dict(self.tuning().get("loop", {}))

    def tuning(self) -> dict[str, Any]:
        """What ``catheter-lab tune`` recorded of its decision ({} before tuning)."""
        path = self.tune_dir / "feedback.json"
        if not path.exists():
            return {}
        return dict(FeedbackGains.load(path).tuning)

    def tip_mode_hz(self) -> float:
        """The ringing tip the tuned loop has [Hz] (0: none found, or not tuned yet)."""
        return float(self.tuned_loop().get("resonance_hz", 0.0) or 0.0)

    def candidates(self) -> list[Candidate]:
        """The compensators fitted so far, each with the tuned PI.

        Where the tuned loop has a ringing tip, each is tried with its pressure input-shaped
        (``zvd``) as well: a hysteresis inverse kinks the pressure at every reversal and rings
        the tip, which the PI, held to a crossover below the mode, cannot undo.
        """
        # The explained chain first: where the lab found the catheter's physics its inverse
        # is the likely winner, and the others are then cut short sooner (:meth:`hopeless`).
        kinds = ["greybox"] if self.candidate_dir("greybox").exists() else []
        kinds += ["idrdpi"] + (["clstm"] if self.clstm_budget_s > 0 else [])
        shapings = ["none"] + (["zvd"] if self.tip_mode_hz() > 0.0 else [])
        gains = self.tune_dir / "feedback.json"
        return [
            Candidate(
                f"{k}+pi" if shaping == "none" else f"{k}+{shaping}+pi",
                k,
                self.candidate_dir(k),
                "pi",
                gains,
                shaping,
            )
            for k in kinds
            for shaping in shapings
            # The chain's inverse pulls a ringing tip by the plan itself: shaping its
            # pressure would delay what it already timed.
            if not (k == "greybox" and shaping != "none")
        ]

    # -- running steps --------------------------------------------------------------------
    def step(
        self, name: str, title: str, run: Callable[[StepRecord], None], *outputs: Path
    ) -> None:
        """Run ``run`` as step ``name`` unless it is done and its outputs exist."""
        if self.state.done(name) and all(p.exists() for p in outputs):
            print(f"commission: {title}: done already ({self.state.steps[name].seconds:.0f} s)")
            return
        print(f"\ncommission: {title}", flush=True)
        record = StepRecord()
        start = time.monotonic()
        run(record)
        record.seconds = time.monotonic() - start
        record.done = True
        self.state.steps[name] = record
        self.state.save()
        print(f"commission: {title}: done in {record.seconds:.0f} s", flush=True)

    def ensure_rig(self) -> None:
        """Bring the rig up the first time a step needs it."""
        if not self._rig_up:
            print(f"commission: rig: {self.choice.describe()} (logs in {self.rig.log_dir})")
            self.rig.start()
            self._rig_up = True

    def close(self) -> None:
        """Stop what was started."""
        if self._rig_up:
            self.rig.stop()
            self._rig_up = False

    def run(self) -> int:
        """Every step in order; the exit code (raises on a failed step)."""
        signals = protocol_signals(self.protocol)
        # Refused before the rig moves: a disk that fills mid-recording costs the recording.
        to_record = [
            signals[part]
            for part in ("train", "test")
            if not (self.state.done(f"record_{part}") and self.bag(part).exists())
        ]
        if to_record:
            check_free_space(recording_need(self.out_dir / "bags", to_record))
        for part in ("train", "test"):
            self.step(
                f"record_{part}",
                f"record the {part} excitation ({', '.join(signals[part])})",
                functools.partial(self._record, part, signals[part]),
                self.bag(part),
            )
        train, test = str(self.bag("train")), str(self.bag("test"))
        forward = self.out_dir / "forward"
        self.step("explain", "explain the catheter (lab)", self._explain, forward / "explain")
        self.step(
            "tune",
            "tune the PI on the measured bend (the loop's shape from the explained chain)",
            functools.partial(self._tune, train),
            self.tune_dir / "feedback.json",
        )
        self.step(
            "idrdpi",
            "fit the inverse DRDPI compensator (told the tuned loop's dead time)",
            functools.partial(self._idrdpi, train, test),
            self.candidate_dir("idrdpi"),
        )
        if self.clstm_budget_s > 0:
            self.step(
                "clstm",
                f"fit the c-LSTM ({self.clstm_budget_s:g} s budget)",
                self._clstm,
                self.candidate_dir("clstm"),
            )
        self.step(
            "greybox",
            "run the explained chain backwards (the greybox compensator)",
            self._greybox,
        )
        self._follow_all()
        return self._select()

    def _follow_all(self) -> None:
        """Each candidate on each trajectory, but none that can no longer be chosen.

        Every candidate follows the first trajectory; then the one that tracked it best
        follows the rest, and the others after it, each cut short once it cannot win
        (:meth:`hopeless`). The order of :meth:`candidates` is a prior (the explained chain
        usually wins) that breaks ties; the first trajectory is evidence. Where the prior was
        wrong (``maxwell_slip_lag`` of tests/support, commissioned 2026-11-29: the chain's
        inverse 0.51 deg on the descending sine, the IDRDPI's 0.28) the runner-up's remaining
        three runs, about two minutes, are no longer spent finding it out.
        """
        candidates = self.candidates()
        first, *rest = self.trajectories
        for candidate in candidates:
            self._follow_step(candidate, first)
        on_first = {c: s.get(first, math.inf) for c, s in self.scores().items()}
        # sorted() is stable: equal scores (or none) keep the prior order.
        for candidate in sorted(candidates, key=lambda c: on_first.get(c.name, math.inf)):
            for trajectory in rest:
                self._follow_step(candidate, trajectory)

    def _follow_step(self, candidate: Candidate, trajectory: str) -> None:
        run_dir = self.out_dir / "runs" / candidate.name / trajectory
        name = f"follow:{candidate.name}:{trajectory}"
        hopeless = "" if self.state.done(name) else self.hopeless(candidate.name)
        if hopeless:
            print(f"commission: {candidate.name}: not followed on {trajectory}: {hopeless}")
            self.state.steps[name] = StepRecord(facts={"skipped": hopeless})
            self.state.save()
            return
        self.step(
            name,
            f"follow {trajectory} with {candidate.name}",
            functools.partial(self._follow, candidate, trajectory, run_dir),
            run_dir / "report.json",
        )

    # -- the steps ------------------------------------------------------------------------
    def _record(self, part: str, signals: list[str], record: StepRecord) -> None:
        self.ensure_rig()
        bag = self.bag(part)
        if bag.exists():
            # A bag from an interrupted recording is incomplete: record it again.
            shutil.rmtree(bag)
        bag.parent.mkdir(parents=True, exist_ok=True)
        ns = self.choice.namespace
        record.commands.append(
            f"excite --ros-args -r __ns:={ns} -p signal:={','.join(signals)} "
            f"-p min_subscribers:=2   (beside: recorder --ros-args -r __ns:={ns} "
            f"-p bag_path:={bag})"
        )
        self.rig.record(
            signals,
            bag,
            {"source": "commission", "signal": ",".join(signals), "rig": self.choice.describe()},
            show_progress=self.show_progress,
        )
        check = check_response(bag)
        record.facts["check"] = check.to_dict()
        problem = check.problem()
        if problem:
            # Either the rig does not respond or the recording is not fit to learn from.
            raise RigError(problem)
        if check.commands_missing:
            print(
                f"commission: {bag.name}: {check.commands_missing} of "
                f"{check.commands_expected} commands missing from the recording "
                f"({check.commands_missing_share:.2%}; refused above "
                f"{MAX_COMMANDS_LOST_SHARE:.0%})"
            )
        print(
            f"commission: {bag.name}: {check.duration_s:.0f} s, command spans "
            f"{check.command_span_bar:.2f} bar, measured {check.measured_span_bar:.2f} bar, "
            f"bend {check.bend_span_deg:.1f} deg"
        )

    def _explain(self, record: StepRecord) -> None:
        train, test = str(self.bag("train")), str(self.bag("test"))
        forward = self.out_dir / "forward"
        for stale in (forward / "drdpi", forward / "explain"):
            if stale.exists():  # left by an interrupted run: the verbs want new directories
                shutil.rmtree(stale)
        run_lab(
            ["train", "drdpi", "--train", train, "--quiet", "-o", str(forward / "drdpi")], record
        )
        argv = [
            "explain",
            str(forward / "drdpi"),
            "--train",
            train,
            "--test",
            test,
            "-o",
            str(forward / "explain"),
            "--max-steps",
            str(self.explain_steps),
        ]
        if self.workers is not None:
            argv += ["--workers", str(self.workers)]
        run_lab(argv, record)
        explanation = json.loads((forward / "explain" / "explanation.json").read_text())
        record.facts["explanation"] = explanation

    def _tune(self, train: str, record: StepRecord) -> None:
        argv = ["tune", train, "-o", str(self.tune_dir), "--report", str(self.tune_dir / "report")]
        explained = self.explained_dir()
        if explained is not None:
            # One model of the catheter: the loop's dead time, lag and tip are the chain's,
            # checked against the recorded steps (disagreements said, in the tuning record).
            argv += ["--chain", str(explained)]
        run_lab(argv, record)

    def tuned_dead_time_s(self) -> float:
        """The tuned loop's dead time plus lag [s] (0 before tuning).

        A first-order lag is, to first order, a dead time of its time constant, so the two
        are read ahead together.
        """
        return _dead_time_of(self.tuned_loop())

    def explained_dir(self) -> Path | None:
        """The lab's last version of the explained chain.

        None when the lab changed nothing (or has not explained the catheter yet).
        """
        steps = [
            p
            for p in (self.out_dir / "forward" / "explain").glob("step*")
            if p.name[4:].isdigit() and (p / "manifest.json").exists()
        ]
        return max(steps, key=lambda p: int(p.name[4:])) if steps else None

    def chain_dead_time_s(self) -> float | None:
        """The explained chain's transport delay plus pneumatic lag [s].

        None when the lab found neither (or has not explained the catheter yet).
        """
        final = self.explained_dir()
        if final is None:
            return None
        # Asked by the IDRDPI's step and the c-LSTM's: the model is loaded (and its hash
        # checked) once per version of the explained chain.
        key = (final, (final / "manifest.json").stat().st_mtime_ns)
        if key not in self._chain_dead_times:
            from catheter_models.models import load_model
            from catheter_models.models.greybox import GreyBox

            chain = GreyBox.chain_of(load_model(final))
            self._chain_dead_times[key] = chain.dead_time_s() if chain is not None else None
        return self._chain_dead_times[key]

    def dead_time(self) -> tuple[float, str]:
        """The dead time the compensators read ahead [s], whole control samples, and its source.

        The lab's explained chain where it found a delay or a lag and the tuner found its
        shape fits the recorded steps (``chain_fits_steps`` in ``feedback.json``), else the
        tuned loop. The chain is fitted on the whole recording with the hysteresis in it;
        the tuner's linear step fit read 30-33 ms where the chain read 50.6 ms on a plant
        with 40 ms of delay behind an 8 ms valve (tracking 0.50 / 0.23 / 0.66 / 0.42 deg
        against 0.37 / 0.23 / 0.40 / 0.40 deg offline).
        """
        chain = self.chain_dead_time_s()
        tuning = self.tuning()  # one read of the sealed file for both branches
        tuned_s = _dead_time_of(tuning.get("loop", {}))
        if chain is not None and tuning.get("chain_fits_steps") is False:
            # The tuner found the chain's shape does not fit the recorded steps (a delay
            # where the catheter has a lag): its dead time is not the loop's either.
            seconds, source = (
                tuned_s,
                "the tuned loop: the explained chain's shape does not fit the recorded steps",
            )
        elif chain is not None:
            seconds, source = chain, "the lab's explained chain"
        else:
            seconds, source = tuned_s, "the tuned loop"
        from catheter_models.models.idrdpi import MAX_PREVIEW_S

        if seconds > MAX_PREVIEW_S:
            # A loop this slow is not a dead time to read ahead: the IDRDPI would refuse it.
            seconds, source = MAX_PREVIEW_S, f"{source}, {seconds:.2f} s cut to MAX_PREVIEW_S"
        return round(seconds * self.control_rate_hz) / self.control_rate_hz, source

    def dead_time_s(self) -> float:
        """:meth:`dead_time`'s seconds."""
        return self.dead_time()[0]

    def _idrdpi(self, train: str, test: str, record: StepRecord) -> None:
        out = self.candidate_dir("idrdpi")
        if out.exists():
            shutil.rmtree(out)  # left by an interrupted run: train wants a new directory
        preview_s, source = self.dead_time()
        tuned_s = self.tuned_dead_time_s()
        record.facts.update(preview_s=preview_s, preview_from=source, tuned_dead_time_s=tuned_s)
        print(
            f"commission: dead time {preview_s * 1e3:.0f} ms (from {source}; the tuned loop's "
            f"{tuned_s * 1e3:.0f} ms): the IDRDPI is fitted across it and reads the plan that "
            "much ahead"
            if preview_s > 0.0
            else f"commission: no dead time of a sample or more (from {source})"
        )
        run_lab(
            [
                "train",
                "idrdpi",
                "--train",
                train,
                "--validate",
                test,
                "--set",
                f"preview_s={preview_s:.6g}",
                "--quiet",
                "-o",
                str(out),
            ],
            record,
        )

    def _clstm(self, record: StepRecord) -> None:
        try:
            import torch  # noqa: F401
        except ImportError:
            raise StepError(
                "the c-LSTM needs torch (the training extra: `make setup`, or "
                "`pip install -r requirements-train.txt`); run without --clstm-budget-s"
            ) from None
        out = self.candidate_dir("clstm")
        if out.exists():
            shutil.rmtree(out)
        run_lab(
            [
                "train",
                "clstm",
                "--train",
                str(self.bag("train")),
                "--validate",
                str(self.bag("test")),
                "--set",
                f"time_budget_s={self.clstm_budget_s:g}",
                # One recording of training data: hold out its tail, not a whole recording.
                "--set",
                'validation_split="time"',
                # A causal network cannot undo a dead time; read ahead, as the IDRDPI does
                # (in samples of the rate it is trained at, train's default).
                "--set",
                f"preview_samples={round(self.dead_time_s() * SENSOR_RATE_HZ)}",
                "--quiet",
                "-o",
                str(out),
            ],
            record,
        )

    def _greybox(self, record: StepRecord) -> None:
        """The explained chain as a candidate, where its core can be run backwards.

        A chain whose fitted core is not invertible sample by sample is said, with its
        miss, and left out of the candidates (the others still run).
        """
        from catheter_models.errors import ParameterError
        from catheter_models.models import load_model
        from catheter_models.models.greybox import GreyBox
        from catheter_models.models.greybox_inverse import GreyBoxInverse

        out = self.candidate_dir("greybox")
        if out.exists():
            shutil.rmtree(out)
        source = self.explained_dir() or self.out_dir / "forward" / "drdpi"
        model = load_model(source)
        chain = GreyBox.chain_of(model)
        if chain is None:
            raise StepError(f"{source} holds no chain to run backwards")
        record.commands.append(f"compensator greybox from {source}")
        try:
            inverse = GreyBoxInverse(chain)
        except ParameterError as exc:
            record.facts.update(refused=str(exc), chain=list(chain.chain))
            print(f"commission: greybox left out: {exc}")
            return
        record.facts.update(
            chain=list(chain.chain),
            preview_s=inverse.preview_s,
            inversion_miss_deg=inverse.inversion_miss_deg,
        )
        if chain is model:
            shutil.copytree(source, out)
        else:
            chain.save(out)  # the thesis's DRDPI as the chain it is (no change was made)
        print(
            f"commission: greybox: {' -> '.join(chain.chain)}, reads the plan "
            f"{inverse.preview_s * 1e3:.0f} ms ahead"
        )

    def _follow(
        self, candidate: Candidate, trajectory: str, run_dir: Path, record: StepRecord
    ) -> None:
        from catheter_control import tracking_report as report

        self.ensure_rig()
        knots = lead_in_knots(preset_trajectory(trajectory), LEAD_IN_S, LEAD_IN_S)
        lead_s = knots.lead_s
        plan = knots.plan(TrajectoryLimits(), self.control_rate_hz, trajectory)
        record.commands.append(
            f"follow_trajectory --preset {trajectory} --model-dir {candidate.model_dir} "
            f"--compensator {candidate.compensator} --feedback pi --feedback-gains "
            f"{candidate.feedback_gains} --feedforward-shaping {candidate.feedforward_shaping}"
        )
        follow_once = functools.partial(
            self.rig.follow,
            plan,
            candidate,
            lead_s,
            control_rate_hz=self.control_rate_hz,
            show_progress=self.show_progress,
        )
        run = follow_once()
        if run.stopped and is_sensor_silence(run.stopped):
            # A sensor that fell silent for a moment and came back (seen live: both sensors
            # 332 ms silent at the compensator while the rig kept its deadlines) says
            # nothing about the candidate. Once more from rest, and the report says so; a
            # laser that froze stops the second run too, and the step with it.
            print(
                f"commission: {candidate.name} on {trajectory} stopped part-way: "
                f"{run.stopped}; following it once more from rest",
                flush=True,
            )
            record.facts["retried_after"] = run.stopped
            run = follow_once()
        result = report.score_record(run, plan.duration_s, lead_s)
        print(result.text(f"{trajectory}, {candidate.name}"))
        run_dir.mkdir(parents=True, exist_ok=True)
        report.save_plot(result, run_dir / "tracking.png", f"{trajectory}: {candidate.name}")
        summary = report.RunSummary.of(run)
        losses = report.sample_losses(run, None)
        facts = report.run_facts(
            run, summary, losses, trajectory=trajectory, bag_path=None, lead_s=lead_s
        )
        report.save_json(result, run_dir / "report.json", facts)
        record.facts.update(
            rmse_deg=math.degrees(result.overall.rmse),
            mae_deg=math.degrees(result.overall.mae),
            stopped=run.stopped,
        )
        if result.vented is not None:
            record.facts["vented_floor"] = result.vented.to_json()
        if run.stopped:
            raise StepError(f"{candidate.name} on {trajectory} stopped part-way: {run.stopped}")

    def scores(self) -> dict[str, dict[str, float]]:
        """RMSE [deg] by candidate and trajectory, of the runs done."""
        out: dict[str, dict[str, float]] = {}
        for candidate in self.candidates():
            for trajectory in self.trajectories:
                rec = self.state.steps.get(f"follow:{candidate.name}:{trajectory}")
                if rec is not None and rec.done:
                    out.setdefault(candidate.name, {})[trajectory] = float(rec.facts["rmse_deg"])
        return out

    def hopeless(self, name: str) -> str:
        """Why candidate ``name`` can no longer be chosen, or '' while it can.

        The choice goes to the best worst trajectory (:meth:`_select`), so a candidate with one
        run already worse than the worst run of a candidate that completed every trajectory
        cannot win: its remaining runs would cost minutes on the rig and change nothing.
        ``every_run`` follows them anyway, for comparison.
        """
        if self.every_run:
            return ""
        scores = self.scores()
        worst_of = {
            c: max(s.values()) for c, s in scores.items() if len(s) == len(self.trajectories)
        }
        mine = scores.get(name, {})
        if not worst_of or not mine:
            return ""
        best = min(worst_of, key=lambda c: worst_of[c])
        trajectory, worst = max(mine.items(), key=lambda item: item[1])
        if worst <= worst_of[best]:
            return ""  # a tie on the worst may still win on the sum
        return (
            f"its {trajectory} ({worst:.3f} deg) is already worse than {best}'s worst "
            f"trajectory ({worst_of[best]:.3f} deg), so it cannot be chosen (--every-run "
            "follows it anyway)"
        )

    def _select(self) -> int:
        scores = self.scores()
        complete = {c: s for c, s in scores.items() if len(s) == len(self.trajectories)}
        if not complete:
            raise StepError("no candidate completed every trajectory")
        # The worst trajectory decides: a compensator is only as good as where it fails.
        best = min(complete, key=lambda c: (max(complete[c].values()), sum(complete[c].values())))
        candidate = next(c for c in self.candidates() if c.name == best)
        model = self.out_dir / MODEL_DIR
        if model.exists():
            shutil.rmtree(model)
        shutil.copytree(candidate.model_dir, model)
        shutil.copy2(candidate.feedback_gains, model / "feedback.json")
        misses = {t: r for t, r in complete[best].items() if r > TARGET_RMSE_DEG}
        floors = {
            t: self.state.steps[f"follow:{best}:{t}"].facts.get("vented_floor") for t in misses
        }
        commissioned = {
            "compensator": candidate.compensator,
            "feedback": candidate.feedback,
            "feedforward_shaping": candidate.feedforward_shaping,
            "rig": self.choice.to_dict(),
            "rmse_deg": complete[best],
            "target_rmse_deg": TARGET_RMSE_DEG,
            "misses": misses,
            # Where the catheter rests vented, for each miss: how much no pressure could reach.
            "misses_vented_floor": {t: f for t, f in floors.items() if f},
            "candidates": scores,
        }
        (model / COMMISSIONED_FILE).write_text(json.dumps(commissioned, indent=2) + "\n")
        self.state.steps["select"] = StepRecord(done=True, facts=commissioned)
        self.state.save()
        print(
            f"\ncommission: chosen {best}: RMSE "
            + ", ".join(f"{t} {r:.3f} deg" for t, r in complete[best].items())
        )
        print(f"commission: model directory: {model}")
        print(f"commission: use it: follow_trajectory --model-dir {model} ...")
        if misses:
            print(
                f"commission: above the {TARGET_RMSE_DEG} deg target on "
                + ", ".join(
                    f"{t} ({r:.3f} deg{_below_rest(floors[t])})" for t, r in misses.items()
                ),
                file=sys.stderr,
            )
            return EXIT_BELOW_TARGET
        return 0


def _below_rest(floor: dict[str, Any] | None) -> str:
    """What of a miss lies below the bend the catheter rests at vented ('' if nothing known)."""
    # Here, not at the top: the report module brings matplotlib, which `--help` need not load.
    from catheter_control.tracking_report import VentedFloor

    vented = VentedFloor.from_json(floor) if floor else None
    return f"; it {vented.text()}" if vented is not None and vented.matters else ""


def _parse(argv: list[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="commission",
        description="Commission a catheter: record, explain, fit, tune, verify, write one "
        "model directory and a report (docs/commissioning.md).",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        required=True,
        help="commissioning directory (a rerun goes on where it stopped)",
    )
    rig = parser.add_mutually_exclusive_group()
    rig.add_argument("--sim", action="store_true", help="start the simulated rig")
    rig.add_argument(
        "--emulated-rig",
        action="store_true",
        help="start emulated devices and the real valve_driver and laser_angle",
    )
    parser.add_argument(
        "--plant",
        default="",
        metavar="MODULE:FACTORY",
        help="with --sim/--emulated-rig: your plant (docs/simulated_rig.md)",
    )
    parser.add_argument("--namespace", default=DEFAULT_NAMESPACE)
    parser.add_argument(
        "--domain-id",
        type=domain_id_argument,
        default=None,
        help="with --sim/--emulated-rig: ROS domain of the rig it starts: auto = one where "
        "nobody is (printed), env = ROS_DOMAIN_ID as set, N = that one (default: env when "
        "ROS_DOMAIN_ID is set, else auto, so a simulated rig never lands on a real one's)",
    )
    parser.add_argument(
        "--protocol",
        choices=PROTOCOLS,
        default="full",
        help="the excitations: the lab's sets (full, ~7 min) or a short smoke set",
    )
    parser.add_argument(
        "--clstm-budget-s",
        type=float,
        default=0.0,
        help="also fit a c-LSTM within this wall time [s] (needs torch; 0: no)",
    )
    parser.add_argument(
        "--explain-steps", type=int, default=3, help="changes the lab's loop may make at most"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help="processes for the lab's refits (default: one per core)",
    )
    parser.add_argument(
        "--trajectories",
        default=",".join(TEST_TRAJECTORIES),
        help="comma-separated thesis trajectories to verify on",
    )
    parser.add_argument(
        "--every-run",
        action="store_true",
        help="follow every candidate on every trajectory, also one that can no longer be "
        "chosen (by default its runs stop once one is worse than the best candidate's worst)",
    )
    parser.add_argument("--control-rate-hz", type=float, default=CONTROL_RATE_HZ)
    parser.add_argument("--no-progress", action="store_true", help="no progress bars")
    args = parser.parse_args(argv)
    if args.domain_id is not None and not (args.sim or args.emulated_rig):
        parser.error("--domain-id needs --sim or --emulated-rig (a running rig's is its own)")
    if args.plant and not (args.sim or args.emulated_rig):
        parser.error("--plant needs --sim or --emulated-rig (a real rig has its own plant)")
    if args.clstm_budget_s < 0 or not math.isfinite(args.clstm_budget_s):
        parser.error(f"--clstm-budget-s must be >= 0, not {args.clstm_budget_s}")
    if args.explain_steps < 0:
        parser.error(f"--explain-steps must be >= 0, not {args.explain_steps}")
    unknown = set(args.trajectories.split(",")) - set(TEST_TRAJECTORIES)
    if unknown:
        parser.error(f"unknown trajectories {sorted(unknown)}; the thesis's: {TEST_TRAJECTORIES}")
    return args


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    from catheter_control.commission_report import write_report

    args = _parse(argv)
    mode = "sim" if args.sim else "emulated" if args.emulated_rig else "running"
    domain = default_domain_choice(args.domain_id)
    try:
        job = Commission(
            out_dir=args.output,
            choice=RigChoice(mode, args.plant, args.namespace, domain),
            protocol=args.protocol,
            clstm_budget_s=args.clstm_budget_s,
            explain_steps=args.explain_steps,
            workers=args.workers,
            control_rate_hz=args.control_rate_hz,
            show_progress=not args.no_progress,
            trajectories=tuple(args.trajectories.split(",")),
            every_run=args.every_run,
        )
    except (CatheterError, OSError, ValueError) as exc:
        print(f"commission: {exc}", file=sys.stderr)
        return EXIT_REFUSED
    failure = ""
    try:
        code = job.run()
    except KeyboardInterrupt:
        failure, code = "interrupted (Ctrl-C); rerun the same command to go on", EXIT_INTERRUPTED
    except (GraphConflictError, DiskSpaceError) as exc:
        failure, code = str(exc), EXIT_REFUSED
    except RigError as exc:
        failure = str(exc)
        code = EXIT_GRAPH if not job._rig_up else EXIT_STOPPED
    except CatheterError as exc:
        failure, code = str(exc), EXIT_STOPPED
    finally:
        job.close()
    if failure:
        print(f"commission: stopped: {failure}", file=sys.stderr)
        print("commission: nothing was commissioned", file=sys.stderr)
    report = write_report(job, failure, job.out_dir / MODEL_DIR, TARGET_RMSE_DEG)
    print(f"commission: report: {report}")
    return code


def entry() -> None:
    """Console-script wrapper that turns the return code into the exit status."""
    sys.exit(main())


if __name__ == "__main__":
    entry()
