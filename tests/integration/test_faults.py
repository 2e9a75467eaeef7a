"""Fault injection over the simulated graph, each node its own process over DDS.

Each test injects one fault into a running graph (recorder, sim_hardware, compensator) and
checks the invariants a person trusting the controller relies on (fault_log.INVARIANTS): the
pressure never leaves its range; after command loss the valve vents within the watchdog
time; every refusal and fault is reported; no bag data from before the fault is lost. Each
test is one row of the fault table in docs/reliability.md (``make faults``). Faults of the
real drivers against the emulated devices (an unplugged valve, a silent transmitter, a
killed valve_driver) are in test_hardware_graph.py under the same marker; the recorder
killed mid-run in test_recorder_kill.py; a stalled laser in test_compensator.py.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fault_log import FaultRecord
from graph_utils import (
    COMPENSATOR,
    MAX_PRESSURE_PA,
    NOISE_MARGIN_PA,
    SIM,
    SLACK_SENSOR_TIMEOUT_S,
    Children,
    Probe,
    Stamped,
    diagnostic_values,
    gauge_pa,
    node_argv,
    statuses,
    trajectory_msg,
    wait_for_recorder,
)
from sensor_msgs.msg import FluidPressure
from trajectory_msgs.msg import JointTrajectory

from catheter_control.bringup import ProcessGraph, sim_graph_specs
from catheter_models.bag import load_bag
from catheter_models.contract import (
    DIAGNOSTICS,
    PRESSURE_COMMAND,
    PRESSURE_MEASURED,
    TIP_ANGLE,
    TRAJECTORY,
    qualify,
)
from catheter_ros import messages, qos
from catheter_ros.qos import RECORD, STREAM

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

VENTED_PA = 0.1e5
WATCHDOG_S = 0.1
"""sim_hardware's command_timeout_s (its default): how soon the rig vents without commands."""
SENSOR_TIMEOUT_S = SLACK_SENSOR_TIMEOUT_S
"""The compensator's stale limit here. Its 0.1 s default stopped the bend before the fault on a
busy machine (the rig's process went quiet for over 100 ms; docs/reliability.md); what these
tests judge is what follows the fault, so the rig's stop is judged against this limit."""
SLEW_PA_PER_S = 2.0e6
SAMPLE_S = 1.0 / 250.0
HOLD_20_DEG = [(0.0, 0.0), (2.0, 20.0), (40.0, 20.0)]
"""Up to 20 deg (about 2 bar) and hold: the fault comes while the catheter is bent."""
SHIPPED_CLSTM = (
    Path(__file__).resolve().parents[2] / "src/catheter_control/catheter_control/data/clstm"
)
CATHETER_LAB = Path(sys.executable).with_name("catheter-lab")
SAMPLE_BAG = Path(__file__).resolve().parents[2] / "bags/model_test_up_chirp"


def _check_range(fault: FaultRecord, commands: list[Stamped], measured: list[Stamped]) -> None:
    cmd, meas = gauge_pa(commands), gauge_pa(measured)
    ok = (cmd.size == 0 or (cmd.min() >= -1e-6 and cmd.max() <= MAX_PRESSURE_PA + 1e-6)) and (
        meas.size == 0 or meas.max() <= MAX_PRESSURE_PA + NOISE_MARGIN_PA
    )
    fault.check(
        "range",
        ok,
        f"commands [{cmd.min(initial=0):.0f}, {cmd.max(initial=0):.0f}] Pa, "
        f"measured max {meas.max(initial=0):.0f} Pa, range [0, {MAX_PRESSURE_PA:.0f}] Pa",
    )


def _first_time(stamped: list[Stamped], after_s: float, test: Callable[[float], bool]) -> float:
    """Monotonic time of the first message after ``after_s`` from which on ``test`` holds."""
    after = [m for m in stamped if m.mono_s > after_s]
    values = gauge_pa(after)
    for i in range(len(after)):
        if all(test(v) for v in values[i:]):
            return after[i].mono_s
    return float("nan")


