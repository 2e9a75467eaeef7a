"""A commissioned model directory replayed offline on a plant, to try a change in seconds.

A live commissioning run takes half a minute per trajectory and a graph of processes; this
runs the same compensator and feedback (the model directory's ``manifest.json`` and
``feedback.json``, as ``follow_trajectory --model-dir`` loads them) through
:class:`catheter_models.feedback.ClosedLoop` with the node's clamp and slew limit, on a
plant of the rig's plant contract (``--plant module:factory``, as ``sim_hardware`` takes
it), one sample at a time, the plan read ``preview_s`` ahead. Before each trajectory the
plant is bent to 2.2 bar and vented, as the live plant has been by commissioning's own
recordings, and the bend heard in the half second before the plan starts is taken as where
it rests vented (as the tracking report does).

On the ``maxwell_slip_delay`` and ``maxwell_slip_tip`` directories of docs/benchmarks.md
("Latest (2026-11-27, night)") it gives 0.263 / 0.082 / 0.259 / 0.277 and 0.313 / 0.097 /
0.333 / 0.290 deg where the live runs gave 0.259 / 0.070 / 0.253 / 0.275 and 0.314 / 0.079 /
0.324 / 0.287 deg (within 0.018 deg). What it leaves out: DDS, the laser node's
sampling and the compensator's interpolation between a model's samples; a change it
favours must still be proven live (``bench/bench_commission.py``).

    .venv/bin/python bench/replay_commissioned.py /tmp/bench_s11/maxwell_slip_tip/model \\
        --plant foreign_plants.plugin:maxwell_slip_tip
    .venv/bin/python bench/replay_commissioned.py DIR --plant ... --no-feedback

Prints, per thesis trajectory, the RMSE, the least RMSE the vented rest costs
(:class:`~catheter_control.tracking_report.VentedFloor`) and the RMSE where the set-point
is above the rest, in degrees.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "support"))  # foreign_plants.plugin:<name>

from bench_closed_loop import follow_plan  # noqa: E402

from catheter_control.models import gains_file, load_compensator, resolve_compensator  # noqa: E402
from catheter_models.contract import MAX_PRESSURE_PA  # noqa: E402
from catheter_models.feedback import FeedbackGains  # noqa: E402
from catheter_models.models.evaluate import lead_in  # noqa: E402
from catheter_models.plant.interface import load_plant  # noqa: E402
from catheter_models.signals import TEST_TRAJECTORIES, get_preset  # noqa: E402
from catheter_models.units import rad_to_deg  # noqa: E402

BENT_PA = 2.2e5
"""How far the plant is bent before each run, then vented: it has been, live [Pa]."""
REST_S = 0.5
"""How long the plant rests vented before the plan, and the window its rest is taken in [s]."""


def rms_deg(error_rad: np.ndarray) -> float:
    """Root mean square of an error [rad], in degrees (0 for no samples)."""
    return float(rad_to_deg(np.sqrt(np.mean(error_rad**2)))) if error_rad.size else 0.0


def replay(model_dir: Path, plant_spec: str, trajectory: str, feedback: bool) -> dict[str, float]:
    """One thesis trajectory from rest, with the lead-in; RMSEs in degrees."""
    kind = resolve_compensator(None, str(model_dir))
    ff = load_compensator(kind, str(model_dir), max_pressure_pa=MAX_PRESSURE_PA)
    gains = FeedbackGains.load(gains_file("", str(model_dir))) if feedback else None
    plant = load_plant(plant_spec)
    rate_hz = float(plant.rate_hz)
    desired = np.asarray(get_preset(trajectory).generate(rate_hz).values_si)
    rest = np.zeros(round(REST_S * rate_hz))
    plan = np.concatenate([rest, lead_in(float(desired[0]), rate_hz, 1.0, 1.0), desired])
    plant.reset()
    ramp = np.linspace(0.0, BENT_PA, round(2.0 * rate_hz))
    for pressure_pa in np.concatenate([ramp, ramp[::-1], np.zeros(round(2.0 * rate_hz))]):
        plant.step(float(pressure_pa))
    measured, _, fault = follow_plan(
        ff, gains, lambda command_pa: plant.step(command_pa)[1], plan, rate_hz
    )
    if fault:
        print(f"  {trajectory}: ramped down: {fault}")
    error = measured[plan.size - desired.size :] - desired
    rest_rad = float(np.median(measured[: rest.size]))
    return {
        "rmse_deg": rms_deg(error),
        "floor_deg": rms_deg(np.maximum(rest_rad - desired, 0.0)),
        "above_rest_deg": rms_deg(error[desired >= rest_rad]),
        "rest_deg": float(rad_to_deg(rest_rad)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model_dir", type=Path, help="a model directory (commission's OUT/model)")
    parser.add_argument("--plant", required=True, help="module:factory of the plant")
    parser.add_argument("--no-feedback", action="store_true", help="the feedforward alone")
    args = parser.parse_args()
    for trajectory in TEST_TRAJECTORIES:
        r = replay(args.model_dir, args.plant, trajectory, not args.no_feedback)
        print(
            f"{trajectory:34s} RMSE {r['rmse_deg']:.3f} deg   vented floor "
            f"{r['floor_deg']:.3f} deg (rests at {r['rest_deg']:.2f} deg)   above the rest "
            f"{r['above_rest_deg']:.3f} deg"
        )


if __name__ == "__main__":
    main()
