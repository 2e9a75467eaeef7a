"""Tests of the lab's compare and locate: catheter_models.lab.compare and `catheter-lab compare`."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from catheter_models.bag.messages import fluid_pressure_cdr
from catheter_models.cli import main
from catheter_models.lab.compare import Comparison, compare, write_report
from catheter_models.metrics import REGIMES, compute_metrics, metrics_by_regime
from catheter_models.models import NotFittedError, RateMismatchError, load_model
from catheter_models.models.base import Recording
from catheter_models.models.data import simulate_recording
from catheter_models.models.drdpi import DRDPI, PARAMS_FILE, DRDPIParams
from catheter_models.models.idrdpi import IDRDPI
from catheter_models.units import AMBIENT_PRESSURE_PA, bar_to_pa, deg_to_rad, rad_to_deg

REPO = Path(__file__).resolve().parents[3]
CLSTM_DIR = REPO / "src" / "catheter_control" / "catheter_control" / "data" / "clstm"
RATE_HZ = 250.0
# A DRDPI inside the default box (as in tests/catheter_models/models/test_drdpi.py).
TRUE = DRDPIParams(
    alpha0=3.0 * math.exp(0.5),
    alpha1=-1.0 * math.exp(1.0),
    alpha2=0.0,
    beta0=0.5,
    beta1=1.0,
    beta2=0.0,
    dp=10.0,
    dn=10.0,
    zeta=0.1,
    beta=0.02,
    a0=2.0,
    g0=0.05,
)


@pytest.fixture(scope="module")
def truth() -> DRDPI:
    return DRDPI.from_params(TRUE, RATE_HZ)


def _ramps_pa() -> np.ndarray:
    """1 s rest, a slow rise to 2.5 bar (1-5 s), 2 s hold, a fast fall (7-8 s), 2 s rest.

    The rise is four times slower than the fall, so it is loading but not fast motion, and
    above 1 bar (after 3 s) it is out of the deadband: one regime only.
    """
    t = np.arange(round(10.0 * RATE_HZ)) / RATE_HZ
    bar = np.interp(t, [0.0, 1.0, 5.0, 7.0, 8.0, 10.0], [0.0, 0.0, 2.5, 2.5, 0.0, 0.0])
    return np.asarray(bar_to_pa(bar))


def _sine_pa() -> np.ndarray:
    t = np.arange(round(12.0 * RATE_HZ)) / RATE_HZ
    return np.asarray(bar_to_pa(1.25 * (1.0 - np.cos(2.0 * math.pi * 0.5 * t))))


def _perfect(model: DRDPI, bias: tuple[float, float, float] | None = None) -> list[Recording]:
    """Recordings the model predicts exactly, but for ``(start_s, end_s, bias_deg)`` in "ramps"."""
    out = []
    for name, p in (("sine", _sine_pa()), ("ramps", _ramps_pa())):
        angle = model.predict(p)
        if bias is not None and name == "ramps":
            t = np.arange(p.size) / RATE_HZ
            angle = angle - deg_to_rad(bias[2]) * ((t >= bias[0]) & (t < bias[1]))
        out.append(Recording(name, RATE_HZ, p, angle))
    return out


def test_metrics_are_those_of_compute_metrics_on_the_same_arrays(truth: DRDPI) -> None:
    recordings = (
        simulate_recording("model_test_descending_sine"),
        Recording("ramps", RATE_HZ, _ramps_pa(), truth.predict(_ramps_pa()) + 0.01),
    )
    result = compare(truth, recordings)
    predicted = [truth.predict(r.pressure_pa) for r in recordings]
    for rc, rec, pred in zip(result.recordings, recordings, predicted, strict=True):
        np.testing.assert_array_equal(rc.predicted_si, pred)
        np.testing.assert_array_equal(rc.measured_si, rec.angle_rad)
        assert rc.overall == compute_metrics(pred, rec.angle_rad)
    all_pred = np.concatenate(predicted)
    all_meas = np.concatenate([r.angle_rad for r in recordings])
    assert result.overall == compute_metrics(all_pred, all_meas)
    masks = {k: np.concatenate([rc.regimes[k] for rc in result.recordings]) for k in REGIMES}
    assert result.by_regime == metrics_by_regime(
        all_pred, all_meas, masks, normalization_range=float(np.ptp(all_meas))
    )
    assert result.output_unit == "rad" and result.display_unit == "deg"


def test_regimes_present_are_scored_and_absent_ones_are_not(truth: DRDPI) -> None:
    rec = simulate_recording("model_test_descending_sine")
    result = compare(truth, [rec])
    regimes = result.recordings[0].regimes
    assert set(result.by_regime) == set(REGIMES)
    for name in ("loading", "unloading", "peak", "valley", "deadband"):
        assert result.by_regime[name] is not None, name
    for name, mask in regimes.items():
        scored = result.by_regime[name]
        assert (scored is None) == (np.count_nonzero(mask) < 25), name
        if scored is not None:
            assert scored.n_samples == np.count_nonzero(mask)


def test_a_bias_in_one_window_is_reported_first_with_recording_time_and_regime(
    truth: DRDPI,
) -> None:
    result = compare(truth, _perfect(truth, bias=(3.0, 4.0, 2.0)), n_worst=1)
    [seg] = result.worst
    assert (seg.recording, seg.start_s, seg.end_s, seg.regime) == ("ramps", 3.0, 4.0, "loading")
    assert rad_to_deg(seg.rmse) == pytest.approx(2.0)
    assert rad_to_deg(seg.max_abs) == pytest.approx(2.0)
    assert seg.n_samples == 250
    # and the terminal report says where to look, in degrees
    line = next(x for x in result.text().splitlines() if x.strip().startswith("1."))
    assert "ramps  3.00-4.00 s  loading" in line and "RMSE 2 deg" in line


def test_a_bias_across_two_windows_is_one_segment_and_ranked_first(truth: DRDPI) -> None:
    rng = np.random.default_rng(0)
    recordings = [
        Recording(
            r.name, r.rate_hz, r.pressure_pa, r.angle_rad + 1e-4 * rng.standard_normal(len(r))
        )
        for r in _perfect(truth, bias=(3.5, 4.5, 2.0))
    ]
    result = compare(truth, recordings, n_worst=4)
    first = result.worst[0]
    assert (first.recording, first.start_s, first.end_s) == ("ramps", 3.0, 5.0)
    assert first.regime == "loading"
    assert [s.rmse for s in result.worst] == sorted((s.rmse for s in result.worst), reverse=True)
    assert all(s.rmse < first.rmse / 10 for s in result.worst[1:])


def test_write_report_writes_a_page_whose_images_exist(truth: DRDPI, tmp_path: Path) -> None:
    result = compare(truth, _perfect(truth, bias=(3.0, 4.0, 2.0)), n_worst=2)
    index = write_report(result, tmp_path / "report", title="drdpi <vs> sine & ramps")
    page = index.read_text()
    assert index == tmp_path / "report" / "index.html"
    assert "drdpi &lt;vs&gt; sine &amp; ramps" in page and "<script" not in page
    images = re.findall(r'<img src="([^"]+)"', page)
    assert len(images) == 1 + 2 * 2  # regime summary; time and loops per recording
    for src in images:
        assert not Path(src).is_absolute()
        assert (index.parent / src).stat().st_size > 1000
    assert "<td>ramps</td><td>3.00</td><td>4.00</td><td>loading</td>" in page
    saved = json.loads((index.parent / "comparison.json").read_text())
    assert saved == json.loads(json.dumps(result.to_dict()))
    assert saved["worst"][0]["rmse_deg"] == pytest.approx(2.0)


def test_an_inverse_model_is_compared_in_bar(tmp_path: Path) -> None:
    clstm = load_model(CLSTM_DIR)
    assert clstm.direction == "inverse" and clstm.fitted_rate_hz == RATE_HZ
    rec = simulate_recording("model_test_descending_sine")
    result = compare(clstm, [rec])
    assert result.output_unit == "pa" and result.display_unit == "bar"
    [rc] = result.recordings
    np.testing.assert_array_equal(rc.input_si, rec.angle_rad)
    assert rc.overall == compute_metrics(clstm.predict(rec.angle_rad), rec.pressure_pa)
    text = result.text()
    assert re.search(r"RMSE +\d+\.\d+ bar", text) and " deg" not in text
    assert "rmse_bar" in result.to_dict()["overall"]
    # regimes come from the motion, so they are those a forward model is scored on
    forward = compare(DRDPI.from_params(TRUE, RATE_HZ), [rec])
    for name in REGIMES:
        np.testing.assert_array_equal(rc.regimes[name], forward.recordings[0].regimes[name])
    # the IDRDPI too, and its report plots pressure against angle
    idrdpi = compare(IDRDPI.from_params(TRUE), [rec])
    assert idrdpi.display_unit == "bar"
    index = write_report(idrdpi, tmp_path, "idrdpi")
    assert "RMSE [bar]" in index.read_text()


def test_a_recording_at_another_rate_or_an_unfitted_model_is_refused(truth: DRDPI) -> None:
    p = _sine_pa()
    slow = Recording("slow", 100.0, p, truth.predict(p))
    with pytest.raises(RateMismatchError, match=r"'slow' is sampled at 100 Hz.*250 Hz"):
        compare(truth, [slow])
    with pytest.raises(NotFittedError, match="not fitted"):
        compare(DRDPI(), [slow])


def test_text_names_every_part_a_person_needs(truth: DRDPI) -> None:
    result = compare(truth, _perfect(truth, bias=(3.0, 4.0, 2.0)))
    text = result.text()
    for needle in ("RMSE", "MAE", "NRMSE", "maximum absolute error", "by regime", "worst"):
        assert needle in text
    assert isinstance(result, Comparison) and len(result.worst) <= 5


# -- the command line ------------------------------------------------------------------------


def _pressure_only_bag(path: Path) -> Path:
    """A bag with both pressure streams but no tip/angle: no model can be scored on it."""
    from catheter_models.bag.messages import kilted_typestore

    store = kilted_typestore()
    kind = "sensor_msgs/msg/FluidPressure"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [
            writer.add_connection(f"/catheter/pressure/{t}", kind, typestore=store)
            for t in ("command", "measured")
        ]
        for i in range(50):
            stamp = 10**18 + i * 4_000_000
            for conn in conns:
                writer.write(
                    conn, stamp, fluid_pressure_cdr(stamp, 1.2e5, ambient_pa=AMBIENT_PRESSURE_PA)
                )
    return path


@pytest.fixture(scope="module")
def model_and_bag(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("cli")
    DRDPI.from_params(TRUE, RATE_HZ).save(root / "drdpi")
    with pytest.raises(SystemExit) as info:
        main(["simulate", "model_test_arbitrary_plateaus", "-o", str(root / "plateaus")])
    assert info.value.code == 0
    return root / "drdpi", root / "plateaus"


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as info:
        main(argv)
    out, err = capsys.readouterr()
    return int(info.value.code or 0), out, err


def test_cli_compares_a_model_dir_with_a_bag(
    model_and_bag: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model, bag = model_and_bag
    out_dir = tmp_path / "report"
    code, out, _ = _run(
        ["compare", str(model), str(bag), "-o", str(out_dir), "--worst", "3"], capsys
    )
    assert code == 0
    assert re.search(r"RMSE +\d+\.\d+ deg", out)
    assert "worst segments" in out and re.search(r"1\. plateaus  \d+\.\d\d-\d+\.\d\d s", out)
    assert (out_dir / "index.html").is_file()
    assert out.strip().splitlines()[-1] == f"report: {out_dir / 'index.html'}"


def test_cli_default_report_dir_names_the_model(
    model_and_bag: tuple[Path, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    model, bag = model_and_bag
    monkeypatch.chdir(tmp_path)
    code, out, _ = _run(["compare", str(model), str(bag), "--worst", "1"], capsys)
    assert code == 0
    [report] = (tmp_path / "lab").glob("compare-drdpi-*")
    assert re.fullmatch(r"compare-drdpi-\d{8}-\d{6}", report.name)
    assert (report / "index.html").is_file()
    assert out.strip().splitlines()[-1] == f"report: {Path('lab') / report.name / 'index.html'}"


def _one_line_refusal(code: int, err: str, *needles: str) -> None:
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("catheter-lab compare: "), err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


def test_cli_refusals_are_one_line(
    model_and_bag: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model, bag = model_and_bag
    no_angle = _pressure_only_bag(tmp_path / "no_angle")
    code, _, err = _run(["compare", str(model), str(no_angle), "-o", str(tmp_path / "a")], capsys)
    _one_line_refusal(code, err, "tip/angle", "no_angle")
    assert not (tmp_path / "a").exists()

    code, _, err = _run(["compare", str(bag), str(bag)], capsys)
    _one_line_refusal(code, err, "not a model directory")

    tampered = tmp_path / "tampered"
    DRDPI.from_params(TRUE, RATE_HZ).save(tampered)
    params = tampered / PARAMS_FILE
    params.write_text(params.read_text().replace('"zeta": 0.1', '"zeta": 0.2'))
    code, _, err = _run(["compare", str(tampered), str(bag)], capsys)
    _one_line_refusal(code, err, "sha256", PARAMS_FILE)

    code, _, err = _run(["compare", str(model), str(bag), "--rate-hz", "100"], capsys)
    _one_line_refusal(code, err, "100 Hz", "250 Hz", "--rate-hz")