@dataclass(frozen=True)
class Kill:
    """A node killed mid-run: when the run began (wall) and when the kill came."""

    start_wall_s: float
    n_diag: int
    mono_s: float
    wall_s: float


class SimGraph:
    """recorder + sim_hardware + compensator as separate processes, and a probe on them."""

    def __init__(self, children: Children, tmp_path: Path, **compensator: object) -> None:
        self.bag = tmp_path / "bag"
        specs = sim_graph_specs(
            self.bag,
            {"source": "test_faults"},
            compensator_params={
                "require_tip_angle": True,
                "sensor_timeout_s": SENSOR_TIMEOUT_S,
                **compensator,
            },
        )
        self.graph: ProcessGraph = children.graph(specs)
        self.children = children
        self.probe = Probe(children.domain_id).__enter__()
        self.commands = self.probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        self.measured = self.probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        self.diags = self.probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        self.pub = self.probe.node.create_publisher(
            JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY
        )

    def close(self) -> None:
        self.probe.__exit__(None, None, None)

    def wait_ready(self) -> None:
        ready = self.probe.spin_until(
            lambda: bool(statuses(self.diags, COMPENSATOR)) and bool(statuses(self.diags, SIM)),
            40.0,
        )
        assert ready, f"graph not up:\n{self.children.all_logs()}"
        wait_for_recorder(
            self.probe, [qualify(PRESSURE_MEASURED), qualify(TIP_ANGLE)], timeout_s=30.0
        )
        # The probe's own stream too: "nothing moved" is judged on what it received, and once
        # it had received nothing yet when the refusals were over (an empty array, no verdict).
        assert self.probe.spin_until(lambda: len(self.measured) > 0, 30.0), (
            f"the probe received no {PRESSURE_MEASURED.name}:\n{self.children.all_logs()}"
        )

    def bend_and_hold(self) -> None:
        """Send the 20 deg hold; return once the line holds about 2 bar."""
        self.pub.publish(trajectory_msg(HOLD_20_DEG))
        assert self.probe.spin_until(lambda: len(self.commands) > 250, 15.0), (
            self.children.all_logs()
        )
        self.probe.spin_for(2.5)
        assert gauge_pa(self.measured[-25:]).mean() > 1.5e5, "not bent to 20 deg before the fault"

    def kill_bent(self, node: str) -> Kill:
        """Bend to 20 deg, then kill -9 ``node``; when, on both clocks."""
        start_wall_s = time.time()
        self.bend_and_hold()
        kill = Kill(start_wall_s, len(self.diags), time.monotonic(), time.time())
        self.graph.procs[node].send_signal(signal.SIGKILL)
        return kill

    def finish(self, fault: FaultRecord, kill: Kill) -> None:
        """The range held over the run; the graph stopped; the bag kept up to the kill."""
        _check_range(fault, self.commands, self.measured)
        self.children.close()  # the recorder closes the bag
        _check_bag_kept(fault, self.bag, kill.wall_s, kill.start_wall_s)

    def status_after(
        self, node: str, n_diag: int, test: Callable[[DiagnosticStatus], bool], timeout_s: float
    ) -> DiagnosticStatus | None:
        def found() -> DiagnosticStatus | None:
            return next((s for s in statuses(self.diags[n_diag:], node) if test(s)), None)

        self.probe.spin_until(lambda: found() is not None, timeout_s)
        return found()


@pytest.fixture
def sim(children: Children, tmp_path: Path) -> Any:
    graph = SimGraph(children, tmp_path)
    try:
        graph.wait_ready()
        yield graph
    finally:
        graph.close()


