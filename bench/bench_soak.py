"""Soak: the whole simulated graph at 1 kHz for 10 minutes with the recorder on. Does anything grow?

Runs ``follow_trajectory --sim`` (recorder, sim_hardware and the compensator with the shipped
c-LSTM, each its own process, real rclpy over Fast DDS on localhost) at 1 kHz on thesis
trajectories 4 then 1 repeated to ``--duration-s``, and meanwhile samples once a second the
RSS of every process in its tree (``/proc``). Afterwards it reports:

* missed deadlines per minute, from the compensator's own counters in report.json's
  ``timing_series``, and whether the last third of the run after the warm-up misses more
  than the first (more than 3 Poisson standard deviations of the difference);
* RSS growth per process: a straight line fitted to the samples after a warm-up (60 s;
  ``--quick``: 20 % of the run), its slope [MB/min] and the growth it implies over the window,
  flagged against a bound (``RSS_BOUND_MB_PER_H``, ``RSS_FLOOR_MB``);
* dropped messages: the recorded MCAP bag read with the ``mcap`` package (not the project's
  reader), header stamps taken from the CDR bytes (checked against ``mcap_ros2`` decoding),
  and per topic the messages, the count the stamps' span implies at the topic's rate, and the
  gaps (> 1.5 periods). The compensator skips a deadline it has already missed instead of
  bursting, so a gap in ``pressure/command``/``angle/desired`` up to its missed deadlines is a
  skipped tick, not a drop; sim_hardware publishes its backlog, so its gaps are drops. The two
  compensator topics share their stamps: a stamp in one and not the other is a drop.

    .venv/bin/python bench/bench_soak.py              # 600 s at 1 kHz, about 11 minutes
    .venv/bin/python bench/bench_soak.py --quick      # 60 s smoke run, soak.quick.json

Writes ``bench/results/soak.json`` and ``soak.png`` (``--quick``: ``soak.quick.*``). Exits 0
if the run completed; the verdicts are in the JSON. Run it on an otherwise idle machine.
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "bench" / "results"
CONTROL_RATE_HZ = 1000.0
SENSOR_RATE_HZ = 250.0
"""sim_hardware's sample rate (the thesis rig's, ``catheter_models.contract.SENSOR_RATE_HZ``)."""
DEFAULT_DURATION_S = 600.0
QUICK_DURATION_S = 60.0
WARMUP_S = 60.0
QUICK_WARMUP_FRACTION = 0.2
GAP_FACTOR = 1.5
"""A step between consecutive header stamps beyond this many periods is a gap."""
SIGMAS = 3.0
"""Missed deadlines grow if the last third's count exceeds the first's by more than this many
standard deviations of the difference of two Poisson counts (sqrt(first + last)); missed
deadlines are scheduling hiccups, roughly independent events, so at equal rates the chance of a
false alarm is about 0.1 %."""
RSS_BOUND_MB_PER_H = 10.0
"""RSS growth flagged above this slope, extrapolated to an hour. A leak of a few bytes per
message on a 1 kHz stream (3 B x 1000/s x 3600 s = 10.8 MB/h) exceeds it; at the bound a node
would grow by a quarter of a gigabyte in a day of running, which the rig PC can carry."""
RSS_FLOOR_MB = 1.0
"""...and only if the fitted line grows more than this over the window: RSS moves in page and
arena steps (glibc arenas, CPython's pools) and a fit over less than this cannot tell those
from a slope. Over the 10-minute soak's 540 s window the floor is 6.7 MB/h, under the bound,
so the bound decides; a 60 s quick run can only see > 75 MB/h. The line is a Theil-Sen fit
(median of pairwise slopes), so a one-off step (an arena grown once, a buffer sized up) does
not read as growth the way a least-squares line through it would: a 1 MB step mid-run is
10 MB/h to least squares."""
THEIL_SEN_MAX_POINTS = 1500
"""Theil-Sen over more samples than this uses every k-th one (n^2/2 pairs)."""
HARNESS = frozenset({"follow_trajectory"})
"""Processes that are not nodes: follow_trajectory keeps every desired and measured sample it
receives for the tracking score (about 10 MB/min at 1 kHz), so it grows by design; it is
reported but not judged."""
RSS_SERIES_EVERY_S = 10.0
TOPIC_RATES_HZ: dict[str, float] = {
    "pressure/command": CONTROL_RATE_HZ,
    "angle/desired": CONTROL_RATE_HZ,
    "pressure/measured": SENSOR_RATE_HZ,
    "tip/distance": SENSOR_RATE_HZ,
    "tip/angle": SENSOR_RATE_HZ,
}
"""The recorded streams (without the namespace) and the rates their publishers run at."""
COMPENSATOR_TOPICS = ("pressure/command", "angle/desired")
"""Published together on each compensator tick, with the same stamp."""


# --- the process tree under /proc -----------------------------------------------------------


def parse_stat(text: str) -> tuple[int, int]:
    """(pid, ppid) from the text of ``/proc/<pid>/stat``.

    The second field (comm) is in parentheses and may itself hold spaces and parentheses, so
    the fields after it are counted from the last ``)``.
    """
    pid = int(text[: text.index(" ")])
    after = text[text.rindex(")") + 1 :].split()
    return pid, int(after[1])  # after[0] is the state


def descendants(root: int, ppid_of: Mapping[int, int]) -> list[int]:
    """``root`` and every process below it, from a pid -> ppid map; sorted."""
    children: dict[int, list[int]] = {}
    for pid, ppid in ppid_of.items():
        children.setdefault(ppid, []).append(pid)
    found, todo = {root}, [root]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return sorted(found)


def parse_vmrss_kb(status: str) -> int | None:
    """``VmRSS`` [kB] from the text of ``/proc/<pid>/status`` (None for a zombie/kernel task)."""
    for line in status.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return None


def process_name(cmdline: bytes) -> str:
    """A short name from ``/proc/<pid>/cmdline``: ``python -m pkg.recorder_node`` -> recorder."""
    args = [a.decode(errors="replace") for a in cmdline.split(b"\0") if a]
    if not args:
        return "?"
    if "-m" in args[:-1]:
        name = args[args.index("-m") + 1].rsplit(".", 1)[-1]
    elif len(args) > 1 and Path(args[0]).name.startswith("python"):
        name = Path(args[1]).stem
    else:
        name = Path(args[0]).name
    return name.removesuffix("_node")


def _read(path: str) -> bytes | None:
    try:
        with open(path, "rb") as fh:  # noqa: PTH123 (thousands a second; keep it cheap)
            return fh.read()
    except OSError:
        return None  # the process ended meanwhile


def tree_rss_mb(root: int) -> dict[str, float]:
    """RSS [MB] of ``root`` and its descendants now, by process name (pid added on a clash)."""
    ppid_of: dict[int, int] = {}
    for entry in os.listdir("/proc"):  # noqa: PTH208
        if entry.isdigit():
            raw = _read(f"/proc/{entry}/stat")
            if raw:
                pid, ppid = parse_stat(raw.decode(errors="replace"))
                ppid_of[pid] = ppid
    out: dict[str, float] = {}
    for pid in descendants(root, ppid_of):
        status, cmdline = _read(f"/proc/{pid}/status"), _read(f"/proc/{pid}/cmdline")
        kb = parse_vmrss_kb(status.decode(errors="replace")) if status else None
        if kb is None or cmdline is None:
            continue
        name = process_name(cmdline)
        out[f"{name}[{pid}]" if name in out else name] = kb / 1024.0
    return out


# --- the trajectory -------------------------------------------------------------------------


def repeat_knots(
    t_s: npt.ArrayLike, angle: npt.ArrayLike, duration_s: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Knots repeated back to back, one knot spacing between copies, up to ``duration_s``.

    The block must start and end where it can join itself (the thesis trajectories start and
    end straight), so the copies follow one another without a step.
    """
    t = np.asarray(t_s, float)
    a = np.asarray(angle, float)
    block_s = t[-1] - t[0] + (t[1] - t[0])
    copies = max(1, math.ceil(duration_s / block_s))
    tt = np.concatenate([t - t[0] + i * block_s for i in range(copies)])
    aa = np.tile(a, copies)
    keep = tt <= duration_s + 1e-9
    return tt[keep], aa[keep]


