"""Diagnose what physics a model lacks: floors, residual tests, then a refit per change.

For a grey-box model (or a DRDPI, taken as the default chain) the diagnosis tries every
change the lab knows, each refitted on the training data and scored on held-out data:

* **another hysteresis core** (:mod:`.cores`) with the same blocks: the core's law may be
  the largest miss, and a wrong core absorbs the add-on effects it half mimics;
* **every catalogue effect** the chain lacks, as a block (:mod:`.blocks`), searched over its
  whole range with a linear core re-solved at every point (:mod:`.greybox`).

Changes are ranked by the held-out error they remove; the next change is a significant core
change if there is one, else the best significant block. One is **significant** only if it
removes at least ``min_reduction`` of the held-out error (and some on training data), and,
for an effect, only if it earns its place: it helps where its effect shows (the regimes its
block names, ``Block.regimes``) and its parameter is not pinned to the end of its range (a
block at its limit is standing in for something else).

The verdict is judged against two floors measured on the same data (:mod:`.floors`): the
sensor's noise, and a black-box reference fitted on the same split. **Adequate** only when
the model is within :data:`NEAR_NOISE` of the noise floor; otherwise, with no significant
change, **unexplained**: how far above the floors, in which regimes, with which residual
signature, and whether a black box does any better (when none does, the rest does not follow
from the pressure alone). The lab never names an effect that does not earn its place on
held-out data, nor one whose fitted values its physics never has (a 5 ms "transport delay"
is the valve's own response; :meth:`.blocks.Block.unlike_effect`), nor one that its rival on
the core's other side fits better (:attr:`.blocks.Block.rival`).

Learned models (LSTM, c-LSTM, SVR) get the floors and the residual tests: they have no blocks.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from concurrent.futures import Executor, Future
from contextlib import nullcontext
from typing import Final

import numpy as np
import numpy.typing as npt

from catheter_models.errors import ParameterError
from catheter_models.lab.diagnose_plot import plot_diagnosis
from catheter_models.lab.floors import noise_std_deg
from catheter_models.lab.references import FILTER_BANK, REFERENCES, reference_floor
from catheter_models.lab.refit_pool import (
    RefitWorkerError,
    default_workers,
    lab_pool,
    refit_executor,
)
from catheter_models.lab.residuals import ResidualReport, residual_tests
from catheter_models.lab.verdicts import (
    CORE_CHANGE,
    MIN_REDUCTION,
    NEAR_NOISE,
    NEAR_REFERENCE,
    Candidate,
    Diagnosis,
    Floors,
)
from catheter_models.metrics import classify_regimes
from catheter_models.models.base import FloatArray, Model, Recording
from catheter_models.models.blocks import BLOCKS, FORMS, block
from catheter_models.models.cores import CORES, one_blas_thread
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.models.greybox import GreyBox
from catheter_models.units import pa_to_bar, rad_to_deg

BoolArray = npt.NDArray[np.bool_]
VENTED_BAR: Final = 0.3
"""Drive below which the muscle is vented ('vented' regime): below any PAM's opening
pressure (about 1 bar), so the tip is at rest whatever the plant."""

REGIME_SHARE: Final = 0.5
"""An effect must remove, in its regimes, at least this share of what it removes overall."""

RIVAL_SHARE: Final = 0.9
"""A block's rival (the same signature from the core's other side) that leaves at most this
share of the block's held-out error takes the block's name away. Development seeds 11-14,
both foreign plants, free-weight core: a lag after the core left 0.94-1.39x the error of the
pneumatic lag with the lag at the valve and 0.20-0.99x with it on the sensor; 1.02-1.63x the
error of a transport delay with a delay hidden, 0.16-0.77x with a sensor lag."""


def _rmse_deg(model: Model, recordings: Sequence[Recording]) -> float:
    return float(rad_to_deg(pooled_rmse(model, recordings)))


def _residuals(model: Model, recordings: Sequence[Recording]) -> list[FloatArray]:
    out = []
    for r in recordings:
        x, y = r.io(model.direction)
        out.append(np.asarray(model.predict(x) - y, dtype=float))
    return out


def _residual_report(
    recordings: Sequence[Recording], residual: Sequence[FloatArray], direction: str
) -> ResidualReport:
    """The residual tests on ``recordings``' residuals (inputs pooled by recording)."""
    inputs: list[FloatArray] = []
    segments: list[tuple[int, int]] = []
    start = 0
    for r in recordings:
        x, _ = r.io(direction)  # type: ignore[arg-type]
        inputs.append(np.asarray(x, dtype=float))
        segments.append((start, start + x.size))
        start += x.size
    return residual_tests(
        np.concatenate(residual), np.concatenate(inputs), recordings[0].rate_hz, segments=segments
    )