def _check_bag_kept(
    fault: FaultRecord, bag: Path, t_fault_wall_s: float, t_start_wall_s: float
) -> None:
    """The bag holds pressure/measured and tip/angle, gap-free, from before the run to the fault."""
    data = load_bag(bag)
    problems = []
    for series in (data.pressure_measured, data.tip_angle):
        t_wall = np.asarray(series.t_s) + data.start_time_ns * 1e-9
        before = t_wall[t_wall <= t_fault_wall_s]
        if before.size == 0 or before[0] > t_start_wall_s:
            problems.append(f"{series.name}: nothing from before the run")
            continue
        gaps = np.diff(before)
        if gaps.max(initial=0.0) > 3 * SAMPLE_S:
            problems.append(f"{series.name}: a {gaps.max() * 1e3:.0f} ms gap before the fault")
        # The last sample before the fault is at most 50 ms before it (callbacks in flight).
        if t_fault_wall_s - before[-1] > 0.05:
            problems.append(
                f"{series.name}: ends {(t_fault_wall_s - before[-1]) * 1e3:.0f} ms before the fault"
            )
    fault.check("bag", not problems, "; ".join(problems))


@pytest.mark.fault(
    "kill -9 compensator mid-trajectory",
    safe="line vented: sim_hardware's watchdog (commands stop)",
)
def test_killed_compensator(sim: SimGraph, fault: FaultRecord) -> None:
    kill = sim.kill_bent("compensator")
    t_kill = kill.mono_s
    status = sim.status_after(
        SIM, kill.n_diag, lambda s: diagnostic_values(s)["venting"] == "True", 3.0
    )
    fault.check(
        "reported",
        status is not None and status.message == "watchdog: no pressure command, valve vented",
        f"sim_hardware said {None if status is None else status.message!r}",
    )
    sim.probe.spin_for(1.0)
    vented_s = _first_time(sim.measured, t_kill, lambda v: v < VENTED_PA)
    fault.safe_after(vented_s - t_kill)
    # The watchdog (100 ms) vents; then the line empties below 0.1 bar (~0.2 s from 2 bar).
    fault.check("vent", vented_s - t_kill <= WATCHDOG_S + 0.4, f"{vented_s - t_kill:.3f} s")
    sim.finish(fault, kill)


@pytest.mark.fault(
    "kill -9 sim_hardware (the rig: driver and sensors) mid-trajectory",
    safe="compensator stopped on pressure/measured stale (limit 0.5 s here), command ramped to 0",
)
def test_killed_rig(sim: SimGraph, fault: FaultRecord) -> None:
    kill = sim.kill_bent("sim_hardware")
    t_kill = kill.mono_s
    status = sim.status_after(
        COMPENSATOR, kill.n_diag, lambda s: s.level == DiagnosticStatus.ERROR, 3.0
    )
    message = "" if status is None else status.message
    fault.check(
        "reported",
        "stale" in message and "ramped down" in message,
        f"compensator said {message!r}",
    )
    sim.probe.spin_for(0.5)
    zero_s = _first_time(sim.commands, t_kill, lambda v: v == 0.0)
    fault.safe_after(zero_s - t_kill)
    # Stale after the limit (the first of the two sensor streams to be missed), then down from
    # 2 bar at the slew limit (20 bar/s: 0.1 s).
    bound_s = SENSOR_TIMEOUT_S + 2.0e5 / SLEW_PA_PER_S + 0.1
    fault.check(
        "command ramped to 0 after the sensors went quiet",
        zero_s - t_kill <= bound_s,
        f"{zero_s - t_kill:.3f} s (bound {bound_s:.2f} s)",
    )
    ramp = gauge_pa([m for m in sim.commands if m.mono_s > t_kill])
    fault.check(
        "ramp at the slew limit, never up",
        bool(np.all(np.diff(ramp) <= 1.0))
        and bool(np.all(-np.diff(ramp) <= SLEW_PA_PER_S * SAMPLE_S + 1.0)),
        f"largest step {np.diff(ramp).min(initial=0):.0f} Pa",
    )
    sim.finish(fault, kill)


