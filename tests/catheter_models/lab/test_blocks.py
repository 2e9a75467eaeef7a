"""Effect blocks and the grey-box chain: named, bounded, and what they claim to be."""

import math
from pathlib import Path

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.models import load_model
from catheter_models.models.base import ModelError
from catheter_models.models.blocks import BLOCKS, FORMS, block, ordered
from catheter_models.models.cores import make_core
from catheter_models.models.data import simulate_recordings
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.greybox import GreyBox
from catheter_models.units import pa_to_bar, rad_to_deg

RATE_HZ = 250.0


def step(n: int = 2500, at: int = 250) -> np.ndarray:
    x = np.zeros(n)
    x[at:] = 1.0
    return x


PLAIN_LAG = [0.1, 1.0, 1e8, 1.0, 0.0, 0.0, 0.0]  # no asymmetry, flow limit, pressure dependence


def test_lag_reaches_63_percent_after_one_time_constant() -> None:
    y = block("pneumatic_lag").apply(step(), RATE_HZ, PLAIN_LAG)
    # The step enters at sample 250 and counts as the first of the 25 samples of 0.1 s.
    assert y[250 + 24] == pytest.approx(1 - math.exp(-1), abs=1e-9)
    assert y[0] == 0.0 and y[-1] == pytest.approx(1.0, abs=1e-6)


def test_a_lag_whose_flow_chokes_ramps_then_relaxes() -> None:
    # 2 bar/s at most: a 1 bar step ramps for the first half second, where the plain
    # lag's own slope (1 bar / 0.1 s) is faster, then relaxes as the plain lag does.
    y = block("pneumatic_lag").apply(step(), RATE_HZ, [0.1, 1.0, 2e5, 1.0, 0.0, 0.0, 0.0])
    assert np.diff(y).max() == pytest.approx(2.0 / RATE_HZ, rel=1e-9)
    assert y[250 + 49] == pytest.approx(50 * 2.0 / RATE_HZ, rel=1e-9)  # still on the ramp
    assert y[-1] == pytest.approx(1.0, abs=1e-3)
    plain = block("pneumatic_lag").apply(step(), RATE_HZ, PLAIN_LAG)
    assert np.all(y <= plain + 1e-12)


def test_a_lag_vents_at_its_own_time_constant() -> None:
    down = 1.0 - step()
    y = block("pneumatic_lag").apply(
        down, RATE_HZ, [0.1, 2.0, 1e8, 1.0, 0.0, 0.0, 0.0]
    )  # vents in 0.2 s
    assert y[250 + 49] == pytest.approx(math.exp(-1), abs=1e-9)
    rise = block("pneumatic_lag").apply(step(), RATE_HZ, [0.1, 2.0, 1e8, 1.0, 0.0, 0.0, 0.0])
    assert rise[250 + 24] == pytest.approx(1 - math.exp(-1), abs=1e-9)  # fills in 0.1 s


def test_a_lag_saved_before_venting_and_flow_limits_loads_as_the_plain_lag() -> None:
    assert BLOCKS["pneumatic_lag"].check({"time_constant_s": 0.04}) == [
        0.04,
        1.0,
        1e8,
        1.0,
        0.0,
        0.0,
        0.0,
    ]


def test_a_lag_vents_against_its_own_flow_limit() -> None:
    # Filling at most 4 bar/s, venting at most 2 bar/s (a smaller exhaust port): a 1 bar step
    # up ramps at 4 bar/s, the step down at 2 bar/s, each until the plain lag is slower.
    values = [0.02, 1.0, 4e5, 0.5, 0.0, 0.0, 0.0]
    up = block("pneumatic_lag").apply(step(), RATE_HZ, values)
    down = block("pneumatic_lag").apply(1.0 - step(), RATE_HZ, values)
    assert np.diff(up).max() == pytest.approx(4.0 / RATE_HZ, rel=1e-9)
    assert np.diff(down).min() == pytest.approx(-2.0 / RATE_HZ, rel=1e-9)
    assert up[-1] == pytest.approx(1.0, abs=1e-6) and down[-1] == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize("exponent", [1.0, -0.5])
