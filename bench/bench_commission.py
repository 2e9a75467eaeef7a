"""``commission`` on plants it has never seen: the wall time of each step and the tracking.

Each plant gets one ``commission --sim --plant ...`` (or ``--emulated-rig``) run in a fresh
directory and a ROS domain of its own, exactly as a person types it; this script only reads
what the run wrote (``commission.json``, ``model/commissioned.json``) and lays the runs side by
side. Plants:

* ``ours``: the project's simulated rig (the default plant).
* ``foreign_plants.plugin:<name>``: the two simulated catheters of ``tests/support`` written
  apart from ours (Maxwell-slip and Bouc-Wen laws), nothing hidden and with a pneumatic lag,
  a transport delay and a ringing tip, put behind ``sim_hardware`` through the plant
  interface (docs/simulated_rig.md).
* ``emulated``: the emulated devices (Keller, DAC bridge, laser ADC over pseudo-terminals)
  and the real drivers around our plant.

Beside each: today's by-hand path. Its commands are the ones commission runs (the report
lists them), so its tracking is the ``idrdpi+pi`` candidate's; what commission adds is one
command instead of eleven, the rig check, the choice between candidates, and the report.

    .venv/bin/python bench/bench_commission.py                       # every plant (~2 h)
    .venv/bin/python bench/bench_commission.py --plants ours boucwen_tip
    .venv/bin/python bench/bench_commission.py --clstm-budget-s 600 --plants ours

Writes ``bench/results/commission.json`` (merged by plant, so runs can be split).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
SUPPORT = REPO / "tests" / "support"
sys.path.insert(0, str(SUPPORT))

from foreign_plants import pythonpath_with_support  # noqa: E402
from provenance import commit  # noqa: E402

RESULTS = REPO / "bench" / "results" / "commission.json"
TARGET_RMSE_DEG = 0.3
TRAJECTORIES = (
    "traj_descending_sine",
    "traj_down_chirp",
    "traj_up_chirp",
    "traj_arbitrary_small_variations",
)
FOREIGN = (
    "maxwell_slip",
    "maxwell_slip_lag",
    "maxwell_slip_delay",
    "maxwell_slip_tip",
    "boucwen",
    "boucwen_lag",
    "boucwen_delay",
    "boucwen_tip",
)
PLANTS = ("ours", *FOREIGN, "emulated")


def rig_args(plant: str) -> list[str]:
    """commission's rig options for a plant name of this bench."""
    if plant == "ours":
        return ["--sim"]
    if plant == "emulated":
        return ["--emulated-rig"]
    return ["--sim", "--plant", f"foreign_plants.plugin:{plant}"]


def run_one(plant: str, out: Path, domain_id: int, args: argparse.Namespace) -> dict[str, Any]:
    """One commission run; what it wrote, its exit code and wall time."""
    env = {
        **os.environ,
        "ROS_DOMAIN_ID": str(domain_id),
        "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        "PYTHONPATH": pythonpath_with_support(),
    }
    argv = [
        sys.executable,
        "-m",
        "catheter_control.commission",
        "-o",
        str(out),
        *rig_args(plant),
        "--protocol",
        args.protocol,
        "--no-progress",
    ]
    if args.clstm_budget_s:
        argv += ["--clstm-budget-s", str(args.clstm_budget_s)]
    print(f"== {plant}: {' '.join(argv[2:])}", flush=True)
    start = time.monotonic()
    log = out.parent / f"{plant}.log"
    with log.open("w") as fh:
        code = subprocess.run(
            argv, env=env, stdout=fh, stderr=subprocess.STDOUT, check=False
        ).returncode
    wall_s = time.monotonic() - start
    timed = steps = _steps(out)
    comparison_s = 0.0
    if code in (0, 5) and any(rec.get("facts", {}).get("skipped") for rec in timed.values()):
        # commission stops following a candidate that can no longer be chosen; the by-hand
        # path beside it needs its runs. Gone on from where it stopped, outside the timing.
        print(f"== {plant}: the runs commission skipped, for the by-hand column", flush=True)
        start = time.monotonic()
        with log.open("a") as fh:
            subprocess.run(
                [*argv, "--every-run"], env=env, stdout=fh, stderr=subprocess.STDOUT, check=False
            )
        comparison_s = time.monotonic() - start
        steps = _steps(out)
    times: dict[str, float] = {}  # commission's own steps, not the comparison's runs
    for name, rec in timed.items():
        group = name.split(":")[0] if name.startswith("follow:") else name
        times[group] = times.get(group, 0.0) + float(rec.get("seconds", 0.0))
    scores: dict[str, dict[str, float]] = {}
    for name, rec in steps.items():
        if name.startswith("follow:") and rec.get("done"):
            _, cand, traj = name.split(":")
            scores.setdefault(cand, {})[traj] = float(rec["facts"]["rmse_deg"])
    chosen = timed.get("select", {}).get("facts", {})
    explanation = steps.get("explain", {}).get("facts", {}).get("explanation", {})
    tail = log.read_text().splitlines()[-6:]
    return {
        "exit_code": code,
        "wall_s": wall_s,
        "comparison_runs_s": comparison_s,
        "step_seconds": times,
        "scores_rmse_deg": scores,
        "chosen": chosen.get("compensator"),
        "chosen_feedforward_shaping": chosen.get("feedforward_shaping", "none"),
        "commands_missing": {
            part: steps.get(f"record_{part}", {})
            .get("facts", {})
            .get("check", {})
            .get("commands_missing")
            for part in ("train", "test")
        },
        "chosen_rmse_deg": chosen.get("rmse_deg", {}),
        "misses": chosen.get("misses", {}),
        "explain_changes": [
            s.get("change") for s in explanation.get("steps", []) if s.get("change")
        ],
        "explain_verdict": (explanation.get("steps") or [{}])[-1].get("verdict"),
        "by_hand_rmse_deg": scores.get("idrdpi+pi", {}),
        "by_hand_commands": 11,
        "log_tail": tail if code not in (0, 5) else [],
    }