@pytest.mark.fault(
    "kill -9 of follow_trajectory, the launcher of the graph, mid-run",
    safe="every node it started shuts down cleanly; the bag is closed",
)
def test_killed_launcher_takes_its_graph_down_cleanly(
    children: Children, tmp_path: Path, fault: FaultRecord
) -> None:
    csv = tmp_path / "hold.csv"
    csv.write_text("t_s,angle_deg\n" + "".join(f"{t},{a}\n" for t, a in HOLD_20_DEG))
    out = tmp_path / "run"
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)

        def start(run_dir: Path) -> subprocess.Popen[Any]:
            argv = [sys.executable, "-m", "catheter_control.follow_trajectory", "--sim"]
            return children.start(
                run_dir.name,
                [*argv, "--file", str(csv), "--out", str(run_dir), "--no-progress"],
            )

        # Both subscriptions must have matched: under load the probe's command subscription
        # once matched after its measured one, and the run was judged with no command seen.
        launcher, out = _pressurised_run(
            probe,
            start,
            out,
            lambda: (
                bool(commands) and len(measured) > 25 and gauge_pa(measured[-25:]).mean() > 1.5e5
            ),
            [commands, measured],
        )
        # The bag must hold everything from the first command the probe saw on.
        t_start_wall = time.time() - (time.monotonic() - commands[0].mono_s)
        nodes = _children_of(launcher.pid)
        assert {"sim_hardware_node", "compensator_node", "recorder_node"} <= set(nodes.values())
        t_kill, t_kill_wall = time.monotonic(), time.time()
        launcher.send_signal(signal.SIGKILL)
        gone = probe.spin_until(lambda: not any(_alive(pid) for pid in nodes), 10.0)
        t_gone = time.monotonic()
        _check_range(fault, commands, measured)
    left = {pid: name for pid, name in nodes.items() if _alive(pid)}
    for pid in left:
        os.kill(pid, signal.SIGKILL)  # do not leak them into the next test
    fault.check("no node left running orphaned", gone and not left, f"still running: {left}")
    fault.safe_after(t_gone - t_kill)
    logs = {p.stem: p.read_text(errors="replace") for p in (out / "logs").glob("*.log")}
    silent = [name for name, text in logs.items() if "is gone: shutting down" not in text]
    fault.check(
        "reported",
        len(logs) >= 3 and not silent,
        f"nodes that did not log that their launcher is gone: {silent} (logs: {sorted(logs)})",
    )
    _check_bag_kept(fault, out / "bag", t_kill_wall, t_start_wall)