def test_a_lag_that_depends_on_the_pressure_is_quicker_where_its_exponent_says(
    exponent: float,
) -> None:
    # The same 0.1 bar step from 0.4 and from 2.4 bar gauge: the time to 63 % scales as the
    # absolute pressure to the minus exponent (the reference, 1.5 bar, takes 0.1 s).
    lag = block("pneumatic_lag")
    values = [0.1, 1.0, 1e8, 1.0, exponent, 0.0, 0.0]

    def time_to_63_percent_s(base_bar: float) -> float:
        y = lag.apply(base_bar + 0.1 * step(), RATE_HZ, values)
        return float(np.argmax(y - base_bar >= 0.1 * (1 - math.exp(-1))) - 250 + 1) / RATE_HZ

    low, high = time_to_63_percent_s(0.4), time_to_63_percent_s(2.4)
    expected = ((2.4 + 1.01325) / (0.4 + 1.01325)) ** exponent
    assert low / high == pytest.approx(expected, rel=0.1)


def test_a_gradual_flow_limit_bends_the_fill_before_the_limit_and_never_passes_it() -> None:
    # 2 bar/s at most, a 1 bar step: a hard limit ramps at exactly 2 bar/s; with a knee the
    # flow bends towards that limit (never reaching it) and a small step, far below the
    # limit, fills almost as the plain lag does.
    lag = block("pneumatic_lag")
    hard = lag.apply(step(), RATE_HZ, [0.1, 1.0, 2e5, 1.0, 0.0, 0.0, 0.0])
    for knee in (0.5, 1.0):
        values = [0.1, 1.0, 2e5, 1.0, 0.0, knee, 0.0]
        y = lag.apply(step(), RATE_HZ, values)
        assert np.diff(y).max() < 2.0 / RATE_HZ
        assert np.all(y <= hard + 1e-12)  # slower than the hard limit everywhere
        assert y[-1] == pytest.approx(1.0, abs=1e-2)
        small = lag.apply(0.01 * step(), RATE_HZ, values)
        plain = lag.apply(0.01 * step(), RATE_HZ, PLAIN_LAG)
        assert small[250 + 24] == pytest.approx(plain[250 + 24], rel=0.06)
    # The more gradual the knee, the slower the large step's first half second.
    halfway = [
        lag.apply(step(), RATE_HZ, [0.1, 1.0, 2e5, 1.0, 0.0, k, 0.0])[375] for k in (0, 1, 3)
    ]
    assert halfway[0] > halfway[1] > halfway[2]


def test_a_flow_limit_with_an_upstream_share_grows_with_the_pressure_pushing_the_air() -> None:
    # The same 1 bar step, choked at 2 bar/s at the reference (1.5 bar gauge): filling from
    # 0 to 1 bar, the valve pushes at 1 bar gauge; from 1.5 to 2.5 bar at 2.5. With the
    # whole limit upstream, the ramps' slopes are in the ratio of those absolute pressures;
    # venting, the muscle pushes, so a vent from 2.5 is as quick as the fill to it.
    lag = block("pneumatic_lag")
    values = [0.1, 1.0, 2e5, 1.0, 0.0, 0.0, 1.0]
    low = lag.apply(step(), RATE_HZ, values)
    high = lag.apply(1.5 + step(), RATE_HZ, values)
    vent = lag.apply(2.5 - step(), RATE_HZ, values)
    ref = 1.5 + 1.01325
    assert np.diff(low).max() == pytest.approx(2.0 / RATE_HZ * (1.0 + 1.01325) / ref, rel=1e-9)
    assert np.diff(high).max() == pytest.approx(2.0 / RATE_HZ * (2.5 + 1.01325) / ref, rel=1e-9)
    assert -np.diff(vent).min() == pytest.approx(np.diff(high).max(), rel=1e-9)
    # At no share the limit is the reference's wherever the step is.
    flat = [0.1, 1.0, 2e5, 1.0, 0.0, 0.0, 0.0]
    assert np.diff(lag.apply(1.5 + step(), RATE_HZ, flat)).max() == pytest.approx(2.0 / RATE_HZ)


def test_a_lag_whose_flow_bends_at_a_pressure_ratio_is_not_doubted_as_pinned() -> None:
    # The new parameters' ends are each a physical law (a hard limit or the rational bend; a
    # limit in pressure difference or one that chokes at a pressure ratio); the time
    # constant's top is still a sign that the block stands in for something slower.
    from catheter_models.lab.diagnose import _pinned

    model = GreyBox(effects=["pneumatic_lag"], core="free_pi")
    ends = [0.05, 1.0, 4e5, 1.0, 0.0, 1.0, 1.0]
    model._set(make_core("free_pi"), {"pneumatic_lag": ends}, RATE_HZ)
    assert _pinned(model, "pneumatic_lag") == []
    slowest = [0.5, 1.0, 4e5, 1.0, 0.0, 1.0, 1.0]
    model._set(make_core("free_pi"), {"pneumatic_lag": slowest}, RATE_HZ)
    assert [d.split(" ")[0] for d in _pinned(model, "pneumatic_lag")] == ["time_constant_s"]


