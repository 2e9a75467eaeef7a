"""The recording is watched: under ``follow_trajectory --sim``, a recorder that is killed or
whose disk fills stops the run ramped down (exit 4), with report.json, the plot and the
unrecorded seconds from when; a disk without room is refused before anything starts.

Each test runs follow_trajectory as a person does, over DDS in a domain of its own, and
injects its fault once the catheter holds about 2 bar. The full disk is a real tmpfs (root
only: skipped otherwise, with the reason), filled by another writer mid-run, as a disk that
something else fills is.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fault_log import FaultRecord
from graph_utils import SLACK_SENSOR_TIMEOUT_S, Children, Probe, Stamped, gauge_pa, statuses
from sensor_msgs.msg import FluidPressure
from tmpfs import mounted_tmpfs

from catheter_models.contract import (
    CONTROL_RATE_HZ,
    DIAGNOSTICS,
    MAX_SLEW_PA_PER_S,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
)
from catheter_ros.qos import RECORD

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

HOLD_20_DEG = [(0.0, 0.0), (2.0, 20.0), (40.0, 20.0)]
"""Up to 20 deg (about 2 bar) and hold: the fault comes while the catheter is bent."""
HOLD_S = 40.0
VENTED_PA = 0.1e5
EXIT_STOPPED = 4
EXIT_REFUSED = 2
RECORDER = "catheter/recorder"
CATHETER_LAB = Path(sys.executable).with_name("catheter-lab")
# These runs are about the recording, not a sensor's silence: the slack keeps a busy machine's
# pauses from stopping them first.
FOLLOW = [
    sys.executable,
    "-m",
    "catheter_control.follow_trajectory",
    "--sim",
    "--no-progress",
    "--sensor-timeout-s",
    str(SLACK_SENSOR_TIMEOUT_S),
]


def _hold_csv(directory: Path) -> Path:
    csv = directory / "hold.csv"
    csv.write_text("t_s,angle_deg\n" + "".join(f"{t},{a}\n" for t, a in HOLD_20_DEG))
    return csv


def _recorder_pid(launcher: subprocess.Popen[Any]) -> int:
    """The pid of the recorder follow_trajectory started."""
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
            cmdline = (stat.parent / "cmdline").read_bytes()
        except (FileNotFoundError, ProcessLookupError, IndexError, ValueError):
            continue
        if ppid == launcher.pid and b"catheter_control.recorder_node" in cmdline:
            return int(stat.parent.name)
    raise AssertionError("follow_trajectory started no recorder")


class Run:
    """follow_trajectory --sim on a hold, watched by a probe, up to about 2 bar."""

    def __init__(self, children: Children, csv: Path, out: Path, *extra: str) -> None:
        self.out = out
        self.probe = Probe(children.domain_id).__enter__()
        self.commands = self.probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        self.measured = self.probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        self.diags = self.probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 50)
        self.launcher = subprocess.Popen(
            [*FOLLOW, "--file", str(csv), "--out", str(out), *extra],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=children.full_env(),
        )

    def pressurised(self, timeout_s: float = 60.0) -> None:
        """Until the catheter holds 1.5 bar (the run has started and recorded for seconds)."""

        def held() -> bool:
            recent = self.measured[-25:]
            return len(recent) == 25 and float(gauge_pa(recent).mean()) > 1.5e5

        self.probe.spin_until(lambda: self.launcher.poll() is not None or held(), timeout_s)
        if self.launcher.poll() is not None:
            out, err = self.launcher.communicate(timeout=30.0)
            raise AssertionError(f"the run ended before 1.5 bar:\n{out[-2000:]}\n{err[-2000:]}")
        assert held(), "the run did not reach 1.5 bar within 60 s"

    def finish(self, timeout_s: float = 90.0) -> tuple[str, str]:
        """Spin until follow_trajectory exits; its stdout and stderr."""
        self.probe.spin_until(lambda: self.launcher.poll() is not None, timeout_s)
        out, err = self.launcher.communicate(timeout=30.0)
        return out, err

    def close(self) -> None:
        if self.launcher.poll() is None:
            self.launcher.send_signal(signal.SIGKILL)
            self.launcher.communicate(timeout=30.0)
        self.probe.__exit__()

    def check_ramped_down(self, fault: FaultRecord, t_fault: float) -> None:
        """After the fault the commands came down to vented as a ramp, never a step or a rise."""
        after = [m for m in self.commands if m.mono_s > t_fault]
        assert after, "no command after the fault"
        pa = gauge_pa(after)
        peak = int(np.argmax(pa))
        ramp = pa[peak:]
        largest_drop_pa = float(-np.diff(ramp).min(initial=0.0))
        fault.check(
            "the compensator ramped down at its slew limit (no step, never up)",
            bool(np.all(np.diff(ramp) <= 1.0))
            and largest_drop_pa <= MAX_SLEW_PA_PER_S / CONTROL_RATE_HZ + 1.0,
            f"largest drop {largest_drop_pa:.0f} Pa a tick, from {pa[peak]:.0f} Pa",
        )
        vented = [m for m in after if gauge_pa([m])[0] <= VENTED_PA]
        fault.check("range", bool(vented), f"commands after the fault end at {pa[-1]:.0f} Pa")
        fault.safe_after(vented[0].mono_s - t_fault)
        fault.check(
            "range",
            float(gauge_pa(self.measured).max()) <= 3.0e5 + 2000.0,
            f"measured max {gauge_pa(self.measured).max():.0f} Pa",
        )

    def report(self) -> dict[str, Any]:
        path = self.out / "report.json"
        assert path.is_file(), f"no report.json in {sorted(p.name for p in self.out.iterdir())}"
        loaded: dict[str, Any] = json.loads(path.read_text())
        return loaded


def _check_unrecorded(
    fault: FaultRecord,
    report: dict[str, Any],
    stderr: str,
    t_fault_into_s: float,
    t_fault_done_into_s: float | None = None,
) -> None:
    """report.json's unrecorded span starts at the bag's last flush, between 1.5 s before
    the fault began (a 0.5 s flush period, and margin) and when it was complete (the disk
    full: a flush while the filler was still writing succeeded), give or take 0.25 s
    between this probe's clock of the run and follow_trajectory's."""
    done_s = t_fault_into_s if t_fault_done_into_s is None else t_fault_done_into_s
    recording = report["recording"]
    fault.check(
        "reported",
        recording["state"] == "failed"
        and recording["unrecorded_s"] > 0.0
        and "went unrecorded, from" in stderr,
        f"report.json recording {recording}; stderr {stderr[-600:]}",
    )
    # What the bag lacks starts at its last flush (0.5 s period), just before the fault.
    from_s = recording["unrecorded_from_run_s"]
    fault.check(
        "bag",
        t_fault_into_s - 1.5 <= from_s <= done_s + 0.25,
        f"unrecorded from {from_s} s into the run; the fault came {t_fault_into_s:.2f} to "
        f"{done_s:.2f} s in",
    )


def _run_start_mono(run: Run) -> float:
    """When the run's first command came (monotonic), as the probe heard it."""
    return run.commands[0].mono_s


