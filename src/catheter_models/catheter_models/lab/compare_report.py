"""The HTML page of a comparison (:mod:`catheter_models.lab.compare`): tables, plots, JSON.

:func:`write_report` writes a self-contained directory: ``index.html`` (plain HTML, no script,
images by relative path), the PNG figures of :mod:`catheter_models.lab.compare_plots` and
``comparison.json``. Apart from the numerics so that the page's layout can change without
touching how a model is scored.
"""

from __future__ import annotations

import html
import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Final

from catheter_models.lab.compare_plots import plot_loops, plot_regimes, plot_time
from catheter_models.lab.compare_text import MIXED, mapping_text
from catheter_models.metrics import ErrorMetrics

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from catheter_models.lab.compare import Comparison

MAX_PLOTTED_RECORDINGS: Final = 8
"""Reports plot the first this many recordings only, so a report of many bags stays small."""


def _file_stem(index: int, name: str) -> str:
    """A safe, unique file name stem for a recording's plots."""
    return f"{index:02d}_" + (re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._") or "recording")


def _metrics_row(label: str, m: ErrorMetrics | None, k: float) -> str:
    cells = [html.escape(label)]
    if m is None:
        cells += ["n/a", "n/a", "n/a", "too few"]
    else:
        nrmse = "n/a" if m.nrmse is None else f"{100 * m.nrmse:.2f} %"
        cells += [f"{m.rmse * k:.3f}", f"{m.mae * k:.3f}", nrmse, str(m.n_samples)]
    return "<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>"


_CSS: Final = """
body { font-family: sans-serif; max-width: 1500px; margin: 1em auto; padding: 0 1em; }
table { border-collapse: collapse; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }
th:first-child, td:first-child { text-align: left; }
th { background: #f0f0f0; }
img { max-width: 100%; display: block; margin: 0.5em 0 1.5em; }
.note { color: #555; }
"""


def write_report(comparison: Comparison, out_dir: Path, title: str) -> Path:
    """Write ``out_dir/index.html`` with the tables and plots; returns its path.

    The page is plain HTML (no script, images by relative path), so the directory can be
    copied, archived or attached as it is. Plots cover the first
    :data:`MAX_PLOTTED_RECORDINGS` recordings; the tables cover all. ``comparison.json``
    beside it holds :meth:`Comparison.to_dict`.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    unit, k = comparison.display_unit, comparison.display_scale
    esc = html.escape

    def save(fig: Figure, name: str) -> str:
        fig.savefig(out_dir / name, dpi=90)
        return name

    summary_png = save(plot_regimes(comparison), "regimes.png")
    ranked = list(enumerate(comparison.worst, 1))
    figures: list[tuple[str, list[str]]] = []
    for i, rc in enumerate(comparison.recordings[:MAX_PLOTTED_RECORDINGS]):
        stem = _file_stem(i, rc.name)
        mine = [(rank, s) for rank, s in ranked if s.recording == rc.name]
        figures.append(
            (
                rc.name,
                [
                    save(plot_time(comparison, rc, mine), f"{stem}_time.png"),
                    save(plot_loops(comparison, rc), f"{stem}_loops.png"),
                ],
            )
        )
    (out_dir / "comparison.json").write_text(json.dumps(comparison.to_dict(), indent=2) + "\n")

    head = "<tr><th>{}</th><th>RMSE [{u}]</th><th>MAE [{u}]</th><th>NRMSE</th><th>samples</th></tr>"
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{esc(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{esc(title)}</h1>",
        f"<p>Model <b>{esc(comparison.model_kind)}</b> "
        f"({esc(mapping_text(comparison.direction))}) against "
        f"{len(comparison.recordings)} recording(s). Errors are model minus measurement, in "
        f"{esc(unit)}; MAE is the <em>maximum</em> absolute error (thesis eq. 5.13); NRMSE is "
        "RMSE over the range of the measurement (eq. 5.15). Regimes are classified from the "
        "recording's pressure and measured bend.</p>",
        "<h2>Metrics</h2><table>",
        head.format("", u=esc(unit)),
        _metrics_row("overall", comparison.overall, k),
    ]
    parts += [_metrics_row(name, m, k) for name, m in comparison.by_regime.items()]
    parts.append("</table>")
    parts.append(f'<img src="{esc(summary_png)}" alt="RMSE per regime">')
    if len(comparison.recordings) > 1:
        parts += ["<h2>Recordings</h2><table>", head.format("recording", u=esc(unit))]
        parts += [_metrics_row(r.name, r.overall, k) for r in comparison.recordings]
        parts.append("</table>")
    parts += [
        "<h2>Worst segments</h2>",
        f'<p class="note">Fixed windows ranked by RMSE, neighbours merged; time in seconds from '
        f"the recording's start. Regime: the one covering most samples ({MIXED} if none covers "
        "more than half).</p>",
        "<table><tr><th>#</th><th>recording</th><th>from [s]</th><th>to [s]</th>"
        f"<th>regime</th><th>RMSE [{esc(unit)}]</th><th>max |error| [{esc(unit)}]</th>"
        "<th>samples</th></tr>",
    ]
    for rank, s in ranked:
        cells = [
            str(rank),
            esc(s.recording),
            f"{s.start_s:.2f}",
            f"{s.end_s:.2f}",
            esc(s.regime),
            f"{s.rmse * k:.3f}",
            f"{s.max_abs * k:.3f}",
            str(s.n_samples),
        ]
        parts.append("<tr>" + "".join(f"<td>{c}</td>" for c in cells) + "</tr>")
    parts.append("</table>")
    for name, images in figures:
        parts.append(f"<h2>{esc(name)}</h2>")
        parts += [f'<img src="{esc(src)}" alt="{esc(name)}">' for src in images]
    skipped = len(comparison.recordings) - len(figures)
    if skipped > 0:
        parts.append(
            f'<p class="note">{skipped} more recording(s) not plotted (the first '
            f"{MAX_PLOTTED_RECORDINGS} are); their metrics are in the tables above.</p>"
        )
    parts.append("</body></html>")
    index = out_dir / "index.html"
    index.write_text("\n".join(parts) + "\n", encoding="utf-8")
    return index