def test_delay_shifts_by_the_delay() -> None:
    y = block("transport_delay").apply(step(), RATE_HZ, [0.04])
    assert y[250 + 9] == 0.0 and y[250 + 10] == pytest.approx(1.0)


def test_creep_jumps_by_the_instant_share_then_creeps() -> None:
    y = block("creep").apply(step(), RATE_HZ, [0.2, 1.0, 1.0])
    assert y[250] == pytest.approx(0.8, abs=0.01)
    assert y[250 + 250] == pytest.approx(0.8 + 0.2 * (1 - math.exp(-1)), abs=0.01)


def test_a_spread_creep_is_faster_at_first_and_still_going_when_one_lag_has_settled() -> None:
    t_s = np.arange(30 * RATE_HZ) / RATE_HZ
    x = (t_s >= 1.0).astype(float)
    one = block("creep").apply(x, RATE_HZ, [0.2, 1.0, 1.0])
    spread = block("creep").apply(x, RATE_HZ, [0.2, 1.0, 9.0])  # branches at 1/3 s and 3 s
    after = (t_s - 1.0)[250 + 75]  # 0.3 s after the step
    expected = 0.8 + 0.1 * ((1 - math.exp(-after * 3.0)) + (1 - math.exp(-after / 3.0)))
    assert spread[250 + 75] == pytest.approx(expected, abs=1e-3)
    assert spread[250 + 75] > one[250 + 75]  # the fast branch leads
    assert spread[250 + 1250] < one[250 + 1250] - 0.01  # 5 s on: the slow one still creeps
    assert spread[-1] == pytest.approx(1.0, abs=1e-3)


def test_a_creep_saved_before_its_spread_existed_loads_as_one_lag() -> None:
    assert BLOCKS["creep"].check({"fraction": 0.2, "time_constant_s": 1.5}) == [0.2, 1.5, 1.0]


def test_a_slow_fill_passes_a_share_of_a_step_at_once_and_the_rest_over_its_time() -> None:
    y = block("slow_fill").apply(step(), RATE_HZ, [0.2, 0.1])
    assert y[250] == pytest.approx(0.8 + 0.2 * (1 - math.exp(-1 / 25)), abs=1e-9)
    assert y[250 + 24] == pytest.approx(0.8 + 0.2 * (1 - math.exp(-1)), abs=1e-9)
    assert y[-1] == pytest.approx(1.0, abs=1e-6)


def test_tip_dynamics_ring_at_the_natural_frequency() -> None:
    y = block("tip_dynamics").apply(step(), RATE_HZ, [5.0, 0.05, 0.0])
    ripple = y[260:] - 1.0
    crossings = np.flatnonzero(np.diff(np.sign(ripple)) != 0)
    period_s = 2 * np.median(np.diff(crossings)) / RATE_HZ
    assert period_s == pytest.approx(1 / (5.0 * math.sqrt(1 - 0.05**2)), rel=0.05)
    assert y[-1] == pytest.approx(1.0, abs=0.05)


def test_tip_dynamics_damp_a_bent_tip_more_than_a_straight_one() -> None:
    # Released from 30 deg to straight, the tip rings freely; pulled from straight to 30 deg
    # it swings against damping 0.05 + 2/rad * 0.52 rad = 1.1: no overshoot at all.
    values = [5.0, 0.05, 2.0]
    up = block("tip_dynamics").apply(30.0 * step(), RATE_HZ, values)
    down = block("tip_dynamics").apply(30.0 * (1.0 - step()), RATE_HZ, values)
    assert up.max() <= 30.0 + 1e-9
    assert down.min() < -0.5 * 30.0  # a lightly damped swing past straight
    # Without growth the two directions mirror each other (the block is linear then).
    lin_up = block("tip_dynamics").apply(30.0 * step(), RATE_HZ, [5.0, 0.05, 0.0])
    lin_down = block("tip_dynamics").apply(30.0 * (1.0 - step()), RATE_HZ, [5.0, 0.05, 0.0])
    np.testing.assert_allclose(lin_up - 30.0, -lin_down, atol=1e-9)


