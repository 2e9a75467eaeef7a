"""Cores, floors and verdicts: the lab's judgement on plants it was not developed on.

The foreign plants (tests/support/foreign_plants) are written apart from the project's
simulator; the lab must never import them, or its tests on them prove nothing.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from foreign_plants import PLANTS
from foreign_plants.cases import draw_case, draw_twin_case, make_case

from catheter_models.cli import main
from catheter_models.lab.diagnose import (
    VENTED_BAR,
    Candidate,
    Diagnosis,
    Floors,
    RefitWorkerError,
    default_workers,
    diagnose,
    lab_pool,
    refit_executor,
)
from catheter_models.lab.floors import FilterBankReference, noise_std_deg
from catheter_models.lab.residuals import residual_tests
from catheter_models.models import load_model
from catheter_models.models.base import ModelError
from catheter_models.models.blocks import block
from catheter_models.models.cores import FreePI
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.models.greybox import GreyBox
from catheter_models.units import pa_to_bar

REPO = Path(__file__).resolve().parents[3]
LEARNED_CORE_VERDICTS = ("core free_pi", "core viscous_pi")
"""A core change to one of the two free-weight cores: both learn the loop's shape."""


def test_nothing_under_src_imports_the_foreign_plants() -> None:
    offenders = [
        str(p.relative_to(REPO))
        for p in (REPO / "src").rglob("*.py")
        if re.search(r"\bforeign_plants\b", p.read_text())
    ]
    assert not offenders, offenders


@pytest.mark.parametrize("plant", sorted(PLANTS))
def test_the_noise_floor_is_estimated_from_the_data(plant: str) -> None:
    case = draw_case(PLANTS[plant], [], 3)
    truth = math.degrees(case.plant.noise_std_rad)
    for rec in (case.train, case.test):
        assert noise_std_deg([rec]) == pytest.approx(truth, rel=0.1)


@pytest.fixture(scope="module")
def creep_case():
    return draw_case(PLANTS["maxwell_slip"], ["creep"], 5)


@pytest.fixture(scope="module")
def free_pi_on_creep(creep_case) -> GreyBox:
    """The free-weight core alone, fitted once on the creep case (the tests only read it)."""
    return GreyBox(core="free_pi").fit([creep_case.train], progress=False)


def test_a_free_pi_greybox_saves_loads_and_streams(
    tmp_path: Path, creep_case, free_pi_on_creep: GreyBox
) -> None:
    model = free_pi_on_creep
    model.save(tmp_path / "m", training=[creep_case.train])
    loaded = load_model(tmp_path / "m")
    assert isinstance(loaded, GreyBox) and loaded.chain == ("free_pi",)
    x = creep_case.test.pressure_pa[:2000]
    np.testing.assert_array_equal(loaded.predict(x), model.predict(x))
    stream = loaded.stream()
    np.testing.assert_allclose([stream.step(p) for p in x[:300]], model.predict(x[:300]))
    doc = json.loads((tmp_path / "m" / "greybox.json").read_text())
    assert doc["format"] == 2 and doc["core"]["name"] == "free_pi"


def _vented_rms_deg(model: GreyBox, rec) -> float:
    """RMS error [deg] where the muscle is vented (the diagnosis's 'vented' regime)."""
    vented = pa_to_bar(rec.pressure_pa) < VENTED_BAR
    err = np.degrees(model.predict(rec.pressure_pa) - rec.angle_rad)[vented]
    return float(np.sqrt(np.mean(err**2)))


@pytest.mark.slow
def test_friction_that_grows_with_tension_lets_a_vented_tip_come_home() -> None:
    # The Bouc-Wen plant's friction level grows with the wire's load (its own law, not the
    # core's). Fixed thresholds leave a residual bend after every vent that depends on the
    # last excursion; thresholds that grow with the pressure do not.
    case = draw_case(PLANTS["boucwen"], [], 2)
    fixed = GreyBox(core="free_pi", core_settings={"tension_shares": [0.0]})
    fixed.fit([case.train], progress=False)
    grown = GreyBox(core="free_pi").fit([case.train], progress=False)
    assert isinstance(grown.core_, FreePI) and grown.core_.tension_share > 0.0
    assert _vented_rms_deg(grown, case.test) < 0.6 * _vented_rms_deg(fixed, case.test)
    assert pooled_rmse(grown, [case.test]) < 0.8 * pooled_rmse(fixed, [case.test])


