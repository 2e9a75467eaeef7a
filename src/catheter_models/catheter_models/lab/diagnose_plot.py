"""The picture of a diagnosis: held-out RMSE of the model, of each change, and the floors."""

from __future__ import annotations

import math
from pathlib import Path

from catheter_models.lab.verdicts import MIN_REDUCTION, Diagnosis


def plot_diagnosis(diagnosis: Diagnosis, path: Path) -> Path:
    """Held-out RMSE of the model, of each change, and the floors: why the verdict."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.0, 3.8), layout="constrained")
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
    floors = diagnosis.floors
    if math.isfinite(floors.noise_deg):
        ax.axhline(floors.noise_deg, color="tab:red", lw=1.0, label="noise floor")
    if math.isfinite(floors.reference_deg):
        ax.axhline(floors.reference_deg, color="tab:purple", lw=1.0, ls=":", label=floors.reference)
    ax.set_ylabel("held-out RMSE [deg]")
    ax.set_title(f"{' -> '.join(diagnosis.chain)}: verdict {diagnosis.verdict}")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.3), fontsize=8, frameon=False, ncol=2)
    plt.setp(ax.get_xticklabels(), rotation=20, ha="right")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