def soak_csv(path: Path, duration_s: float) -> Path:
    """Thesis trajectory 4 then 1 (60 s, as bench_graph_timing), repeated to ``duration_s``."""
    from catheter_control.trajectory import preset_knots

    t4, a4 = preset_knots("traj_arbitrary_small_variations")
    t1, a1 = preset_knots("traj_descending_sine")
    t = np.concatenate([t4, t1 + t4[-1] + (t4[1] - t4[0])])
    t, a = repeat_knots(t, np.concatenate([a4, a1]), duration_s)
    rows = "\n".join(f"{ti:.4f},{np.degrees(ai):.6f}" for ti, ai in zip(t, a, strict=True))
    path.write_text("t_s,angle_deg\n" + rows + "\n")
    return path


# --- missed deadlines -----------------------------------------------------------------------


def counter_points(series: Sequence[Mapping[str, Any]], key: str) -> list[tuple[float, int]]:
    """(t_s, value) of a cumulative counter from report.json's ``timing_series``, reports
    that lack it (or hold '') skipped."""
    out = []
    for row in series:
        try:
            out.append((float(row["t_s"]), int(float(row[key]))))
        except (KeyError, TypeError, ValueError):
            continue
    return out


def counter_at(points: Sequence[tuple[float, int]], t_s: float) -> int:
    """The counter as of the last report at or before ``t_s`` (the first report if none)."""
    value = points[0][1]
    for t, v in points:
        if t > t_s:
            break
        value = v
    return value