@pytest.mark.fault(
    "kill -9 sim_hardware under follow_trajectory --sim",
    safe="the run stops, ramped down; follow_trajectory says why and exits 4",
)
def test_a_run_stopped_part_way_is_not_reported_as_a_success(
    children: Children, tmp_path: Path, fault: FaultRecord
) -> None:
    csv = tmp_path / "hold.csv"
    csv.write_text("t_s,angle_deg\n" + "".join(f"{t},{a}\n" for t, a in HOLD_20_DEG))
    out = tmp_path / "run"
    argv = [sys.executable, "-m", "catheter_control.follow_trajectory", "--sim"]
    launcher: subprocess.Popen[Any] | None = None

    def start(run_dir: Path) -> subprocess.Popen[Any]:
        nonlocal launcher
        launcher = subprocess.Popen(
            [*argv, "--file", str(csv), "--out", str(run_dir), "--no-progress"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=children.full_env(),
        )
        return launcher

    try:
        with Probe(children.domain_id) as probe:
            measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
            launcher, out = _pressurised_run(
                probe,
                start,
                out,
                lambda: len(measured) > 25 and gauge_pa(measured[-25:]).mean() > 1.5e5,
                [measured],
            )
        rig = next(
            pid for pid, name in _children_of(launcher.pid).items() if name.startswith("sim")
        )
        t_kill = time.monotonic()
        os.kill(rig, signal.SIGKILL)
        _, stderr = launcher.communicate(timeout=30.0)
    finally:
        if launcher is not None and launcher.poll() is None:
            launcher.kill()
    assert launcher is not None
    fault.safe_after(time.monotonic() - t_kill)  # until the user has the answer
    print(stderr.strip())
    fault.check("exit code 4", launcher.returncode == 4, f"exit code {launcher.returncode}")
    fault.check(
        "reported",
        "compensator: stopped: " in stderr and "stale" in stderr,
        f"stderr: {stderr[-400:]}",
    )
    report = json.loads((out / "report.json").read_text())
    fault.check("report.json says why", "stale" in report["stopped"], str(report["stopped"]))


def _pressurised_run(
    probe: Probe,
    start: Callable[[Path], subprocess.Popen[Any]],
    out: Path,
    pressurised: Callable[[], bool],
    streams: Sequence[list[Any]],
) -> tuple[subprocess.Popen[Any], Path]:
    """Start ``follow_trajectory --sim`` (``start(run_dir)``) and wait until it holds pressure.

    A run that stopped on a stale sensor before that, with no fault injected yet, is started
    once more, and the test says so. A few seconds into such a run, started from the pytest
    process after the model tests on an idle machine, the compensator's sensors sometimes
    went silent for 0.1-0.33 s and it stopped on its 100 ms stale limit: the safe answer to a
    fault these tests do not inject, and not explained yet (docs/reliability.md). Twice in a
    row fails the test.
    """
    for attempt in (1, 2):
        run_dir = out if attempt == 1 else out.with_name(f"{out.name}_again")
        for stream in streams:
            stream.clear()
        launcher = start(run_dir)
        probe.spin_until(lambda proc=launcher: proc.poll() is not None or pressurised(), 60.0)
        if launcher.poll() is None:
            if pressurised():
                return launcher, run_dir
            raise AssertionError("the run did not reach 1.5 bar within 60 s")
        launcher.communicate(timeout=30.0)  # also drains and closes its pipes, if it has any
        report = run_dir / "report.json"
        stopped = json.loads(report.read_text()).get("stopped", "") if report.exists() else ""
        if attempt == 2 or launcher.returncode != 4 or "stale" not in stopped:
            raise AssertionError(
                f"the run ended (exit {launcher.returncode}) before it held 1.5 bar: "
                f"{stopped or 'no report'}"
            )
        # A warning, so that the suite's summary shows every time this happened.
        warnings.warn(
            f"{run_dir.name}: the run stopped before the fault was injected ({stopped}); "
            "started again",
            RuntimeWarning,
            stacklevel=2,
        )
    raise AssertionError("unreachable")


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, IndexError):
        return False
    return state != "Z"


def _children_of(pid: int) -> dict[int, str]:
    """Child pids of ``pid`` and the module each runs (``python -m <module>``)."""
    found = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            cmdline = (stat.parent / "cmdline").read_bytes().split(b"\0")
        except (FileNotFoundError, ProcessLookupError, IndexError):
            continue
        if int(fields[1]) == pid and b"-m" in cmdline:
            module = cmdline[cmdline.index(b"-m") + 1].decode()
            found[int(stat.parent.name)] = module.rsplit(".", 1)[-1]
    return found


# -- commands straight at the driver: reordered, late, huge -------------------------------


class Driver:
    """sim_hardware alone, with a probe that publishes pressure/command as a test wants."""

    def __init__(self, children: Children) -> None:
        children.start("sim_hardware", node_argv("catheter_driver.sim_hardware_node"))
        self.probe = Probe(children.domain_id).__enter__()
        self.measured = self.probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        self.diags = self.probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        self.pub = self.probe.node.create_publisher(FluidPressure, PRESSURE_COMMAND.name, STREAM)
        self.clock = self.probe.node.get_clock()
        ready = self.probe.spin_until(
            lambda: self.pub.get_subscription_count() > 0 and len(self.measured) > 25, 30.0
        )
        assert ready, children.all_logs()

    def send(
        self,
        duration_s: float,
        make: Callable[[int], list[tuple[float, int]]],
        until: Callable[[], bool] = lambda: False,
    ) -> int:
        """Publish ``make(now_ns)``'s (gauge Pa, stamp ns) every 4 ms; how many rounds went.

        Sends for ``duration_s`` or until ``until()``; fewer rounds go on a busy machine.
        """
        end = time.monotonic() + duration_s
        rounds = 0
        while time.monotonic() < end and not until():
            for value_pa, stamp_ns in make(self.clock.now().nanoseconds):
                self.pub.publish(messages.fluid_pressure(value_pa, stamp_ns, ""))
            rounds += 1
            self.probe.spin_for(SAMPLE_S)
        return rounds

    def values(self, since: int = 0) -> dict[str, str]:
        found = statuses(self.diags[since:], SIM)
        return diagnostic_values(found[-1]) if found else {}

    def wait_values(self, test: Callable[[dict[str, str]], bool], since: int) -> dict[str, str]:
        self.probe.spin_until(lambda: bool(self.values(since)) and test(self.values(since)), 3.0)
        return self.values(since)


