"""Tracking report of a run (no ROS): align measured bend on the set-points, score, plot.

Set-points (``angle/desired``) and measurements (``tip/angle``) are aligned on their header
stamps, the time each value was true, never on receive time (docs/interfaces.md).

Besides the score, this holds what ``follow_trajectory`` keeps of a run
(:class:`RunRecord`, filled by :mod:`catheter_control.trajectory_client`) and what it makes
of it: the nodes' timing and controller values over the run, the samples lost, and the
facts written to ``report.json``.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import os
from array import array
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import numpy.typing as npt

from catheter_models.contract import ANGLE_DESIRED, TIP_ANGLE
from catheter_models.errors import CatheterError
from catheter_models.gaps import find_gaps, say_gaps
from catheter_models.metrics import (
    ErrorMetrics,
    classify_regimes,
    compute_metrics,
    metrics_by_regime,
)
from catheter_models.units import deg_to_rad, rad_to_deg

FloatArray = npt.NDArray[np.float64]


class TrackingError(CatheterError):
    """The run has too little data to score (e.g. no measurement during the trajectory)."""


REST_START_RAD = math.radians(0.05)
"""A run whose first set-point is at most this bend starts from rest, with the valve vented."""

FLOOR_WORTH_SAYING_RAD = math.radians(0.005)
"""Below this, what the vented rest costs a run is not said on the terminal (a catheter
resting straight, within its noise)."""

REST_WINDOW_S = 0.5
"""How long before a run from rest its bend is taken as where the catheter rests [s]."""


@dataclass(frozen=True)
class VentedFloor:
    """Where the catheter rests with the valve vented, and what that costs a trajectory.

    A catheter whose friction holds it bent when vented (measured: the Maxwell-slip plant keeps
    0.85-1 deg) cannot be brought lower by any pressure: a set-point below that bend is an
    error the controller cannot remove. A run whose first set-point is at rest (the thesis's
    trajectories, or their lead-in) starts from rest with the valve vented, so the bend just
    before it is where the catheter rests. It is a lower estimate: after a high peak the
    catheter may rest higher still.

    Attributes:
        rest_bend_rad: The median bend over the half second before the first set-point.
        bound_rmse_rad: The RMSE the set-points below it cost at least, were the rest
            tracked perfectly (the root mean square of ``max(0, rest - desired)``).
        above_rmse_rad: The RMSE where the set-point is at or above the rest bend (None if
            too few samples are).
        below_share: The share of the scored samples whose set-point is below it.
    """

    rest_bend_rad: float
    bound_rmse_rad: float
    above_rmse_rad: float | None
    below_share: float

    @property
    def matters(self) -> bool:
        """Whether the set-points below the rest cost the run anything worth saying."""
        return self.bound_rmse_rad >= FLOOR_WORTH_SAYING_RAD

    def text(self) -> str:
        """One line for the terminal report (degrees)."""
        above = (
            "n/a" if self.above_rmse_rad is None else f"{rad_to_deg(self.above_rmse_rad):.3f} deg"
        )
        return (
            f"rests at {rad_to_deg(self.rest_bend_rad):.2f} deg vented (before the run): "
            f"{100 * self.below_share:.0f} % of the set-points lie below it, at least "
            f"{rad_to_deg(self.bound_rmse_rad):.3f} deg RMSE no pressure removes; RMSE where the "
            f"set-point is above it {above}"
        )

    @classmethod
    def from_json(cls, d: dict[str, Any]) -> VentedFloor:
        """Back from :meth:`to_json` (a run's ``vented_floor`` in report.json or commission)."""
        above = d.get("above_rmse_deg")
        return cls(
            rest_bend_rad=float(deg_to_rad(d["rest_bend_deg"])),
            bound_rmse_rad=float(deg_to_rad(d["bound_rmse_deg"])),
            above_rmse_rad=None if above is None else float(deg_to_rad(above)),
            below_share=float(d["below_share"]),
        )

    def to_json(self) -> dict[str, float | None]:
        """In degrees, for report.json."""
        return {
            "rest_bend_deg": rad_to_deg(self.rest_bend_rad),
            "bound_rmse_deg": rad_to_deg(self.bound_rmse_rad),
            "above_rmse_deg": (
                None if self.above_rmse_rad is None else rad_to_deg(self.above_rmse_rad)
            ),
            "below_share": self.below_share,
        }


@dataclass(frozen=True)
class TrackingResult:
    """A scored run: aligned series (SI) and metrics (rad; shown in degrees)."""

    t_s: FloatArray
    desired_rad: FloatArray
    measured_rad: FloatArray
    overall: ErrorMetrics
    by_regime: dict[str, ErrorMetrics | None]
    vented: VentedFloor | None = None
    """Where the catheter rests vented, for a run that starts from rest."""

    def text(self, title: str) -> str:
        """The report a person reads in the terminal (degrees; MAE = maximum abs error)."""
        lines = [
            f"Tracking report: {title}",
            f"  samples {self.overall.n_samples} over {self.t_s[-1] - self.t_s[0]:.1f} s",
            f"  RMSE  {rad_to_deg(self.overall.rmse):7.3f} deg",
            f"  MAE   {rad_to_deg(self.overall.mae):7.3f} deg   (maximum absolute error, eq. 5.13)",
            "  NRMSE "
            + ("    n/a" if self.overall.nrmse is None else f"{100 * self.overall.nrmse:7.2f} %"),
            "  by regime:",
        ]
        for name, m in self.by_regime.items():
            if m is None:
                lines.append(f"    {name:<12} (too few samples)")
            else:
                lines.append(
                    f"    {name:<12} RMSE {rad_to_deg(m.rmse):6.3f} deg  "
                    f"MAE {rad_to_deg(m.mae):6.3f} deg  n={m.n_samples}"
                )
        if self.vented is not None and self.vented.matters:
            lines.append(f"  {self.vented.text()}")
        return "\n".join(lines)

    def to_json(self) -> dict[str, object]:
        """Metrics in degrees for a machine-readable report."""

        def conv(m: ErrorMetrics | None) -> dict[str, float | int | None] | None:
            if m is None:
                return None
            return {
                "rmse_deg": rad_to_deg(m.rmse),
                "mae_deg": rad_to_deg(m.mae),
                "nrmse": m.nrmse,
                "n_samples": m.n_samples,
            }

        return {
            "overall": conv(self.overall),
            "by_regime": {k: conv(v) for k, v in self.by_regime.items()},
            "vented_floor": None if self.vented is None else self.vented.to_json(),
        }


def score_run(
    desired_stamps_s: npt.ArrayLike,
    desired_rad: npt.ArrayLike,
    measured_stamps_s: npt.ArrayLike,
    measured_rad: npt.ArrayLike,
    window_s: tuple[float, float] | None = None,
) -> TrackingResult:
    """Interpolate the measurement onto the set-point stamps within the window and score it.

    Args:
        desired_stamps_s: header stamps of the set-points (``angle/desired``) [s].
        desired_rad: set-points in force [rad].
        measured_stamps_s: header stamps of the ``tip/angle`` samples [s].
        measured_rad: measured bend [rad].
        window_s: only set-points with stamps in [start, end] are scored (the trajectory,
            not the ramp-down after it).
    """
    td = np.asarray(desired_stamps_s, dtype=float)
    yd = np.asarray(desired_rad, dtype=float)
    tm = np.asarray(measured_stamps_s, dtype=float)
    ym = np.asarray(measured_rad, dtype=float)
    order = np.argsort(tm, kind="stable")
    tm, ym = tm[order], ym[order]
    keep = np.isfinite(td) & np.isfinite(yd)
    if window_s is not None:
        keep &= (td >= window_s[0]) & (td <= window_s[1])
    # Only score where a measurement brackets the set-point: no extrapolation.
    if tm.size < 2:
        raise TrackingError(f"only {tm.size} tip/angle samples were received; nothing to score")
    keep &= (td >= tm[0]) & (td <= tm[-1])
    td, yd = td[keep], yd[keep]
    if td.size < 10:
        raise TrackingError(
            f"only {td.size} set-points overlap the tip/angle measurements; "
            "was the rig publishing during the trajectory?"
        )
    ym_on_d = np.interp(td, tm, ym)
    overall = compute_metrics(ym_on_d, yd)
    regimes = classify_regimes(td - td[0], yd, ym_on_d, deadband_drive_threshold=math.radians(1.0))
    return TrackingResult(td - td[0], yd, ym_on_d, overall, metrics_by_regime(ym_on_d, yd, regimes))


def save_plot(result: TrackingResult, path: Path, title: str) -> Path:
    """Save the run's plot: desired and measured, error, and measured against desired.

    The last panel is thesis fig. 11.6: a straight line when hysteresis is compensated.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(plot_png(result, title))
    return path


def plot_png(result: TrackingResult, title: str) -> bytes:
    """The run's plot (see :func:`save_plot`) as PNG bytes, drawn in memory."""
    d = rad_to_deg(result.desired_rad)
    m = rad_to_deg(result.measured_rad)
    fig = plt.figure(figsize=(12, 7), constrained_layout=True)
    grid = fig.add_gridspec(2, 3)
    ax_t = fig.add_subplot(grid[0, :2])
    ax_e = fig.add_subplot(grid[1, :2], sharex=ax_t)
    ax_x = fig.add_subplot(grid[:, 2])
    ax_t.plot(result.t_s, d, label="desired", color="black", lw=1.2)
    ax_t.plot(result.t_s, m, label="measured", color="tab:red", lw=1.0)
    if result.vented is not None:
        ax_t.axhline(
            rad_to_deg(result.vented.rest_bend_rad),
            color="grey",
            lw=0.8,
            ls=":",
            label="rests vented",
        )
    ax_t.set_ylabel("bend [deg]")
    ax_t.legend(loc="upper right")
    ax_t.set_title(title)
    ax_e.plot(result.t_s, m - d, color="tab:blue", lw=0.8)
    ax_e.axhline(0.0, color="grey", lw=0.5)
    ax_e.set_xlabel("time [s]")
    ax_e.set_ylabel("error [deg]")
    o = result.overall
    ax_e.set_title(
        f"RMSE {rad_to_deg(o.rmse):.2f} deg, MAE {rad_to_deg(o.mae):.2f} deg"
        + ("" if o.nrmse is None else f", NRMSE {100 * o.nrmse:.1f} %"),
        fontsize=10,
    )
    lim = (min(d.min(), m.min()) - 1, max(d.max(), m.max()) + 1)
    ax_x.plot(lim, lim, color="grey", lw=0.8, ls="--", label="ideal")
    ax_x.plot(d, m, color="tab:red", lw=0.8, label="measured")
    ax_x.set_xlim(lim)
    ax_x.set_ylim(lim)
    ax_x.set_aspect("equal")
    ax_x.set_xlabel("desired [deg]")
    ax_x.set_ylabel("measured [deg]")
    ax_x.legend(loc="upper left")
    png = io.BytesIO()
    fig.savefig(png, dpi=110, format="png")
    plt.close(fig)
    return png.getvalue()


def save_json(result: TrackingResult, path: Path, extra: dict[str, object]) -> Path:
    """Metrics (degrees) and run facts as JSON."""
    path.write_text(report_json(result, extra))
    return path


def report_json(result: TrackingResult | None, extra: dict[str, object]) -> str:
    """``report.json``'s text: the run's facts, then its metrics (null when not scored)."""
    metrics = result.to_json() if result is not None else {"overall": None, "by_regime": None}
    return json.dumps({**extra, **metrics}, indent=2) + "\n"


REPORT_RESERVE_BYTES = 64_000
"""Space held for report.json at the start of a run, beside :data:`REPORT_BYTES_PER_S`."""
REPORT_BYTES_PER_S = 600
"""report.json grows with the run: two timing series, one entry a second each (~250 B)."""
PLOT_RESERVE_BYTES = 1_000_000
"""Space held for tracking.png (a 1320 x 770 PNG of three panels: 100-300 kB)."""


class ReservedFile:
    """A file whose space is taken at the start of a run, and written in place at its end.

    A disk that fills during the run (the recording, another program) cannot then keep the
    run's report or plot from being written: the blocks are already the file's. The
    placeholder is valid JSON that says the run did not finish writing its report, so a
    tool that dies mid-run still leaves a report.json that says so.

    Args:
        path: The file to hold.
        n_bytes: How much to hold [bytes].
    """

    def __init__(self, path: Path, n_bytes: int) -> None:
        self.path = path
        self.n_bytes = n_bytes
        placeholder = b'{"outcome": "no report was written: the run did not get that far"}\n'
        path.parent.mkdir(parents=True, exist_ok=True)
        # Whitespace after the JSON is still valid JSON; real bytes, not a sparse hole.
        path.write_bytes(placeholder + b" " * max(0, n_bytes - len(placeholder)))
        self.written = False

    def discard(self) -> None:
        """Remove the placeholder if nothing was written (a run that never got to report)."""
        if not self.written:
            self.path.unlink(missing_ok=True)

    def write(self, data: bytes) -> str:
        """Write ``data`` in place (past the reservation if it must); '' or the problem."""
        self.written = True  # whatever happens now, the placeholder is not to be removed
        try:
            with self.path.open("r+b") as stream:
                stream.write(data)
                stream.truncate(len(data))
                stream.flush()
                os.fsync(stream.fileno())
        except OSError as exc:
            return f"could not write {self.path}: {exc.strerror or exc}"
        return ""


def _floats(reports: list[dict[str, str]], key: str) -> list[float]:
    out = []
    for values in reports:
        try:
            out.append(float(values[key]))
        except (KeyError, ValueError):
            continue  # not reported yet (e.g. no command received before this report)
    return out


def timing_summary(
    compensator: list[dict[str, str]], driver: list[dict[str, str]]
) -> dict[str, float | int | str | None]:
    """The control loop's timing over a run, from the nodes' 1 Hz /diagnostics values.

    Args:
        compensator: the compensator's status values, in order, from the first report after
            the run started to the first after it ended.
        driver: the same for the node that received the commands (sim_hardware or
            valve_driver).

    Ticks and missed deadlines are the nodes' own counters, differenced over the run (to
    within one report period). Percentiles are reported by the nodes over their recent
    window (5000 ticks): the worst window of the run is kept, which bounds the run's own.
    """
    ticks = _floats(compensator, "ticks")
    missed = _floats(compensator, "missed_deadlines")

    def worst(reports: list[dict[str, str]], key: str) -> float | None:
        found = _floats(reports, key)
        return max(found) if found else None

    n_ticks = int(ticks[-1] - ticks[0]) if len(ticks) >= 2 else 0
    n_missed = int(missed[-1] - missed[0]) if len(missed) >= 2 else 0
    rate = _floats(compensator, "control_rate_hz")
    return {
        "control_rate_hz": rate[-1] if rate else None,
        "realtime": compensator[-1].get("realtime") if compensator else None,
        "ticks": n_ticks,
        "missed_deadlines": n_missed,
        "missed_fraction": n_missed / (n_ticks + n_missed) if n_ticks else None,
        "lateness_p99_ms": worst(compensator, "lateness_p99_ms"),
        "compute_p99_ms": worst(compensator, "compute_p99_ms"),
        "command_latency_p50_ms": worst(driver, "command_latency_p50_ms"),
        "command_latency_p99_ms": worst(driver, "command_latency_p99_ms"),
        "command_latency_max_ms": worst(driver, "command_latency_max_ms"),
    }


def timing_text(timing: dict[str, float | int | str | None]) -> str:
    """One paragraph a person reads: did the loop hold its deadlines?"""

    def ms(key: str) -> str:
        value = timing.get(key)
        return f"{value:.3f} ms" if isinstance(value, float | int) else "n/a"

    fraction = timing.get("missed_fraction")
    missed = f"{100 * fraction:.3f} %" if isinstance(fraction, float | int) else "n/a"
    return "\n".join(
        [
            f"Control loop at {timing.get('control_rate_hz') or 0:g} Hz "
            f"({timing.get('realtime') or 'scheduling unknown'}):",
            f"  ticks {timing['ticks']}, missed deadlines {timing['missed_deadlines']} ({missed})",
            f"  lateness p99 {ms('lateness_p99_ms')}, compute p99 {ms('compute_p99_ms')}",
            f"  command latency, tick to driver: p50 {ms('command_latency_p50_ms')}, "
            f"p99 {ms('command_latency_p99_ms')}, max {ms('command_latency_max_ms')}",
        ]
    )


# -- a follow_trajectory run: what it keeps, and what it reports -------------------------------

Report = dict[str, str]
"""One node's status values from ``/diagnostics``, by key."""

_CONTROLLER_KEYS = (
    "compensator",
    "feedback",
    "feedforward_shaping",
    "feedback_untrusted_samples",
    "feedback_saturated_ticks",
    "feedback_integral_pa",
)
"""What the compensator says it ran, as the report lists it."""

_TIMING_SERIES_KEYS = (
    "state",
    "ticks",
    "missed_deadlines",
    "lateness_p99_ms",
    "compute_p99_ms",
    "behind_max_ms",
)
"""The compensator's per-report timing values kept in ``timing_series`` (and each
``<stream>_longest_silence_ms`` it reports)."""


class Series:
    """Stamps [s] and values of one topic, packed: 16 bytes a sample.

    A run keeps every sample to score it; as a list of tuples (~120 bytes a sample) the
    10-minute soak at 1 kHz grew 10 MB a minute.
    """

    def __init__(self) -> None:
        self.t_s = array("d")
        self.values = array("d")

    def append(self, t_s: float, value: float) -> None:
        """Keep one sample: its header stamp [s] and its value."""
        self.t_s.append(t_s)
        self.values.append(value)

    def clear(self) -> None:
        """Forget every sample (those from before the run)."""
        self.t_s = array("d")
        self.values = array("d")

    def truncate(self, count: int) -> None:
        """Keep the first ``count`` samples only."""
        del self.t_s[count:]
        del self.values[count:]

    def __len__(self) -> int:
        return len(self.t_s)


@dataclass
class RunRecord:
    """Everything a ``follow_trajectory`` run heard, for its report.

    Diagnostics are kept with their monotonic receipt time [s], so the report can take the
    ones that span the run.
    """

    desired: Series = field(default_factory=Series)
    measured: Series = field(default_factory=Series)
    stopped: str = ""
    """Why the run stopped part-way ('' if it went to its end): the compensator's reason, or
    the watch's (``stopped_by_watch``: the recorder died or cannot write)."""
    stopped_by_watch: bool = False
    interrupted: str = ""
    """When a person interrupted the run (Ctrl-C), and what was done ('' if nobody did)."""
    recorder: Report = field(default_factory=dict)
    """The recorder's newest report."""
    recorder_error: str = ""
    """The recorder's newest /diagnostics message when its level was ERROR ('' otherwise):
    it cannot write (disk full, I/O error) and records nothing more."""
    recording: dict[str, Any] = field(default_factory=dict)
    """What became of the recording (``recording`` in report.json): filled by
    :class:`catheter_control.recording_watch.RecordingWatch`; empty for a run without a bag."""
    compensator: list[tuple[float, Report]] = field(default_factory=list)
    driver: list[tuple[float, Report]] = field(default_factory=list)
    """The node that received the commands: sim_hardware or valve_driver."""
    sent_at_s: float = 0.0
    """When the goal was sent (monotonic) [s]."""
    started_at_s: float | None = None
    """When the first set-point arrived (monotonic) [s]; None if none did."""

    @property
    def run_start_s(self) -> float:
        """The run's start: its first set-point, or the goal if none came."""
        return self.started_at_s if self.started_at_s is not None else self.sent_at_s


@dataclass(frozen=True)
class RunSummary:
    """The nodes' reports over one run, and what the report makes of them."""

    first_report_s: float
    """Receipt of the last compensator report before the run started [s]: reports from
    then on span the run."""
    timing: dict[str, float | int | str | None]
    controller: Report

    @classmethod
    def of(cls, record: RunRecord) -> RunSummary:
        """Reports from the last one before the first set-point to the first after the end."""
        start_s = record.run_start_s
        first = max([t for t, _ in record.compensator if t <= start_s], default=start_s)
        timing = timing_summary(
            [v for t, v in record.compensator if t >= first],
            [v for t, v in record.driver if t >= first],
        )
        # What the compensator says it ran, from its last report of the run.
        last = next((v for t, v in reversed(record.compensator) if t >= first), {})
        controller = {k: last[k] for k in _CONTROLLER_KEYS if k in last}
        return cls(first, timing, controller)

    def controller_text(self) -> str | None:
        """``Controller: compensator clstm, feedback none``; None if it said nothing."""
        if not self.controller:
            return None
        return "Controller: " + ", ".join(f"{k} {v}" for k, v in self.controller.items())


def score_record(record: RunRecord, duration_s: float, lead_s: float) -> TrackingResult:
    """Score the run from its first set-point, leaving out the lead-in (``lead_s``).

    Raises:
        TrackingError: nothing to score (no set-point, or too few measurements in the window).
    """
    if not record.desired:
        raise TrackingError("no set-point was received; nothing to score")
    start = record.desired.t_s[0]
    result = score_run(
        record.desired.t_s,
        record.desired.values,
        record.measured.t_s,
        record.measured.values,
        window_s=(start + lead_s, start + duration_s),
    )
    rest_rad = rest_bend_rad(record)
    if rest_rad is None:
        return result
    return dataclasses.replace(result, vented=vented_floor(result, rest_rad))


def rest_bend_rad(record: RunRecord) -> float | None:
    """The bend the catheter rests at, vented, before a run that starts from rest.

    Measured over the :data:`REST_WINDOW_S` before the first set-point, when that set-point is
    at rest: the compensator starts such a run from rest, with the valve vented. None when the
    run starts elsewhere, or too few samples of the bend came before it.
    """
    if not record.desired or abs(record.desired.values[0]) > REST_START_RAD:
        return None
    start = record.desired.t_s[0]
    tm, ym = np.asarray(record.measured.t_s), np.asarray(record.measured.values)
    rest = (tm >= start - REST_WINDOW_S) & (tm < start) & np.isfinite(ym)
    if np.count_nonzero(rest) < 5:
        return None
    return float(np.median(ym[rest]))


def vented_floor(result: TrackingResult, rest_bend_rad: float) -> VentedFloor:
    """What set-points below ``rest_bend_rad`` cost the scored run (:class:`VentedFloor`)."""
    rest = max(rest_bend_rad, 0.0)
    below = result.desired_rad < rest
    shortfall = np.where(below, rest - result.desired_rad, 0.0)
    above = ~below
    err = result.measured_rad - result.desired_rad
    return VentedFloor(
        rest_bend_rad=rest_bend_rad,
        bound_rmse_rad=float(np.sqrt(np.mean(shortfall**2))),
        above_rmse_rad=(
            float(np.sqrt(np.mean(err[above] ** 2))) if np.count_nonzero(above) >= 10 else None
        ),
        below_share=float(np.mean(below)),
    )


@dataclass(frozen=True)
class SampleLosses:
    """What the bag and the score lack: counts by topic, and lines for a person."""

    bag: dict[str, int]
    scored: dict[str, int]
    said: list[str]


def sample_losses(record: RunRecord, bag_path: Path | None) -> SampleLosses:
    """What the bag and the score lack: counts by topic, and lines for a person.

    The bag's counts are the recorder's at its last report (1 Hz); the bag's own
    ``custom_data`` has the final ones.
    """
    said: list[str] = []
    bag: dict[str, int] = {}
    if bag_path is not None:
        prefix = "lost "
        bag = {k[len(prefix) :]: int(v) for k, v in record.recorder.items() if k.startswith(prefix)}
        if not record.recorder:
            said.append("follow_trajectory: no report from the recorder; the bag is unchecked")
        elif any(bag.values()):
            said.append(
                "follow_trajectory: the bag lacks samples: "
                + ", ".join(f"{n} of {t}" for t, n in bag.items() if n)
                + " (in the command streams these include ticks the compensator skipped, "
                "commands that never existed)"
            )
    scored: dict[str, int] = {}
    for name, series, pauses in (
        (ANGLE_DESIRED.name, record.desired, True),
        (TIP_ANGLE.name, record.measured, False),
    ):
        t_s = np.frombuffer(series.t_s, dtype=float)
        period_s, found = find_gaps(t_s, pauses=pauses)
        scored[name] = sum(m for _, _, m in found)
        line = say_gaps(name, period_s, found, origin_s=float(t_s[0]) if t_s.size else 0.0)
        if line is not None:
            said.append(f"follow_trajectory: scored without them: {line}")
    return SampleLosses(bag, scored, said)


def run_facts(
    record: RunRecord,
    summary: RunSummary,
    losses: SampleLosses,
    *,
    trajectory: str,
    bag_path: Path | None,
    lead_s: float,
) -> dict[str, Any]:
    """What ``report.json`` says of the run beside its metrics, in the order it lists them."""
    start_s, first = record.run_start_s, summary.first_report_s
    return {
        "trajectory": trajectory,
        "bag": str(bag_path or ""),
        # Whether the bag holds the whole run; if not, why, and how many seconds from when
        # went unrecorded.
        "recording": record.recording,
        # Why the compensator stopped part-way ('' if the run went to its end).
        "stopped": record.stopped,
        # When a person interrupted it (Ctrl-C): the score covers the run up to there.
        "interrupted": record.interrupted,
        "lead_in_s": lead_s,
        "controller": summary.controller,
        "timing": summary.timing,
        # Samples missing from the bag (the recorder's counts, by topic) and from the
        # streams this run was scored on (from their stamps).
        "bag_samples_lost": losses.bag,
        "scored_samples_lost": losses.scored,
        # How far the recorder's writer fell behind its intake (messages queued at worst,
        # and at its last report): a queue that only grows would end in drops.
        "recorder_queue": {
            k: int(record.recorder[k])
            for k in ("queue", "queue_max")
            if str(record.recorder.get(k, "")).isdigit()
        },
        # The compensator's 1 Hz reports over the run: where in it deadlines were missed,
        # how far behind its loop fell and how long each sensor it needs went quiet.
        "timing_series": [
            {
                "t_s": round(t - start_s, 3),
                **{
                    k: v.get(k, "")
                    for k in (
                        *_TIMING_SERIES_KEYS,
                        *(k for k in v if k.endswith("_longest_silence_ms")),
                    )
                },
            }
            for t, v in record.compensator
            if t >= first
        ],
        # The driver's (the sensors' producer) beside it: a sensor silence with the
        # driver's loop on time was lost on the way, one with it behind was never sent.
        "driver_timing_series": [
            {
                "t_s": round(t - start_s, 3),
                **{k: v.get(k, "") for k in ("missed_deadlines", "behind_max_ms")},
            }
            for t, v in record.driver
            if t >= first
        ],
    }