def test_tip_dynamics_do_not_depend_on_the_sample_rate() -> None:
    # Sub-stepped at 1 ms: the same tip sampled at 100 Hz and at 1 kHz is the same tip.
    values = [8.0, 0.1, 1.0]
    t100 = np.arange(300) / 100.0
    t1k = np.arange(3000) / 1000.0
    y100 = block("tip_dynamics").apply(np.where(t100 >= 0.5, 20.0, 0.0), 100.0, values)
    y1k = block("tip_dynamics").apply(np.where(t1k >= 0.5, 20.0, 0.0), 1000.0, values)
    np.testing.assert_allclose(y100, y1k[::10], rtol=0, atol=1e-9)


def test_drift_adds_a_trend_in_degrees_from_a_rate_in_si() -> None:
    # 6 deg/min, settling in 10 h: a straight trend over a 10 s recording.
    y = block("drift").apply(np.zeros(2500), RATE_HZ, [math.radians(6.0) / 60, 36_000.0])
    assert y[-1] == pytest.approx(0.1 * 2499 / RATE_HZ, rel=1e-3)


def test_a_drift_slows_to_a_stop_at_its_settle_time() -> None:
    rate_rad_s, settle_s = math.radians(2.0) / 60, 120.0  # 2 deg/min, stops after 2 min
    t_s = np.arange(0, 300 * 10) / 10.0
    y = block("drift").apply(np.zeros(t_s.size), 10.0, [rate_rad_s, settle_s])
    # Starts at its rate, has half the rate halfway, and holds rate * settle / 2 once settled.
    assert (y[1] - y[0]) * 10.0 == pytest.approx(2.0 / 60, rel=1e-3)
    assert (y[601] - y[600]) * 10.0 == pytest.approx(1.0 / 60, rel=1e-2)
    assert np.all(y[t_s >= settle_s] == pytest.approx(2.0 / 60 * settle_s / 2))


def test_a_drift_saved_before_its_settle_time_existed_loads_as_a_straight_trend() -> None:
    # Models saved with the straight-trend form hold only the rate.
    assert BLOCKS["drift"].check({"rate_rad_per_s": 1e-4}) == [1e-4, 36_000.0]
    with pytest.raises(ParameterError, match=r"drift\.settle_s = 10\.0 is outside"):
        BLOCKS["drift"].check({"rate_rad_per_s": 1e-4, "settle_s": 10.0})


def test_unknown_and_default_chain_effects_are_refused_by_name() -> None:
    with pytest.raises(ParameterError, match=r"unknown effect 'backlash'.*pneumatic_lag"):
        block("backlash")
    with pytest.raises(ParameterError, match="'play' is part of the default chain"):
        GreyBox(effects=["play"])
    with pytest.raises(ParameterError, match="listed twice"):
        ordered(["creep", "creep"])
    # Physics fixes the order: input side, then output side, whatever the user wrote.
    assert GreyBox(effects=["drift", "pneumatic_lag"]).chain == ("pneumatic_lag", "drdpi", "drift")


def test_block_values_are_checked_against_their_bounds() -> None:
    with pytest.raises(ParameterError, match=r"pneumatic_lag.time_constant_s = 5.0 is outside"):
        BLOCKS["pneumatic_lag"].check({"time_constant_s": 5.0})


@pytest.fixture(scope="module")
def drdpi_and_data() -> tuple[DRDPI, list]:
    recs = simulate_recordings(["train_zero_f0.4", "train_nonzero_f0.4"])
    model = DRDPI(budget={"max_generations": 15, "wall_time_s": 10}).fit(recs, progress=False)
    return model, recs


def test_a_greybox_saves_loads_and_predicts_alike(tmp_path: Path, drdpi_and_data) -> None:
    drdpi, recs = drdpi_and_data
    base = GreyBox.from_drdpi(drdpi)
    # The default chain is the DRDPI itself.
    np.testing.assert_allclose(
        base.predict(recs[0].pressure_pa), drdpi.predict(recs[0].pressure_pa)
    )
    lagged = base.with_effect("pneumatic_lag")
    lagged.polish_evals = 20
    lagged.fit(recs, progress=False)
    out = tmp_path / "gb"
    lagged.save(out, training=recs)
    loaded = load_model(out)
    assert isinstance(loaded, GreyBox) and loaded.chain == ("pneumatic_lag", "drdpi")
    np.testing.assert_array_equal(
        loaded.predict(recs[1].pressure_pa), lagged.predict(recs[1].pressure_pa)
    )
    stream = loaded.stream()
    head = [stream.step(p) for p in recs[1].pressure_pa[:50]]
    np.testing.assert_allclose(head, lagged.predict(recs[1].pressure_pa[:50]))