class _Regimes:
    """The held-out recordings' regime masks, computed once, and RMSE per regime."""

    def __init__(self, recordings: Sequence[Recording]) -> None:
        self.masks: dict[str, BoolArray] = {}
        parts: dict[str, list[BoolArray]] = {}
        for r in recordings:
            t = np.arange(r.pressure_pa.size) / r.rate_hz
            for name, mask in classify_regimes(t, r.pressure_pa, r.angle_rad).items():
                parts.setdefault(name, []).append(np.asarray(mask, dtype=bool))
            # Unlike 'deadband', no test on the measured bend: a drifted bend is still at rest.
            parts.setdefault("vented", []).append(pa_to_bar(r.pressure_pa) < VENTED_BAR)
        self.masks = {k: np.concatenate(v) for k, v in parts.items()}

    def rmse_deg(self, residual: Sequence[FloatArray], names: Sequence[str]) -> float:
        pooled = np.concatenate(residual)
        mask = np.zeros(pooled.size, dtype=bool)
        for n in names:
            if n in self.masks:
                mask |= self.masks[n]
        if mask.sum() < 25:
            return float("nan")
        return float(rad_to_deg(np.sqrt(np.mean(pooled[mask] ** 2))))

    def table(self, residual: Sequence[FloatArray]) -> dict[str, float]:
        return {k: v for k in self.masks if math.isfinite(v := self.rmse_deg(residual, [k]))}


def _signature(
    residual: Sequence[FloatArray],
    regimes: _Regimes,
    report: ResidualReport,
    noise_deg: float,
) -> list[str]:
    """The residual's shape in words a person checks against the plots."""
    out: list[str] = []
    pooled = rad_to_deg(np.concatenate(residual))
    plateau = regimes.masks.get("plateau")
    if plateau is not None and plateau.any():
        # On each plateau, how far the residual moves from its start to its end.
        edges = np.flatnonzero(np.diff(np.concatenate([[0], plateau.astype(int), [0]])))
        moves = [
            pooled[b - 1] - pooled[a]
            for a, b in zip(edges[::2], edges[1::2], strict=True)
            if b - a > 25
        ]
        if moves:
            typical = float(np.median(np.abs(moves)))
            if typical > 3.0 * noise_deg:
                out.append(
                    f"keeps moving on plateaus (median {typical:.2f} deg from a plateau's "
                    "start to its end): slow dynamics the model lacks"
                )
    labels = {
        "rate_cross": "follows the pressure's rate (a lag, or rate dependence of another form)",
        "input_cross": "follows the pressure itself (a gain or delay error)",
        "time_trend": "trends with time within a recording (a drift of offset or gain)",
        "u2_e": "depends on the pressure's level (the static curve's shape)",
        "abs_rate_e": "grows with the speed of the pressure (fast-motion dynamics)",
    }
    for name in report.significant():
        if name in labels:
            out.append(f"{labels[name]}: {report.by_name(name).evidence()}")
    return out


def _changes(
    model: GreyBox, effects: Sequence[str] | None, cores: Sequence[str] | None
) -> tuple[list[str], list[str]]:
    """The effects and cores to try; unknown or present names are refused before any fit."""
    wanted = list(effects) if effects is not None else [e for e in BLOCKS if e not in model.effects]
    for e in wanted:
        block(e)
        if e in model.effects:
            raise ParameterError(f"the model has {e!r} already: {' -> '.join(model.chain)}")
    other_cores = list(cores) if cores is not None else [c for c in CORES if c != model.core_name]
    for c in other_cores:
        if c not in CORES:
            raise ParameterError(f"unknown core {c!r}; known cores: {', '.join(CORES)}")
    return wanted, other_cores


