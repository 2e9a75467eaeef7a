"""Where the compensator's gains come in, the sealed-gains check holds (no DDS).

``load_feedback`` (the node's configure) and ``bringup --feedback-gains`` (before anything
starts) refuse a hand-edited ``feedback.json`` by name, and take the shipped, sealed one.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from catheter_control import bringup
from catheter_control.models import SHIPPED_GAINS, load_feedback, shipped_model_dir
from catheter_models.contract import CONTROL_RATE_HZ
from catheter_models.feedback import GAINS_FILE
from catheter_models.feedback.seal import SEAL_KEY, FeedbackFileError

SHIPPED = shipped_model_dir(SHIPPED_GAINS) / GAINS_FILE


def _probe_file(tmp_path: Path) -> Path:
    """The probe's file: the shipped gains x100, a 6 bar authority, a 10^6 s timeout."""
    raw = json.loads(SHIPPED.read_text())
    raw["kp_pa_per_rad"] *= 100.0
    raw["ki_pa_per_rad_s"] *= 100.0
    raw["max_correction_pa"] = 6.0e5
    raw["authority_timeout_s"] = 1.0e6
    path = tmp_path / GAINS_FILE
    path.write_text(json.dumps(raw, indent=2))
    return path


def test_the_shipped_gains_are_sealed_and_load() -> None:
    assert SEAL_KEY in json.loads(SHIPPED.read_text())
    feedback = load_feedback("pi", "", "", CONTROL_RATE_HZ)
    assert feedback is not None and feedback.gains.tuning["recordings"] == ["lab_steps_101"]


def test_the_node_loader_refuses_the_probes_file_by_name(tmp_path: Path) -> None:
    bad = _probe_file(tmp_path)
    for gains_path, model_dir in ((str(bad), ""), ("", str(tmp_path))):
        with pytest.raises(FeedbackFileError) as info:
            load_feedback("pi", gains_path, model_dir, CONTROL_RATE_HZ)
        said = str(info.value)
        for name in ("kp_pa_per_rad", "max_correction_pa", "authority_timeout_s", SEAL_KEY):
            assert name in said, name


def test_bringup_refuses_edited_feedback_gains_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    started: list[object] = []
    monkeypatch.setattr(bringup.ProcessGraph, "start", lambda self, *a, **k: started.append(a))
    bad = _probe_file(tmp_path)
    with pytest.raises(SystemExit) as stop:
        bringup.main(["--feedback", "pi", "--feedback-gains", str(bad)])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "max_correction_pa 6 bar is beyond the safety envelope" in err, err
    assert not started
    args, _ = bringup.parse_args(["--feedback", "pi", "--feedback-gains", str(SHIPPED)])
    assert bringup.compensator_choice(args)["feedback_gains"] == str(SHIPPED)