@pytest.fixture
def driver(children: Children) -> Any:
    d = Driver(children)
    try:
        yield d
    finally:
        d.probe.__exit__(None, None, None)


@pytest.mark.fault(
    "reordered pressure commands (each pair swapped, the older one asking for more)",
    safe="older commands refused; the line holds the newer intent",
)
def test_reordered_commands_are_refused(driver: Driver, fault: FaultRecord) -> None:
    def newer(now: int) -> list[tuple[float, int]]:
        return [(1.0e5, now)]

    driver.send(1.5, newer)
    n_diag, t_fault = len(driver.diags), time.monotonic()
    # The newer stamp says 1 bar; the older, arriving after it, says 2.5 bar.
    pairs = driver.send(1.5, lambda now: [(1.0e5, now), (2.5e5, now - 2_000_000)])

    def refused() -> int:
        return int(driver.values(n_diag).get("commands_refused_out_of_order", "0"))

    # Keep the newer intent coming until the driver's next report: with commands stopped its
    # watchdog would vent (rightly) and its status would say that instead. The input is best
    # effort, so a few of the pairs may never arrive; nine in ten must be counted.
    driver.send(5.0, newer, until=lambda: refused() >= 0.9 * pairs)
    held = gauge_pa([m for m in driver.measured if m.mono_s > t_fault])
    fault.check(
        "the older intent never applied",
        held.size > 100 and held.max() < 1.0e5 + 5.0e3,
        f"line reached {held.max(initial=0) / 1e5:.3f} bar (newer intent 1 bar, older 2.5 bar)",
    )
    status = statuses(driver.diags[n_diag:], SIM)[-1]
    fault.check(
        "reported",
        0.9 * pairs <= refused() <= pairs
        and status.level == DiagnosticStatus.WARN
        and "out-of-order" in status.message,
        f"{status.message!r}, {refused()} of {pairs} older commands refused",
    )
    fault.safe_after(0.0)  # never left the safe state: the first reordered command is refused
    _check_range(fault, [], driver.measured)


@pytest.mark.fault(
    "pressure commands delayed 80 ms on the way to the driver",
    safe="applied in order, the delay reported as command latency",
)
def test_delayed_commands_are_applied_and_their_latency_reported(
    driver: Driver, fault: FaultRecord
) -> None:
    n_diag = len(driver.diags)
    driver.send(2.5, lambda now: [(1.5e5, now - 80_000_000)])
    meas = gauge_pa(driver.measured[-25:])
    fault.check(
        "late but in-order commands are followed",
        abs(meas.mean() - 1.5e5) < 3.0e3,
        f"line at {meas.mean() / 1e5:.3f} bar, commanded 1.5 bar",
    )
    values = driver.wait_values(lambda v: v.get("command_latency_p50_ms", "") != "", n_diag)
    p50 = float(values.get("command_latency_p50_ms") or "nan")
    fault.check("reported", 75.0 <= p50 <= 200.0, f"command latency p50 {p50} ms")
    fault.safe_after(0.0)
    _check_range(fault, [], driver.measured)


