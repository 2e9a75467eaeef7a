"""The lab's history: every model version with its chain and errors, in plain files.

``<lab dir>/history.jsonl`` holds one JSON object per version, appended, never rewritten, so
a crash loses at most the line being written and any text tool can read it. A version names
its model directory, its chain, the effect that was added to its parent, and its RMSE on the
training and held-out bags (recorded with their sha256, so a later version scored on other
data is visible as such).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from catheter_models.errors import CatheterError
from catheter_models.models.base import Model, Recording
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.units import rad_to_deg

HISTORY_FILE = "history.jsonl"


class HistoryError(CatheterError):
    """The history file is unreadable or a line in it is malformed."""


@dataclass(frozen=True)
class Version:
    """One model version of the lab."""

    version: int
    model_dir: str
    kind: str
    chain: list[str]
    added: str | None
    parent: int | None
    rmse_train_deg: float | None
    rmse_test_deg: float | None
    test_sources: list[str] = field(default_factory=list)
    recorded_at: str = ""
    noise_floor_deg: float | None = None
    reference_deg: float | None = None
    """The black-box reference's held-out RMSE on the same split (see lab.floors)."""

    def label(self) -> str:
        """How the plot and the table name it."""
        return f"v{self.version}: " + " -> ".join(self.chain)


def _rmse_deg(model: Model, recordings: Sequence[Recording]) -> float | None:
    if not recordings or model.direction != "forward":
        return None  # the history plots bend errors; an inverse model's are in pascals
    return float(rad_to_deg(pooled_rmse(model, recordings)))


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def load_history(lab_dir: Path) -> list[Version]:
    """Every version recorded in ``lab_dir`` (empty if none yet)."""
    path = Path(lab_dir) / HISTORY_FILE
    if not path.exists():
        return []
    out = []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        if not line.strip():
            continue
        try:
            out.append(Version(**json.loads(line)))
        except (TypeError, ValueError) as exc:
            raise HistoryError(f"{path}:{n} is not a history entry: {exc}") from None
    return out


def record(
    lab_dir: Path,
    model_dir: Path,
    model: Model,
    *,
    train: Sequence[Recording] = (),
    test: Sequence[Recording] = (),
    added: str | None = None,
    parent: int | None = None,
    floors: tuple[float, float] | None = None,
) -> Version:
    """Append ``model`` (saved at ``model_dir``) as the next version; returns it."""
    lab_dir = Path(lab_dir)
    lab_dir.mkdir(parents=True, exist_ok=True)
    versions = load_history(lab_dir)
    chain = list(getattr(model, "chain", (model.kind,)))
    entry = Version(
        version=len(versions) + 1,
        model_dir=str(Path(model_dir).resolve()),
        kind=model.kind,
        chain=chain,
        added=added,
        parent=parent,
        rmse_train_deg=_rmse_deg(model, train),
        rmse_test_deg=_rmse_deg(model, test),
        test_sources=[r.source or r.name for r in test],
        recorded_at=time.strftime("%Y-%m-%dT%H:%M:%S"),
        noise_floor_deg=_finite(floors[0]) if floors else None,
        reference_deg=_finite(floors[1]) if floors else None,
    )
    with (lab_dir / HISTORY_FILE).open("a") as fh:
        fh.write(json.dumps(asdict(entry)) + "\n")
    return entry


def find(versions: Sequence[Version], model_dir: Path) -> Version | None:
    """The latest version recorded for ``model_dir``, if any."""
    wanted = str(Path(model_dir).resolve())
    hits = [v for v in versions if v.model_dir == wanted]
    return hits[-1] if hits else None


def history_text(versions: Sequence[Version]) -> str:
    """The table a person reads."""
    if not versions:
        return "no model versions recorded yet (catheter-lab add ... --lab DIR records them)"

    def fmt(v: float | None) -> str:
        return "    n/a" if v is None else f"{v:7.3f}"

    lines = [f"{'ver':>4} {'train':>7} {'held-out':>8}  added            chain"]
    for v in versions:
        lines.append(
            f"{v.version:>4} {fmt(v.rmse_train_deg)} {fmt(v.rmse_test_deg):>8}  "
            f"{(v.added or '-'):<16} {' -> '.join(v.chain)}"
        )
    return "\n".join(lines) + "\n(RMSE in deg)"


def plot_history(versions: Sequence[Version], path: Path) -> Path:
    """Held-out (and training) RMSE across versions: the error falling as effects are added."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 3.8), layout="constrained")
    ax = fig.add_subplot()
    x = np.arange(len(versions))
    for key, label, style in (
        ("rmse_test_deg", "held out", "o-"),
        ("rmse_train_deg", "training", "s--"),
    ):
        y = [getattr(v, key) for v in versions]
        if any(val is not None for val in y):
            ax.plot(x, [np.nan if val is None else val for val in y], style, label=label)
    ax.set_xticks(
        x, [f"v{v.version}\n+{v.added}" if v.added else f"v{v.version}" for v in versions]
    )
    for key, label, color, style in (
        ("noise_floor_deg", "noise floor", "tab:red", "-"),
        ("reference_deg", "black-box reference", "tab:purple", ":"),
    ):
        y = [getattr(v, key) for v in versions]
        if any(val is not None for val in y):
            ax.plot(
                x, [np.nan if val is None else val for val in y], style, color=color, label=label
            )
    ax.set_ylabel("RMSE [deg]")
    ax.set_ylim(bottom=0.0)
    ax.set_title("model versions: " + " | ".join(" -> ".join(v.chain) for v in versions[-1:]))
    ax.legend()
    fig.savefig(path, dpi=110)
    return path
