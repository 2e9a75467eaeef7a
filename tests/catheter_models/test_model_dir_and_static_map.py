"""Model directories are hash-checked; the static map fits the central curve and inverts it."""

import json

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.model_dir import (
    ModelDirError,
    read_manifest,
    read_model_dir,
    write_model_dir,
)
from catheter_models.plant import Plant, PlantConfig
from catheter_models.signals import training_set
from catheter_models.static_map import StaticMap


def test_round_trip_and_manifest(tmp_path) -> None:
    m = write_model_dir(tmp_path / "m", "demo", {"a": "rad"}, {"p": "Pa"}, {"w.json": b"[1,2]"})
    manifest, payload = read_model_dir(tmp_path / "m", expected_kind="demo")
    assert manifest == m
    assert payload == {"w.json": b"[1,2]"}


def test_training_bags_are_recorded_by_name_never_by_path(tmp_path) -> None:
    """A path is the training machine's; the manifest keeps the bag's name and hash."""
    bags = {"/home/me/bags/training": "a" * 64, "bags/training/run_0.mcap": "b" * 64, "sim": ""}
    write_model_dir(tmp_path / "m", "demo", {}, {}, {"w.json": b"[]"}, training_bags=bags)
    manifest, _ = read_model_dir(tmp_path / "m")
    assert manifest.training_bags == {"training": "a" * 64, "run_0.mcap": "b" * 64, "sim": ""}
    clash = {"/x/training": "a" * 64, "/y/training": "c" * 64}
    with pytest.raises(ModelDirError, match="two training bags are named 'training'"):
        write_model_dir(tmp_path / "n", "demo", {}, {}, {"w.json": b"[]"}, training_bags=clash)


def test_tampered_weight_file_is_refused(tmp_path) -> None:
    write_model_dir(tmp_path / "m", "demo", {}, {}, {"w.json": b"[1,2]"})
    (tmp_path / "m" / "w.json").write_bytes(b"[1,3]")
    with pytest.raises(ModelDirError, match=r"'w.json' fails its sha256 check"):
        read_model_dir(tmp_path / "m")


def test_the_manifest_alone_is_read_sealed_and_the_weights_only_with_the_model(tmp_path) -> None:
    """``load_model`` reads the kind from the manifest, then the kind's load reads and checks
    each weight file once (it read and hashed every file twice)."""
    write_model_dir(tmp_path / "m", "demo", {}, {}, {"w.json": b"[1,2]"})
    (tmp_path / "m" / "w.json").write_bytes(b"[1,3]")
    assert read_manifest(tmp_path / "m").kind == "demo"  # the weights are not its business
    with pytest.raises(ModelDirError, match="expected 'other'"):
        read_manifest(tmp_path / "m", expected_kind="other")
    manifest = json.loads((tmp_path / "m" / "manifest.json").read_text())
    manifest["kind"] = "edited"
    (tmp_path / "m" / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(ModelDirError, match="sha256"):
        read_manifest(tmp_path / "m")  # the seal is checked all the same


@pytest.mark.parametrize(
    "edit",
    [
        lambda raw: raw["files"].update({"w.json": "0" * 64}),  # a weight's recorded hash
        lambda raw: raw.update(normalization={"scale": 2.0}),  # constants beside the weights
        lambda raw: raw.update(kind="other"),
    ],
    ids=["weight hash", "normalization", "kind"],
)
def test_an_edited_manifest_is_refused(tmp_path, edit) -> None:
    write_model_dir(tmp_path / "m", "demo", {}, {}, {"w.json": b"[1,2]"})
    path = tmp_path / "m" / "manifest.json"
    raw = json.loads(path.read_text())
    edit(raw)
    path.write_text(json.dumps(raw))
    with pytest.raises(ModelDirError, match=r"manifest\.json fails its own sha256 check"):
        read_model_dir(tmp_path / "m")
    del raw["manifest_sha256"]  # removing the seal does not help
    path.write_text(json.dumps(raw))
    with pytest.raises(ModelDirError, match="has no manifest_sha256"):
        read_model_dir(tmp_path / "m")


def test_missing_file_wrong_kind_and_garbage_manifest(tmp_path) -> None:
    write_model_dir(tmp_path / "m", "demo", {}, {}, {"w.json": b"1"})
    with pytest.raises(ModelDirError, match="expected 'static_map'"):
        read_model_dir(tmp_path / "m", expected_kind="static_map")
    (tmp_path / "m" / "w.json").unlink()
    with pytest.raises(ModelDirError, match="missing"):
        read_model_dir(tmp_path / "m")
    (tmp_path / "g").mkdir()
    (tmp_path / "g" / "manifest.json").write_text("{not json")
    with pytest.raises(ModelDirError, match="malformed"):
        read_model_dir(tmp_path / "g")
    with pytest.raises(ModelDirError, match=r"no manifest\.json"):
        read_model_dir(tmp_path / "nothing")


def test_refuses_to_overwrite_a_model(tmp_path) -> None:
    write_model_dir(tmp_path / "m", "demo", {}, {}, {"w": b"1"})
    with pytest.raises(ModelDirError, match="already holds a model"):
        write_model_dir(tmp_path / "m", "demo", {}, {}, {"w": b"2"})


@pytest.fixture(scope="module")
def training_run() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    cmd = np.concatenate([s.generate().values_si for s in training_set()])
    out = Plant(PlantConfig.thesis_rig()).simulate(cmd)
    return cmd, out.angle_rad, out.true_angle_rad


def test_fit_lies_between_the_branches_and_is_monotone(training_run) -> None:
    cmd, angle, _ = training_run
    m = StaticMap.fit(cmd, angle)
    assert np.all(np.diff(m.angle_rad) >= 0.0)
    assert np.all(np.diff(m.pressure_pa) > 0.0)
    # Below the opening pressure (~0.85 bar) the rig does not move, and the curve says so.
    assert np.degrees(m.angle(0.5e5)) < 0.5
    # Quasi-statically the rig bends about 18 deg/bar above the opening pressure.
    assert 15.0 < np.degrees(m.angle(2.0e5)) < 25.0


def test_inverse_of_forward_is_identity_on_the_moving_part(training_run) -> None:
    cmd, angle, _ = training_run
    m = StaticMap.fit(cmd, angle)
    p = np.linspace(1.2e5, 2.5e5, 20)
    np.testing.assert_allclose(m.pressure(m.angle(p)), p, rtol=0.02)


def test_static_map_save_load_and_tamper(tmp_path, training_run) -> None:
    cmd, angle, _ = training_run
    m = StaticMap.fit(cmd, angle)
    m.save(tmp_path / "sm")
    loaded = StaticMap.load(tmp_path / "sm")
    np.testing.assert_array_equal(loaded.angle_rad, m.angle_rad)
    data = json.loads((tmp_path / "sm" / "static_map.json").read_text())
    data["angle_rad"][5] += 0.1
    (tmp_path / "sm" / "static_map.json").write_text(json.dumps(data))
    with pytest.raises(ModelDirError):
        StaticMap.load(tmp_path / "sm")


def test_fit_refuses_bad_data() -> None:
    with pytest.raises(ParameterError, match="NaN"):
        StaticMap.fit([0.0, np.nan, 1.0], [0.0, 0.0, 0.0])
    with pytest.raises(ParameterError, match="both loading and"):
        StaticMap.fit(np.linspace(0, 3e5, 1000), np.linspace(0, 0.5, 1000))
