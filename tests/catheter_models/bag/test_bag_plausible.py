"""Plausible data, or a clear word: each bad-data probe of issue 31 is refused by name.

Every bad bag is the shipped ``model_test_up_chirp`` with one thing changed (``bad_bags``), so
the rest of it is a real recording. A refusal must name the topic, the check, the count and the
first offending time; ``--accept-implausible`` goes on and still says it; ``bag info`` shows the
same findings; and real recordings (the shipped bags) raise no finding at all.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import bad_bags as bb
import numpy as np
import pytest

from catheter_models import cli
from catheter_models.bag import load_bag
from catheter_models.bag.info import inspect_bag
from catheter_models.bag.plausible import (
    ACCEPT_FLAG,
    BEND_LIMIT_RAD,
    PRESSURE_NOISE_MARGIN_PA,
    ImplausibleBagError,
    PlausibilityWarning,
)
from catheter_models.contract import PRESSURE_LIMIT_HARD_PA
from catheter_models.models.data import recording_from_bag
from catheter_models.units import NS_PER_S, deg_to_rad

REPO = Path(__file__).resolve().parents[3]
SHIPPED_BAGS = sorted(p for p in (REPO / "bags").iterdir() if p.is_dir())
IDRDPI = REPO / "src/catheter_control/catheter_control/data/idrdpi"


def _half_reused(s: np.ndarray) -> np.ndarray:
    half = s.size // 2
    return np.concatenate([s[:half], s[: s.size - half]])


def _every_other_nan(v: np.ndarray) -> np.ndarray:
    v[1::2] = np.nan
    return v


def _both(*edits: bb.Edit) -> bb.Edit:
    def edit(name: str, s: bb.Stream) -> bb.Stream:
        for e in edits:
            s = e(name, s)
        return s

    return edit


# One row per probe: (edit, topic, check, the words that name it).
PROBES: dict[str, tuple[bb.Edit, str, str, str]] = {
    "300 bar": (
        bb.values("pressure/measured", lambda v: v * (300e5 / v.max())),
        "/catheter/pressure/measured",
        "range",
        "outside [-50000, 650000] Pa gauge",
    ),
    "1,574 deg bends": (
        bb.values("tip/angle", lambda v: v * (deg_to_rad(1574.0) / v.max())),
        "/catheter/tip/angle",
        "units",
        "beyond the joint's limits",
    ),
    "bar stored as Pa": (
        _both(
            bb.values("pressure/command", lambda v: v / 1e5),
            bb.values("pressure/measured", lambda v: v / 1e5),
        ),
        "/catheter/pressure/command",
        "units",
        "bar stored as Pa",
    ),
    "degrees stored as radians": (
        bb.values("tip/angle", np.degrees),
        "/catheter/tip/angle",
        "units",
        "degrees stored as radians",
    ),
    "duplicate stamps": (
        bb.duplicated,
        "/catheter/tip/angle",
        "repeated stamps",
        "50.0% of the samples carry a header stamp another sample",
    ),
    "half the bag re-using stamps": (
        bb.stamps(_half_reused),
        "/catheter/tip/angle",
        "stamps not increasing",
        "earlier than the one before it",
    ),
    "a time-reversed bag": (
        bb.stamps(lambda s: s[::-1]),
        "/catheter/pressure/command",
        "stamps not increasing",
        "earlier than the one before it",
    ),
    "every other tip/angle sample NaN": (
        bb.values("tip/angle", _every_other_nan),
        "/catheter/tip/angle",
        "non-finite",
        "50.0% of the samples are NaN or infinite",
    ),
}


@pytest.fixture(scope="module")
def probe_bags(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("probes")
    return {
        name: bb.rewrite(root / name.replace(" ", "_").replace(",", ""), edit)
        for name, (edit, *_rest) in PROBES.items()
    }


@pytest.mark.parametrize("probe", list(PROBES))
def test_each_bad_data_probe_is_refused_by_name(probe: str, probe_bags: dict[str, Path]) -> None:
    _edit, topic, check, words = PROBES[probe]
    bag = probe_bags[probe]
    with pytest.raises(ImplausibleBagError) as refused:
        recording_from_bag(bag)
    message = str(refused.value)
    assert str(bag) in message and ACCEPT_FLAG in message
    finding = next(
        f for f in refused.value.report.refusals if f.topic == topic and f.check == check
    )
    assert words in finding.detail
    assert f"{topic}: {check}: {finding.count} of {finding.total} samples" in message
    assert finding.count > 0 and finding.first_s is not None
    # The first offending time is a real log time of the recording.
    assert 0.0 <= finding.first_s <= 25.0


def test_a_refusal_counts_and_places_what_it_found(probe_bags: dict[str, Path]) -> None:
    streams = bb.read_streams(probe_bags["300 bar"])
    measured = streams["pressure/measured"]
    margin_pa = PRESSURE_NOISE_MARGIN_PA
    # The noise about zero, scaled up too, falls below the lower bound.
    over = (measured.values > PRESSURE_LIMIT_HARD_PA + margin_pa) | (measured.values < -margin_pa)
    report = load_bag(probe_bags["300 bar"]).plausibility
    (finding,) = report.refusals
    assert finding.count == int(np.count_nonzero(over))
    assert finding.total == measured.values.size
    start_ns = min(int(s.log_ns[0]) for s in streams.values())
    first_ns = int(measured.log_ns[np.flatnonzero(over)[0]])
    assert finding.first_s == pytest.approx((first_ns - start_ns) / NS_PER_S)
    assert "extreme 3e+07 Pa (300 bar)" in finding.detail


@pytest.mark.parametrize("probe", ["300 bar", "every other tip/angle sample NaN"])
def test_accepting_goes_on_and_still_says_it(probe: str, probe_bags: dict[str, Path]) -> None:
    bag = probe_bags[probe]
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        rec = recording_from_bag(bag, accept_implausible=True)
    said = [w.message for w in seen if isinstance(w.message, PlausibilityWarning)]
    assert said and all(w.accepted for w in said if w.finding.severity == "refuse")
    assert any("implausible, accepted knowingly" in str(w) for w in said)
    assert len(rec) > 1000 and np.all(np.isfinite(rec.angle_rad))


def test_a_few_glitches_warn_and_the_data_is_used(tmp_path: Path) -> None:
    def glitches(name: str, s: bb.Stream) -> bb.Stream:
        if name != "tip/angle":
            return s
        v = s.values.copy()
        v[[100, 2000, 4000]] = np.nan
        stamp = s.stamp_ns.copy()
        stamp[1:30] = stamp[0]  # as the laser driver stamps its first samples
        return bb.Stream(s.log_ns, stamp, v)

    bag = bb.rewrite(tmp_path / "glitches", glitches)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        recording_from_bag(bag)
    findings = {
        w.message.finding.check: w.message.finding
        for w in seen
        if isinstance(w.message, PlausibilityWarning)
    }
    assert set(findings) == {"non-finite", "repeated stamps"}
    assert all(f.severity == "warn" for f in findings.values())
    assert findings["non-finite"].count == 3
    assert findings["repeated stamps"].count == 29


def test_a_bag_whose_sensors_begin_mid_motion_is_said_so(tmp_path: Path) -> None:
    # A live commissioning once recorded the laser from 2.2 s into the excitation (the
    # recorder had not heard it yet): the bag began mid-motion, and the lab fitted from a
    # wrong rest. Here the sensors lose their first second after the command left rest.
    command = bb.read_streams()["pressure/command"]
    left_rest_ns = int(command.stamp_ns[np.flatnonzero(command.values > 1e3)[0]])

    def late(name: str, s: bb.Stream) -> bb.Stream:
        if name == "pressure/command":
            return s
        keep = s.stamp_ns >= left_rest_ns + NS_PER_S
        return bb.Stream(s.log_ns[keep], s.stamp_ns[keep], s.values[keep])

    bag = bb.rewrite(tmp_path / "late", late)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        recording_from_bag(bag)
    findings = [
        w.message.finding
        for w in seen
        if isinstance(w.message, PlausibilityWarning)
        and w.message.finding.check == "starts after the motion"
    ]
    assert {f.topic for f in findings} == {"/catheter/tip/angle", "/catheter/pressure/measured"}
    assert all(f.severity == "warn" for f in findings)
    assert "1.00 s after pressure/command left rest" in findings[0].detail
    assert "does not start at rest" in findings[0].detail


@pytest.mark.parametrize("bag", SHIPPED_BAGS, ids=lambda p: p.name)
def test_real_recordings_raise_no_finding(bag: Path) -> None:
    data = load_bag(bag)
    assert data.plausibility.findings == (), data.plausibility.lines()
    assert float(np.max(np.abs(data.tip_angle.values))) < BEND_LIMIT_RAD


def test_bag_info_shows_the_same_findings(
    probe_bags: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    bag = probe_bags["every other tip/angle sample NaN"]
    inspection = inspect_bag(bag)
    assert inspection.problem
    assert "REFUSE /catheter/tip/angle: non-finite: " in inspection.text
    assert "50.0% of the samples are NaN or infinite" in inspection.text
    code = _lab(["bag", "info", str(bag)])
    assert code == cli.EXIT_BAG_PROBLEM
    assert "REFUSE /catheter/tip/angle: non-finite" in capsys.readouterr().out
    assert not inspect_bag(SHIPPED_BAGS[0]).problem


def _lab(argv: list[str]) -> int:
    with pytest.raises(SystemExit) as done:
        cli.main(argv)
    return int(done.value.code or 0)


def test_compare_refuses_then_goes_on_knowingly(
    probe_bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = probe_bags["degrees stored as radians"]
    argv = ["compare", str(IDRDPI), str(bag), "-o", str(tmp_path / "refused")]
    assert _lab(argv) == 2
    err = capsys.readouterr().err
    assert "/catheter/tip/angle: units:" in err and "degrees stored as radians" in err
    assert not (tmp_path / "refused").exists()
    argv = ["compare", str(IDRDPI), str(bag), "-o", str(tmp_path / "accepted"), ACCEPT_FLAG]
    assert _lab(argv) == 0
    err = capsys.readouterr().err
    assert "implausible, accepted knowingly" in err and "degrees stored as radians" in err


def test_train_records_accepted_findings_in_the_manifest(
    probe_bags: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = probe_bags["duplicate stamps"]
    out = tmp_path / "model"
    argv = ["train", "drdpi", "--train", str(bag), "-o", str(out), "--quiet", ACCEPT_FLAG]
    assert _lab(argv) == 0
    assert "repeated stamps" in capsys.readouterr().err
    manifest = json.loads((out / "manifest.json").read_text())
    said = manifest["metrics"]["bag_plausibility"][bag.name]
    assert {f["check"] for f in said} == {"repeated stamps"}
    assert all(f["accepted"] and f["severity"] == "refuse" for f in said)
