"""Training data for models: bags in, clear refusals for data that cannot train a model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer

from catheter_models.bag.messages import fluid_pressure_cdr
from catheter_models.cli import main
from catheter_models.errors import BagError, MissingTopicError, SignalError
from catheter_models.model_dir import ModelDirError
from catheter_models.models import ModelError, load_model, model_class
from catheter_models.models.base import (
    DataRequirement,
    InsufficientDataError,
    MinMaxScaler,
    RateMismatchError,
    Recording,
    check_rates,
)
from catheter_models.models.data import (
    locate_training_bags,
    recording_from_bag,
    simulate_recording,
)
from catheter_models.models.drdpi import DRDPI
from catheter_models.models.evaluate import run_compensator
from catheter_models.units import AMBIENT_PRESSURE_PA

REPO = Path(__file__).resolve().parents[3]


def _recording(n: int = 100, rate_hz: float = 250.0, name: str = "r") -> Recording:
    t = np.arange(n) / rate_hz
    return Recording(name, rate_hz, 1e5 * (1 + np.sin(t)), 0.1 * np.sin(t))


def test_recording_from_a_sample_bag() -> None:
    rec = recording_from_bag(REPO / "bags" / "model_test_descending_sine")
    assert rec.rate_hz == 250.0
    assert len(rec) > 5000  # about 25 s of the thesis's test signal 1
    assert 2.0e5 < rec.pressure_pa.max() <= 3.0e5
    assert np.radians(15) < rec.angle_rad.max() < np.radians(35)
    assert len(rec.sha256) == 64
    assert rec.source.endswith("model_test_descending_sine")


def _pressure_only_bag(path: Path) -> Path:
    """A bag with both pressure streams but no tip/angle: it cannot train a model."""
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


def test_a_bag_without_the_models_signals_is_refused(tmp_path: Path) -> None:
    bag = _pressure_only_bag(tmp_path / "no_angle")
    with pytest.raises(MissingTopicError, match=r"does not fit the models' signals.*tip/angle"):
        recording_from_bag(bag)


def test_cli_train_refuses_such_a_bag_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = _pressure_only_bag(tmp_path / "no_angle")
    with pytest.raises(SystemExit) as info:
        main(["train", "drdpi", "--train", str(bag), "-o", str(tmp_path / "m")])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert "tip/angle" in err and "Traceback" not in err
    assert not (tmp_path / "m").exists()


def test_unknown_kind_lists_the_known_ones(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(ModelError, match="known kinds: drdpi, gpi, idrdpi, svr, lstm, clstm"):
        model_class("preisach")
    bag = REPO / "bags" / "model_test_up_chirp"
    with pytest.raises(SystemExit):
        main(["train", "preisach", "--train", str(bag), "-o", str(tmp_path / "m")])
    assert "unknown model kind 'preisach'" in capsys.readouterr().err


def test_load_model_refuses_a_directory_without_manifest(tmp_path: Path) -> None:
    with pytest.raises(ModelDirError, match="not a model directory"):
        load_model(tmp_path)


def test_recording_refuses_nan_and_mismatched_lengths() -> None:
    p = np.full(10, 1e5)
    a = np.zeros(10)
    a[7] = np.nan
    with pytest.raises(SignalError, match=r"angle_rad has 1 non-finite samples.*index 7"):
        Recording("bad", 250.0, p, a)
    with pytest.raises(SignalError, match="equally long"):
        Recording("bad", 250.0, p, np.zeros(9))


def test_too_little_data_says_how_much_more() -> None:
    need = DataRequirement(min_samples=2500, why="A model needs several hysteresis loops.")
    with pytest.raises(InsufficientDataError, match=r"100 training samples.*record 2400 more"):
        need.check("drdpi", [_recording(100)])
    with pytest.raises(InsufficientDataError, match=r"≈ 10 s at 250 Hz"):
        need.check("drdpi", [_recording(100)])
    need.check("drdpi", [_recording(2500)])  # exactly enough is enough


def test_one_sample_rate_per_model() -> None:
    assert check_rates("lstm", [_recording(), _recording()]) == 250.0
    with pytest.raises(RateMismatchError, match=r"'slow' is sampled at 100 Hz.*works at 250 Hz"):
        check_rates("lstm", [_recording(), _recording(rate_hz=100.0, name="slow")])


def test_min_max_scaler_is_eq_7_9() -> None:
    scaler = MinMaxScaler.fit([2.0, 4.0, 3.0])
    assert scaler.transform([2.0, 3.0, 4.0]).tolist() == [-1.0, 0.0, 1.0]
    assert scaler.inverse(scaler.transform([2.5])).tolist() == [2.5]
    assert MinMaxScaler.from_dict(scaler.to_dict()) == scaler
    with pytest.raises(ModelError, match="must vary"):
        MinMaxScaler.fit([1.0, 1.0])


class _Echo:
    """A 'compensator' that asks for a fixed pressure per desired angle."""

    def __init__(self, out: list[float]) -> None:
        self.out = out
        self.k = 0

    def reset(self) -> None:
        self.k = 0

    def step(self, value: float) -> float:
        self.k += 1
        return self.out[self.k - 1]


def test_run_compensator_limits_like_the_node() -> None:
    asked = [5e5, 5e5, -1e5, float("nan"), 1e5]
    out = run_compensator(
        _Echo(asked), np.zeros(5), rate_hz=250.0, max_pressure_pa=3e5, max_slew_pa_per_s=25e6
    )
    # 1e5 Pa per tick at most, never above 3e5, never below 0, and a NaN stops the run at 0.
    assert out.tolist() == [1e5, 2e5, 1e5, 0.0, 0.0]


def test_simulated_recording_is_a_recording() -> None:
    rec = simulate_recording("model_test_up_chirp")
    assert rec.source == "simulated:model_test_up_chirp" and rec.sha256 == ""
    assert rec.io("inverse")[0] is rec.angle_rad


@pytest.mark.filterwarnings("ignore::catheter_models.gaps.BagGapWarning")
def test_a_trained_models_manifest_names_its_bags_not_their_paths(tmp_path: Path) -> None:
    """training_bags holds bag names and hashes: the training machine's paths never ship."""
    bags_dir = REPO / "bags"
    rec = recording_from_bag(bags_dir / "model_test_descending_sine")  # an absolute path
    assert Path(rec.source).is_absolute()
    tiny = {"max_generations": 1, "popsize": 2, "wall_time_s": 2.0, "polish": "none"}
    model = DRDPI(n_play=2, n_deadband=1, budget=tiny).fit([rec], progress=False)
    model.save(tmp_path / "m", training=[rec])
    on_disk = json.loads((tmp_path / "m" / "manifest.json").read_text())["training_bags"]
    assert on_disk == {"model_test_descending_sine": rec.sha256}
    assert all("/" not in k and "\\" not in k for k in on_disk)
    # A reader finds each bag by name in a bags directory and proves it by its hash.
    found = locate_training_bags(on_disk, bags_dir)
    assert found == {"model_test_descending_sine": bags_dir / "model_test_descending_sine"}


def test_locating_a_training_bag_checks_its_hash(tmp_path: Path) -> None:
    bags_dir = REPO / "bags"
    with pytest.raises(BagError, match="sha256"):
        locate_training_bags({"model_test_up_chirp": "0" * 64}, bags_dir)
    with pytest.raises(BagError, match="not found"):
        locate_training_bags({"no_such_bag": "0" * 64}, bags_dir)
    assert locate_training_bags({"simulated:x": ""}, bags_dir) == {}


def test_the_shipped_manifests_name_bags_not_paths() -> None:
    data = REPO / "src" / "catheter_control" / "catheter_control" / "data"
    for manifest in sorted(data.glob("*/manifest.json")):
        names = json.loads(manifest.read_text())["training_bags"]
        assert names, manifest
        assert all("/" not in k and "\\" not in k for k in names), manifest