def test_a_free_pi_file_without_tension_values_loads_with_fixed_thresholds() -> None:
    # Model files written before the thresholds could grow carry no tension values.
    core = FreePI()
    core.load_values({"beta_s": 0.01, "weights": [0.0] * core.n_columns})
    assert core.tension_share == 0.0 and core.tension_onset_bar == 0.0
    with pytest.raises(ModelError, match="tension_share"):
        core.load_values({"beta_s": 0.01, "tension_share": 1.5, "weights": [0.0] * core.n_columns})


@pytest.mark.slow
def test_a_block_search_refits_a_linear_core_and_finds_the_hidden_creep(
    creep_case, free_pi_on_creep: GreyBox
) -> None:
    base = free_pi_on_creep
    crept = base.with_effect("creep").fit([creep_case.train], progress=False)
    before = pooled_rmse(base, [creep_case.test])
    after = pooled_rmse(crept, [creep_case.test])
    assert after < 0.7 * before
    truth = creep_case.effects[0].params
    fraction = crept.block_values()["creep"]["fraction"]
    assert fraction == pytest.approx(truth["fraction"], rel=0.5)


def test_the_black_box_reference_learns_what_a_plain_core_cannot(
    creep_case, free_pi_on_creep: GreyBox
) -> None:
    reference = FilterBankReference().fit([creep_case.train])
    core_only = free_pi_on_creep
    assert reference.rmse_deg([creep_case.test]) < 0.8 * math.degrees(
        pooled_rmse(core_only, [creep_case.test])
    )


def test_a_reference_already_fitted_on_the_split_is_used_as_it_is(
    creep_case, free_pi_on_creep: GreyBox, monkeypatch: pytest.MonkeyPatch
) -> None:
    """``explain`` fits the black box once and passes its figure to later diagnoses: a
    diagnosis given it reports that figure and fits no reference of its own."""
    import catheter_models.lab.diagnose as diagnose_module

    def no_fit(*_args: object) -> float:
        raise AssertionError("the reference was fitted again")

    monkeypatch.setattr(diagnose_module, "_reference", no_fit)
    model = free_pi_on_creep
    given = diagnose(
        model,
        [creep_case.train],
        [creep_case.test],
        effects=[],
        cores=[],
        reference_deg=0.321,
        workers=1,
    )
    assert given.floors.reference_deg == 0.321
    assert "0.321 deg" in given.text(), given.text()
    # Without a reference at all the verdict rests on the noise floor alone.
    bare = diagnose(
        model,
        [creep_case.train],
        [creep_case.test],
        effects=[],
        cores=[],
        reference=False,
        reference_deg=0.321,
        workers=1,
    )
    assert math.isnan(bare.floors.reference_deg)


def _diagnosis(rmse: float, noise: float, reference: float, *candidates: Candidate) -> Diagnosis:
    rng = np.random.default_rng(0)
    report = residual_tests(rng.normal(size=2000), rng.normal(size=2000), 250.0)
    return Diagnosis(
        model_kind="greybox",
        chain=["free_pi"],
        rmse_train_deg=rmse,
        rmse_test_deg=rmse,
        candidates=list(candidates),
        untestable={},
        residual_report=report,
        floors=Floors(noise, reference),
        regimes_deg={"plateau": 0.9, "fast_motion": 0.2},
        signature=["keeps moving on plateaus"],
    )


def test_adequate_only_near_the_floors() -> None:
    assert _diagnosis(0.12, 0.05, 0.4).verdict == "adequate"  # within 3x the noise
    assert "black box does no better" not in _diagnosis(0.12, 0.05, 0.4).text()
    # A black box that does no better does not make an 8x-noise model adequate (issue 13's
    # slow gain drift read "adequate" so): unexplained, saying that no black box learns it.
    by_reference = _diagnosis(0.42, 0.05, 0.4)
    assert by_reference.verdict == "unexplained"
    assert "8.4 x" in by_reference.text()
    assert "black box does no better" in by_reference.text()
    far = _diagnosis(1.0, 0.05, 0.3)
    assert far.verdict == "unexplained"
    text = far.text()
    assert "unexplained" in text and "20.0 x" in text and "plateau 0.900 deg" in text
    assert "keeps moving on plateaus" in text
    assert "does better (0.300 deg against 1.000)" in text


