"""The explained model run backwards: the chain's inverse gives back the bends it was asked for.

The bends asked for are the chain's own response to a smooth pressure, so each is reachable:
an exact inverse gives them back to within its search tolerance, whatever the chain holds.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from catheter_control.models import load_compensator, resolve_compensator
from catheter_models.errors import ParameterError
from catheter_models.models.blocks import FORMS
from catheter_models.models.cores import make_core
from catheter_models.models.cores.base import CHARGE_SLACK_DEG, CoreInverse
from catheter_models.models.data import simulate_recordings
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.greybox import GreyBox
from catheter_models.models.greybox_inverse import GreyBoxInverse, probe_pressure_bar
from catheter_models.units import bar_to_pa, pa_to_bar, rad_to_deg

RATE_HZ = 250.0
VALUES = {
    "transport_delay": [0.0491],  # not a whole number of samples
    "pneumatic_lag": [0.08, 1.7, 5e5, 0.6, 0.7, 0.0, 0.0],  # venting slower, limits, quicker full
    "creep": [0.3, 1.2, 6.0],
    "tip_dynamics": [4.0, 0.07, 2.0],
    "drift": [math.radians(5.0) / 60.0, 3.3],
    "slow_fill": [0.2, 1.7],
    "output_lag": [0.05],
}
EXACT_BLOCKS = [e for e in FORMS if e != "tip_dynamics"]


@pytest.fixture(scope="module")
def cores() -> dict:
    recs = simulate_recordings(["train_zero_f0.4", "train_nonzero_f0.4"])
    drdpi = DRDPI(budget={"max_generations": 15, "wall_time_s": 10}).fit(recs, progress=False)
    xs = [pa_to_bar(r.pressure_pa) for r in recs]
    ys = [rad_to_deg(r.angle_rad) for r in recs]
    gpi, free_pi = make_core("gpi"), make_core("free_pi")
    gpi.fit(xs, ys, RATE_HZ)
    free_pi.fit(xs, ys, RATE_HZ)
    return {"drdpi": GreyBox.from_drdpi(drdpi).core_, "gpi": gpi, "free_pi": free_pi}


def chain(cores: dict, core: str, effects: list[str]) -> GreyBox:
    model = GreyBox(effects=effects, core=core)
    model._set(cores[core], {e: VALUES[e] for e in effects}, RATE_HZ)
    return model


def given_back(model: GreyBox) -> tuple[np.ndarray, np.ndarray, GreyBoxInverse]:
    """The chain's bend on a smooth probe, and its bend on what the inverse commanded."""
    pressure_pa = bar_to_pa(probe_pressure_bar(RATE_HZ, 0.0, 3.0))
    wanted = model.predict(pressure_pa)
    inverse = GreyBoxInverse(model)
    t = np.arange(wanted.size) / RATE_HZ
    # As the node feeds it: the plan read preview_s ahead (interpolated), its end held.
    fed = np.interp(t + inverse.preview_s, t, wanted)
    command = np.array([inverse.step(v) for v in fed])
    return wanted, model.predict(command), inverse


def rms_deg(a: np.ndarray, b: np.ndarray) -> float:
    # The first second (the chain and its inverse leaving rest) and the held end apart.
    return float(np.degrees(np.sqrt(np.mean((a - b)[250:-50] ** 2))))


@pytest.mark.parametrize("core", ["drdpi", "gpi"])
@pytest.mark.parametrize("effect", ["", *EXACT_BLOCKS])
def test_each_block_s_inverse_gives_back_the_bend_asked_for(cores, core: str, effect: str) -> None:
    model = chain(cores, core, [effect] if effect else [])
    wanted, got, _ = given_back(model)
    assert rms_deg(got, wanted) < 0.02, (core, effect)


@pytest.mark.parametrize("core", ["drdpi", "gpi"])
@pytest.mark.parametrize(("knee", "upstream"), [(1.0, 0.0), (0.0, 1.0), (0.6, 1.0)])
def test_a_lag_whose_flow_bends_or_follows_the_upstream_pressure_is_given_back(
    cores, core: str, knee: float, upstream: float
) -> None:
    # The filling limit grows with the command itself under an upstream share: the inverse
    # solves for the command (bisection) instead of dividing.
    model = GreyBox(effects=["pneumatic_lag"], core=core)
    model._set(
        cores[core], {"pneumatic_lag": [*VALUES["pneumatic_lag"][:5], knee, upstream]}, RATE_HZ
    )
    wanted, got, _ = given_back(model)
    assert rms_deg(got, wanted) < 0.02