@pytest.mark.fault(
    "kill -9 of the recorder under follow_trajectory --sim --out, mid-run",
    safe="the run stops, ramped down; exit 4; report.json and the plot written, with the "
    "seconds unrecorded from when",
)
def test_killed_recorder_stops_the_run_ramped_down(
    children: Children, tmp_path: Path, fault: FaultRecord
) -> None:
    run = Run(children, _hold_csv(tmp_path), tmp_path / "run")
    try:
        run.pressurised()
        recorder = _recorder_pid(run.launcher)
        t_kill = time.monotonic()
        os.kill(recorder, signal.SIGKILL)
        _out, err = run.finish()
        run.check_ramped_down(fault, t_kill)
        t_kill_into_s = t_kill - _run_start_mono(run)
    finally:
        run.close()
    print(err[-1500:])
    fault.check(
        "exit code 4", run.launcher.returncode == EXIT_STOPPED, f"exit {run.launcher.returncode}"
    )
    fault.check(
        "reported",
        "the recording failed" in err and "recorder exited (code -9)" in err,
        err[-800:],
    )
    report = run.report()
    fault.check("report.json says why", "recorder exited" in report["stopped"], report["stopped"])
    assert (run.out / "tracking.png").read_bytes()[:4] == b"\x89PNG"
    _check_unrecorded(fault, report, err, t_kill_into_s)
    # The run stopped at the fault: it did not go on for the rest of the 40 s hold.
    fault.check(
        "the run stopped at the fault",
        report["overall"]["n_samples"] < CONTROL_RATE_HZ * (t_kill_into_s + 3.0),
        f"{report['overall']['n_samples']} set-points scored; the kill came "
        f"{t_kill_into_s:.1f} s in",
    )