@pytest.mark.fault(
    "huge, negative, NaN and infinite pressure commands",
    safe="clamped to [0, 3 bar] or refused; the last good command stays in force",
)
def test_huge_and_non_finite_commands(driver: Driver, fault: FaultRecord) -> None:
    n_diag, t_fault = len(driver.diags), time.monotonic()
    bad = [1.0e12, -1.0e9, float("nan"), float("inf"), -float("inf")]
    driver.send(1.0, lambda now: [(v, now + i) for i, v in enumerate(bad)])
    driver.send(0.5, lambda now: [(1.0e5, now)])
    after = gauge_pa([m for m in driver.measured if m.mono_s > t_fault])
    fault.check(
        "range",
        after.size > 100 and after.max() <= MAX_PRESSURE_PA + NOISE_MARGIN_PA,
        f"line peaked at {after.max(initial=0) / 1e5:.3f} bar (limit 3 bar)",
    )
    values = driver.wait_values(lambda v: int(v.get("commands_clamped", "0")) > 0, n_diag)
    fault.check(
        "reported",
        int(values.get("commands_clamped", "0")) >= 100
        and int(values.get("commands_refused_nonfinite", "0")) >= 150,
        f"clamped {values.get('commands_clamped')}, "
        f"refused {values.get('commands_refused_nonfinite')}",
    )
    fault.safe_after(0.0)


# -- what the compensator is given: malformed trajectories, untrusted senders, bad models ------


MALFORMED: dict[str, list[tuple[float, float]]] = {
    "NaN angle": [(0.0, 0.0), (1.0, float("nan")), (2.0, 0.0)],
    "time going backwards": [(0.0, 0.0), (2.0, 5.0), (1.0, 10.0)],
    "beyond the bend limit (80 deg)": [(0.0, 0.0), (5.0, 80.0)],
    "faster than the catheter can bend (30 deg in 10 ms)": [(0.0, 0.0), (0.01, 30.0), (2.0, 30.0)],
    "empty": [],
}


@pytest.mark.fault(
    "malformed trajectories: NaN, time backwards, beyond limits, too fast, empty",
    safe="each refused whole, with its reason, before anything moves",
)
def test_malformed_trajectories_are_refused(sim: SimGraph, fault: FaultRecord) -> None:
    reasons = []
    for i, (label, points) in enumerate(MALFORMED.items(), start=1):
        sim.pub.publish(trajectory_msg(points))
        status = sim.status_after(
            COMPENSATOR,
            0,
            lambda s, i=i: diagnostic_values(s)["trajectories_refused"] == str(i),
            5.0,
        )
        fault.check(
            "reported",
            status is not None and bool(diagnostic_values(status)["last_refusal"]),
            f"{label}: no refusal reported",
        )
        assert status is not None
        reasons.append(f"{label}: {diagnostic_values(status)['last_refusal']}")
    print("\n".join(reasons))
    fault.check(
        "nothing moved",
        gauge_pa(sim.commands).max(initial=0.0) == 0.0 and gauge_pa(sim.measured).max() < VENTED_PA,
        f"commands up to {gauge_pa(sim.commands).max(initial=0.0):.0f} Pa",
    )
    fault.safe_after(0.0)


@pytest.mark.fault(
    "a trajectory sent to a compensator started with accept_trajectories:=false",
    safe="not subscribed: the catheter stays at rest",
)
def test_a_locked_compensator_ignores_trajectories(
    children: Children, tmp_path: Path, fault: FaultRecord
) -> None:
    sim = SimGraph(children, tmp_path, accept_trajectories=False)
    try:
        sim.wait_ready()
        sim.pub.publish(trajectory_msg(HOLD_20_DEG))
        sim.probe.spin_for(3.0)
        status = statuses(sim.diags, COMPENSATOR)[-1]
        values = diagnostic_values(status)
        fault.check(
            "reported",
            values["accept_trajectories"] == "false" and values["trajectories_accepted"] == "0",
            str(values),
        )
        fault.check(
            "nothing moved",
            gauge_pa(sim.measured).max() < VENTED_PA,
            f"line reached {gauge_pa(sim.measured).max() / 1e5:.3f} bar",
        )
        fault.safe_after(0.0)
    finally:
        sim.close()