def _pinned(model: GreyBox, effect: str) -> list[str]:
    """Parameters of ``effect``'s block that ended at a bound of their range."""
    pinned: list[str] = []
    if BLOCKS[effect].ends_are_plain:
        return pinned
    for p, v in zip(BLOCKS[effect].params, model.blocks_[effect], strict=True):
        span = p.high - p.low
        if p.low > 0.0 and p.high / p.low > 10.0:
            width = math.log(p.high / p.low)
            at_low = math.log(v / p.low) < 0.01 * width
            at_high = math.log(p.high / v) < 0.01 * width
        else:
            at_low, at_high = v - p.low < 0.01 * span, p.high - v < 0.01 * span
        # Zero (no delay, no share, no growth of the tip's damping) and the block's earlier,
        # simpler form (one creep lag, a lag without a flow limit) are plain answers; any
        # other end of a range means the block stands in for something else.
        plain_low = p.plain_ends or p.low in (0.0, p.absent)
        plain_high = p.plain_ends or p.high == p.absent
        if (at_high and not plain_high) or (at_low and not plain_low):
            pinned.append(f"{p.name} at the end of its range ({p.display(v)})")
    return pinned


@one_blas_thread
def _fit_change(
    model: GreyBox, change: str, train: Sequence[Recording], progress: bool = False
) -> GreyBox:
    """One change refitted (a worker's task): ``core:<name>`` or an effect's name."""
    if change.startswith(f"{CORE_CHANGE}:"):
        return model.with_core(change.split(":", 1)[1]).fit(train, progress=progress)
    return model.with_effect(change).fit(train, progress=progress)


def _removes_enough(measured: float, expected: float, min_reduction: float) -> bool:
    """Whether a change removes enough held-out error (and some on the training data)."""
    return measured >= min_reduction and expected >= 0.5 * min_reduction


def _block_doubts(
    fitted: GreyBox,
    effect: str,
    base_residual: Sequence[FloatArray],
    *,
    regimes: _Regimes,
    test: Sequence[Recording],
    measured: float,
) -> tuple[float, list[str]]:
    """The share ``fitted`` removes in ``effect``'s regimes, and why it would not count.

    Pinned parameters, values the effect never has, or help least where the effect shows;
    the rival check needs one more refit and is the caller's.
    """
    before = regimes.rmse_deg(base_residual, BLOCKS[effect].regimes)
    after = regimes.rmse_deg(_residuals(fitted, test), BLOCKS[effect].regimes)
    in_regime = (before - after) / before if before > 0 else float("nan")
    doubts = _pinned(fitted, effect) + block(effect).unlike_effect(fitted.blocks_[effect])
    if math.isfinite(in_regime) and in_regime < REGIME_SHARE * measured:
        doubts.append(
            f"helps least where {effect} shows ({', '.join(BLOCKS[effect].regimes)}: "
            f"{-100 * in_regime:+.0f} % there)"  # '+59 %': it adds error there
        )
    return in_regime, doubts


