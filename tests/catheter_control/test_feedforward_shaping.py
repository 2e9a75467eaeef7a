"""Feedforward shaping in the compensator: the tip stops ringing, and the bend stays on time."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from tuned_gains import sealed_gains

from catheter_control import commission as cm
from catheter_control import commission_steps as steps
from catheter_control.commission_rig import RigChoice
from catheter_control.control_core import ControlCore
from catheter_control.models import (
    ShapedCompensator,
    load_shaping,
    resolve_shaping,
    shipped_model_dir,
)
from catheter_control.trajectory import TrajectoryPlan
from catheter_models.errors import ParameterError
from catheter_models.shaping import InputShaper
from catheter_models.signals import TEST_TRAJECTORIES

RATE_HZ = 250.0
GAIN_RAD_PER_PA = math.radians(10.0) / 1e5
TIP_HZ, TIP_DAMPING = 4.5, 0.07


class LinearInverse:
    """The inverse of a plant with no hysteresis: its kinks are the plan's own."""

    preview_s = 0.0
    sample_period_s: float | None = 1.0 / RATE_HZ
    steps = 0

    def reset(self) -> None:
        """Stateless."""

    def step(self, angle_desired_rad: float) -> float:
        self.steps += 1
        return angle_desired_rad / GAIN_RAD_PER_PA


class TipPlant:
    """Pressure to bend through a static gain and a lightly damped tip mode (semi-implicit
    Euler at 10 kHz inside each 4 ms sample)."""

    def __init__(self) -> None:
        self.angle_rad = 0.0
        self.rate_rad_s = 0.0

    def step(self, pressure_pa: float) -> float:
        wn = 2.0 * math.pi * TIP_HZ
        dt_s = 1e-4
        for _ in range(40):
            accel = wn * wn * (GAIN_RAD_PER_PA * pressure_pa - self.angle_rad)
            accel -= 2.0 * TIP_DAMPING * wn * self.rate_rad_s
            self.rate_rad_s += dt_s * accel
            self.angle_rad += dt_s * self.rate_rad_s
        return self.angle_rad


def _follow(compensator: LinearInverse | ShapedCompensator) -> tuple[np.ndarray, np.ndarray]:
    """A triangle with a rest (kinks: every reversal of a hysteresis inverse is one)."""
    knots_s = np.array([0.0, 0.5, 1.5, 2.5, 3.5, 5.0])
    knots_rad = np.radians([0.0, 0.0, 15.0, 5.0, 20.0, 20.0])
    plan = TrajectoryPlan(knots_s, knots_rad, "kinks")
    core = ControlCore(compensator, 0.0, 3e5, 1e7)
    core.start(plan, 0.0)
    plant = TipPlant()
    t_s = np.arange(0.0, 5.0, 1.0 / RATE_HZ)
    bend = np.empty_like(t_s)
    for i, t in enumerate(t_s):
        out = core.tick(float(t), 1.0 / RATE_HZ)
        assert out is not None, f"the core went idle at {t:.3f} s"
        bend[i] = plant.step(out.pressure_pa)
    return t_s, np.degrees(bend - np.interp(t_s, knots_s, knots_rad))


