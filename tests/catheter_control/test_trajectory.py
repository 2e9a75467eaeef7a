"""Trajectory validation: refused with a message that names the point and the limit."""

import math
from pathlib import Path

import numpy as np
import pytest

from catheter_control.trajectory import (
    TrajectoryLimits,
    TrajectoryPlan,
    hermite,
    lead_in_knots,
    load_trajectory_file,
    preset_knots,
    preset_trajectory,
    with_lead_in,
)
from catheter_models.contract import MAX_TRAJECTORY_FILE_BYTES
from catheter_models.errors import SignalError
from catheter_models.signals import TEST_TRAJECTORIES, get_preset

LIM = TrajectoryLimits()


def plan(t: list[float], a_deg: list[float]) -> TrajectoryPlan:
    return TrajectoryPlan.from_knots(t, np.radians(a_deg), LIM, 250.0)


@pytest.mark.parametrize("name", TEST_TRAJECTORIES)
def test_every_thesis_trajectory_is_accepted(name: str) -> None:
    t, a = preset_knots(name)
    p = TrajectoryPlan.from_knots(t, a, LIM, 250.0, name)
    assert p.duration_s > 10.0


def test_interpolates_and_holds_at_the_ends() -> None:
    p = plan([0.0, 1.0, 2.0], [0.0, 10.0, 10.0])
    assert p.desired_at(0.5) == pytest.approx(math.radians(5.0))
    assert p.desired_at(5.0) == pytest.approx(math.radians(10.0))


def test_first_point_after_zero_starts_from_rest() -> None:
    p = plan([1.0], [5.0])
    assert p.desired_at(0.0) == 0.0
    assert p.desired_at(1.0) == pytest.approx(math.radians(5.0))


@pytest.mark.parametrize(
    ("t", "a_deg", "words"),
    [
        ([0.0, 1.0, 2.0], [0.0, math.nan, 0.0], "point 1"),
        ([0.0, 1.0, 2.0], [0.0, 50.0, 0.0], "outside the allowed"),
        ([0.0, 1.0, 1.0], [0.0, 5.0, 5.0], "increase strictly"),
        ([0.0, 0.05, 2.0], [0.0, 30.0, 30.0], "rate"),
        ([0.0], [5.0], "single point"),
        ([0.0, 1.0, 2.0], [0.0, -5.0, 0.0], "outside the allowed"),
    ],
)
def test_impossible_trajectories_are_refused_by_name(
    t: list[float], a_deg: list[float], words: str
) -> None:
    with pytest.raises(SignalError, match=words):
        plan(t, a_deg)


def test_reads_csv_and_yaml(tmp_path) -> None:
    csv = tmp_path / "p.csv"
    csv.write_text("t_s,angle_deg\n0,0\n1,10\n2,0\n")
    t, a = load_trajectory_file(csv)
    assert t.tolist() == [0, 1, 2] and np.degrees(a).tolist() == pytest.approx([0, 10, 0])
    yml = tmp_path / "p.yaml"
    yml.write_text("- {t_s: 0, angle_deg: 0}\n- {t_s: 2, angle_deg: 4}\n")
    t, a = load_trajectory_file(yml)
    assert np.degrees(a[-1]) == pytest.approx(4.0)