def _pair_cores_with_the_leading_block(
    candidates: list[Candidate],
    train: Sequence[Recording],
    test: Sequence[Recording],
    *,
    regimes: _Regimes,
    min_reduction: float,
    progress: bool,
    pool: Executor,
) -> None:
    """Refit each significant core with the leading significant block, where cores compete.

    Where two or more core changes earn their place and a block does too, the cores are
    ranked by the lower of their held-out errors alone and with that block. A core can
    absorb an effect: on a Maxwell-slip plant with a hidden drift (seed 1004), the Bouc-Wen
    core alone beat the free-weight core held out (0.93 against 0.98 deg), but the
    free-weight core had fitted the drift in training (0.19 deg there) and with the drift
    block reached 0.20 deg, while the Bouc-Wen core with it stayed at 0.99. One more refit per
    competing core, all in the pool at once. Sets ``paired_with`` and ``paired_test_deg``.

    The pair counts only where the block would earn its place on that core in the next
    diagnosis (the same share removed and the same checks, its rival aside): on a Bouc-Wen
    plant's drift (seed 1005), the Bouc-Wen core with a drift block that helped least at
    rest outranked the free-weight core, and the next diagnosis withheld the drift.
    """
    significant = [c for c in candidates if c.significant]
    cores = {c.model: c for c in significant if c.is_core and c.model is not None}
    blocks = [c for c in significant if not c.is_core]
    if len(cores) < 2 or not blocks:
        return
    lead = blocks[0].effect
    fits = {alone: pool.submit(_fit_change, alone, lead, train, progress) for alone in cores}
    for alone, core in cores.items():
        paired = fits[alone].result()
        rmse_train, rmse_test = _rmse_deg(paired, train), _rmse_deg(paired, test)
        measured = (core.rmse_test_deg - rmse_test) / core.rmse_test_deg
        expected = (core.rmse_train_deg - rmse_train) / core.rmse_train_deg
        _, doubts = _block_doubts(
            paired, lead, _residuals(alone, test), regimes=regimes, test=test, measured=measured
        )
        if not _removes_enough(measured, expected, min_reduction):
            doubts.insert(0, f"removes {100 * measured:.0f} % on this core")
        core.paired_with, core.paired_test_deg, core.paired_doubts = lead, rmse_test, doubts


@one_blas_thread
def _reference(
    kind: str, train: Sequence[Recording], test: Sequence[Recording]
) -> tuple[float, str, dict[str, float]]:
    return reference_floor(kind, train, test)


@one_blas_thread
def diagnose(
    model: Model,
    train: Sequence[Recording],
    test: Sequence[Recording],
    *,
    effects: Sequence[str] | None = None,
    cores: Sequence[str] | None = None,
    reference: bool | str = True,
    reference_deg: float | None = None,
    reference_name: str = FILTER_BANK,
    min_reduction: float = MIN_REDUCTION,
    progress: bool = False,
    workers: int | None = None,
    pool: Executor | None = None,
    ray: str | None = None,
) -> Diagnosis:
    """Floors and residual tests on ``test``; for a grey box, a refit and score per change.

    Args:
        model: A fitted model (a DRDPI is taken as the default grey-box chain).
        train: Recordings every change is refitted on.
        test: Held-out recordings every change is scored on.
        effects: Catalogue effects to try (default: every one the chain lacks).
        cores: Cores to try instead of the chain's (default: every other one; ``[]``: none).
        reference: The black-box reference to fit: one of
            :data:`~catheter_models.lab.floors.REFERENCES` (``True``: the filter bank,
            seconds; ``"recurrent"`` or ``"stronger"``: minutes); ``False``: none, only the
            noise floor.
        reference_deg: The reference's held-out RMSE, already fitted on this same split
            (``explain`` passes its first step's): used as it is, not fitted again.
        reference_name: What ``reference_deg`` is (said beside it).
        min_reduction: Least share of the held-out error a change must remove.
        progress: Show the core's search progress (refits then run in this process).
        workers: Processes for the refits, which are independent (default: one per core
            this process may use; 1: in this process). Results do not depend on it.
        pool: An executor to run the refits in, kept across calls (``explain`` passes one so
            that its steps do not each start processes); overrides ``workers``.
        ray: A Ray cluster's address (``auto``, ``ray://host:port``, or ``local`` for a
            Ray started here) to run the refits on instead of local processes; the same
            answers (:class:`~catheter_models.lab.refit_pool.RayExecutor`).

    Raises:
        ParameterError: An unknown effect or core, or no training / held-out data.
        RefitWorkerError: A worker process died before it answered.
    """
    if not train or not test:
        raise ParameterError("diagnose needs training recordings and held-out test recordings")
    wanted: list[str] = []
    other_cores: list[str] = []
    chain = GreyBox.chain_of(model)
    if chain is not None:
        wanted, other_cores = _changes(chain, effects, cores)
    forward = model.direction == "forward"
    kind = "filter_bank" if reference is True else reference or ""
    if kind and kind not in REFERENCES:
        raise ParameterError(f"unknown reference {kind!r}; one of {', '.join(REFERENCES)}")
    fit_reference = kind if kind and forward and reference_deg is None else ""
    tasks = len(other_cores) + len(wanted) + (1 if fit_reference else 0)
    with (
        refit_executor(workers, progress=progress, tasks=tasks, ray=ray)
        if pool is None or progress
        else nullcontext(pool)
    ) as chosen:
        return _diagnose(
            model,
            train,
            test,
            wanted,
            other_cores,
            chain=chain,
            reference=fit_reference,
            given_reference=(
                (reference_deg, reference_name) if kind and reference_deg is not None else None
            ),
            min_reduction=min_reduction,
            progress=progress,
            pool=chosen,
        )