@pytest.mark.parametrize("core", ["drdpi", "gpi"])
def test_the_tip_is_pulled_so_that_it_follows_without_ringing(cores, core: str) -> None:
    model = chain(cores, core, ["tip_dynamics"])
    wanted, got, inverse = given_back(model)
    assert inverse.preview_s == pytest.approx(2 / RATE_HZ)  # the plan's curvature
    # Uncompensated, the 4 Hz tip with damping 0.07 rings on every reversal of the probe.
    plain = model.predict(bar_to_pa(probe_pressure_bar(RATE_HZ, 0.0, 3.0)))
    naive = GreyBoxInverse(chain(cores, core, []))
    t = np.arange(plain.size) / RATE_HZ
    without_tip = model.predict(np.array([naive.step(v) for v in np.interp(t, t, wanted)]))
    assert rms_deg(got, wanted) < 0.5 * rms_deg(without_tip, wanted)
    assert rms_deg(got, wanted) < 0.6


def test_a_delay_is_read_ahead_not_computed(cores) -> None:
    inverse = GreyBoxInverse(chain(cores, "gpi", ["transport_delay", "pneumatic_lag"]))
    assert inverse.preview_s == pytest.approx(0.0491)
    assert inverse.chain == ("transport_delay", "pneumatic_lag", "gpi")


def test_a_plan_step_through_a_lag_opens_the_valve_within_its_bounds(cores) -> None:
    model = GreyBox(effects=["pneumatic_lag"], core="gpi")
    model._set(
        cores["gpi"], {"pneumatic_lag": [0.08, 1.0, 1e8, 1.0, 0.0, 0.0, 0.0]}, RATE_HZ
    )  # no flow limit
    inverse = GreyBoxInverse(model, max_pressure_pa=2.5e5)
    level_rad = float(model.predict(np.full(500, 1.5e5))[-1])
    commands = [inverse.step(0.0) for _ in range(50)]
    commands += [inverse.step(level_rad) for _ in range(400)]
    assert max(commands) <= 2.5e5 and min(commands) >= 0.0
    assert commands[50] == pytest.approx(2.5e5)  # the valve fully open to fill
    assert commands[-1] == pytest.approx(1.5e5, rel=0.02)  # then the set-point
    assert math.degrees(abs(inverse.model_bend_rad - level_rad)) < 0.01


def test_a_non_finite_bend_is_refused_by_name(cores) -> None:
    inverse = GreyBoxInverse(chain(cores, "gpi", []))
    with pytest.raises(Exception, match="not finite"):
        inverse.step(math.nan)


def test_a_core_whose_fitted_law_is_not_increasing_is_refused_with_its_miss(cores) -> None:
    # This free_pi fit (free weights, some negative) bends more at a lower pressure near a
    # reversal; its inverse would jump between branches.
    with pytest.raises(ParameterError, match=r"free_pi core .* misses by [0-9.]+ deg"):
        GreyBoxInverse(chain(cores, "free_pi", []))


def test_a_block_without_an_inverse_is_refused_by_name(cores) -> None:
    import sys

    from catheter_models.models.blocks import register, unregister

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "support"))
    from toy_effect import SensorLatency  # a block a user added, with no inverse

    register(SensorLatency)
    try:
        model = GreyBox(effects=[SensorLatency.effect], core="gpi")
        model._set(cores["gpi"], {SensorLatency.effect: SensorLatency.defaults()}, RATE_HZ)
        with pytest.raises(ParameterError, match=f"{SensorLatency.effect} has no inverse"):
            GreyBoxInverse(model)
    finally:
        unregister(SensorLatency.effect)


def test_the_node_loads_a_saved_grey_box_as_the_greybox_compensator(cores, tmp_path: Path) -> None:
    recs = simulate_recordings(["train_zero_f0.4"])
    model = chain(cores, "gpi", ["transport_delay", "creep"])
    model.save(tmp_path / "explained", training=recs)
    directory = str(tmp_path / "explained")
    assert resolve_compensator(None, directory) == "greybox"
    compensator = load_compensator("greybox", directory)
    assert compensator.preview_s == pytest.approx(0.0491)
    assert compensator.sample_period_s == pytest.approx(1 / RATE_HZ)
    assert "transport_delay -> gpi -> creep" in compensator.label
    assert math.isfinite(compensator.step(math.radians(5.0)))
    with pytest.raises(ParameterError, match="no grey box is shipped"):
        load_compensator("greybox", "")


def test_a_tick_costs_a_few_core_evaluations(cores) -> None:
    # Behaviour, not speed: the search's work per tick is bounded and small (the timing is
    # bench/bench_greybox_compensator.py's).
    model = chain(cores, "drdpi", list(VALUES))
    inverse = GreyBoxInverse(model)
    evaluations = []
    for v in np.radians(10.0 + 8.0 * np.sin(np.arange(2500) / RATE_HZ * 2 * np.pi * 0.4)):
        inverse.step(float(v))
        evaluations.append(inverse.core_evaluations)
    assert np.percentile(evaluations, 99) <= 25


def test_greybox_without_a_model_directory_is_refused_before_anything_starts() -> None:
    with pytest.raises(ParameterError, match="no grey box is shipped"):
        resolve_compensator("greybox", "")