def per_bin(points: Sequence[tuple[float, int]], bin_s: float, duration_s: float) -> list[int]:
    """Counter increments per ``bin_s`` bin of [0, duration_s].

    Each increment between consecutive reports goes to the bin of the later report; those
    before 0 (start-up) and after ``duration_s`` (ramp-down) go to the first and last bin, so
    the bins add up to the whole run's count.
    """
    n = max(1, math.ceil(duration_s / bin_s - 1e-9))
    bins = [0] * n
    for (_, v0), (t1, v1) in itertools.pairwise(points):
        bins[min(n - 1, max(0, int(t1 // bin_s)))] += v1 - v0
    return bins


def thirds_growth(
    points: Sequence[tuple[float, int]], start_s: float, end_s: float
) -> dict[str, Any]:
    """Counts in the first and last third of [start_s, end_s], per minute, and whether the
    last grew. ``start_s`` is after the warm-up: the first seconds of a run miss deadlines
    while the model and DDS warm up, which would hide growth behind a high first third."""
    third = (end_s - start_s) / 3.0
    first = counter_at(points, start_s + third) - counter_at(points, start_s)
    last = counter_at(points, end_s) - counter_at(points, end_s - third)
    allowed = SIGMAS * math.sqrt(first + last)
    return {
        "window_s": [start_s, end_s],
        "warmup": counter_at(points, start_s) - counter_at(points, 0.0),
        "first_third": first,
        "last_third": last,
        "first_third_per_min": first / third * 60.0,
        "last_third_per_min": last / third * 60.0,
        "allowed_increase": allowed,
        "growth": last - first > allowed,
    }


def early_stop_s(
    series: Sequence[Mapping[str, Any]], duration_s: float, margin_s: float = 1.5
) -> float | None:
    """When the compensator stopped following before the trajectory's end, else None.

    Its 1 Hz reports should say ``following`` from about 1 s into the run to about 1 s before
    the end; the first report in that span that says otherwise (a stale sensor's fault ramps
    it down to ``idle``) is when it stopped, to within a report.
    """
    for row in series:
        try:
            t = float(row["t_s"])
        except (KeyError, TypeError, ValueError):
            continue
        if margin_s <= t <= duration_s - margin_s and row.get("state") not in ("following", ""):
            return t
    return None


def log_problems(text: str, limit: int = 10) -> list[str]:
    """The first ``limit`` ERROR/WARN lines of a node's log (rclpy's ``[ERROR]``/``[WARN]``)."""
    hits = [ln.strip() for ln in text.splitlines() if "[ERROR]" in ln or "[WARN]" in ln]
    return hits[:limit]


# --- RSS ------------------------------------------------------------------------------------


def theil_sen_slope(t: npt.ArrayLike, y: npt.ArrayLike) -> float:
    """Median of the slopes between every pair of samples (robust to steps and outliers)."""
    tt = np.asarray(t, float)
    yy = np.asarray(y, float)
    if tt.size > THEIL_SEN_MAX_POINTS:
        pick = np.linspace(0, tt.size - 1, THEIL_SEN_MAX_POINTS).round().astype(int)
        tt, yy = tt[pick], yy[pick]
    i, j = np.triu_indices(tt.size, k=1)
    dt = tt[j] - tt[i]
    ok = dt > 0
    return float(np.median((yy[j] - yy[i])[ok] / dt[ok]))


def rss_growth(
    t_s: Sequence[float], rss_mb: Sequence[float], start_s: float, end_s: float
) -> dict[str, Any]:
    """A Theil-Sen line through the RSS samples in [start_s, end_s]; growth flagged against
    ``RSS_BOUND_MB_PER_H`` and ``RSS_FLOOR_MB``."""
    t = np.asarray(t_s, float)
    r = np.asarray(rss_mb, float)
    keep = (t >= start_s) & (t <= end_s) & np.isfinite(r)
    t, r = t[keep], r[keep]
    if t.size < 3 or t[-1] - t[0] <= 0.0:
        return {"samples": int(t.size), "slope_mb_per_min": None, "growth": None}
    slope_per_s = theil_sen_slope(t, r)
    window_s = float(t[-1] - t[0])
    fitted = float(slope_per_s * window_s)
    per_h = float(slope_per_s * 3600.0)
    return {
        "samples": int(t.size),
        "window_s": window_s,
        "start_mb": float(r[0]),
        "end_mb": float(r[-1]),
        "peak_mb": float(r.max()),
        "slope_mb_per_min": float(slope_per_s * 60.0),
        "slope_mb_per_h": per_h,
        "fitted_growth_mb": fitted,
        "raw_growth_mb": float(r[-1] - r[0]),
        # The smallest slope this window can flag: the bound, or the floor over the window.
        "resolvable_mb_per_h": max(RSS_BOUND_MB_PER_H, RSS_FLOOR_MB / window_s * 3600.0),
        "growth": per_h > RSS_BOUND_MB_PER_H and fitted > RSS_FLOOR_MB,
    }


# --- the bag --------------------------------------------------------------------------------


def cdr_header_stamp_ns(data: bytes) -> int:
    """The ``std_msgs/Header`` stamp [ns] at the start of a CDR-serialized message.

    Bytes 0-3 are the encapsulation (byte 1: 1 little endian, 0 big endian), then the
    header's ``int32 sec`` and ``uint32 nanosec``.
    """
    sec, nsec = struct.unpack_from("<iI" if data[1] == 1 else ">iI", data, 4)
    return int(sec) * 1_000_000_000 + int(nsec)


def stamp_gaps(stamps_ns: npt.ArrayLike, rate_hz: float) -> dict[str, Any]:
    """Messages, duplicates, stamps out of order and gaps of a stream expected at ``rate_hz``.

    ``expected`` is what the stamps' span holds at the rate (the distinct stamps plus those
    missing inside gaps); a gap is a step between consecutive distinct stamps of more than
    ``GAP_FACTOR`` periods, and holds round(step / period) - 1 missing messages.
    """
    s = np.asarray(stamps_ns, np.int64)
    if s.size == 0:
        return {"messages": 0, "expected": 0, "missing": 0, "gaps": 0, "max_gap_periods": None}
    distinct = np.unique(s)
    period_ns = 1e9 / rate_hz
    steps = np.diff(distinct) / period_ns
    big = steps[steps > GAP_FACTOR]
    missing = int(np.rint(big).sum() - big.size)
    return {
        "messages": int(s.size),
        "duplicates": int(s.size - distinct.size),
        "out_of_order": int((np.diff(s) < 0).sum()),
        "span_s": float((distinct[-1] - distinct[0]) * 1e-9),
        "expected": int(distinct.size + missing),
        "missing": missing,
        "gaps": int(big.size),
        "max_gap_periods": float(steps.max()) if steps.size else None,
    }


def read_bag(bag_dir: Path) -> dict[str, Any]:
    """Per topic: header stamps in file order, the MCAP statistics' count, and a decode check.

    Reads every ``*.mcap`` in ``bag_dir`` with the ``mcap`` package; the stamps come from the
    CDR bytes (fast), checked on each topic's first and last message against ``mcap_ros2``.
    """
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    decoders = DecoderFactory()
    stamps: dict[str, list[int]] = {}
    summary_counts: dict[str, int] = {}
    checks: dict[str, bool] = {}
    for path in sorted(bag_dir.glob("*.mcap")):
        with path.open("rb") as fh:
            reader = make_reader(fh)
            summary = reader.get_summary()
            last: dict[str, tuple[Any, Any, bytes]] = {}
            for schema, channel, message in reader.iter_messages():
                topic = channel.topic
                if topic not in stamps:
                    stamps[topic] = []
                    checks[topic] = _stamp_check(decoders, schema, channel, message.data)
                stamps[topic].append(cdr_header_stamp_ns(message.data))
                last[topic] = (schema, channel, message.data)
            for topic, (schema, channel, data) in last.items():
                checks[topic] = checks[topic] and _stamp_check(decoders, schema, channel, data)
            if summary is not None and summary.statistics is not None:
                for cid, n in summary.statistics.channel_message_counts.items():
                    topic = summary.channels[cid].topic
                    summary_counts[topic] = summary_counts.get(topic, 0) + n
    return {
        "stamps": {t: np.asarray(v, np.int64) for t, v in stamps.items()},
        "summary_counts": summary_counts,
        "decode_check": checks,
    }


def _stamp_check(decoders: Any, schema: Any, channel: Any, data: bytes) -> bool:
    decode = decoders.decoder_for(channel.message_encoding, schema)
    msg = decode(data)
    stamp = msg.header.stamp
    return bool(stamp.sec * 1_000_000_000 + stamp.nanosec == cdr_header_stamp_ns(data))


def bag_table(
    stamps: Mapping[str, npt.NDArray[np.int64]],
    namespace: str,
    compensator_skipped: int,
) -> dict[str, dict[str, Any]]:
    """Per recorded stream: :func:`stamp_gaps`, the gaps explained by skipped ticks, drops.

    Args:
        stamps: header stamps per bag topic.
        namespace: the graph's namespace ("/catheter").
        compensator_skipped: deadlines the compensator missed over the run (it skips them
            and publishes nothing for them); counted over slightly more than the publishing
            span, so the drops it leaves are a lower bound.
    """
    ns = namespace.rstrip("/")
    comp = {t: stamps.get(f"{ns}/{t}", np.zeros(0, np.int64)) for t in COMPENSATOR_TOPICS}
    a, b = (np.unique(comp[t]) for t in COMPENSATOR_TOPICS)
    # Only where both streams ran: a stream may begin or end a tick later in the bag.
    lo, hi = (max(a[0], b[0]), min(a[-1], b[-1])) if a.size and b.size else (0, -1)
    only = {
        COMPENSATOR_TOPICS[0]: np.setdiff1d(b[(b >= lo) & (b <= hi)], a).size,  # missing in a
        COMPENSATOR_TOPICS[1]: np.setdiff1d(a[(a >= lo) & (a <= hi)], b).size,
    }
    rows: dict[str, dict[str, Any]] = {}
    for topic, rate in TOPIC_RATES_HZ.items():
        row = {"rate_hz": rate, **stamp_gaps(stamps.get(f"{ns}/{topic}", []), rate)}
        skipped = compensator_skipped if topic in COMPENSATOR_TOPICS else 0
        row["explained_by_skipped_ticks"] = min(row["missing"], skipped)
        row["missing_in_this_not_sibling"] = only.get(topic)
        row["dropped"] = max(row["missing"] - skipped, only.get(topic, 0))
        rows[topic] = row
    return rows


# --- the run --------------------------------------------------------------------------------


def run_soak(
    argv: list[str], env: Mapping[str, str], log: Path, duration_s: float, timeout_s: float
) -> tuple[int, float | None, list[tuple[float, dict[str, float]]]]:
    """Run follow_trajectory, sampling its tree's RSS each second, with a progress bar.

    Returns its exit code, when (on this function's clock) it said it was following, and the
    samples (t_s on that clock, RSS [MB] by process).
    """
    from tqdm import tqdm

    samples: list[tuple[float, dict[str, float]]] = []
    following: float | None = None
    with log.open("wb") as out:
        proc = subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, env=dict(env))
    t0 = time.monotonic()
    bar = tqdm(
        total=round(duration_s),
        unit="s",
        desc="starting",
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} s [{elapsed}]",
    )
    try:
        tick = 0
        while proc.poll() is None:
            now = time.monotonic() - t0
            if following is None and b"follow_trajectory: following" in log.read_bytes():
                following = now
                bar.set_description_str("soak")
            samples.append((now, tree_rss_mb(proc.pid)))
            if following is not None:
                done = min(round(now - following), round(duration_s))
                if done > bar.n:
                    bar.update(done - bar.n)
                if now - following > duration_s:
                    bar.set_description_str("scoring")
            if now > timeout_s:
                bar.write(f"soak: no exit after {timeout_s:g} s; interrupting follow_trajectory")
                proc.send_signal(signal.SIGINT)  # it stops its graph on the way out
                try:
                    proc.wait(30.0)
                except subprocess.TimeoutExpired:
                    proc.kill()
                break
            tick += 1
            time.sleep(max(0.0, t0 + tick - time.monotonic()))
    finally:
        bar.close()
        if proc.poll() is None:
            proc.kill()
        proc.wait()
    return proc.returncode, following, samples


def rss_by_process(
    samples: Sequence[tuple[float, dict[str, float]]], t_origin: float
) -> tuple[list[float], dict[str, list[float]]]:
    """Sample times relative to ``t_origin`` and each process's RSS (NaN where absent)."""
    names = sorted({n for _, s in samples for n in s})
    t = [round(ts - t_origin, 2) for ts, _ in samples]
    return t, {n: [s.get(n, math.nan) for _, s in samples] for n in names}


def downsample(
    t: Sequence[float], series: Mapping[str, Sequence[float]], every_s: float
) -> dict[str, Any]:
    """The first sample in each ``every_s`` slot, for the JSON (NaN written as null)."""
    picked: list[int] = []
    last_slot = None
    for i, ts in enumerate(t):
        slot = math.floor(ts / every_s)
        if slot != last_slot:
            picked.append(i)
            last_slot = slot
    return {
        "t_s": [t[i] for i in picked],
        "rss_mb": {
            n: [None if math.isnan(v[i]) else round(v[i], 2) for i in picked]
            for n, v in series.items()
        },
    }


def save_plot(
    path: Path,
    *,
    t: Sequence[float],
    rss: Mapping[str, Sequence[float]],
    fits: Mapping[str, dict[str, Any]],
    warmup_s: float,
    duration_s: float,
    missed_bins: Sequence[int],
    bin_s: float,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    tm = np.asarray(t) / 60.0
    for name, values in rss.items():
        ax1.plot(tm, values, label=name)
        fit = fits.get(name, {})
        if fit.get("slope_mb_per_min") is not None:
            ax1.annotate(
                f"{fit['slope_mb_per_min']:+.3f} MB/min",
                (tm[-1], float(np.nanmax(np.asarray(values, float)))),
                fontsize=7,
                ha="right",
                va="bottom",
            )
    ax1.axvspan(tm[0], warmup_s / 60.0, color="0.9", label="start-up and warm-up (not fitted)")
    ax1.axvline(duration_s / 60.0, color="0.5", ls=":", lw=1)
    ax1.set_ylabel("RSS [MB]")
    ax1.legend(fontsize=8, loc="lower right")
    ax1.set_title(f"Soak: the simulated graph at {CONTROL_RATE_HZ:g} Hz, recorder on")
    ax2.bar(
        (np.arange(len(missed_bins)) + 0.5) * bin_s / 60.0,
        missed_bins,
        width=0.9 * bin_s / 60.0,
        color="C3",
    )
    ax2.set_ylabel(f"missed deadlines per {bin_s:g} s")
    ax2.set_xlabel("time since the trajectory was sent [min]")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _fmt(value: float | None, spec: str) -> str:
    return "n/a" if value is None else format(value, spec)


STALL_MS = 50.0
"""A sensor silence the compensator saw longer than this [ms] is a stall worth placing."""
BEHIND_MS = 25.0
"""A loop this far behind its schedule [ms] in the same second is where the stall came from."""


def stall_table(
    series: Sequence[Mapping[str, Any]], driver_series: Sequence[Mapping[str, Any]]
) -> dict[str, Any]:
    """Each second in which a sensor the compensator needs went quiet for over ``STALL_MS``,
    beside how far behind the compensator's loop and the driver's (the producer's) fell then.

    A silence with the driver behind is samples produced late (the producer stalled); with the
    compensator behind, samples taken late (the consumer stalled); with neither, the delay was
    on the way (DDS, the kernel) or in a part of a node no loop measures.
    """

    def ms(row: Mapping[str, Any], key: str) -> float:
        try:
            return float(row.get(key, "") or "nan")
        except ValueError:
            return math.nan

    def driver_at(t_s: float) -> float:
        # The driver reports on its own 1 Hz clock: the worst of its reports within 1 s.
        near = [ms(r, "behind_max_ms") for r in driver_series if abs(r["t_s"] - t_s) <= 1.0]
        near = [v for v in near if not math.isnan(v)]
        return max(near) if near else math.nan

    rows = []
    for row in series:
        silences = {
            k.removesuffix("_longest_silence_ms"): ms(row, k)
            for k in row
            if k.endswith("_longest_silence_ms")
        }
        loud = {k: v for k, v in silences.items() if v > STALL_MS}
        if not loud:
            continue
        comp, drv = ms(row, "behind_max_ms"), driver_at(row["t_s"])
        cause = (
            "driver behind"
            if drv > BEHIND_MS
            else "compensator behind"
            if comp > BEHIND_MS
            else "neither loop behind"
        )
        rows.append(
            {
                "t_s": row["t_s"],
                "silence_ms": loud,
                "compensator_behind_ms": comp,
                "driver_behind_ms": drv,
                "where": cause,
            }
        )
    measured = any(k.endswith("_longest_silence_ms") for r in series for k in r)
    return {
        "measured": measured,
        "stall_ms": STALL_MS,
        "behind_ms": BEHIND_MS,
        "seconds_with_a_stall": len(rows),
        "by_where": {w: sum(r["where"] == w for r in rows) for w in {r["where"] for r in rows}},
        "rows": rows,
    }


def analyse(
    report: Mapping[str, Any],
    samples: Sequence[tuple[float, dict[str, float]]],
    following_s: float,
    bag: Mapping[str, Any],
    *,
    duration_s: float,
    warmup_s: float,
    namespace: str,
    node_logs: Mapping[str, list[str]] | None = None,
) -> dict[str, Any]:
    """Everything the soak reports, from follow_trajectory's report.json, the RSS samples
    (t_s on the clock where it said it was following at ``following_s``) and :func:`read_bag`.

    Keys starting with ``_`` hold the full series for the plot and are not saved.
    """
    # Missed deadlines.
    series = list(report.get("timing_series", []))
    missed_pts = counter_points(series, "missed_deadlines")
    tick_pts = counter_points(series, "ticks")
    timing = dict(report["timing"])
    missed = {
        "total": timing["missed_deadlines"],
        "ticks": timing["ticks"],
        "fraction": timing["missed_fraction"],
        "per_minute": per_bin(missed_pts, 60.0, duration_s) if missed_pts else [],
        "ticks_per_minute": per_bin(tick_pts, 60.0, duration_s) if tick_pts else [],
        **(
            thirds_growth(missed_pts, warmup_s, duration_s)
            if missed_pts
            else {"growth": None, "warmup": None}
        ),
    }

    # RSS.
    t_rss, rss = rss_by_process(samples, following_s)
    fits = {name: rss_growth(t_rss, v, warmup_s, duration_s) for name, v in rss.items()}
    memory_growth = any(f["growth"] for n, f in fits.items() if n not in HARNESS)

    # Bag. The compensator's missed deadlines while it published (series t_s 0 is about its
    # first command): idle ticks it missed leave no gap in the bag.
    stamps = bag["stamps"]
    cmd_stamps = stamps.get(f"{namespace.rstrip('/')}/{COMPENSATOR_TOPICS[0]}", np.zeros(0))
    cmd_span_s = float(np.ptp(cmd_stamps)) * 1e-9 if cmd_stamps.size else 0.0
    skipped = (
        counter_at(missed_pts, cmd_span_s + 1.5) - missed_pts[0][1]
        if missed_pts
        else int(timing["missed_deadlines"] or 0)
    )
    topics = bag_table(stamps, namespace, skipped)
    for topic, row in topics.items():
        row["summary_count"] = bag["summary_counts"].get(f"{namespace.rstrip('/')}/{topic}")
    dropped = sum(r["dropped"] for r in topics.values())
    counts_agree = all(
        r["summary_count"] == r["messages"] for r in topics.values() if r["messages"]
    )
    bag_consistent = counts_agree and all(bag["decode_check"].values())

    stopped_s = early_stop_s(series, duration_s)
    completed = stopped_s is None and cmd_span_s >= duration_s - 1.0
    verdicts = {
        "run_completed": completed,
        "compensator_stopped_at_s": stopped_s,
        "missed_deadlines_growth": missed["growth"],
        "memory_growth": memory_growth,
        "memory_growth_by_process": {n: f["growth"] for n, f in fits.items()},
        "dropped_messages": dropped,
        "bag_counts_consistent": bag_consistent,
        "ok": completed
        and missed["growth"] is False
        and not memory_growth
        and dropped == 0
        and bag_consistent,
    }
    plot_bin_s = 60.0 if duration_s >= 180.0 else 10.0
    return {
        "duration_s": duration_s,
        "control_rate_hz": CONTROL_RATE_HZ,
        "warmup_s": warmup_s,
        "bounds": {
            "missed_growth_sigmas": SIGMAS,
            "rss_bound_mb_per_h": RSS_BOUND_MB_PER_H,
            "rss_floor_mb": RSS_FLOOR_MB,
            "gap_factor_periods": GAP_FACTOR,
        },
        "timing": timing,
        "rmse_deg": report.get("overall", {}).get("rmse_deg"),
        "missed_deadlines": missed,
        "compensator_series": {
            "t_s": [row.get("t_s") for row in series],
            **{k: [row.get(k) for row in series] for k in ("state", "ticks", "missed_deadlines")},
        },
        "node_log_problems": dict(node_logs or {}),
        "rss": {
            "t_origin": "seconds since follow_trajectory sent the trajectory",
            "fits": fits,
            "not_judged": sorted(HARNESS),
            **downsample(t_rss, rss, RSS_SERIES_EVERY_S),
        },
        "bag": {
            "reader": "mcap (stamps from CDR bytes, checked with mcap_ros2)",
            "decode_check": dict(bag["decode_check"]),
            "read_s": bag.get("read_s"),
            "compensator_span_s": cmd_span_s,
            "compensator_skipped_ticks": skipped,
            "topics": topics,
            "trajectory_messages": len(stamps.get(f"{namespace.rstrip('/')}/trajectory", ())),
        },
        "stalls": stall_table(series, report.get("driver_timing_series", [])),
        "verdicts": verdicts,
        "_plot": {
            "t": t_rss,
            "rss": rss,
            "fits": fits,
            "warmup_s": warmup_s,
            "duration_s": duration_s,
            "missed_bins": per_bin(missed_pts, plot_bin_s, duration_s) if missed_pts else [],
            "bin_s": plot_bin_s,
        },
    }


def print_table(result: Mapping[str, Any]) -> None:
    """The figures a person reads, from :func:`analyse`'s result."""
    v, missed, bag = result["verdicts"], result["missed_deadlines"], result["bag"]
    warmup_s = result["warmup_s"]
    print(
        f"\nSoak: the graph at {result['control_rate_hz']:g} Hz for {result['duration_s']:g} s, "
        "recorder on"
    )
    if v["run_completed"]:
        print(f"Run: the compensator followed all of it ({bag['compensator_span_s']:.1f} s)")
    else:
        stopped = v["compensator_stopped_at_s"]
        print(
            "Run: the compensator STOPPED EARLY ("
            + ("" if stopped is None else f"not following at {stopped:.0f} s; ")
            + f"commands span {bag['compensator_span_s']:.1f} s of the run): the figures "
            "cover less than the run; see the node logs"
        )
    for name, lines in result["node_log_problems"].items():
        for line in lines:
            print(f"  {name}.log: {line}")
    frac = missed["fraction"]
    print(
        f"Missed deadlines (compensator): {missed['total']} of {missed['ticks']} ticks "
        f"({_fmt(None if frac is None else 100 * frac, '.3f')} %); per minute: "
        + " ".join(str(m) for m in missed["per_minute"])
    )
    if missed["growth"] is not None:
        print(
            f"  after the {warmup_s:g} s warm-up ({missed['warmup']} missed in it): first third "
            f"{missed['first_third_per_min']:.1f}/min, last third "
            f"{missed['last_third_per_min']:.1f}/min: "
            + ("GROWTH" if missed["growth"] else "no growth")
            + f" (allowed increase {missed['allowed_increase']:.1f} over a third)"
        )
    print(
        f"\nRSS after {warmup_s:g} s warm-up [MB]; growth if > {RSS_BOUND_MB_PER_H:g} MB/h "
        f"and > {RSS_FLOOR_MB:g} MB over the window"
    )
    print(f"{'process':<20}{'start':>8}{'end':>8}{'peak':>8}{'MB/min':>9}{'fit MB':>8}  verdict")
    for name, f in result["rss"]["fits"].items():
        if f["slope_mb_per_min"] is None:
            print(f"{name:<20}{'(too few samples)':>41}")
            continue
        verdict = "GROWTH" if f["growth"] else "flat"
        if name in HARNESS:
            verdict += " (harness: keeps every sample; not judged)"
        elif not f["growth"]:
            verdict += f" (resolves > {f['resolvable_mb_per_h']:.0f} MB/h)"
        print(
            f"{name:<20}{f['start_mb']:>8.1f}{f['end_mb']:>8.1f}{f['peak_mb']:>8.1f}"
            f"{f['slope_mb_per_min']:>+9.3f}{f['fitted_growth_mb']:>+8.2f}  {verdict}"
        )
    print(f"\nBag ({_fmt(bag['read_s'], '.1f')} s to read with mcap): header stamps per topic")
    print(
        f"{'topic':<19}{'rate':>6}{'span s':>8}{'messages':>10}{'expected':>10}{'missing':>9}"
        f"{'gaps':>6}{'max gap':>9}{'skipped':>9}{'dropped':>9}"
    )
    for topic, r in bag["topics"].items():
        print(
            f"{topic:<19}{r['rate_hz']:>6g}{_fmt(r.get('span_s'), '.1f'):>8}{r['messages']:>10}"
            f"{r['expected']:>10}{r['missing']:>9}{r['gaps']:>6}"
            f"{_fmt(r['max_gap_periods'], '.1f'):>9}"
            f"{r['explained_by_skipped_ticks']:>9}{r['dropped']:>9}"
        )
    print(
        "skipped: gaps the compensator's missed deadlines account for (it skips, not bursts); "
        "max gap in periods"
    )
    stalls = result.get("stalls", {})
    if stalls.get("measured"):
        where = ", ".join(f"{w}: {n}" for w, n in sorted(stalls["by_where"].items()))
        print(
            f"\nStalls: {stalls['seconds_with_a_stall']} second(s) in which a sensor the "
            f"compensator needs went quiet for over {stalls['stall_ms']:g} ms"
            + (f" ({where})" if where else "")
        )
        for row in stalls["rows"][:10]:
            quiet = ", ".join(f"{k} {v:.0f} ms" for k, v in row["silence_ms"].items())
            print(
                f"  t = {row['t_s']:7.1f} s  {quiet}; behind: compensator "
                f"{row['compensator_behind_ms']:.0f} ms, driver {row['driver_behind_ms']:.0f} ms"
            )
    print(
        "Verdicts: run "
        + ("completed" if v["run_completed"] else "STOPPED EARLY")
        + "; missed deadlines "
        + {True: "GROW", False: "do not grow", None: "n/a"}[v["missed_deadlines_growth"]]
        + "; memory "
        + ("GROWS" if v["memory_growth"] else "does not grow")
        + f"; dropped messages {v['dropped_messages']}; bag counts "
        + ("consistent" if v["bag_counts_consistent"] else "INCONSISTENT")
    )


def main(argv: list[str] | None = None) -> int:
    from bench_plant import _machine

    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n")[0])
    parser.add_argument("--quick", action="store_true", help=f"{QUICK_DURATION_S:g} s smoke run")
    parser.add_argument("--duration-s", type=float, default=DEFAULT_DURATION_S)
    parser.add_argument("--domain-id", type=int, default=93, help="ROS_DOMAIN_ID of the graph")
    parser.add_argument("--out", type=Path, help="JSON path (default bench/results/soak.json)")
    parser.add_argument("--keep-run", type=Path, help="keep the run (bag, logs) in this new dir")
    parser.add_argument(
        "--hogs",
        type=int,
        default=0,
        help="busy-loop processes beside the graph (2: a lab PC doing other work); results "
        "then go to soak_loaded.json",
    )
    args = parser.parse_args(argv)
    duration_s = QUICK_DURATION_S if args.quick else args.duration_s
    warmup_s = QUICK_WARMUP_FRACTION * duration_s if args.quick else min(WARMUP_S, duration_s / 5)
    stem = "soak_loaded" if args.hogs else "soak"
    out_json = args.out or RESULTS / (f"{stem}.quick.json" if args.quick else f"{stem}.json")
    namespace = "/catheter"

    with tempfile.TemporaryDirectory(prefix="bench_soak_") as tmp:
        run_dir = args.keep_run or Path(tmp) / "run"
        csv = soak_csv(Path(tmp) / "soak_trajectory.csv", duration_s)
        cmd = [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--sim",
            "--file",
            str(csv),
            "--control-rate-hz",
            f"{CONTROL_RATE_HZ:g}",
            "--namespace",
            namespace,
            "--out",
            str(run_dir),
            "--no-progress",
        ]
        env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(args.domain_id),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "PYTHONUNBUFFERED": "1",
        }
        log = Path(tmp) / "follow_trajectory.log"
        print(f"--- soak: {duration_s:g} s at {CONTROL_RATE_HZ:g} Hz, recorder on ---", flush=True)
        busy = [
            subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(args.hogs)
        ]
        try:
            start = time.monotonic()
            code, following, samples = run_soak(cmd, env, log, duration_s, duration_s + 240.0)
            wall_s = time.monotonic() - start
        finally:
            for hog in busy:
                hog.kill()
                hog.wait()
        output = log.read_text(errors="replace")
        print(output)
        report_path = run_dir / "report.json"
        if code != 0 or following is None or not report_path.exists():
            print(f"soak: follow_trajectory failed (exit {code})", file=sys.stderr)
            return 1
        report: dict[str, Any] = json.loads(report_path.read_text())
        node_logs = {
            p.stem: log_problems(p.read_text(errors="replace"))
            for p in sorted((run_dir / "logs").glob("*.log"))
        }
        t0 = time.monotonic()
        bag = read_bag(Path(report["bag"]))
        bag["read_s"] = time.monotonic() - t0

    result = analyse(
        report,
        samples,
        following,
        bag,
        duration_s=duration_s,
        warmup_s=warmup_s,
        namespace=namespace,
        node_logs=node_logs,
    )
    print_table(result)
    plot = result.pop("_plot")
    saved = {
        "benchmark": "soak",
        "command": " ".join(["bench/bench_soak.py", *(argv if argv is not None else sys.argv[1:])]),
        "follow_trajectory": " ".join(["follow_trajectory", *cmd[3:]]),
        "trajectory": "traj_arbitrary_small_variations then traj_descending_sine, repeated",
        "quick": args.quick,
        "cpu_hogs": args.hogs,
        "wall_s": wall_s,
        **result,
        "machine": _machine()
        | {"rmw": os.environ.get("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp (default)")},
    }
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(saved, indent=2) + "\n")
    out_png = out_json.with_suffix(".png")
    save_plot(out_png, **plot)
    print(f"Results: {out_json}\nPlot: {out_png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