def _tamper_weights(model: Path) -> str:
    onnx = next(model.glob("*.onnx"))
    data = bytearray(onnx.read_bytes())
    data[len(data) // 2] ^= 0x01  # one bit of one weight
    onnx.write_bytes(bytes(data))
    return onnx.name


def _tamper_manifest(model: Path) -> str:
    manifest = model / "manifest.json"
    doc = json.loads(manifest.read_text())
    doc["normalization"]["output"]["hi"] *= 2.0  # twice the pressure for the same output
    manifest.write_text(json.dumps(doc, indent=2))
    return manifest.name


def _remove_weights(model: Path) -> str:
    onnx = next(model.glob("*.onnx"))
    onnx.unlink()
    return onnx.name


TAMPERINGS: dict[str, Callable[[Path], str]] = {
    "one weight bit flipped": _tamper_weights,
    "manifest edited": _tamper_manifest,
    "weights file deleted": _remove_weights,
}


@pytest.mark.fault(
    "tampered model directory given to the compensator",
    safe="the node refuses to start, naming the file; nothing is published",
)
@pytest.mark.parametrize("how", list(TAMPERINGS))
def test_tampered_model_is_refused_at_start(
    children: Children, tmp_path: Path, fault: FaultRecord, how: str
) -> None:
    fault.fault = f"tampered model directory ({how})"
    model = tmp_path / "clstm"
    shutil.copytree(SHIPPED_CLSTM, model)
    before = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in model.iterdir()}
    name = TAMPERINGS[how](model)
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        t0 = time.monotonic()
        result = children.run(
            "compensator",
            node_argv("catheter_control.compensator_node", {"model_dir": str(model)}),
            timeout_s=60.0,
        )
        probe.spin_for(0.5)
    output = result.stdout + result.stderr
    fault.check("refused to start", result.returncode == 2, f"exit code {result.returncode}")
    fault.check("reported", name in output, f"the refusal does not name {name}: {output[-400:]}")
    fault.check("nothing published", not commands, f"{len(commands)} commands")
    fault.safe_after(time.monotonic() - t0)
    print(output.strip().splitlines()[-1])
    assert before  # the untouched files were read (a directory, not a file)


@pytest.mark.fault(
    "truncated and corrupted bags given to the lab",
    safe="refused with the reason (and the repair command); the bag is not modified",
    category="offline",
)
@pytest.mark.parametrize("how", ["truncated", "corrupted"])
def test_bad_bags_are_refused_and_left_untouched(
    tmp_path: Path, fault: FaultRecord, how: str
) -> None:
    fault.fault = f"{how} bag given to the lab (catheter-lab compare)"
    bag = tmp_path / "bag"
    shutil.copytree(SAMPLE_BAG, bag)
    mcap = next(bag.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    if how == "truncated":
        data = data[: len(data) // 2]
    else:
        third = len(data) // 3
        data[third : third + 64] = bytes(b ^ 0xFF for b in data[third : third + 64])
    mcap.write_bytes(bytes(data))
    digest = hashlib.sha256(mcap.read_bytes()).hexdigest()
    t0 = time.monotonic()
    result = subprocess.run(
        [
            str(CATHETER_LAB),
            "compare",
            str(SHIPPED_CLSTM.with_name("idrdpi")),
            str(bag),
            "-o",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        text=True,
        timeout=120.0,
        check=False,
    )
    fault.safe_after(time.monotonic() - t0)
    message = (result.stdout + result.stderr).strip()
    print(message)
    fault.check("refused", result.returncode == 2, f"exit code {result.returncode}")
    # Damage inside a chunk shows as a checksum mismatch, or (in a compressed chunk) as the
    # decompressor failing first; either way the user is told the bag is damaged.
    expected = "truncated" if how == "truncated" else "damaged"
    fault.check(
        "reported",
        str(bag) in message and expected in message.lower(),
        f"the refusal should name the bag and say {expected!r}: {message[-300:]}",
    )
    if how == "truncated":
        fault.check("reported", "catheter-lab bag repair" in message, "no repair hint")
    fault.check(
        "the refused bag is left as it was (nothing lost)",
        hashlib.sha256(mcap.read_bytes()).hexdigest() == digest,
        "the refused bag was modified",
    )