def test_a_model_worse_than_the_black_box_is_never_left_unsaid() -> None:
    # Adequate by the noise (2.4x) yet the black box is clearly better: the verdict stands,
    # and the text says that what is left is learnable.
    adequate = _diagnosis(0.12, 0.05, 0.08)
    assert adequate.verdict == "adequate"
    assert "filter-bank black box does better (0.080 deg against 0.120)" in adequate.text()
    assert adequate.to_dict()["floors"]["reference_does_better"] is True
    # Within 1.1x of it: nothing to say.
    close = _diagnosis(0.12, 0.05, 0.115)
    assert "does better" not in close.text()
    assert close.to_dict()["floors"]["reference_does_better"] is False


def test_a_change_that_does_not_earn_its_place_is_shown_but_not_named() -> None:
    doubtful = Candidate(
        effect="creep",
        parameter="fraction",
        value_si=0.5,
        display="50 %",
        rmse_train_deg=0.5,
        rmse_test_deg=0.5,
        expected_reduction=0.5,
        measured_reduction=0.5,
        evidence="",
        significant=False,
        doubts=["fraction at the end of its range (50 %)"],
    )
    d = _diagnosis(1.0, 0.05, 0.3, doubtful)
    assert d.verdict == "unexplained" and d.best is None
    assert "not counted: fraction at the end of its range" in d.text()


def _change(effect: str, removes: float) -> Candidate:
    return Candidate(
        effect=effect,
        parameter="x",
        value_si=1.0,
        display="1",
        rmse_train_deg=1.0 - removes,
        rmse_test_deg=1.0 - removes,
        expected_reduction=removes,
        measured_reduction=removes,
        evidence="",
        significant=True,
    )


def test_a_core_change_comes_before_a_block_that_removes_more() -> None:
    # A block scored on a wrong law is partly scored on what it makes up for the law.
    lag, core = _change("pneumatic_lag", 0.6), _change("core:free_pi", 0.3)
    d = _diagnosis(1.0, 0.05, 0.3, lag, core)
    assert d.best is core and d.verdict == "core free_pi"
    assert "pneumatic_lag removes more (60 %)" in d.text()
    assert _diagnosis(1.0, 0.05, 0.3, lag).verdict == "add pneumatic_lag"


def test_competing_cores_are_ranked_by_where_they_lead_with_the_leading_block() -> None:
    # Seed 1004's Maxwell-slip drift: the Bouc-Wen core alone was ahead, but the free-weight
    # core had fitted the drift in training and with the drift block went far lower.
    drift = _change("drift", 0.55)
    boucwen, free_pi = _change("core:boucwen", 0.45), _change("core:free_pi", 0.43)
    assert _diagnosis(1.0, 0.05, 0.3, drift, boucwen, free_pi).best is boucwen  # not paired
    boucwen.paired_with, boucwen.paired_test_deg = "drift", 0.99  # worse than alone: 0.55
    free_pi.paired_with, free_pi.paired_test_deg = "drift", 0.20
    d = _diagnosis(1.0, 0.05, 0.3, drift, boucwen, free_pi)
    assert d.best is free_pi and d.verdict == "core free_pi"
    assert boucwen.reach_deg == boucwen.rmse_test_deg  # a pairing that adds error is ignored
    assert "free_pi removes 43 %, 0.200 deg with drift" in d.text(), d.text()
    assert "with drift: 0.990 deg held out" in d.text()
    # A pair whose block the next diagnosis would withhold is not counted (seed 1005).
    boucwen.paired_test_deg, boucwen.paired_doubts = 0.10, ["helps least where drift shows"]
    d = _diagnosis(1.0, 0.05, 0.3, drift, boucwen, free_pi)
    assert d.best is free_pi and boucwen.reach_deg == boucwen.rmse_test_deg
    assert "[not counted: helps least where drift shows]" in d.text(), d.text()


