"""catheter-lab diagnose / add: what a person gets, and one-line refusals."""

import sys
from pathlib import Path

import numpy as np
import pytest

from catheter_models.cli import main

REPO = Path(__file__).resolve().parents[3]
BAG = REPO / "bags" / "model_test_descending_sine"
CLSTM = REPO / "src" / "catheter_control" / "catheter_control" / "data" / "clstm"


def run(argv: list[str]) -> int:
    try:
        main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


def test_a_learned_model_gets_the_residual_tests(tmp_path: Path, capsys) -> None:
    code = run(
        ["diagnose", str(CLSTM), "--train", str(BAG), "--test", str(BAG), "-o", str(tmp_path)]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "residual tests beyond their 95 % band" in out
    assert "has no physical blocks to add: floors and residual tests only" in out
    assert (tmp_path / "residual_tests.png").is_file() and (tmp_path / "diagnosis.json").is_file()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["add", "friction", str(CLSTM), "-o", "NEW", "--train", str(BAG)], "clstm model"),
        (["add", "creep", str(BAG), "-o", "NEW", "--train", str(BAG)], "not a model directory"),
        (
            ["diagnose", str(CLSTM), "--train", str(BAG), "--test", str(REPO / "bags")],
            "catheter-lab diagnose:",
        ),
    ],
)
def test_refusals_are_one_line(argv: list[str], message: str, tmp_path: Path, capsys) -> None:
    argv = [str(tmp_path / a) if a == "NEW" else a for a in argv]
    assert run(argv) == 2
    # Warnings about the inputs read before the refusal (gaps in a bag) are lines of their
    # own, marked as such; the refusal itself is one line.
    err = capsys.readouterr().err.strip().splitlines()
    refusals = [line for line in err if not line.startswith(f"catheter-lab {argv[0]}: warning:")]
    assert len(refusals) == 1 and message in refusals[0], err


@pytest.mark.parametrize("command", ["diagnose", "explain"])
def test_a_worker_count_below_one_is_refused_by_name(command: str, capsys) -> None:
    argv = [command, str(CLSTM), "--train", str(BAG), "--test", str(BAG), "--workers", "0"]
    assert run([*argv, "-o", "unused"] if command == "explain" else argv) == 2
    err = capsys.readouterr().err
    assert "argument --workers: --workers must be a whole number >= 1, not '0'" in err


@pytest.mark.parametrize("command", ["diagnose", "explain"])
def test_ray_without_ray_installed_is_refused_naming_the_extra(
    command: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys
) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # what `import ray` meets where it is absent
    argv = [command, str(CLSTM), "--train", str(BAG), "--test", str(BAG), "--ray", "auto"]
    assert run([*argv, "-o", str(tmp_path / "out")] if command == "explain" else argv) == 2
    err = capsys.readouterr().err
    assert "--ray auto: Ray is not installed" in err
    assert "pip install 'catheter_models[ray]'" in err


def _write_with_rosbags(path: Path, rate_hz: float = 250.0) -> None:
    """A bag in the contract written by rosbags' own writer, not ours (as another lab's
    recorder would): absolute pressures, a JointState angle, stamps in the headers."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from catheter_models.models.data import simulate_recording

    rec = simulate_recording("train_zero_f0.4")
    ts = get_typestore(Stores.ROS2_KILTED)
    Time, Header = ts.types["builtin_interfaces/msg/Time"], ts.types["std_msgs/msg/Header"]
    FluidPressure = ts.types["sensor_msgs/msg/FluidPressure"]
    JointState = ts.types["sensor_msgs/msg/JointState"]
    t0_ns = 1_700_000_000_000_000_000
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {
            topic: writer.add_connection(f"/catheter/{topic}", msgtype, typestore=ts)
            for topic, msgtype in (
                ("pressure/command", "sensor_msgs/msg/FluidPressure"),
                ("pressure/measured", "sensor_msgs/msg/FluidPressure"),
                ("tip/angle", "sensor_msgs/msg/JointState"),
            )
        }
        for k, (p_pa, a_rad) in enumerate(zip(rec.pressure_pa, rec.angle_rad, strict=True)):
            ns = t0_ns + round(k * 1e9 / rate_hz)
            header = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="")
            for topic in ("pressure/command", "pressure/measured"):
                msg = FluidPressure(header=header, fluid_pressure=101325.0 + p_pa, variance=0.0)
                writer.write(conns[topic], ns, ts.serialize_cdr(msg, FluidPressure.__msgtype__))
            joint = JointState(
                header=header,
                name=["bend"],
                position=np.array([a_rad]),
                velocity=np.array([], dtype=float),
                effort=np.array([], dtype=float),
            )
            writer.write(conns["tip/angle"], ns, ts.serialize_cdr(joint, JointState.__msgtype__))


def test_a_bag_written_with_rosbags_goes_through_the_lab(tmp_path: Path, capsys) -> None:
    bag = tmp_path / "foreign"
    _write_with_rosbags(bag)
    model = tmp_path / "drdpi"
    budget = '{"max_generations": 8, "wall_time_s": 8}'
    assert (
        run(["train", "drdpi", "--train", str(bag), "-o", str(model), "--set", f"budget={budget}"])
        == 0
    )
    assert run(["compare", str(model), str(bag), "-o", str(tmp_path / "cmp")]) == 0
    out = capsys.readouterr().out
    assert "RMSE" in out and (tmp_path / "cmp" / "index.html").is_file()
    # A 13 s recording: drift cannot be identified, and the lab says so instead of guessing.
    assert (
        run(["diagnose", str(model), "--train", str(bag), "--test", str(bag), "--effect", "drift"])
        == 0
    )
    out = capsys.readouterr().out
    assert "drift: not testable here: the longest recording lasts 13 s" in out


def test_the_lab_signal_sets_simulate_into_bags(tmp_path: Path, capsys) -> None:
    from catheter_models.lab.signals import lab_spec, lab_test_specs, lab_training_specs
    from catheter_models.models.data import recording_from_bag

    names = [s.name for s in (*lab_training_specs(), *lab_test_specs())]
    assert "lab_steps_102" in names and "lab_plateaus_999" in names
    assert len(set(names)) == len(names)  # held-out signals are not training ones
    fast, slow = lab_spec("lab_steps_7"), lab_spec("lab_plateaus_7")
    assert fast is not None and slow is not None and lab_spec("lab_nonsense") is None
    assert fast.generate(250.0).values_si.tolist() != slow.generate(250.0).values_si.tolist()
    assert run(["simulate", "lab_steps_102", "-o", str(tmp_path / "bag")]) == 0
    rec = recording_from_bag(tmp_path / "bag")
    assert rec.duration_s > 30.0
    # Fast ramps: the pressure moves faster than 10 bar/s somewhere.
    assert np.max(np.abs(np.diff(rec.pressure_pa))) * 250.0 > 10.0e5