def test_a_shaped_feedforward_does_not_ring_the_tip_and_stays_on_time() -> None:
    t_s, plain = _follow(LinearInverse())
    shaper = InputShaper.zvd(TIP_HZ, TIP_DAMPING)
    _, shaped = _follow(ShapedCompensator(LinearInverse(), shaper))

    def ringing(error_deg: np.ndarray) -> float:
        # Between kinks, once the shaper's impulses are through (it starts a kink 0.11 s
        # early and ends it 0.11 s late), a tip that does not ring follows a ramp at a
        # constant lag: what is left beyond a straight line is ringing.
        worst = 0.0
        for kink_s, next_s in ((0.5, 1.5), (1.5, 2.5), (2.5, 3.5), (3.5, 5.15)):
            inside = (t_s > kink_s + 0.15) & (t_s < next_s - 0.15)
            trend = np.polyval(np.polyfit(t_s[inside], error_deg[inside], 1), t_s[inside])
            worst = max(worst, float(np.ptp(error_deg[inside] - trend)))
        return worst

    assert ringing(shaped) < 0.1 * ringing(plain), (ringing(plain), ringing(shaped))
    # Read ahead by the shaper's delay, the bend is not late: the shaped run's error is a
    # fraction of the plain one's, not the lag of 110 ms at 15 deg/s (1.6 deg).
    rms = {k: float(np.sqrt(np.mean(e**2))) for k, e in (("plain", plain), ("shaped", shaped))}
    assert rms["shaped"] < 0.5 * rms["plain"], rms
    assert np.max(np.abs(shaped[t_s > 4.0])) < 0.05  # settled on the held end, no ringing


def test_the_shaper_reads_the_plan_ahead_by_its_mean_delay() -> None:
    shaper = InputShaper.zvd(TIP_HZ, TIP_DAMPING)
    wrapped = ShapedCompensator(LinearInverse(), shaper)
    assert wrapped.preview_s == pytest.approx(shaper.mean_delay_s)
    assert wrapped.sample_period_s == pytest.approx(1.0 / RATE_HZ)
    assert "4.50 Hz tip" in wrapped.label


def test_load_shaping_takes_the_tip_from_the_sealed_tuning_and_refuses_a_loop_without_one() -> None:
    shipped = str(shipped_model_dir("feedback") / "feedback.json")
    inner = LinearInverse()
    assert load_shaping("none", inner, shipped, "") is inner
    # The shipped gains were tuned on the simulated rig, whose tip does not ring.
    with pytest.raises(ParameterError, match="has none"):
        load_shaping("zvd", inner, shipped, "")
    with pytest.raises(ParameterError, match="unknown feedforward shaping"):
        load_shaping("zv", inner, shipped, "")


def test_commission_tries_a_shaped_candidate_on_a_ringing_tip_and_records_its_choice(
    tmp_path: Path,
) -> None:
    job = cm.Commission(
        out_dir=tmp_path / "out",
        choice=RigChoice("sim", "", "/catheter"),
        protocol="quick",
        clstm_budget_s=0.0,
        explain_steps=1,
        workers=1,
        control_rate_hz=RATE_HZ,
        show_progress=False,
    )
    sealed_gains(job.tune_dir, resonance_hz=0.0)
    assert [c.name for c in job.candidates()] == ["idrdpi+pi"]
    sealed_gains(job.tune_dir, resonance_hz=TIP_HZ, resonance_damping=0.05)
    candidates = {c.name: c for c in job.candidates()}
    assert set(candidates) == {"idrdpi+pi", "idrdpi+zvd+pi"}
    assert candidates["idrdpi+zvd+pi"].params(RATE_HZ)["feedforward_shaping"] == "zvd"
    d = job.candidate_dir("idrdpi")
    d.mkdir(parents=True)
    (d / "manifest.json").write_text(json.dumps({"kind": "idrdpi"}))
    for name, rmse in (("idrdpi+pi", 0.9), ("idrdpi+zvd+pi", 0.5)):
        for traj in TEST_TRAJECTORIES:
            job.state.steps[f"follow:{name}:{traj}"] = steps.StepRecord(
                done=True, facts={"rmse_deg": rmse}
            )
    job._select()
    model = str(job.out_dir / cm.MODEL_DIR)
    record = json.loads((job.out_dir / cm.MODEL_DIR / cm.COMMISSIONED_FILE).read_text())
    assert record["feedforward_shaping"] == "zvd"
    # The directory runs as it was verified: shaped, unless asked otherwise.
    assert resolve_shaping(None, model) == "zvd"
    assert resolve_shaping("none", model) == "none"
    assert resolve_shaping(None, str(d)) == "none"