def _steps(out: Path) -> dict[str, Any]:
    """The steps a commission directory's ``commission.json`` records ({} before the first)."""
    state = out / "commission.json"
    return dict(json.loads(state.read_text()).get("steps", {})) if state.exists() else {}


def table(results: dict[str, dict[str, Any]]) -> str:
    """Plant by plant: time, chosen, RMSE per trajectory beside the by-hand path's."""
    short = {t: t.replace("traj_", "")[:10] for t in TRAJECTORIES}
    lines = [
        f"{'plant':20s} {'rc':>3s} {'min':>5s} {'chosen':8s} "
        + " ".join(f"{short[t]:>10s}" for t in TRAJECTORIES)
        + "   by hand (idrdpi+pi)"
    ]
    for plant, r in results.items():
        chosen = r["chosen_rmse_deg"]
        hand = r["by_hand_rmse_deg"]
        lines.append(
            f"{plant:20s} {r['exit_code']:3d} {r['wall_s'] / 60:5.1f} {r['chosen']!s:8s} "
            + " ".join(f"{chosen.get(t, float('nan')):10.3f}" for t in TRAJECTORIES)
            + "   "
            + " ".join(f"{hand.get(t, float('nan')):.3f}" for t in TRAJECTORIES)
        )
    lines.append("")
    lines.append("wall time per step [s]:")
    for plant, r in results.items():
        lines.append(
            f"  {plant:20s} " + ", ".join(f"{k} {v:.0f}" for k, v in r["step_seconds"].items())
        )
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plants", nargs="+", default=list(PLANTS), choices=PLANTS)
    parser.add_argument("--protocol", default="full", choices=("full", "quick"))
    parser.add_argument("--clstm-budget-s", type=float, default=0.0)
    parser.add_argument("--keep", type=Path, default=None, help="keep the runs' directories here")
    args = parser.parse_args()
    root = args.keep or Path(tempfile.mkdtemp(prefix="bench_commission-"))
    root.mkdir(parents=True, exist_ok=True)
    results: dict[str, dict[str, Any]] = {}
    # The file is merged by plant over many runs: each row says which code and command made it.
    provenance = {
        "commit": commit(),
        "command": "python bench/bench_commission.py " + " ".join(sys.argv[1:]),
    }
    for k, plant in enumerate(args.plants):
        results[plant] = run_one(plant, root / plant, 60 + k, args)
        results[plant]["provenance"] = {
            **provenance,
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
        print(table({plant: results[plant]}), flush=True)
    print("\n" + table(results))
    merged: dict[str, Any] = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
    merged.setdefault("plants", {}).update(results)
    merged["target_rmse_deg"] = TARGET_RMSE_DEG
    merged["machine"] = {"cpus": os.cpu_count(), "platform": platform.platform()}
    merged["command"] = "python bench/bench_commission.py " + " ".join(sys.argv[1:])
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(json.dumps(merged, indent=2) + "\n")
    print(f"results: {RESULTS} (runs in {root})")


if __name__ == "__main__":
    main()
