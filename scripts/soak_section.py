"""The soak figures of docs/reliability.md from a soak run (``make soak``).

    .venv/bin/python bench/bench_soak.py
    .venv/bin/python scripts/soak_section.py bench/results/soak.json --docs docs/reliability.md
    .venv/bin/python bench/bench_soak.py --hogs 2
    .venv/bin/python scripts/soak_section.py bench/results/soak_loaded.json \
        --docs docs/reliability.md

Prints the section (run, missed deadlines per minute, command latency, RSS per process,
messages per topic, sensor stalls, verdicts) and, with ``--docs``, writes it between
``<!-- <stem>:begin -->`` and ``<!-- <stem>:end -->``, the stem being the JSON's (``soak``,
``soak_loaded``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from doc_markers import write_between


def markers(stem: str) -> tuple[str, str]:
    """The markers a result's section sits between in the docs."""
    return f"<!-- {stem}:begin -->", f"<!-- {stem}:end -->"


def _f(value: float | None, spec: str) -> str:
    return "n/a" if value is None else format(value, spec)


def section(result: dict[str, Any], stem: str = "soak") -> str:
    """Markdown for one soak result (bench_soak.py's JSON, saved as ``<stem>.json``)."""
    v, missed, bag = result["verdicts"], result["missed_deadlines"], result["bag"]
    machine = result.get("machine", {})
    frac = missed.get("fraction")
    hogs = int(result.get("cpu_hogs") or 0)
    command = (
        "`make soak` (`bench/bench_soak.py`"
        if not hogs
        else (
            f"`bench/bench_soak.py --hogs {hogs}` (beside {hogs} busy loops at normal priority, "
            "a lab PC doing other work;"
        )
    )
    timing = result.get("timing", {})
    lines = [
        f"{command} figures in `bench/results/{stem}.json`, plot "
        f"`bench/results/{stem}.png`): the whole simulated graph (recorder, `sim_hardware`, "
        f"`compensator` with the shipped c-LSTM, each its own process) at "
        f"{result['control_rate_hz']:g} Hz for {result['duration_s']:g} s, following thesis "
        "trajectories 4 and 1 over and over, the recorder on"
        + (f", on {machine.get('cpu', 'this machine')}" if machine.get("cpu") else "")
        + ".",
        "",
        "- **Run:** "
        + (
            f"completed; the compensator followed all of it ({bag['compensator_span_s']:.0f} s of "
            f"commands), tracking RMSE {_f(result.get('rmse_deg'), '.3f')}°."
            if v["run_completed"]
            else f"**stopped early** (at {_f(v['compensator_stopped_at_s'], '.0f')} s)."
        ),
        f"- **Missed deadlines:** {missed['total']} of {missed['ticks']} ticks "
        f"({_f(None if frac is None else 100 * frac, '.3f')} %). Per minute: "
        + ", ".join(str(m) for m in missed.get("per_minute", []))
        + ".",
    ]
    series = result.get("compensator_series", {})
    before = [
        int(m)
        for t, m in zip(series.get("t_s", []), series.get("missed_deadlines", []), strict=False)
        if t is not None and t <= 0.0 and str(m).isdigit()
    ]
    if before and before[-1]:
        lines.append(
            f"  Of these, {before[-1]} were missed before the trajectory was sent (the node "
            "starting up, at rest). The largest gap in the compensator's topics over the run: "
            f"{bag['topics'][next(iter(bag['topics']))]['max_gap_periods']:.0f} periods."
        )
    if missed.get("growth") is not None:
        lines.append(
            f"  After the {result['warmup_s']:g} s warm-up: first third "
            f"{missed['first_third_per_min']:.1f}/min, last third "
            f"{missed['last_third_per_min']:.1f}/min: "
            + ("**growth**" if missed["growth"] else "no growth")
            + f" (the bound: an increase beyond {result['bounds']['missed_growth_sigmas']:g} "
            "Poisson standard deviations)."
        )
    if timing.get("command_latency_p99_ms") is not None:
        lines.append(
            f"- **Command latency** (the compensator's tick to the driver's tick that applied "
            f"it): p50 {_f(timing.get('command_latency_p50_ms'), '.2f')} ms, p99 "
            f"{_f(timing.get('command_latency_p99_ms'), '.2f')} ms, max "
            f"{_f(timing.get('command_latency_max_ms'), '.2f')} ms."
        )
    stalls = result.get("stalls", {})
    if stalls.get("measured"):
        where = "; ".join(f"{w}: {n}" for w, n in sorted(stalls["by_where"].items()))
        lines.append(
            f"- **Sensor stalls:** {stalls['seconds_with_a_stall']} second(s) in which a sensor "
            f"the compensator needs went quiet for over {stalls['stall_ms']:g} ms"
            + (
                f" ({where}; a loop counts as behind past {stalls['behind_ms']:g} ms)"
                if where
                else ""
            )
            + "."
        )
        for row in stalls["rows"][:8]:
            quiet = ", ".join(f"`{k}` {val:.0f} ms" for k, val in row["silence_ms"].items())
            lines.append(
                f"  At {row['t_s']:.0f} s: {quiet}; the compensator's loop "
                f"{_f(row['compensator_behind_ms'], '.0f')} ms behind, the driver's "
                f"{_f(row['driver_behind_ms'], '.0f')} ms."
            )
    bounds = result["bounds"]
    lines += [
        f"- **Memory:** RSS per process, sampled every second; growth is a fitted slope above "
        f"{bounds['rss_bound_mb_per_h']:g} MB/h and more than {bounds['rss_floor_mb']:g} MB "
        f"over the window after the warm-up.",
        "",
        "  | process | RSS at start | at end | peak | slope | verdict |",
        "  |---|---|---|---|---|---|",
    ]
    not_judged = set(result["rss"].get("not_judged", []))
    for name, fit in result["rss"]["fits"].items():
        if fit.get("slope_mb_per_min") is None:
            continue
        verdict = "**grows**" if fit["growth"] else "flat"
        if name in not_judged:
            verdict = (
                "not judged: the client, not a node of the graph; it keeps every sample it "
                "receives to score the run, so it grows with the run's length"
            )
        lines.append(
            f"  | {name} | {fit['start_mb']:.1f} MB | {fit['end_mb']:.1f} MB | "
            f"{fit['peak_mb']:.1f} MB | {fit['slope_mb_per_min'] * 60:+.1f} MB/h | {verdict} |"
        )
    lines += [
        "",
        "- **Messages in the bag** (read with the `mcap` package, not ours; a gap is a step of "
        f"more than {bounds['gap_factor_periods']:g} periods between header stamps):",
        "",
        "  | topic | rate | messages | expected from the span | missing (in gaps) | of which "
        "skipped ticks | dropped |",
        "  |---|---|---|---|---|---|---|",
    ]
    for topic, row in bag["topics"].items():
        lines.append(
            f"  | `{topic}` | {row['rate_hz']:g} Hz | {row['messages']} | {row['expected']} | "
            f"{row['missing']} ({row['gaps']}) | {row['explained_by_skipped_ticks']} | "
            f"{row['dropped']} |"
        )
    lines += [
        "",
        "  A skipped tick is a deadline the compensator missed: it resumes at the next deadline "
        "rather than burst stale commands, so its topics have a gap there and nothing is lost "
        "in transit; `sim_hardware` publishes its backlog, so a gap in its topics would be a "
        "drop.",
        "- **Verdict:** missed deadlines "
        + {True: "**grow**", False: "do not grow", None: "n/a"}[v["missed_deadlines_growth"]]
        + "; memory "
        + ("**grows**" if v["memory_growth"] else "does not grow")
        + f"; dropped messages: {v['dropped_messages']}; bag index and messages "
        + ("agree" if v["bag_counts_consistent"] else "**disagree**")
        + ".",
        "",
        f"![{stem}](../bench/results/{stem}.png)",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("result", type=Path, help="bench_soak.py's JSON")
    parser.add_argument("--docs", type=Path, help="markdown file to write the section into")
    args = parser.parse_args(argv)
    if not args.result.is_file():
        print(f"soak_section: {args.result} does not exist; run the soak first", file=sys.stderr)
        return 2
    stem = args.result.name.split(".")[0]
    text = section(json.loads(args.result.read_text()), stem)
    print(text)
    if args.docs:
        write_between(args.docs, *markers(stem), text)
        print(f"written into {args.docs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