def test_continue_without_bag_goes_on_and_says_what_went_unrecorded(
    children: Children, tmp_path: Path
) -> None:
    csv = tmp_path / "short.csv"
    csv.write_text("t_s,angle_deg\n0,0\n2,20\n12,20\n")
    run = Run(children, csv, tmp_path / "run", "--continue-without-bag")
    try:
        run.pressurised()
        t_kill = time.monotonic()
        os.kill(_recorder_pid(run.launcher), signal.SIGKILL)
        _out, err = run.finish()
    finally:
        run.close()
    assert run.launcher.returncode == 0, err[-1500:]
    assert "going on without a bag (--continue-without-bag)" in err
    report = run.report()
    recording = report["recording"]
    assert recording["continued_without_bag"] is True
    assert report["stopped"] == ""
    # From about the kill to the end of the 12 s run and its ramp-down.
    left_s = 12.0 - (t_kill - _run_start_mono(run))
    assert left_s - 1.0 <= recording["unrecorded_s"] <= left_s + 6.0, (recording, left_s)


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 40 MB tmpfs: room for a 40 s recorded run, not for much else (root only)."""
    with mounted_tmpfs(
        tmp_path,
        "40m",
        "the full-disk path is covered in-process by test_recorder_failure.py",
    ) as mount:
        yield mount


def _fill(disk: Path) -> int:
    """Write a file until the disk refuses more; the bytes it took."""
    written = 0
    block = b"\0" * 65536
    with (disk / "filler").open("wb", buffering=0) as filler:
        while True:
            try:
                written += filler.write(block)
            except OSError:
                return written


def _errors(diags: list[Stamped]) -> list[Any]:
    return [s for s in statuses(diags, RECORDER) if s.level == DiagnosticStatus.ERROR]


@pytest.mark.fault(
    "disk full (another writer fills it) under follow_trajectory --sim --out, mid-run",
    safe="the recorder reports ERROR (ENOSPC, file, time) and keeps a repairable bag; the run "
    "stops ramped down, exit 4; report.json and the plot written on the full disk",
)
def test_full_disk_stops_the_recording_and_the_run(
    children: Children, tmp_path: Path, small_disk: Path, fault: FaultRecord
) -> None:
    run = Run(children, _hold_csv(tmp_path), small_disk / "run")
    try:
        run.pressurised()
        t_full = time.monotonic()
        taken = _fill(small_disk)
        t_filled = time.monotonic()
        assert run.probe.spin_until(lambda: bool(_errors(run.diags)), 10.0), (
            "the recorder reported no ERROR within 10 s of a full disk"
        )
        t_error = time.monotonic()
        _out, err = run.finish()
        run.check_ramped_down(fault, t_full)
        t_full_into_s = t_full - _run_start_mono(run)
        t_filled_into_s = t_filled - _run_start_mono(run)
    finally:
        run.close()
    print(f"filled {taken} bytes; ERROR {t_error - t_full:.2f} s later\n{err[-1500:]}")
    error = _errors(run.diags)[0]
    values = {kv.key: kv.value for kv in error.values}
    fault.check(
        "reported",
        "No space left on device" in error.message
        and values.get("errno") == "ENOSPC"
        and values.get("state") == "failed"
        and str(small_disk) in values.get("failed_path", "")
        and values.get("failed_at"),
        f"{error.message} {values}",
    )
    fault.check(
        "exit code 4", run.launcher.returncode == EXIT_STOPPED, f"exit {run.launcher.returncode}"
    )
    report = run.report()
    fault.check(
        "report.json says why", "No space left on device" in report["stopped"], report["stopped"]
    )
    assert (run.out / "tracking.png").read_bytes()[:4] == b"\x89PNG"
    _check_unrecorded(fault, report, err, t_full_into_s, t_filled_into_s)
    fault.check(
        "bag",
        report["recording"]["bag_file"] == "repairable" and "bag repair" in error.message,
        str(report["recording"]),
    )
    # Room again: what the recorder kept is what a repair recovers.
    (small_disk / "filler").unlink()
    repair = subprocess.run(
        [
            str(Path(sys.executable).with_name("catheter-lab")),
            "bag",
            "repair",
            str(run.out / "bag"),
        ],
        capture_output=True,
        text=True,
        timeout=120.0,
        check=False,
    )
    kept = int(values["messages_kept"])
    fault.check(
        "bag",
        repair.returncode == 0 and f"recovered {kept} messages" in repair.stdout,
        f"recorder kept {kept}; repair: {repair.stdout[-500:]} {repair.stderr[-500:]}",
    )


def test_a_disk_without_room_is_refused_before_anything_starts(
    children: Children, tmp_path: Path, small_disk: Path
) -> None:
    _fill(small_disk)
    run_dir = small_disk / "run"
    done = subprocess.run(
        [*FOLLOW, "--file", str(_hold_csv(tmp_path)), "--out", str(run_dir)],
        capture_output=True,
        text=True,
        timeout=120.0,
        env=children.full_env(),
        check=False,
    )
    assert done.returncode == EXIT_REFUSED, done.stderr[-1500:]
    assert "not enough free space for the recording at" in done.stderr
    assert str(run_dir / "bag") in done.stderr and "MB needed" in done.stderr
    assert "starting the simulated rig" not in done.stdout
    assert not run_dir.exists()


@pytest.mark.fault(
    "kill -9 of the recorder during a commission recording",
    safe="excite is stopped and ramps the pressure down; the step fails with the reason and "
    "the seconds unrecorded from when",
)
def test_commission_recording_stops_when_its_recorder_dies(
    children: Children, tmp_path: Path, fault: FaultRecord, monkeypatch: pytest.MonkeyPatch
) -> None:
    from catheter_control.commission_rig import CommissionRig, RigChoice, RigError

    for key, value in children.env.items():
        monkeypatch.setenv(key, value)
    rig = CommissionRig(RigChoice("sim", "", "/catheter", "env"), tmp_path / "logs")
    rig.start()
    probe = Probe(children.domain_id).__enter__()
    commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
    killed: list[float] = []

    def kill_when_pressurised() -> None:
        # Once excite has sent 2 s of commands, the recorder dies (the probe spins here).
        probe.spin_until(lambda: len(commands) > 2 * CONTROL_RATE_HZ, 60.0)
        pids = [
            int(p.parent.name)
            for p in Path("/proc").glob("[0-9]*/cmdline")
            if b"catheter_control.recorder_node" in p.read_bytes()
            and f"{tmp_path}".encode() in p.read_bytes()
        ]
        assert pids, "no recorder to kill"
        killed.append(time.monotonic())
        os.kill(pids[0], signal.SIGKILL)

    import threading

    killer = threading.Thread(target=kill_when_pressurised)
    try:
        killer.start()
        with pytest.raises(RigError) as stopped:
            rig.record(["train_zero_f0.8"], tmp_path / "bags" / "train", {}, show_progress=False)
        killer.join(60.0)
        probe.spin_for(0.5)
    finally:
        rig.stop()
        probe.__exit__()
    said = str(stopped.value)
    print(said)
    fault.check(
        "reported",
        "recorder exited (code -9)" in said and "went unrecorded from" in said,
        said,
    )
    kept = [m for m in commands if m.mono_s > killed[0]]
    after = gauge_pa(kept)
    stamps_s = np.array([m.msg.header.stamp.sec + 1e-9 * m.msg.header.stamp.nanosec for m in kept])
    # The signal goes on (up and down) until excite is stopped; its last descent is the ramp.
    rises = np.flatnonzero(np.diff(after) > 1.0)
    start = int(rises[-1]) + 1 if rises.size else 0
    ramp, ramp_s = after[start:], stamps_s[start:]
    # Judged per second of the commands' own stamps, not per message: a tick the loop
    # skipped on a loaded machine is never sent (its stamp is a gap), and a message the probe
    # missed is a gap too; either leaves a larger step at the same slope (a run beside two
    # busy loops, a benchmark and a second test run saw 8,771 Pa between two messages).
    drop_pa = -np.diff(ramp)
    gap_s = np.maximum(np.diff(ramp_s), 1.0 / CONTROL_RATE_HZ)
    steepest_pa_per_s = float(np.max(drop_pa / gap_s, initial=0.0))
    largest_drop_pa = float(drop_pa.max(initial=0.0))
    fault.check(
        "excite ramped the pressure down (no step to zero)",
        bool(after[-1] <= VENTED_PA) and steepest_pa_per_s <= MAX_SLEW_PA_PER_S + 1.0,
        f"last descent from {ramp[0]:.0f} to {after[-1]:.0f} Pa, at most "
        f"{steepest_pa_per_s / 1e5:.2f} bar/s (largest drop {largest_drop_pa:.0f} Pa "
        "between two messages)",
    )
    # Safe once the ramp's last command (zero) went out: the signal itself passes zero before.
    fault.safe_after(commands[-1].mono_s - killed[0])
