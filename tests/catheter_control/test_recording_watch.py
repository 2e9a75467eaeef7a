"""Watching the recorder, and a run's report on a disk that refuses writes (no ROS).

The watch turns a recorder that exited or reports ERROR into the reason to stop (or not,
with --continue-without-bag) and report.json's unrecorded span; follow_trajectory's report
step writes report.json and the plot into space held from the start, and a write that fails
anyway is said and does not change the exit code.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from tmpfs import mounted_tmpfs

from catheter_control import follow_trajectory
from catheter_control.recording_watch import RecordingWatch
from catheter_control.tracking_report import ReservedFile, RunRecord
from catheter_control.trajectory import TrajectoryLimits, TrajectoryPlan
from catheter_models.bag import write_bag_from_arrays

NS = 1_000_000_000


class FakeGraph:
    """The started graph as the watch sees it: which nodes exited, with which code."""

    def __init__(self) -> None:
        self.dead: dict[str, int] = {}

    def failed(self) -> dict[str, int]:
        return dict(self.dead)


def test_a_killed_recorder_stops_the_run_from_its_bags_last_flush(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start_ns = 1_800_000_000 * NS
    bag = write_bag_from_arrays(
        tmp_path / "bag",
        np.arange(0, 5.0, 0.004),
        np.zeros(1250),
        np.zeros(1250),
        np.zeros(1250),
        start_time_ns=start_ns,
    )
    graph, record = FakeGraph(), RunRecord()
    watch = RecordingWatch(bag, graph, record)  # type: ignore[arg-type]
    assert watch.check() == ""
    graph.dead["recorder"] = -9
    reason = watch.check()
    assert "recorder exited (code -9)" in reason and "bag repair" in reason
    assert "stopping the run" in capsys.readouterr().err
    assert watch.check() == reason  # said once, the same reason after
    assert capsys.readouterr().err == ""
    facts = watch.finish(start_ns + 9 * NS, run_start_ns=start_ns + 1 * NS)
    # The bag holds up to 4.996 s; the run ended at 9 s: 4.004 s unrecorded from 3.996 s in.
    assert facts["state"] == "failed" and facts["bag_file"] == "repairable"
    assert facts["unrecorded_s"] == pytest.approx(4.004, abs=1e-3)
    assert facts["unrecorded_from_run_s"] == pytest.approx(3.996, abs=1e-3)
    assert "4.0 s of the run went unrecorded" in capsys.readouterr().err


def test_an_error_status_stops_unless_the_run_goes_on_without_a_bag(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    record = RunRecord()
    watch = RecordingWatch(tmp_path / "bag", None, record, continue_without_bag=True)
    assert watch.check() == ""
    record.recorder_error = "not recording: No space left on device (ENOSPC) ..."
    record.recorder = {"recorded_until_ns": str(100 * NS), "bag_file": "repairable"}
    assert watch.check() == ""  # goes on, and says so
    assert "going on without a bag (--continue-without-bag)" in capsys.readouterr().err
    facts = watch.finish(103 * NS, run_start_ns=90 * NS)
    assert facts["continued_without_bag"] is True
    assert facts["unrecorded_s"] == pytest.approx(3.0)
    assert facts["unrecorded_from_run_s"] == pytest.approx(10.0)
    stopping = RecordingWatch(tmp_path / "bag", None, record)
    assert "No space left on device" in stopping.check()


def test_a_recording_that_held_says_so(tmp_path: Path) -> None:
    watch = RecordingWatch(tmp_path / "bag", FakeGraph(), RunRecord())  # type: ignore[arg-type]
    assert watch.finish(10 * NS, 1 * NS) == {"bag": str(tmp_path / "bag"), "state": "recorded"}


def _scored_record() -> tuple[RunRecord, follow_trajectory._Trajectory]:
    t_s = np.arange(0.0, 4.0, 0.004)
    angle = np.radians(10.0) * np.sin(t_s)
    record = RunRecord()
    for t, a in zip(t_s, angle, strict=True):
        record.desired.append(100.0 + t, a)
        record.measured.append(100.0 + t + 0.002, a)
    record.stopped = "stopped 4.0 s in: the recording failed: ...; goal cancelled"
    plan = TrajectoryPlan.from_knots(
        np.array([0.0, 2.0, 4.0]), np.radians([0.0, 10.0, 0.0]), TrajectoryLimits(), 250.0, "t"
    )
    return record, follow_trajectory._Trajectory(plan, "t", {}, 0.0)


def test_report_and_plot_that_cannot_be_written_are_said_and_keep_the_exit_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    record, trajectory = _scored_record()
    blocked = tmp_path / "a_file"
    blocked.write_text("")
    run_dir = blocked / "run"  # below a file: nothing can be written there
    code = follow_trajectory._report(record, trajectory, run_dir, None)
    assert code == follow_trajectory.EXIT_STOPPED
    err = capsys.readouterr().err
    assert f"could not write {run_dir / 'report.json'}" in err
    assert '"stopped": "stopped 4.0 s in' in err  # the report went to the terminal instead
    assert f"could not write {run_dir / 'tracking.png'}" in err


@pytest.fixture
def tiny_disk(tmp_path: Path) -> Iterator[Path]:
    """A 2 MB tmpfs (root only: skipped otherwise, with the reason)."""
    with mounted_tmpfs(tmp_path, "2m", "the failing write above covers what is said") as mount:
        yield mount


def test_space_held_at_the_start_takes_the_report_and_plot_on_a_full_disk(
    tiny_disk: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    record, trajectory = _scored_record()
    run_dir = tiny_disk / "run"
    files = {
        "report": ReservedFile(run_dir / "report.json", 64_000),
        "plot": ReservedFile(run_dir / "tracking.png", 1_000_000),
    }
    placeholder = json.loads((run_dir / "report.json").read_text())
    assert "no report was written" in placeholder["outcome"]
    # Another writer fills the disk.
    with (tiny_disk / "filler").open("wb", buffering=0) as filler, pytest.raises(OSError):
        while True:
            filler.write(b"\0" * 65536)
    code = follow_trajectory._report(record, trajectory, run_dir, None, files)
    assert code == follow_trajectory.EXIT_STOPPED
    assert "could not write" not in capsys.readouterr().err
    report = json.loads((run_dir / "report.json").read_text())
    assert report["stopped"].startswith("stopped 4.0 s in") and report["overall"]["n_samples"]
    assert (run_dir / "tracking.png").read_bytes()[:4] == b"\x89PNG"


def test_a_disk_without_room_is_refused_with_the_figures(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import shutil

    _record, trajectory = _scored_record()
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda _p: usage._replace(free=1_000_000))
    args = argparse.Namespace(control_rate_hz=250.0)
    with pytest.raises(follow_trajectory.CatheterError, match=r"1\.0 MB free"):
        follow_trajectory._check_room(args, trajectory, tmp_path / "run" / "bag")
