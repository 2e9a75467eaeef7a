"""Remake the sample bags in bags/ with the real graph: excite -> sim_hardware -> recorder.

Each bag is data acquisition as in thesis ch. 4: one open-loop pressure signal (or the whole
training protocol) sent by ``excite`` to the simulated rig while ``recorder`` records. This
runs in real time (about 4 minutes for all of them) because it exercises the same nodes a lab
runs on the rig.

    python scripts/make_sample_bags.py [--out bags] [--only training,model_test_up_chirp]
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from catheter_control.bringup import NodeSpec, ProcessGraph, sim_graph_specs
from catheter_models.bag import load_bag
from catheter_models.contract import SENSOR_STREAMS
from catheter_models.signals import TEST_PRESSURE_SIGNALS, get_preset, training_set

ATTEMPTS = 3
"""Recordings tried per bag before giving up: a shipped bag must not lack a sensor sample."""

BAGS = {"training": "training"} | {name: name for name in TEST_PRESSURE_SIGNALS}


def describe(signal: str) -> dict[str, str]:
    specs = training_set() if signal == "training" else (get_preset(signal),)
    out = {
        "signal": signal,
        "hardware": "simulated thesis rig (catheter_driver sim_hardware, defaults, seed 0)",
        "made_by": "scripts/make_sample_bags.py",
    }
    for spec in specs:
        out[f"signal_params.{spec.name}"] = repr(dict(spec.params()))
    return out


def record(signal: str, bag: Path, domain: int) -> None:
    env = {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    specs = sim_graph_specs(bag, describe(signal), with_compensator=False)
    specs[0].params["compression"] = "zstd"  # the recorder; keeps the repository small
    excite = NodeSpec(
        "excite",
        "catheter_control.excite_node",
        {"signal": signal, "tail_s": 1.0, "min_subscribers": 2},  # the rig and the recorder
    )
    with ProcessGraph(specs, env=env, log_dir=bag.parent / f".logs-{signal}") as graph:
        time.sleep(2.0)  # let the recorder match every publisher before the first sample
        print(f"{signal}: recording to {bag}", flush=True)
        done = subprocess.run(excite.argv("/catheter"), env={**os.environ, **env}, check=False)
        time.sleep(0.5)
        if done.returncode != 0 or graph.failed():
            raise SystemExit(f"{signal}: excite exited {done.returncode}, graph {graph.failed()}")
    shutil.rmtree(bag.parent / f".logs-{signal}", ignore_errors=True)


def sensor_gaps(bag: Path) -> list[str]:
    """The bag's gap lines for sensor streams (commands skipped by a late tick are allowed:
    the valve held its set-point, and the bag says so)."""
    sensors = {spec.name for spec in SENSOR_STREAMS}
    data = load_bag(bag)
    return [line for line in data.gap_report() if line.split()[0] in sensors]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bags"))
    parser.add_argument("--only", default="", help="comma-separated subset of: " + ", ".join(BAGS))
    parser.add_argument("--domain", type=int, default=77, help="ROS_DOMAIN_ID to record on")
    args = parser.parse_args()
    names = [n for n in args.only.split(",") if n] or list(BAGS)
    for name in names:
        if name not in BAGS:
            sys.exit(f"unknown bag {name!r}; choose from {', '.join(BAGS)}")
        bag = args.out / BAGS[name]
        for attempt in range(1, ATTEMPTS + 1):
            if bag.exists():
                shutil.rmtree(bag)
            record(name, bag, args.domain)
            gaps = sensor_gaps(bag)
            if not gaps:
                break
            print(f"{name}: attempt {attempt} lacks sensor samples: {'; '.join(gaps)}", flush=True)
        else:
            raise SystemExit(f"{name}: every one of {ATTEMPTS} recordings lacked sensor samples")


if __name__ == "__main__":
    main()