def _floors(
    noise_deg: float, reference: Future[tuple[float, str, dict[str, float]]] | None
) -> Floors:
    if reference is None:
        return Floors(noise_deg, math.nan)
    deg, name, fitted = reference.result()
    return Floors(noise_deg, deg, name, fitted)


def _diagnose(
    model: Model,
    train: Sequence[Recording],
    test: Sequence[Recording],
    wanted: list[str],
    other_cores: list[str],
    *,
    chain: GreyBox | None,
    reference: str,
    given_reference: tuple[float, str] | None,
    min_reduction: float,
    progress: bool,
    pool: Executor,
) -> Diagnosis:
    """:func:`diagnose` once its changes are known and its pool chosen.

    ``chain`` is the model as the chain it edits (:meth:`GreyBox.chain_of`).
    """
    noise = noise_std_deg(test)
    forward = model.direction == "forward"
    reference_future: Future[tuple[float, str, dict[str, float]]] | None = None
    if reference:
        reference_future = pool.submit(_reference, reference, train, test)
    elif given_reference is not None and forward:
        reference_future = Future()
        deg, name = given_reference
        reference_future.set_result((deg, name, {name: deg}))
    residual = _residuals(model, test)
    report = _residual_report(test, residual, model.direction)
    rmse_test = float(rad_to_deg(np.sqrt(np.mean(np.concatenate(residual) ** 2))))
    regimes = _Regimes(test)
    regimes_deg = regimes.table(residual) if forward else {}
    signature = _signature(residual, regimes, report, noise) if forward else []
    if chain is None:
        floors = _floors(noise, reference_future)
        return Diagnosis(
            model_kind=model.kind,
            chain=[model.kind],
            rmse_train_deg=_rmse_deg(model, train) if forward else float("nan"),
            rmse_test_deg=rmse_test if forward else float("nan"),
            candidates=[],
            untestable={},
            residual_report=report,
            floors=floors,
            regimes_deg=regimes_deg,
            signature=signature,
            note=(
                f"a {model.kind} model has no physical blocks to add: floors and residual "
                "tests only (a grey-box model of the same data can be diagnosed effect by "
                "effect)"
            ),
        )
    rate = train[0].rate_hz
    xs = [pa_to_bar(r.pressure_pa) for r in train]
    candidates: list[Candidate] = []
    untestable: dict[str, str] = {}
    for e in wanted:
        problem = block(e).excitation_problem(xs, rate)
        if problem:
            untestable[e] = problem
    # Every refit is independent: all go to the pool at once, and are scored here in order.
    fits: dict[str, Future[GreyBox]] = {}
    for c in other_cores:
        fits[c] = pool.submit(_fit_change, chain, f"{CORE_CHANGE}:{c}", train, progress)
    for e in wanted:
        if e not in untestable:
            fits[e] = pool.submit(_fit_change, chain, e, train, progress)
            rival = BLOCKS[e].rival
            if rival and rival not in chain.effects and rival not in fits:
                fits[rival] = pool.submit(_fit_change, chain, rival, train, progress)
    floors = _floors(noise, reference_future)
    base_train = _rmse_deg(chain, train)

    def scored(change: str, fitted: GreyBox) -> tuple[float, float, float, float]:
        rmse_train, rmse_test_new = _rmse_deg(fitted, train), _rmse_deg(fitted, test)
        return (
            rmse_train,
            rmse_test_new,
            (base_train - rmse_train) / base_train,
            (rmse_test - rmse_test_new) / rmse_test,
        )

    for c in other_cores:
        fitted = fits[c].result()
        rmse_train, rmse_test_new, expected, measured = scored(c, fitted)
        candidates.append(
            Candidate(
                effect=f"{CORE_CHANGE}:{c}",
                parameter="law",
                value_si=float("nan"),
                display=c,
                rmse_train_deg=rmse_train,
                rmse_test_deg=rmse_test_new,
                expected_reduction=expected,
                measured_reduction=measured,
                evidence="",
                significant=_removes_enough(measured, expected, min_reduction),
                model=fitted,
            )
        )
    rival_deg_by_name: dict[str, float] = {}
    for e in wanted:
        if e in untestable:
            continue
        fitted = fits[e].result()
        rmse_train, rmse_test_new, expected, measured = scored(e, fitted)
        spec = next(p for p in BLOCKS[e].params if p.name == BLOCKS[e].primary)
        value = fitted.block_values()[e][spec.name]
        in_regime, doubts = _block_doubts(
            fitted, e, residual, regimes=regimes, test=test, measured=measured
        )
        rival = BLOCKS[e].rival
        caveats: list[str] = []
        if rival in fits:
            if rival not in rival_deg_by_name:  # one rival serves several blocks: score once
                rival_deg_by_name[rival] = _rmse_deg(fits[rival].result(), test)
            rival_deg = rival_deg_by_name[rival]
            side = FORMS[rival].side
            if rival_deg < RIVAL_SHARE * rmse_test_new:
                doubts.append(
                    f"{rival} (on the core's {side} side) fits better held out "
                    f"({rival_deg:.3f} deg against {rmse_test_new:.3f}): the effect is on "
                    f"the {side} side, where the catalogue has no block for it"
                )
            elif RIVAL_SHARE * rival_deg < rmse_test_new:
                # Within the band the rule does not decide: the held-out data do not tell
                # the sides apart (seen held out: a sensor's lag named pneumatic_lag with
                # its rival 9 % better), so the name stands with that said beside it.
                caveats.append(
                    f"which side is not certain: {rival} (on the core's {side} side) fits "
                    f"about as well held out ({rival_deg:.3f} deg against "
                    f"{rmse_test_new:.3f}): {FORMS[rival].stands_for} would look the same"
                )
        removes = _removes_enough(measured, expected, min_reduction)
        significant = removes and not doubts
        candidates.append(
            Candidate(
                effect=e,
                parameter=spec.name,
                value_si=value,
                display=spec.display(value),
                rmse_train_deg=rmse_train,
                rmse_test_deg=rmse_test_new,
                expected_reduction=expected,
                measured_reduction=measured,
                evidence=report.by_name(BLOCKS[e].evidence_test).evidence(),
                significant=significant,
                regime_reduction=in_regime,
                doubts=doubts if removes else [],
                caveats=caveats if significant else [],
                model=fitted,
            )
        )
    candidates.sort(key=lambda c: c.measured_reduction, reverse=True)
    _pair_cores_with_the_leading_block(
        candidates,
        train,
        test,
        regimes=regimes,
        min_reduction=min_reduction,
        progress=progress,
        pool=pool,
    )
    return Diagnosis(
        model_kind=chain.kind,
        chain=list(chain.chain),
        rmse_train_deg=base_train,
        rmse_test_deg=rmse_test,
        candidates=candidates,
        untestable=untestable,
        residual_report=report,
        floors=floors,
        regimes_deg=regimes_deg,
        signature=signature,
    )


# The verdict's types, the pool and the plot live apart (verdicts, refit_pool, diagnose_plot);
# the diagnosis is still where a user imports them from.
__all__ = [
    "CORE_CHANGE",
    "MIN_REDUCTION",
    "NEAR_NOISE",
    "NEAR_REFERENCE",
    "Candidate",
    "Diagnosis",
    "Floors",
    "RefitWorkerError",
    "default_workers",
    "diagnose",
    "lab_pool",
    "plot_diagnosis",
    "refit_executor",
]
