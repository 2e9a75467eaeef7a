"""Diagnose what physics a model lacks: residual tests, then a refit per catalogue effect.

For a grey-box model (or a DRDPI, taken as the default chain), every effect of
docs/effects.md that the chain lacks is added in turn, identified on the training data
(warm-started, seconds each) and scored on held-out data. Effects are ranked by the held-out
error they remove; one counts only if it removes at least ``min_reduction`` of it, so data
that a model already explains gets the verdict "adequate" and no effect is invented. Each
candidate carries the residual test that points at it, as its evidence, and its identified
parameter in physical units. Learned models (LSTM, c-LSTM, SVR) get the residual tests: they
have no blocks to add.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from catheter_models.errors import ParameterError
from catheter_models.lab.blocks import BLOCKS, block
from catheter_models.lab.greybox import GreyBox
from catheter_models.lab.residuals import ResidualReport, residual_tests
from catheter_models.models.base import FloatArray, Model, Recording
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.units import pa_to_bar, rad_to_deg

MIN_REDUCTION = 0.10
"""Least share of the held-out RMSE an effect must remove to be reported."""

EVIDENCE_TEST = {
    "pneumatic_lag": "rate_cross",
    "transport_delay": "input_cross",
    "creep": "autocorrelation",
    "tip_dynamics": "abs_rate_e",
    "drift": "time_trend",
}
"""The residual test whose signature each effect leaves (docs/effects.md, 'where the
residual shows it')."""


@dataclass
class Candidate:
    """One catalogue effect, added and refitted."""

    effect: str
    parameter: str
    value_si: float
    display: str
    rmse_train_deg: float
    rmse_test_deg: float
    expected_reduction: float
    measured_reduction: float
    evidence: str
    significant: bool
    model: GreyBox | None = field(default=None, repr=False)

    def line(self, rank: int) -> str:
        """The ranked list's line a person reads."""
        return (
            f"{rank}. {self.effect:<16} {self.parameter} = {self.display:<12} "
            f"held-out RMSE -{100 * self.measured_reduction:5.1f} % "
            f"(expected -{100 * self.expected_reduction:5.1f} % from training)  "
            f"evidence: {self.evidence}"
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, without the model."""
        return {k: v for k, v in self.__dict__.items() if k != "model"}


@dataclass
class Diagnosis:
    """What :func:`diagnose` found."""

    model_kind: str
    chain: list[str]
    rmse_train_deg: float
    rmse_test_deg: float
    candidates: list[Candidate]
    untestable: dict[str, str]
    residual_report: ResidualReport
    note: str = ""

    @property
    def significant(self) -> list[Candidate]:
        """Candidates that remove at least ``MIN_REDUCTION`` of the held-out error, best first."""
        return [c for c in self.candidates if c.significant]

    @property
    def verdict(self) -> str:
        """'adequate', or the effect to add next."""
        return "adequate" if not self.significant else f"add {self.significant[0].effect}"

    def text(self) -> str:
        """The report a person reads in the terminal."""
        lines = [
            f"Diagnosis of a {self.model_kind} model: {' -> '.join(self.chain)}",
            f"  RMSE {self.rmse_train_deg:.3f} deg on training data, "
            f"{self.rmse_test_deg:.3f} deg held out",
        ]
        sig = self.residual_report.significant()
        lines.append(
            "  residual tests beyond their 95 % band: " + (", ".join(sig) if sig else "none")
        )
        if self.note:
            lines.append(f"  {self.note}")
        if self.candidates:
            lines.append("  effects the model lacks, ranked by the held-out error they remove:")
            lines += ["    " + c.line(i) for i, c in enumerate(self.candidates, start=1)]
        for effect, why in self.untestable.items():
            lines.append(f"    {effect}: not testable here: {why}")
        if self.candidates:
            if self.significant:
                best = self.significant[0]
                lines.append(
                    f"  verdict: {best.effect} is missing ({best.parameter} = {best.display}); "
                    f"add it: catheter-lab add {best.effect} MODEL -o NEW --train ..."
                )
            else:
                lines.append(
                    f"  verdict: adequate: no catalogue effect removes {100 * MIN_REDUCTION:.0f} % "
                    "of the held-out error"
                )
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "model_kind": self.model_kind,
            "chain": self.chain,
            "rmse_train_deg": self.rmse_train_deg,
            "rmse_test_deg": self.rmse_test_deg,
            "verdict": self.verdict,
            "candidates": [c.to_dict() for c in self.candidates],
            "untestable": self.untestable,
            "residual_tests": self.residual_report.to_dict(),
            "note": self.note,
        }


def _rmse_deg(model: Model, recordings: Sequence[Recording]) -> float:
    return float(rad_to_deg(pooled_rmse(model, recordings)))


def _residual_report(model: Model, recordings: Sequence[Recording]) -> tuple[ResidualReport, float]:
    """The residual tests on ``recordings`` and the pooled RMSE of the same residual (SI)."""
    residual: list[FloatArray] = []
    inputs: list[FloatArray] = []
    segments: list[tuple[int, int]] = []
    start = 0
    for r in recordings:
        x, y = r.io(model.direction)
        residual.append(np.asarray(model.predict(x) - y, dtype=float))
        inputs.append(np.asarray(x, dtype=float))
        segments.append((start, start + x.size))
        start += x.size
    pooled = np.concatenate(residual)
    report = residual_tests(
        pooled, np.concatenate(inputs), recordings[0].rate_hz, segments=segments
    )
    return report, float(np.sqrt(np.mean(pooled**2)))


def diagnose(
    model: Model,
    train: Sequence[Recording],
    test: Sequence[Recording],
    *,
    effects: Sequence[str] | None = None,
    min_reduction: float = MIN_REDUCTION,
    progress: bool = False,
) -> Diagnosis:
    """Residual tests on ``test``; for a grey box, a refit and score per missing effect.

    Raises:
        ParameterError: An unknown effect name, or no training / held-out data.
    """
    if not train or not test:
        raise ParameterError("diagnose needs training recordings and held-out test recordings")
    report, rmse_test_si = _residual_report(model, test)
    if isinstance(model, DRDPI):
        model = GreyBox.from_drdpi(model)
    if not isinstance(model, GreyBox):
        forward = model.direction == "forward"
        return Diagnosis(
            model_kind=model.kind,
            chain=[model.kind],
            rmse_train_deg=_rmse_deg(model, train) if forward else float("nan"),
            rmse_test_deg=float(rad_to_deg(rmse_test_si)) if forward else float("nan"),
            candidates=[],
            untestable={},
            residual_report=report,
            note=(
                f"a {model.kind} model has no physical blocks to add: residual tests only "
                "(a grey-box model of the same data can be diagnosed effect by effect)"
            ),
        )
    wanted = list(effects) if effects is not None else [e for e in BLOCKS if e not in model.effects]
    for e in wanted:  # unknown or present names fail here, before any fitting
        block(e)
        if e in model.effects:
            raise ParameterError(f"the model has {e!r} already: {' -> '.join(model.chain)}")
    base_train, base_test = _rmse_deg(model, train), float(rad_to_deg(rmse_test_si))
    rate = train[0].rate_hz
    xs = [pa_to_bar(r.pressure_pa) for r in train]
    candidates: list[Candidate] = []
    untestable: dict[str, str] = {}
    for e in wanted:
        problem = block(e).excitation_problem(xs, rate)
        if problem:
            untestable[e] = problem
            continue
        fitted = model.with_effect(e).fit(train, progress=progress)
        rmse_train, rmse_test = _rmse_deg(fitted, train), _rmse_deg(fitted, test)
        spec = next(p for p in BLOCKS[e].params if p.name == BLOCKS[e].primary)
        value = fitted.block_values()[e][spec.name]
        measured = (base_test - rmse_test) / base_test
        expected = (base_train - rmse_train) / base_train
        evidence = report.by_name(EVIDENCE_TEST[e]).evidence()
        candidates.append(
            Candidate(
                effect=e,
                parameter=spec.name,
                value_si=value,
                display=spec.display(value),
                rmse_train_deg=rmse_train,
                rmse_test_deg=rmse_test,
                expected_reduction=expected,
                measured_reduction=measured,
                evidence=evidence,
                significant=measured >= min_reduction and expected >= 0.5 * min_reduction,
                model=fitted,
            )
        )
    candidates.sort(key=lambda c: c.measured_reduction, reverse=True)
    return Diagnosis(
        model_kind=model.kind,
        chain=list(model.chain),
        rmse_train_deg=base_train,
        rmse_test_deg=base_test,
        candidates=candidates,
        untestable=untestable,
        residual_report=report,
    )


def plot_diagnosis(diagnosis: Diagnosis, path: Path) -> Path:
    """Held-out RMSE of the model and of each candidate refit: why the verdict is what it is."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 3.6), layout="constrained")
    names = ["model", *[c.effect for c in diagnosis.candidates]]
    values = [diagnosis.rmse_test_deg, *[c.rmse_test_deg for c in diagnosis.candidates]]
    colors = ["grey", *["tab:green" if c.significant else "tab:blue" for c in diagnosis.candidates]]
    ax.bar(names, values, color=colors)
    ax.axhline(
        diagnosis.rmse_test_deg * (1 - MIN_REDUCTION),
        color="black",
        lw=0.8,
        ls="--",
        label=f"{100 * MIN_REDUCTION:.0f} % below the model: significant",
    )
    ax.set_ylabel("held-out RMSE [deg]")
    ax.set_title(f"{' -> '.join(diagnosis.chain)}: verdict {diagnosis.verdict}")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.3), fontsize=8, frameon=False)
    plt.setp(ax.get_xticklabels(), rotation=20, ha="right")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
