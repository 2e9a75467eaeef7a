"""Feedforward shaping over DDS: ``follow_trajectory --sim --feedforward-shaping zvd`` on a
catheter with a ringing tip, through the plant interface, against the same run unshaped.

The plant is the Bouc-Wen catheter with a 4.5 Hz tip (``foreign_plants.plugin:boucwen_tip``,
written apart from ours). ``boucwen_tip_commissioned`` holds what ``commission`` fitted on it
(bench/bench_commission.py --plants boucwen_tip, this repository's run): the IDRDPI, and the
gains ``catheter-lab tune`` sealed from the same recording (tip 4.49 Hz, damping 0.073).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from foreign_plants import SUPPORT_DIR, pythonpath_with_support
from graph_utils import SLACK_SENSOR_TIMEOUT_S, Children
from scipy import signal

from catheter_models.bag import load_bag

pytestmark = [
    pytest.mark.slow,
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

COMMISSIONED = SUPPORT_DIR / "foreign_plants" / "boucwen_tip_commissioned"
KNOTS_DEG = np.array([[0, 0], [0.5, 0], [2, 15], [3.5, 5], [5, 20], [7, 20]], dtype=float)
"""Kinks: the set-point reverses as a hysteresis inverse's pressure does at every reversal."""


def _follow(children: Children, tmp_path: Path, shaping: str, *extra: str) -> tuple[int, str, Path]:
    csv = tmp_path / "kinks.csv"
    csv.write_text("t_s,angle_deg\n" + "\n".join(f"{t:g},{a:g}" for t, a in KNOTS_DEG) + "\n")
    out = tmp_path / f"run_{shaping}"
    run = children.run(
        f"follow_{shaping}",
        [
            sys.executable,
            "-m",
            "catheter_control.follow_trajectory",
            "--file",
            str(csv),
            "--sim",
            "--plant",
            "foreign_plants.plugin:boucwen_tip",
            "--feedforward-shaping",
            shaping,
            "--lead-in-s",
            "0",
            "--out",
            str(out),
            "--no-progress",
            # About the tip's ringing, not a sensor's silence: a loaded run saw tip/angle quiet
            # for 104 ms and the shaped run stopped 0.7 s in.
            "--sensor-timeout-s",
            str(SLACK_SENSOR_TIMEOUT_S),
            *extra,
        ],
        timeout_s=120.0,
    )
    return run.returncode, run.stdout + run.stderr, out


def _errors_deg(run_dir: Path) -> tuple[float, float]:
    """The bend's RMSE against the plan, and the RMS of its error between 3 and 6.5 Hz (the
    tip's band), on the recorded bag's stamps from the first set-point."""
    bag = load_bag(run_dir / "bag")
    assert bag.tip_angle is not None and bag.angle_desired is not None
    t_s = bag.tip_angle.t_s - float(bag.angle_desired.t_s[0])
    grid_s = np.arange(0.0, KNOTS_DEG[-1, 0], 1.0 / 250.0)
    error = np.interp(grid_s, t_s, np.degrees(bag.tip_angle.values)) - np.interp(
        grid_s, KNOTS_DEG[:, 0], KNOTS_DEG[:, 1]
    )
    band = signal.sosfiltfilt(
        signal.butter(4, [3.0, 6.5], "bandpass", fs=250.0, output="sos"), error
    )
    return float(np.sqrt(np.mean(error**2))), float(np.sqrt(np.mean(band**2)))


@pytest.mark.timeout(900)  # 45-80 s idle; minutes beside two busy loops
def test_shaping_stops_the_tip_ringing_on_the_live_graph(
    children: Children, tmp_path: Path
) -> None:
    children.env["PYTHONPATH"] = pythonpath_with_support()
    found = {}
    for shaping in ("none", "zvd"):
        code, output, out = _follow(
            children, tmp_path, shaping, "--model-dir", str(COMMISSIONED), "--feedback", "pi"
        )
        assert code == 0, output[-3000:]
        controller = json.loads((out / "report.json").read_text())["controller"]
        assert controller["feedforward_shaping"] == shaping, controller
        found[shaping] = _errors_deg(out)
    print(f"(RMSE, RMS in the tip's band) [deg]: {found}")
    assert found["none"][1] > 0.1, found  # the unshaped run rings: else this proves nothing
    assert found["zvd"][1] < 0.5 * found["none"][1], found
    assert found["zvd"][0] < found["none"][0], found


def test_shaping_without_a_tip_mode_is_refused_before_anything_starts(
    children: Children, tmp_path: Path
) -> None:
    children.env["PYTHONPATH"] = pythonpath_with_support()
    # The shipped gains were tuned on our plant, whose tip does not ring: nothing to shape.
    code, output, out = _follow(children, tmp_path, "zvd", "--compensator", "idrdpi")
    assert code == 2, output[-3000:]
    assert "has none" in output and "Traceback" not in output, output[-3000:]
    assert not (out / "bag").exists()  # refused before the graph started
