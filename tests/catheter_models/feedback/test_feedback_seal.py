"""A ``feedback.json`` runs only as ``catheter-lab tune`` designed it, and within the envelope.

The probe that asked for this: gains x100, a 6 bar authority and a 10^6 s authority timeout,
typed into the file by hand, were accepted without a word and chattered the valve. Here each
of those is refused by name, a broken seal or a missing one is refused with how to re-tune or
reseal, a tuned file loads, and a deliberate edit is kept only through ``tune --reseal``,
which re-checks it on the loop the tuning recorded.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

import pytest

from catheter_models.cli import main as lab_main
from catheter_models.contract import (
    FEEDBACK_AUTHORITY_PA,
    FEEDBACK_AUTHORITY_TIMEOUT_S,
    FEEDBACK_MAX_AUTHORITY_PA,
    FEEDBACK_MAX_AUTHORITY_TIMEOUT_S,
    MAX_PRESSURE_PA,
)
from catheter_models.errors import ParameterError
from catheter_models.feedback import GAINS_FILE, FeedbackGains
from catheter_models.feedback.reseal import reseal
from catheter_models.feedback.seal import SEAL_KEY, FeedbackFileError
from catheter_models.feedback.tune import LoopModel, design, margins

# A loop like the simulated rig's (15 deg/bar, fast) with a little dead time and lag, so the
# design's margins are those of a real tuning (Ms 1.6, gain margin near 3).
LOOP = LoopModel(
    gain_rad_per_pa=math.radians(15.0) / 1e5,
    gain_median_rad_per_pa=math.radians(12.0) / 1e5,
    time_constant_s=0.02,
    delay_s=0.01,
    resonance_hz=0.0,
    resonance_damping=0.0,
    fit_nrmse=0.05,
    n_steps=5,
    rate_hz=250.0,
)


@pytest.fixture(scope="module")
def tuned() -> FeedbackGains:
    return design(LOOP)[0]


@pytest.fixture
def tuned_file(tuned: FeedbackGains, tmp_path: Path) -> Path:
    return tuned.save(tmp_path)


def _edit(path: Path, **changes: Any) -> None:
    """Change values in the file by hand, leaving its seal as it was."""
    raw = json.loads(path.read_text())
    raw.update(changes)
    path.write_text(json.dumps(raw, indent=2))


def _sealed_with(gains: FeedbackGains, directory: Path, field: str, value: float) -> Path:
    """``gains`` with one value changed, sealed by the tool (a seal that holds)."""
    changes: dict[str, Any] = {field: value}
    return dataclasses.replace(gains, **changes).save(directory)


def _refusal(path: Path) -> str:
    with pytest.raises(FeedbackFileError) as info:
        FeedbackGains.load(path)
    return str(info.value)


def test_a_tuned_file_loads_as_designed(tuned: FeedbackGains, tuned_file: Path) -> None:
    raw = json.loads(tuned_file.read_text())
    assert len(raw[SEAL_KEY]) == 64
    loaded = FeedbackGains.load(tuned_file.parent)
    assert loaded == tuned
    record = loaded.tuning
    # What the tuner designed, on what, and the range it considers safe.
    assert record["loop"]["delay_s"] == LOOP.delay_s
    assert record["designed"]["kp_pa_per_rad"] == tuned.kp_pa_per_rad
    gm = record["designed_margins"]["gain_margin"]
    assert gm > 2.6 and record["gain_factor"] == pytest.approx(math.sqrt(gm))
    low, high = record["safe"]["ki_pa_per_rad_s"]
    assert low < tuned.ki_pa_per_rad_s < high


def test_the_defaults_are_the_contracts_and_inside_its_envelope() -> None:
    gains = FeedbackGains(1.0, 1.0)
    assert gains.max_correction_pa == FEEDBACK_AUTHORITY_PA < FEEDBACK_MAX_AUTHORITY_PA
    assert gains.authority_timeout_s == FEEDBACK_AUTHORITY_TIMEOUT_S
    assert FEEDBACK_AUTHORITY_TIMEOUT_S < FEEDBACK_MAX_AUTHORITY_TIMEOUT_S
    # An authority as wide as the clamp would be no bound at all.
    assert FEEDBACK_MAX_AUTHORITY_PA < MAX_PRESSURE_PA


def test_the_probes_file_is_refused_naming_every_field(tuned_file: Path) -> None:
    raw = json.loads(tuned_file.read_text())
    _edit(
        tuned_file,
        kp_pa_per_rad=100 * raw["kp_pa_per_rad"],
        ki_pa_per_rad_s=100 * raw["ki_pa_per_rad_s"],
        max_correction_pa=6.0e5,
        authority_timeout_s=1.0e6,
    )
    said = _refusal(tuned_file)
    assert str(tuned_file) in said
    for name in ("kp_pa_per_rad", "ki_pa_per_rad_s", "max_correction_pa", "authority_timeout_s"):
        assert name in said, name
    assert "100x the tuned" in said
    assert "6 bar is beyond the safety envelope" in said
    assert "1e+06 s is beyond the safety envelope" in said
    assert "does not match its content" in said and "re-tune" in said
    # Resealing could not take these (beyond the envelope and the range): it is not offered.
    assert "--reseal" not in said


def test_a_broken_seal_is_refused_with_how_to_reseal(tuned_file: Path) -> None:
    # Not a gain: the notch's width, within every range. Only the seal catches it.
    _edit(tuned_file, notch_damping=0.3)
    said = _refusal(tuned_file)
    assert "feedback_sha256 does not match its content" in said
    assert "(notch_damping 0.5 -> 0.3)" in said
    assert "re-tune" in said and f"catheter-lab tune --reseal {tuned_file}" in said


def test_an_edited_safe_range_breaks_the_seal(tuned: FeedbackGains, tuned_file: Path) -> None:
    # The tuning record is sealed too: widening the safe range by hand breaks the seal.
    raw = json.loads(tuned_file.read_text())
    raw["tuning"]["safe"]["kp_pa_per_rad"][1] *= 1000.0
    raw["kp_pa_per_rad"] *= 100.0
    tuned_file.write_text(json.dumps(raw))
    said = _refusal(tuned_file)
    assert "does not match its content" in said and "kp_pa_per_rad" in said


def test_an_edited_tuning_record_alone_breaks_the_seal(tuned_file: Path) -> None:
    raw = json.loads(tuned_file.read_text())
    raw["tuning"]["designed_margins"]["gain_margin"] = 10.0
    tuned_file.write_text(json.dumps(raw))
    assert "its tuning record was edited" in _refusal(tuned_file)


@pytest.mark.parametrize(
    ("field", "value", "says"),
    [
        ("max_correction_pa", 6.0e5, "max_correction_pa 6 bar is beyond the safety envelope"),
        ("max_correction_pa", 1.01e5, "max_correction_pa 1.01 bar is beyond"),
        ("authority_timeout_s", 1.0e6, "authority_timeout_s 1e+06 s is beyond the safety"),
        ("authority_timeout_s", 2.5, "authority_timeout_s 2.5 s is beyond the safety"),
    ],
)
def test_a_limit_beyond_the_envelope_is_refused_sealed_or_not(
    tuned: FeedbackGains, tmp_path: Path, field: str, value: float, says: str
) -> None:
    # Sealed by the tool itself (a file a person resealed some other way): still refused.
    path = _sealed_with(tuned, tmp_path, field, value)
    said = _refusal(path)
    assert says in said and "contract.py" in said
    assert "seal" not in said  # the seal holds; the envelope alone refuses it


@pytest.mark.parametrize(
    ("field", "scale", "says"),
    [
        ("kp_pa_per_rad", 100.0, "kp_pa_per_rad"),
        ("ki_pa_per_rad_s", 2.0, "ki_pa_per_rad_s"),
        ("ki_pa_per_rad_s", 0.01, "ki_pa_per_rad_s"),
    ],
)
def test_a_gain_outside_the_tuned_range_is_refused_even_sealed(
    tuned: FeedbackGains, tmp_path: Path, field: str, scale: float, says: str
) -> None:
    value = scale * getattr(tuned, field)
    path = _sealed_with(tuned, tmp_path, field, value)
    said = _refusal(path)
    assert f"{says} {value:.4g} is {scale:.3g}x the tuned" in said
    assert "square root of its gain margin" in said


def test_a_derivative_the_tuning_never_designed_is_refused(
    tuned: FeedbackGains, tmp_path: Path
) -> None:
    path = _sealed_with(tuned, tmp_path, "kd_pa_s_per_rad", 50.0)
    assert "kd_pa_s_per_rad 50 where the tuning designed 0" in _refusal(path)


def test_a_legacy_unsealed_file_is_refused_with_how_to_seal_it(tmp_path: Path) -> None:
    # The shipped file as it was before gains were sealed.
    legacy = {
        "authority_timeout_s": 0.5,
        "derivative_filter_s": 0.01,
        "kd_pa_s_per_rad": 0.0,
        "ki_pa_per_rad_s": 33021374.46098272,
        "kp_pa_per_rad": 58721.23029515071,
        "max_correction_pa": 50000.0,
        "measurement_filter_s": 0.0,
        "notch_damping": 0.5,
        "notch_frequency_hz": 0.0,
        "opening_pressure_pa": 83284.85208801423,
        "tracking_time_s": 0.0,
        "tuning": {"margins": "Ms 1.60, gain margin 2.99", "method": "MIGO"},
    }
    path = tmp_path / GAINS_FILE
    path.write_text(json.dumps(legacy))
    said = _refusal(path)
    assert "it is not sealed" in said and "catheter-lab tune BAGS -o" in said
    # It records no loop, so it cannot be resealed either: only re-tuned.
    with pytest.raises(FeedbackFileError, match="records no tuned loop"):
        reseal(path, "keep the old gains")


def test_a_deliberate_edit_is_kept_only_through_reseal(
    tuned: FeedbackGains, tuned_file: Path
) -> None:
    _edit(tuned_file, kp_pa_per_rad=1.4 * tuned.kp_pa_per_rad)
    with pytest.raises(FeedbackFileError, match="does not match"):
        FeedbackGains.load(tuned_file)
    with pytest.raises(ParameterError, match="--reason"):
        reseal(tuned_file, " ")
    path, _, found = reseal(tuned_file, "a stiffer catheter, checked on the bench")
    assert path == tuned_file
    loaded = FeedbackGains.load(tuned_file)
    assert loaded.kp_pa_per_rad == pytest.approx(1.4 * tuned.kp_pa_per_rad)
    entry = loaded.tuning["resealed"][-1]
    assert entry["reason"] == "a stiffer catheter, checked on the bench"
    assert entry["changed"] == {"kp_pa_per_rad": [tuned.kp_pa_per_rad, loaded.kp_pa_per_rad]}
    assert found.gain_margin == pytest.approx(margins(LOOP, loaded).gain_margin)
    # The range stays the tuner's: resealing step by step cannot walk the gains out of it.
    assert 1.4 < loaded.tuning["gain_factor"] < 1.4**2
    _edit(tuned_file, kp_pa_per_rad=1.4 * loaded.kp_pa_per_rad)
    with pytest.raises(FeedbackFileError, match=r"kp_pa_per_rad .* is 1.96x the tuned"):
        reseal(tuned_file, "a bit more")


def test_reseal_refuses_the_envelope_and_a_loop_it_would_destabilise(
    tuned: FeedbackGains, tuned_file: Path
) -> None:
    _edit(tuned_file, max_correction_pa=2.0e5)
    with pytest.raises(FeedbackFileError, match="max_correction_pa 2 bar is beyond"):
        reseal(tuned_file, "more authority")
    # Gains inside their range, but a slow measurement filter added by hand: on the recorded
    # loop its lag eats the margin, and the re-check says so.
    _edit(tuned_file, max_correction_pa=tuned.max_correction_pa, measurement_filter_s=0.05)
    with pytest.raises(FeedbackFileError, match="on the recorded loop these gains"):
        reseal(tuned_file, "smoother")
    with pytest.raises(FeedbackFileError, match="does not match"):
        FeedbackGains.load(tuned_file)  # nothing was written


def test_the_cli_reseals_and_refuses_with_exit_2(
    tuned: FeedbackGains, tuned_file: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _edit(tuned_file, ki_pa_per_rad_s=0.8 * tuned.ki_pa_per_rad_s)
    with pytest.raises(SystemExit) as done:
        lab_main(["tune", "--reseal", str(tuned_file)])
    assert done.value.code == 2
    assert "--reason" in capsys.readouterr().err
    with pytest.raises(SystemExit) as done:
        lab_main(["tune", "--reseal", str(tuned_file), "--reason", "softer integral"])
    assert not done.value.code, capsys.readouterr().err
    assert "resealed" in capsys.readouterr().out
    assert FeedbackGains.load(tuned_file).ki_pa_per_rad_s == pytest.approx(
        0.8 * tuned.ki_pa_per_rad_s
    )
    with pytest.raises(SystemExit) as done:
        lab_main(["tune"])
    assert done.value.code == 2
    assert "BAG" in capsys.readouterr().err