def test_a_strong_rate_term_is_run_backwards_with_a_slower_filter_not_run_away(
    cores, monkeypatch: pytest.MonkeyPatch
) -> None:
    import catheter_models.models.cores.base as core_base
    from catheter_models.models.drdpi import DRDPIParams
    from catheter_models.models.greybox_inverse import invertibility_deg

    strong = cores["drdpi"].copy()
    values = strong.params.to_dict()
    values["beta"] = 0.06  # thresholds widen 60 ms of rate per bar: loop gain ~2 backwards
    strong.set_params(DRDPIParams.from_dict(values))
    gain_s, alpha = strong.rate_term(RATE_HZ)
    assert gain_s * alpha * RATE_HZ > 1.5
    slowed = invertibility_deg(strong, RATE_HZ, 0.0, 3.0)
    monkeypatch.setattr(core_base, "MOST_RATE_LOOP_GAIN", math.inf)
    as_fitted = invertibility_deg(strong, RATE_HZ, 0.0, 3.0)
    assert slowed < 0.5 * as_fitted, (slowed, as_fitted)


def test_a_bend_out_of_reach_gets_the_nearer_bound_not_a_dip_of_the_fit() -> None:
    # A fitted law that dips at the vented end (0.8 deg at 0.5 bar, 1.0 deg vented), as a
    # free-weight PI may: a plan below every bend it gives vents the valve, since a muscle
    # never bends less for more pressure; the dip's 0.5 bar held the catheter above its rest.
    def bend_deg(x_bar: float) -> float:
        return 1.0 - 0.4 * x_bar if x_bar < 0.5 else 0.8 + 10.0 * (x_bar - 0.5) ** 2

    def advance(x_bar: float, state: np.ndarray) -> float:
        return bend_deg(x_bar)

    inverse = CoreInverse(np.zeros(1), advance, 0.0, 3.0)
    inverse.take(1.0)
    assert inverse.want(0.0) == 0.0
    inverse.take(1.0)
    assert inverse.want(100.0) == 3.0
    inverse.take(1.0)
    reachable = inverse.want(5.0)
    assert bend_deg(reachable) == pytest.approx(5.0, abs=CoreInverse.TOLERANCE_DEG)
    assert reachable > 0.5  # the crossing nearest the last pressure, on the rising branch
    # Told to keep the muscle charged, it stays near where the law bends least (the dip's
    # bottom, to the search's coarse steps on its way down), not vented.
    charging = CoreInverse(np.zeros(1), advance, 0.0, 3.0, bound_out_of_reach=False)
    charging.take(1.0)
    charged = charging.want(0.0)
    assert 0.4 < charged < 0.7 and bend_deg(charged) < bend_deg(0.0)


def test_a_muscle_kept_charged_holds_one_pressure_through_a_valley_out_of_reach() -> None:
    # A law flat at the vented end to within a few thousandths of a degree (a free-weight
    # PI's fit: a tiny slope below its knee at 0.6 bar), with a hysteretic state that creeps
    # as the pressure is held. Asked for a bend below its reach tick after tick, the inverse
    # used to return the pressure whose bend came closest on its search's path, which
    # jumped between the vented end and the knee, and a lag's inverse behind it burst the
    # valve to its bounds at each jump. Now it holds the top of the flat stretch.
    knee_bar = 0.6

    def advance(x_bar: float, state: np.ndarray) -> float:
        state[0] += 0.01 * (x_bar - state[0])  # a slow state the pressure drags along
        flat = 0.8 + 0.004 * x_bar + 0.002 * state[0]
        return flat + (8.0 * (x_bar - knee_bar) ** 2 if x_bar > knee_bar else 0.0)

    def bend_deg(x_bar: float, state: np.ndarray) -> float:
        return advance(x_bar, state.copy())

    state = np.array([1.5])
    charging = CoreInverse(state, advance, 0.0, 3.0, bound_out_of_reach=False)
    charging.take(1.5)  # coming down from a peak
    held = []
    for _ in range(200):
        x = charging.want(0.0)
        held.append(x)
        charging.take(x)
    first = held[0]
    # Where the flat stretch ends, within the slack of the least bend it gives.
    least = min(bend_deg(x, charging._state) for x in np.linspace(0.0, 3.0, 301))
    assert knee_bar <= first < knee_bar + 0.05
    assert bend_deg(first, charging._state) <= least + CHARGE_SLACK_DEG + 1e-6
    # And held there: not one jump, tick after tick, while the state creeps.
    assert max(held) - min(held) < 1e-9, (min(held), max(held))


@pytest.mark.parametrize(
    ("effects", "vents"),
    [([], True), (["transport_delay"], True), (["tip_dynamics"], True), (["pneumatic_lag"], False)],
)
def test_only_a_chain_that_refills_through_a_lag_keeps_the_muscle_charged_out_of_reach(
    cores, effects: list[str], vents: bool
) -> None:
    # Behind a lag, venting where the plan is out of reach costs the refill when it rises.
    inverse = GreyBoxInverse(chain(cores, "gpi", effects))
    assert inverse._core.bound_out_of_reach is vents
    inverse.reset()
    assert inverse._core.bound_out_of_reach is vents
