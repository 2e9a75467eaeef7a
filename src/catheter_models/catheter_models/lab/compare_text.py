"""How a comparison (:mod:`catheter_models.lab.compare`) reads: terminal text, JSON and units.

The numbers of a comparison are SI (rad, Pa); people read degrees and bar. This module holds
that conversion and the two plain forms of a result, the table printed in the terminal and the
JSON summary written beside the HTML report, apart from the numerics so that changing a
column touches no arithmetic. The result classes' ``text`` and ``to_dict`` methods call these.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, Final

from catheter_models.errors import ParameterError
from catheter_models.metrics import ErrorMetrics
from catheter_models.models.base import Direction
from catheter_models.units import PA_PER_BAR, rad_to_deg

if TYPE_CHECKING:
    from catheter_models.lab.compare import Comparison, OutputUnit, Segment

MIXED: Final = "mixed"
"""Regime name of a segment in which no single regime covers more than half the samples."""

# SI unit of a model's output -> (display unit, factor from SI to display), for people.
_DISPLAY: Final[Mapping[str, tuple[str, float]]] = {
    "rad": ("deg", float(rad_to_deg(1.0))),
    "pa": ("bar", 1.0 / PA_PER_BAR),
}
# Any unit a caller may ask Segment.text for -> factor from the output's SI unit.
_SCALE: Final[Mapping[str, float]] = {
    "deg": float(rad_to_deg(1.0)),
    "rad": 1.0,
    "bar": 1.0 / PA_PER_BAR,
    "Pa": 1.0,
    "pa": 1.0,
}


def display_unit_of(output_unit: OutputUnit) -> tuple[str, float]:
    """(Unit people read, factor from the SI unit) for a model output in ``output_unit``."""
    return _DISPLAY[output_unit]


def _scale(unit: str) -> float:
    try:
        return _SCALE[unit]
    except KeyError:
        valid = ", ".join(_SCALE)
        raise ParameterError(f"unknown display unit {unit!r}; valid: {valid}") from None


def mapping_text(direction: Direction) -> str:
    """Which way the model maps, as a person reads it."""
    if direction == "forward":
        return "forward: pressure -> angle"
    return "inverse: angle -> pressure"


def segment_text(segment: Segment, unit: str) -> str:
    """One line for a person, e.g. ``bag  12.00-13.00 s  peak  RMSE 2.1 deg ...``.

    Args:
        segment: The segment.
        unit: Display unit: ``deg`` or ``rad`` for forward models, ``bar`` or ``Pa`` for
            inverse ones.
    """
    k = _scale(unit)
    return (
        f"{segment.recording}  {segment.start_s:.2f}-{segment.end_s:.2f} s  "
        f"{segment.regime:<11}  "
        f"RMSE {segment.rmse * k:.3g} {unit}  max |error| {segment.max_abs * k:.3g} {unit}  "
        f"(n={segment.n_samples})"
    )


def comparison_text(comparison: Comparison) -> str:
    """The report a person reads in the terminal (MAE = maximum absolute error)."""
    unit, k = comparison.display_unit, comparison.display_scale
    n = comparison.overall.n_samples
    rates = sorted({r.rate_hz for r in comparison.recordings})
    duration_s = sum(r.t_s.size / r.rate_hz for r in comparison.recordings)
    lines = [
        f"Compare {comparison.model_kind} ({mapping_text(comparison.direction)}) with "
        f"{len(comparison.recordings)} "
        f"recording(s): {n} samples, {duration_s:.1f} s at "
        + ", ".join(f"{r:g}" for r in rates)
        + " Hz",
        f"  RMSE  {comparison.overall.rmse * k:8.3f} {unit}",
        f"  MAE   {comparison.overall.mae * k:8.3f} {unit}   (maximum absolute error, eq. 5.13)",
        "  NRMSE "
        + (
            "     n/a"
            if comparison.overall.nrmse is None
            else f"{100 * comparison.overall.nrmse:8.2f} %"
        ),
        "",
        f"  by regime      RMSE [{unit}]  MAE [{unit}]   NRMSE  samples",
    ]
    for name, m in comparison.by_regime.items():
        if m is None:
            lines.append(f"    {name:<12} (too few samples)")
            continue
        nrmse = "    n/a" if m.nrmse is None else f"{100 * m.nrmse:6.2f} %"
        lines.append(
            f"    {name:<12} {m.rmse * k:10.3f}  {m.mae * k:9.3f}  {nrmse}  {m.n_samples:7d}"
        )
    if len(comparison.recordings) > 1:
        lines += ["", "  by recording"]
        width = max(len(r.name) for r in comparison.recordings)
        for r in comparison.recordings:
            lines.append(f"    {r.name:<{width}}  {r.overall.format(unit)}")
    lines += ["", "  worst segments (time from the recording's start)"]
    if not comparison.worst:
        lines.append("    none")
    for i, seg in enumerate(comparison.worst, 1):
        lines.append(f"    {i}. {segment_text(seg, unit)}")
    return "\n".join(lines)


def comparison_dict(comparison: Comparison) -> dict[str, Any]:
    """JSON-ready summary in display units (deg or bar; NRMSE a fraction)."""
    unit, k = comparison.display_unit, comparison.display_scale
    return {
        "model_kind": comparison.model_kind,
        "direction": comparison.direction,
        "unit": unit,
        "overall": _metrics_dict(comparison.overall, unit, k),
        "by_regime": {name: _metrics_dict(m, unit, k) for name, m in comparison.by_regime.items()},
        "recordings": [
            {
                "name": r.name,
                "rate_hz": r.rate_hz,
                "duration_s": r.t_s.size / r.rate_hz,
                "overall": _metrics_dict(r.overall, unit, k),
                "by_regime": {name: _metrics_dict(m, unit, k) for name, m in r.by_regime.items()},
            }
            for r in comparison.recordings
        ],
        "worst": [
            {
                "recording": s.recording,
                "start_s": s.start_s,
                "end_s": s.end_s,
                "regime": s.regime,
                f"rmse_{unit}": s.rmse * k,
                f"max_abs_{unit}": s.max_abs * k,
                "n_samples": s.n_samples,
            }
            for s in comparison.worst
        ],
    }


def _metrics_dict(m: ErrorMetrics | None, unit: str, k: float) -> dict[str, Any] | None:
    if m is None:
        return None
    return {
        f"rmse_{unit}": m.rmse * k,
        f"mae_{unit}": m.mae * k,
        "nrmse": m.nrmse,
        "n_samples": m.n_samples,
    }
