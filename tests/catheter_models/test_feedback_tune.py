"""``catheter-lab tune``: the loop it identifies from recorded steps, and the gains it designs.

The plants are linear ones written here with known answers (gain, lag, dead time, a ringing
tip), driven by the lab's fast-steps excitation as a person would record it; the margins
promised on the identified model must hold on the plant itself.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from catheter_models.cli import main as lab_main
from catheter_models.errors import SignalError
from catheter_models.feedback import ClosedLoop, FeedbackGains
from catheter_models.feedback.tune import MAX_STALL_S, design, find_steps, identify, margins
from catheter_models.lab.signals import lab_spec
from catheter_models.models.base import Recording
from catheter_models.signals import get_preset

RATE_HZ = 250.0
DT_S = 1.0 / RATE_HZ
GAIN = math.radians(12.0) / 1e5


class LinearPlant:
    """gain * exp(-s delay) / (1 + s tau) [* wn^2 / (s^2 + 2 zeta wn s + wn^2)], ZOH-exact."""

    def __init__(
        self, tau_s: float, delay_s: float, tip_hz: float = 0.0, tip_zeta: float = 0.1
    ) -> None:
        num, den = np.array([GAIN]), np.array([tau_s, 1.0])
        if tip_hz:
            wn = 2 * math.pi * tip_hz
            num = num * wn**2
            den = np.polymul(den, [1.0, 2 * tip_zeta * wn, wn**2])
        self.a, self.b, self.c, self.d, _ = signal.cont2discrete(
            signal.tf2ss(num, den), DT_S, method="zoh"
        )
        self.delay = round(delay_s / DT_S)
        self.reset()

    def reset(self) -> None:
        self.x = np.zeros((self.a.shape[0], 1))
        self.queue = [0.0] * self.delay

    def step(self, u: float) -> float:
        self.queue.append(u)
        v = self.queue.pop(0)
        self.x = self.a @ self.x + self.b * v
        return float((self.c @ self.x)[0, 0])

    def record(self, seed: int = 1) -> Recording:
        spec = lab_spec(f"lab_steps_{200 + seed}")
        assert spec is not None
        p = np.asarray(spec.generate(RATE_HZ).values_si)
        self.reset()
        y = np.array([self.step(float(u)) for u in p])
        y += np.random.default_rng(seed).normal(0.0, math.radians(0.05), y.size)
        return Recording(f"steps_{seed}", RATE_HZ, p, y)


def test_identifies_a_lag_and_a_dead_time() -> None:
    plant = LinearPlant(tau_s=0.05, delay_s=0.02)
    model = identify([plant.record()])
    assert model.n_steps >= 5
    assert model.time_constant_s == pytest.approx(0.05, rel=0.2)
    # The fitted dead time includes the half sample of the valve's zero-order hold.
    assert model.delay_s == pytest.approx(0.02, abs=0.006)
    assert model.gain_rad_per_pa == pytest.approx(GAIN, rel=0.05)
    assert model.resonance_hz == 0.0


def test_finds_a_ringing_tip_and_designs_a_notch_for_it() -> None:
    plant = LinearPlant(tau_s=0.01, delay_s=0.008, tip_hz=4.0, tip_zeta=0.08)
    model = identify([plant.record()])
    assert model.resonance_hz == pytest.approx(4.0, rel=0.1)
    assert model.resonance_damping < 0.2
    gains, found = design(model)
    assert gains.notch_frequency_hz == pytest.approx(model.resonance_hz)
    assert found.max_sensitivity <= 1.6 + 1e-9


@pytest.mark.parametrize(
    ("tau_s", "delay_s", "tip_hz"),
    [(0.01, 0.004, 0.0), (0.12, 0.06, 0.0), (0.03, 0.02, 5.0)],
    ids=["fast valve", "slow valve and long line", "ringing tip"],
)
def test_the_designed_loop_keeps_its_promise_on_the_plant(
    tau_s: float, delay_s: float, tip_hz: float
) -> None:
    plant = LinearPlant(tau_s, delay_s, tip_hz)
    gains, found = design(identify([plant.record()]))
    # The bound the design promises: Ms <= 1.6 gives GM >= 2.67 and PM >= 36 deg.
    assert found.max_sensitivity <= 1.6 + 1e-9
    assert found.gain_margin >= 1.6 / 0.6 - 1e-6
    assert found.phase_margin_deg >= 36.0
    # On the plant itself (not the fitted model): a set-point step settles, without ringing
    # on, and the overshoot stays what such margins allow.
    wide = FeedbackGains(**{**gains.__dict__, "max_correction_pa": 3e5})
    loop = ClosedLoop(
        None,
        wide,
        rate_hz=RATE_HZ,
        min_pressure_pa=0.0,
        max_pressure_pa=3e5,
        max_slew_pa_per_s=1e9,
    )
    loop.reset()
    plant.reset()
    target = math.radians(10.0)
    y, out = 0.0, []
    for _ in range(round(4 * RATE_HZ)):
        y = plant.step(loop.step(target, y))
        out.append(y)
    bend = np.degrees(np.asarray(out))
    assert abs(bend[-round(RATE_HZ) :] - 10.0).max() < 0.05
    assert bend.max() < 10.0 * 1.5


def test_a_command_lost_inside_a_ramp_does_not_lose_the_step() -> None:
    """A live recording misses a command now and then; the grid holds the one before over it.

    Each stall inside a ramp (the held-over sample) must not cut the ramp in two: the steps
    found are those of the intact recording, each one lasting as long.
    """
    rec = LinearPlant(tau_s=0.05, delay_s=0.02).record()
    intact = find_steps(rec)
    p = np.asarray(rec.pressure_pa).copy()
    moving = np.flatnonzero(np.abs(np.diff(p)) > 0.0) + 1
    ramps = [w.start + 1 for w in intact]  # the second sample of every step's ramp
    assert all(i in set(moving) for i in ramps)
    stall = round(MAX_STALL_S * RATE_HZ)
    for i in ramps:
        p[i : i + stall] = p[i - 1]  # held over the lost samples
    holed = find_steps(Recording(rec.name, RATE_HZ, p, rec.angle_rad))
    assert [(w.start, w.stop, w.continues) for w in holed] == [
        (w.start, w.stop, w.continues) for w in intact
    ]
    # A longer standstill is a plateau, not a stall: that ramp ends there, as before.
    p = np.asarray(rec.pressure_pa).copy()
    p[ramps[0] : ramps[0] + stall + 1] = p[ramps[0] - 1]
    cut = find_steps(Recording(rec.name, RATE_HZ, p, rec.angle_rad))
    assert intact[0].start not in [w.start for w in cut]


def test_a_recording_without_steps_is_refused_with_what_to_record() -> None:
    spec = get_preset("model_test_up_chirp")
    p = np.asarray(spec.generate(RATE_HZ).values_si)
    rec = Recording("chirp", RATE_HZ, p, p * GAIN)
    with pytest.raises(SignalError, match="lab_steps"):
        identify([rec])


def test_margins_report_the_loop_it_was_given() -> None:
    plant = LinearPlant(tau_s=0.05, delay_s=0.02)
    model = identify([plant.record()])
    gains, found = design(model)
    doubled = FeedbackGains(2 * gains.kp_pa_per_rad, 2 * gains.ki_pa_per_rad_s)
    # Twice the gain: the margins shrink (the report is computed, not copied).
    assert margins(model, doubled).gain_margin == pytest.approx(found.gain_margin / 2, rel=0.02)


def test_the_cli_writes_gains_a_node_can_load_and_a_report(tmp_path: Path) -> None:
    bag = tmp_path / "steps"
    with pytest.raises(SystemExit) as done:
        lab_main(["simulate", "lab_steps_101", "-o", str(bag)])
    assert not done.value.code
    with pytest.raises(SystemExit) as done:
        lab_main(["tune", str(bag), "-o", str(tmp_path / "model"), "--report", str(tmp_path / "r")])
    assert not done.value.code
    gains = FeedbackGains.load(tmp_path / "model")
    assert gains.kp_pa_per_rad > 0.0 and gains.ki_pa_per_rad_s > 0.0
    assert gains.opening_pressure_pa > 0.2e5  # the simulated muscle opens near 0.8 bar
    assert "Ms" in gains.tuning["margins"]
    page = (tmp_path / "r" / "index.html").read_text()
    assert "steps.png" in page and "loop.png" in page
    assert (tmp_path / "r" / "loop.png").stat().st_size > 10_000


def test_the_cli_takes_the_loop_from_the_explained_chain_and_says_so(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from catheter_models.models.cores import make_core
    from catheter_models.models.greybox import GreyBox

    bag = tmp_path / "steps"
    with pytest.raises(SystemExit) as done:
        lab_main(["simulate", "lab_steps_101", "-o", str(bag)])
    assert not done.value.code
    # A chain as the lab writes one (its core's values do not enter the loop's shape).
    chain = GreyBox(effects=["transport_delay", "pneumatic_lag"], core="free_pi")
    chain._set(
        make_core("free_pi"),
        {"transport_delay": [0.02], "pneumatic_lag": [0.03, 1.0, 1e8, 1.0, 0.0, 0.0, 0.0]},
        250.0,
    )
    chain.core_.weights, chain.core_.beta_s = np.zeros(chain.core_.n_columns), 0.0
    chain_dir = tmp_path / "explained"
    chain.save(chain_dir)
    capsys.readouterr()
    with pytest.raises(SystemExit) as done:
        lab_main(
            ["tune", str(bag), "-o", str(tmp_path / "m"), "--chain", str(tmp_path / "explained")]
        )
    assert not done.value.code
    out = capsys.readouterr().out
    assert "loop from the chain: " in out and "dead time 20.0 ms, lag 30.0 ms" in out, out
    assert "loop from the steps: " in out
    tuning = FeedbackGains.load(tmp_path / "m").tuning
    assert tuning["chain"] == str(chain_dir)
    assert tuning["shape_from"] in ("chain", "steps")
    assert isinstance(tuning["disagreements"], list)
    if tuning["shape_from"] == "chain":
        assert tuning["loop"]["delay_s"] == pytest.approx(0.02)


def test_a_bend_that_arrives_late_is_designed_for() -> None:
    """A laser driver stamps the time the bend was true and sends it 12 ms later: the steps
    (fitted on stamps) cannot show it, the recording's measurement age does, and a design that
    leaves it out breaks its promise on the loop that actually runs."""
    import dataclasses

    plant = LinearPlant(tau_s=0.01, delay_s=0.004)
    on_time = plant.record()
    late = dataclasses.replace(on_time, measurement_age_s=0.012)
    model_on_time, model_late = identify([on_time]), identify([late])
    assert model_on_time.measurement_age_s == 0.0
    assert model_late.measurement_age_s == pytest.approx(0.012)
    assert model_late.delay_s == pytest.approx(model_on_time.delay_s)  # the steps agree
    assert "measured 12.0 ms before it arrives" in model_late.describe()
    naive, _ = design(model_on_time)
    gains, found = design(model_late)
    assert found.max_sensitivity <= 1.6 + 1e-9
    assert margins(model_late, naive).max_sensitivity > 1.6, "the age made no difference"
    assert found.crossover_hz < margins(model_on_time, naive).crossover_hz
    # On the plant with the bend fed back 3 samples late: a step settles.
    wide = FeedbackGains(**{**gains.__dict__, "max_correction_pa": 3e5})
    loop = ClosedLoop(
        None, wide, rate_hz=RATE_HZ, min_pressure_pa=0.0, max_pressure_pa=3e5, max_slew_pa_per_s=1e9
    )
    loop.reset()
    plant.reset()
    target = math.radians(10.0)
    in_flight = [0.0, 0.0, 0.0]
    out = []
    for _ in range(round(4 * RATE_HZ)):
        y = plant.step(loop.step(target, in_flight[0]))
        in_flight = [*in_flight[1:], y]
        out.append(y)
    bend = np.degrees(np.asarray(out))
    assert abs(bend[-round(RATE_HZ) :] - 10.0).max() < 0.05
    assert bend.max() < 10.0 * 1.5