def test_cores_are_paired_only_where_they_compete_beside_a_block(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    from concurrent.futures import Future

    import catheter_models.lab.diagnose as diagnose_module

    class InProcess:
        def submit(self, fn, *args):  # type: ignore[no-untyped-def]
            done: Future[object] = Future()
            done.set_result(fn(*args))
            return done

    refits: list[tuple[str, str]] = []

    def fit_change(model: str, change: str, *_: object) -> str:
        refits.append((model, change))
        return f"{model}+{change}"

    def doubts(fitted: str, *_: object, **__: object) -> tuple[float, list[str]]:
        return float("nan"), ["helps least where drift shows"] if "gpi" in fitted else []

    monkeypatch.setattr(diagnose_module, "_fit_change", fit_change)
    monkeypatch.setattr(diagnose_module, "_rmse_deg", lambda fitted, _test: len(fitted) / 100)
    monkeypatch.setattr(diagnose_module, "_residuals", lambda model, _test: model)
    monkeypatch.setattr(diagnose_module, "_block_doubts", doubts)

    def changes(*named: tuple[str, float]) -> list[Candidate]:
        out = [_change(name, removes) for name, removes in named]
        for c in out:
            c.model = c.effect  # type: ignore[assignment]
        return out

    def pair(candidates: list[Candidate]) -> None:
        diagnose_module._pair_cores_with_the_leading_block(
            candidates,
            [],
            [],
            regimes=None,  # type: ignore[arg-type]
            min_reduction=0.1,
            progress=False,
            pool=InProcess(),  # type: ignore[arg-type]
        )

    one_core = changes(("drift", 0.5), ("core:free_pi", 0.4), ("creep", 0.2))
    pair(one_core)
    no_block = changes(("core:boucwen", 0.5), ("core:free_pi", 0.4))
    pair(no_block)
    assert refits == [] and not any(c.paired_with for c in one_core + no_block)
    two_cores = changes(("drift", 0.5), ("core:boucwen", 0.45), ("creep", 0.3), ("core:gpi", 0.2))
    pair(two_cores)
    # Each core once, with the leading block only (creep is significant too).
    assert sorted(refits) == [("core:boucwen", "drift"), ("core:gpi", "drift")]
    boucwen, gpi = two_cores[1], two_cores[3]
    assert boucwen.paired_with == "drift" and boucwen.paired_test_deg == 0.18
    assert boucwen.paired_doubts == [] and boucwen.reach_deg == 0.18
    # The block's own checks on that core decide whether the pair counts.
    assert gpi.paired_doubts == ["helps least where drift shows"] and gpi.reach_deg == 0.8


@pytest.mark.parametrize(
    ("effect", "unlike", "like"),
    [
        ("transport_delay", [0.005], [0.03]),  # 5 ms: the valve; 30 ms: a tube's dead time
        (
            "pneumatic_lag",
            [0.004, 1.5, 1e8, 1.0, 0.0, 0.0, 0.0],
            [0.025, 1.0, 1e8, 1.0, 0.0, 0.0, 0.0],
        ),
        (
            "pneumatic_lag",
            [0.004, 2.0, 1e6, 1.0, 0.0],
            [0.006, 2.0, 1e6, 1.0, 0.0],
        ),  # 12 ms to vent: the tube's
        ("tip_dynamics", [3.0, 0.9, 0.0], [4.0, 0.12, 0.2]),  # a tip rings; 0.9 does not
    ],
)
def test_a_block_at_values_its_effect_never_has_says_why(
    effect: str, unlike: list[float], like: list[float]
) -> None:
    assert block(effect).unlike_effect(like) == []
    (why,) = block(effect).unlike_effect(unlike)
    assert ("valve" in why) if effect != "tip_dynamics" else ("does not ring" in why)


@pytest.mark.slow
@pytest.mark.parametrize(("hidden", "counted"), [("drift", True), ("gain_drift", False)])
def test_a_drift_block_is_named_for_an_offset_drift_not_for_a_gain_drift(
    hidden: str, counted: bool
) -> None:
    # Development seed 2 (held-out seeds are for the benchmark). A gain drift changes the bend
    # where it bends and nothing at rest; the drift block half fits it overall, and must not
    # be named for it.
    case = draw_case(PLANTS["boucwen"], [hidden], 2)
    model = GreyBox().fit([case.train], progress=False)
    result = diagnose(
        model, [case.train], [case.test], effects=["drift"], cores=[], reference=False
    )
    print(result.text())
    (drift,) = result.candidates
    assert drift.measured_reduction > 0.05  # it removes error either way...
    assert drift.significant is counted  # ...but only an offset shows with the muscle vented
    if not counted:
        assert "helps least where drift shows (vented" in result.text()


@pytest.mark.timeout(900)  # 45-80 s idle; minutes beside two busy loops
@pytest.mark.slow
@pytest.mark.parametrize(
    ("plant", "hidden", "seed", "answer"),
    [
        ("maxwell_slip", "sensor_lag", 12, "withheld"),
        ("boucwen", "pneumatic_lag", 11, "named"),
        ("boucwen", "sensor_lag", 4, "not counted"),
    ],
)
def test_a_lag_is_named_pneumatic_only_where_it_is_before_the_core(
    plant: str, hidden: str, seed: int, answer: str
) -> None:
    # Development seeds. A lag in the laser's filter (outside the catalogue) removes much of
    # the same error as one in the tube; only the side of the hysteresis tells them apart.
    # Where its rival fits about as well (Bouc-Wen, seed 4: 0.366 against 0.356 deg) the data
    # cannot, and the lab used to name the tube's lag with the side "not certain". Since the
    # lag's flow may bend and follow the upstream pressure, the tube's lag mimics the
    # laser's there only with its venting limit at the end of its range, so it is not
    # counted and the answer is "unexplained": what issue 34 asks for outside the catalogue.
    case = draw_case(PLANTS[plant], [hidden], seed)
    model = GreyBox(core="free_pi").fit([case.train], progress=False)
    result = diagnose(
        model, [case.train], [case.test], effects=["pneumatic_lag"], cores=[], reference=False
    )
    text = result.text()
    print(text)
    (lag,) = result.candidates
    assert lag.measured_reduction > 0.3  # it removes error either way...
    assert lag.significant is answer.startswith("named")  # ...but is named only where it sits
    uncertain = "which side is not certain: output_lag (on the core's output side)"
    if answer == "withheld":
        assert result.verdict == "unexplained"
        assert "output_lag (on the core's output side) fits better" in text
    elif answer == "named":
        assert result.verdict == "add pneumatic_lag" and uncertain not in text
    else:
        assert result.verdict == "unexplained"
        assert "not counted: vent_rate_ratio at the end of its range" in text


@pytest.mark.timeout(900)  # 45-80 s idle; minutes beside two busy loops
@pytest.mark.slow
def test_a_lag_whose_speed_follows_the_pressure_and_direction_is_removed_to_its_twin() -> None:
    # Development seed 5 (issue 34, item 4). The Bouc-Wen plant fills its muscle through a
    # valve whose flow saturates, at another flow when venting, and quicker at a higher
    # pressure (polytropic). One time constant and one flow limit left 0.56 deg where the
    # same catheter with nothing hidden ends at 0.17 deg; the lag's family (its own venting
    # time and flow limit, a speed that follows the absolute pressure) removes it.
    case = draw_twin_case(PLANTS["boucwen"], ["pneumatic_lag"], 5)
    twin = draw_twin_case(PLANTS["boucwen"], [], 5)
    twin_deg = math.degrees(
        pooled_rmse(GreyBox(core="free_pi").fit([twin.train], progress=False), [twin.test])
    )
    lagged = GreyBox(core="free_pi", effects=["pneumatic_lag"]).fit([case.train], progress=False)
    case_deg = math.degrees(pooled_rmse(lagged, [case.test]))
    values = lagged.block_values()["pneumatic_lag"]
    print(f"twin {twin_deg:.3f} deg, with the lag {case_deg:.3f} deg: {values}")
    assert case_deg <= 1.25 * twin_deg  # issue 34's bar: within 1.25x the twin
    # It found the physics, not only a better fit: venting slower and against a lower flow
    # limit than filling, and quicker at a higher pressure.
    assert values["vent_ratio"] > 1.0 and values["vent_rate_ratio"] < 1.0
    assert values["pressure_exponent"] > 0.0


@pytest.mark.slow
@pytest.mark.parametrize(
    ("plant", "hidden", "seed", "named"),
    [("maxwell_slip", "slow_lag", 5, False), ("maxwell_slip", "creep", 5, True)],
)
def test_creep_is_named_only_where_the_slow_part_follows_the_bend(
    plant: str, hidden: str, seed: int, named: bool
) -> None:
    # Development seed 5. A second chamber that fills for seconds (outside the catalogue)
    # keeps the bend moving on plateaus as creep does; only whether the slow part passes
    # through the hysteresis (a share of the pressure) or follows the bend tells them apart.
    case = draw_case(PLANTS[plant], [hidden], seed)
    model = GreyBox(core="free_pi").fit([case.train], progress=False)
    result = diagnose(
        model, [case.train], [case.test], effects=["creep"], cores=[], reference=False
    )
    print(result.text())
    (creep,) = result.candidates
    assert creep.measured_reduction > 0.2  # it removes error either way...
    assert creep.significant is named  # ...but is named only where the slow part is the bend's
    if not named:
        assert "slow_fill (on the core's input side) fits better" in result.text()


def test_workers_import_this_package_even_where_a_directory_of_its_name_comes_first(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Under pytest, tests/ (with tests/catheter_models/lab) is early on sys.path, and spawned
    # workers inherit the path: every refit of the full suite once failed to unpickle there
    # ("No module named 'catheter_models.lab.diagnose'"), while a test run alone passed.
    (tmp_path / "catheter_models" / "lab").mkdir(parents=True)
    monkeypatch.syspath_prepend(str(tmp_path))
    with lab_pool(1) as pool:
        assert pool.submit(default_workers).result(timeout=240) >= 1


def test_a_worker_that_dies_is_reported_with_a_way_out() -> None:
    # A worker killed (the kernel's OOM killer, a signal) breaks the whole pool; the bare
    # BrokenProcessPool names neither cause nor remedy.
    with pytest.raises(RefitWorkerError, match=r"--workers 1"), refit_executor(2) as pool:
        pool.submit(os._exit, 3).result(timeout=240)


@pytest.mark.slow
def test_refits_in_worker_processes_give_the_diagnosis_of_one_process(creep_case) -> None:
    model = GreyBox().fit([creep_case.train], progress=False)
    args = (model, [creep_case.train], [creep_case.test])
    # Two refits (one per worker) and no black box: what differs is only where they run.
    kwargs = {"effects": ["creep", "transport_delay"], "cores": [], "reference": False}
    one = diagnose(*args, **kwargs, workers=1)
    two = diagnose(*args, **kwargs, workers=2)
    assert [c.effect for c in two.candidates] == [c.effect for c in one.candidates]
    for a, b in zip(one.candidates, two.candidates, strict=True):
        assert b.rmse_test_deg == pytest.approx(a.rmse_test_deg, rel=1e-9)
        assert b.value_si == pytest.approx(a.value_si, rel=1e-9, nan_ok=True)
    assert two.verdict == one.verdict


@pytest.mark.slow
def test_refits_on_a_local_ray_give_the_diagnosis_of_local_processes(creep_case) -> None:
    # Where one machine is not enough the refits go to a Ray cluster; a Ray started here
    # is the same code path (Ray tasks, their results through futures) with no cluster.
    pytest.importorskip("ray", reason="Ray is an optional extra (requirements-dev.txt has it)")
    model = GreyBox().fit([creep_case.train], progress=False)
    args = (model, [creep_case.train], [creep_case.test])
    kwargs = {"effects": ["creep", "transport_delay"], "cores": [], "reference": False}
    local = diagnose(*args, **kwargs, workers=2)
    on_ray = diagnose(*args, **kwargs, ray="local")
    assert [c.effect for c in on_ray.candidates] == [c.effect for c in local.candidates]
    for a, b in zip(local.candidates, on_ray.candidates, strict=True):
        assert b.rmse_test_deg == pytest.approx(a.rmse_test_deg, rel=1e-9)
        assert b.value_si == pytest.approx(a.value_si, rel=1e-9, nan_ok=True)
    assert on_ray.verdict == local.verdict
    import ray

    assert not ray.is_initialized()  # the Ray it started is shut down with the diagnosis


@pytest.mark.slow
def test_on_a_foreign_plant_the_core_is_named_as_the_largest_miss() -> None:
    case = draw_case(PLANTS["boucwen"], [], 7)
    drdpi = GreyBox().fit([case.train], progress=False)
    result = diagnose(drdpi, [case.train], [case.test], effects=[])
    print(result.text())
    # Either learned core fixes the loop's shape (this plant's rate dependence is a damper,
    # which viscous_pi names and free_pi's rate factor mimics; they differ by a point or two).
    assert result.verdict in LEARNED_CORE_VERDICTS, result.text()
    assert result.best is not None and result.best.measured_reduction > 0.5


def _run(argv: list[str]) -> int:
    try:
        main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


@pytest.mark.slow
@pytest.mark.timeout(900)  # the whole loop, on a busy 2-core machine
def test_core_and_explain_on_the_command_line(tmp_path: Path, capsys) -> None:
    from catheter_models.bag import write_bag_from_arrays

    # Two minutes of training (the held-out protocol: plateaus and fast steps) and two of
    # held-out data from another seed: enough for creep, half the cost of the full case.
    case = draw_case(PLANTS["maxwell_slip"], ["creep"], 5)
    held_out = make_case(case.plant, case.effects, 6).test
    train, test = tmp_path / "train", tmp_path / "test"
    for path, rec in ((train, case.test), (test, held_out)):
        t_s = np.arange(rec.pressure_pa.size) / rec.rate_hz
        write_bag_from_arrays(path, t_s, rec.pressure_pa, rec.pressure_pa, rec.angle_rad)
    drdpi = tmp_path / "drdpi"
    budget = '{"max_generations": 8, "wall_time_s": 8}'
    argv = ["train", "drdpi", "--train", str(train), "-o", str(drdpi), "--quiet"]
    assert _run([*argv, "--set", f"budget={budget}"]) == 0
    lab = tmp_path / "lab"
    argv = ["core", "free_pi", str(drdpi), "-o", str(tmp_path / "v2"), "--train", str(train)]
    assert _run([*argv, "--test", str(test), "--lab", str(lab), "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "free_pi" in out and (lab / "history.jsonl").is_file()
    out_dir = tmp_path / "explained"
    argv = ["explain", str(tmp_path / "v2"), "--train", str(train), "--test", str(test)]
    assert _run([*argv, "-o", str(out_dir), "--max-steps", "1"]) == 0
    out = capsys.readouterr().out
    assert "add creep" in out, out
    assert (out_dir / "history.png").is_file() and (out_dir / "explanation.json").is_file()
    doc = json.loads((out_dir / "explanation.json").read_text())
    assert doc["changes"] == ["creep"]
    assert all(step["seconds"] > 0 for step in doc["steps"])  # what bench_lab_foreign times
    assert (out_dir / "step1" / "manifest.json").is_file()
    history = [json.loads(line) for line in (out_dir / "history.jsonl").read_text().splitlines()]
    assert [h["added"] for h in history] == [None, "creep"]
    assert history[0]["noise_floor_deg"] == pytest.approx(
        math.degrees(case.plant.noise_std_rad), rel=0.1
    )


def test_a_block_at_zero_growth_is_a_plain_answer_but_at_its_limit_it_is_doubted() -> None:
    from catheter_models.lab.diagnose import _pinned

    model = GreyBox(core="free_pi", effects=["tip_dynamics", "creep"])
    model.blocks_ = {"tip_dynamics": [4.9, 0.12, 0.03], "creep": [0.5, 2.0, 1.0]}
    assert _pinned(model, "tip_dynamics") == []  # no growth of the damping: a real answer
    # At its 50 % cap; one lag (no spread, the block's earlier form) is a plain answer.
    assert [d.split()[0] for d in _pinned(model, "creep")] == ["fraction"]
    model.blocks_["creep"] = [0.2, 2.0, 30.0]  # the widest spread: standing in for more
    assert [d.split()[0] for d in _pinned(model, "creep")] == ["spread"]