def test_a_model_file_that_lists_an_effect_without_parameters_asks_for_a_refit(
    tmp_path: Path, drdpi_and_data
) -> None:
    import json

    from catheter_models.model_dir import ModelDirError

    drdpi, recs = drdpi_and_data
    out = tmp_path / "gb"
    GreyBox.from_drdpi(drdpi).save(out, training=recs)
    doc = json.loads((out / "greybox.json").read_text())
    doc["effects"] = ["creep"]  # the one-line edit, without a refit
    (out / "greybox.json").write_text(json.dumps(doc))
    # The file's hash no longer matches: refused, never silently run without the block.
    with pytest.raises((ModelError, ModelDirError), match=r"greybox\.json"):
        load_model(out)


# Off-grid values (a delay of 37.3 samples, a tip between sub-steps): the stream must match.
STREAM_VALUES = {
    "transport_delay": [0.1491],
    "pneumatic_lag": [0.08, 1.7, 5e5, 0.6, 0.7, 0.0, 0.0],
    "creep": [0.3, 1.2, 6.0],
    "tip_dynamics": [6.3, 0.07, 2.0],
    "drift": [math.radians(5.0) / 60.0, 3.3],  # below its bound: the signal sees it settle
    "slow_fill": [0.2, 1.7],
    "output_lag": [0.05],
}


@pytest.mark.parametrize("effect", list(FORMS))
def test_each_block_streams_what_it_applies(effect: str) -> None:
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0.0, 0.3, 1500)) + 5.0  # a rough signal that starts off rest
    values = STREAM_VALUES[effect]
    step_fn = block(effect).streamer(RATE_HZ, values)
    streamed = np.array([step_fn(v) for v in x])
    np.testing.assert_allclose(streamed, block(effect).apply(x, RATE_HZ, values), atol=1e-9)


@pytest.mark.parametrize(
    "effect", [e for e, b in FORMS.items() if b.side == "output" and e != "tip_dynamics"]
)
def test_an_output_block_on_the_core_s_columns_is_the_block_on_their_sum(effect: str) -> None:
    # The fit solves the core's weights through the block's column form; a model predicts
    # through its plain form. They must agree, or the weights fitted are not the model's.
    rng = np.random.default_rng(5)
    m = np.cumsum(rng.normal(0.0, 0.3, (1500, 4)), axis=0)
    m[:, -1] = 0.0  # the running offset's column
    w = np.array([0.7, -1.3, 2.0])
    values = STREAM_VALUES[effect]
    b = block(effect)
    reference = m[:, :-1] @ w
    cols = b.apply_columns(m, RATE_HZ, values, reference)
    np.testing.assert_allclose(
        cols[:, :-1] @ w + cols[:, -1], b.apply(reference, RATE_HZ, values), atol=1e-9
    )


@pytest.mark.parametrize("core", ["drdpi", "free_pi", "boucwen", "gpi", "viscous_pi"])
def test_a_greybox_with_every_block_streams_its_prediction(core: str, drdpi_and_data) -> None:
    drdpi, recs = drdpi_and_data
    if core == "drdpi":
        fitted = GreyBox.from_drdpi(drdpi).core_
    else:
        fitted = make_core(core, {"starts": 1} if core == "boucwen" else {})
        if core == "gpi":
            fitted = make_core(core)
        fitted.fit(
            [pa_to_bar(r.pressure_pa) for r in recs],
            [rad_to_deg(r.angle_rad) for r in recs],
            RATE_HZ,
        )
    model = GreyBox(effects=list(FORMS), core=core)
    model._set(fitted, STREAM_VALUES, RATE_HZ)  # every block, at off-grid values
    pressure_pa = recs[1].pressure_pa[:1500]
    stream = model.stream()
    streamed = np.array([stream.step(p) for p in pressure_pa])
    np.testing.assert_allclose(streamed, model.predict(pressure_pa), rtol=0, atol=1e-12)
    stream.reset()
    again = np.array([stream.step(p) for p in pressure_pa[:100]])
    np.testing.assert_array_equal(again, streamed[:100])