def test_bad_files_name_the_problem(tmp_path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("t_s,angle_deg\n0,0\n1,abc\n")
    with pytest.raises(SignalError, match=r"bad.csv:3: column 'angle_deg' holds 'abc'"):
        load_trajectory_file(bad)
    nocol = tmp_path / "nocol.csv"
    nocol.write_text("time,angle\n0,0\n")
    with pytest.raises(SignalError, match="no 't_s'"):
        load_trajectory_file(nocol)
    with pytest.raises(SignalError, match="does not exist"):
        load_trajectory_file(tmp_path / "missing.csv")


def test_a_trajectory_that_starts_bent_gets_a_lead_in_from_rest() -> None:
    t, a = preset_knots("traj_down_chirp")  # begins at 8 deg
    t2, a2, lead_s = with_lead_in(t, a, approach_s=1.0, settle_s=1.0)
    assert lead_s == pytest.approx(2.0)
    assert a2[0] == 0.0 and t2[0] == 0.0
    np.testing.assert_array_equal(a2[t2 >= lead_s], a)
    np.testing.assert_allclose(t2[t2 >= lead_s], t + lead_s)
    hold = (t2 >= 1.0) & (t2 < lead_s)
    np.testing.assert_allclose(a2[hold], a[0])
    assert np.all(np.diff(a2[t2 <= 1.0]) >= 0.0)  # a monotone move up to the start angle
    # The plan with its lead-in passes the node's limits, and the step is gone.
    plan = TrajectoryPlan.from_knots(t2, a2, TrajectoryLimits(), 250.0)
    assert plan.desired_at(0.0) == 0.0
    assert abs(plan.desired_at(0.004)) < np.radians(0.05)


def test_a_trajectory_that_starts_at_rest_is_left_alone() -> None:
    t, a = preset_knots("traj_up_chirp")
    t2, a2, lead_s = with_lead_in(t, a)
    assert lead_s == 0.0 and t2 is t and a2 is a


def test_more_points_than_the_limit_are_refused_naming_it() -> None:
    n = LIM.max_points + 1
    with pytest.raises(SignalError, match=rf"{n} points, over the limit of {LIM.max_points}"):
        TrajectoryPlan.from_knots(np.arange(1, n + 1) * 0.01, np.zeros(n), LIM, 250.0)


def test_a_trajectory_at_the_point_limit_is_accepted() -> None:
    n = LIM.max_points  # knots at 50 Hz, the thesis's rate
    p = TrajectoryPlan.from_knots(np.arange(1, n + 1) / 50.0, np.zeros(n), LIM, 250.0)
    assert p.duration_s == pytest.approx(n / 50.0)


def test_a_point_past_the_duration_limit_is_refused_naming_it() -> None:
    with pytest.raises(SignalError, match=r"point 1 .*over the limit of 600 s.*DURATION"):
        plan([1.0, LIM.max_duration_s + 1.0], [5.0, 5.0])


def test_a_file_over_the_byte_limit_is_refused_unread(tmp_path: Path) -> None:
    path = tmp_path / "huge.csv"
    path.write_text("t_s,angle_deg\n" + "not,even,parsed\n" * 40)
    with pytest.raises(SignalError, match=r"over the limit of 100 .*FILE_BYTES.*not read"):
        load_trajectory_file(path, max_bytes=100)


def test_a_csv_with_more_rows_than_the_limit_is_refused_at_the_first_row_over(
    tmp_path: Path,
) -> None:
    path = tmp_path / "long.csv"
    # The row after the limit is garbage: refused for its count, before it is parsed.
    path.write_text("t_s,angle_deg\n1,0\n2,0\n3,0\nthree,x\n")
    with pytest.raises(SignalError, match=r"long.csv:5: more than 3 rows.*MAX_TRAJECTORY_POINTS"):
        load_trajectory_file(path, max_points=3)
    path.write_text("t_s,angle_deg\n1,0\n2,0\n3,0\n")
    t_s, _ = load_trajectory_file(path, max_points=3)
    assert list(t_s) == [1.0, 2.0, 3.0]


def test_a_yaml_file_with_more_points_than_the_limit_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "long.yaml"
    path.write_text("t_s: [1, 2, 3, 4]\nangle_deg: [0, 0, 0, 0]\n")
    with pytest.raises(SignalError, match=r"4 points, over the limit of 3"):
        load_trajectory_file(path, max_points=3)


def test_the_contract_s_file_limit_refuses_a_huge_file_by_its_size(tmp_path: Path) -> None:
    path = tmp_path / "huge.csv"
    with path.open("wb") as fh:  # sparse: as big as the limit says, without writing it
        fh.write(b"t_s,angle_deg\n")
        fh.truncate(MAX_TRAJECTORY_FILE_BYTES + 1)
    with pytest.raises(SignalError, match=rf"{MAX_TRAJECTORY_FILE_BYTES + 1} bytes"):
        load_trajectory_file(path)


def test_follow_trajectory_refuses_a_huge_file_before_anything_starts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from catheter_control.follow_trajectory import EXIT_REFUSED, main

    path = tmp_path / "huge.csv"
    with path.open("wb") as fh:  # sparse, as the 10^7-row CSV that once took 66 s to parse
        fh.write(b"t_s,angle_deg\n")
        fh.truncate(MAX_TRAJECTORY_FILE_BYTES + 1)
    assert main(["--file", str(path), "--out", str(tmp_path / "run")]) == EXIT_REFUSED
    err = capsys.readouterr().err
    assert "trajectory refused" in err and "MAX_TRAJECTORY_FILE_BYTES" in err, err
    assert not (tmp_path / "run").exists()


def test_hermite_segments_reproduce_the_polynomials_of_their_order() -> None:
    t = np.array([0.0, 0.4, 1.0, 1.7])
    at = np.linspace(0.0, 1.7, 171)
    cubic = lambda x: 0.3 - 0.2 * x + 0.5 * x**2 - 0.1 * x**3  # noqa: E731
    d_cubic = lambda x: -0.2 + x - 0.3 * x**2  # noqa: E731
    np.testing.assert_allclose(hermite(t, cubic(t), d_cubic(t), None, at), cubic(at), atol=1e-12)
    quintic = lambda x: 0.1 + 0.2 * x - 0.3 * x**3 + 0.05 * x**5  # noqa: E731
    d1 = lambda x: 0.2 - 0.9 * x**2 + 0.25 * x**4  # noqa: E731
    d2 = lambda x: -1.8 * x + 1.0 * x**3  # noqa: E731
    np.testing.assert_allclose(hermite(t, quintic(t), d1(t), d2(t), at), quintic(at), atol=1e-12)
    # Positions alone: straight lines, as before.
    np.testing.assert_allclose(hermite(t, quintic(t), None, None, at), np.interp(at, t, quintic(t)))


@pytest.mark.parametrize("name", TEST_TRAJECTORIES)
def test_a_preset_s_plan_is_the_preset_with_no_kink_at_its_knots(name: str) -> None:
    """Knotted at 50 Hz with their rates and accelerations, the thesis trajectories come out
    of the plan as the presets themselves; as a polyline their acceleration was an impulse at
    every knot, which rang a ringing tip through the grey box's inverse (issue 30)."""
    knots = lead_in_knots(preset_trajectory(name))
    smooth = knots.plan(LIM, 250.0, name)
    desired = np.asarray(get_preset(name).generate(250.0).values_si)[:-1]
    at = knots.lead_s + np.arange(desired.size) / 250.0
    got = np.array([smooth.desired_at(x) for x in at])
    # Inside: the trajectory's own joints (the lead-in's hold to its start, its end held)
    # are where its acceleration really jumps.
    inside = slice(10, -10)
    assert np.max(np.abs(np.degrees(got - desired))[inside]) < 0.005
    assert np.min(got) >= 0.0  # curved segments do not swing below a knot at rest
    accel = (np.diff(got, 2) * 250.0**2)[inside]
    accel_true = (np.diff(desired, 2) * 250.0**2)[inside]
    # Compared sample by sample: all but the few samples at the preset's own corners (the
    # small-variations trajectory has some) within 1 % of its largest acceleration; as a
    # polyline, one sample in ten is off by a third of it or more.
    scale = np.max(np.abs(accel_true))
    assert np.percentile(np.abs(accel - accel_true), 99) < 0.01 * scale
    polyline = TrajectoryPlan.from_knots(knots.t_s, knots.angle_rad, LIM, 250.0, name)
    kinked = (np.diff([polyline.desired_at(x) for x in at], 2) * 250.0**2)[inside]
    assert np.percentile(np.abs(kinked - accel_true), 90) > 0.3 * scale


def test_rates_and_accelerations_must_come_whole() -> None:
    t, a = [0.0, 1.0, 2.0], np.radians([0.0, 5.0, 5.0])
    with pytest.raises(SignalError, match="accelerations without velocities"):
        TrajectoryPlan.from_knots(t, a, LIM, 250.0, accel_rad_s2=[0.0, 0.0, 0.0])
    with pytest.raises(SignalError, match="2 velocities for 3 points"):
        TrajectoryPlan.from_knots(t, a, LIM, 250.0, velocity_rad_s=[0.0, 0.0])
    with pytest.raises(SignalError, match="point 1: velocity is nan"):
        TrajectoryPlan.from_knots(t, a, LIM, 250.0, velocity_rad_s=[0.0, math.nan, 0.0])


def test_the_goal_sent_carries_the_knots_rates_and_accelerations() -> None:
    from catheter_control.trajectory_client import _goal

    plan = lead_in_knots(preset_trajectory("traj_down_chirp")).plan(LIM, 250.0, "down")
    points = _goal(plan).trajectory.points
    assert len(points) == plan.t_s.size
    assert [p.velocities[0] for p in points] == pytest.approx(plan.velocity_rad_s)
    assert [p.accelerations[0] for p in points] == pytest.approx(plan.accel_rad_s2)
