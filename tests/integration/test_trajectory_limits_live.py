"""A trajectory over the size limits, sent on ``trajectory`` mid-run, over DDS: refused by its
length in the compensator's intake process, never taken into the compensator's, and the run in
progress keeps its deadlines; an intake process that dies is reported.

Before the limits, one 10^6-point message stalled the compensator's loop for seconds (rclpy
built a Python object per point holding the GIL the loop thread needs): 807 missed deadlines,
the valve driver's watchdog vented, and the huge trajectory was then accepted. Refused by its
length but taken in the compensator's process, it still cost 90 ms on an idle machine and, on
a busy CI machine, 395 missed deadlines against 91 in a normal run.
"""

from __future__ import annotations

import os
import signal
import struct
import time

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from fault_log import FaultRecord
from graph_utils import (
    COMPENSATOR,
    SIM,
    Children,
    Probe,
    Stamped,
    diagnostic_values,
    node_argv,
    statuses,
    trajectory_msg,
)
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import FluidPressure
from trajectory_msgs.msg import JointTrajectory

from catheter_models.contract import (
    DIAGNOSTICS,
    MAX_TRAJECTORY_MESSAGE_BYTES,
    PRESSURE_COMMAND,
    TRAJECTORY,
)
from catheter_ros import qos

pytestmark = [
    pytest.mark.slow,
    # lark (imported by the ROS message tooling) still uses sre_parse; not ours.
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

HUGE_POINTS = 1_000_000
"""The fault probe's message: about 32 MB on the wire."""

RUN = [(0.0, 0.0), (2.0, 15.0), (6.0, 15.0), (8.0, 0.0)]
"""Up to 15 deg, held, and back to rest: an 8 s run that ends by itself (no hold at rest)."""

_POINTS_AT = 36
"""Where a one-joint JointTrajectory's CDR has its point count: encapsulation (4), stamp (8),
frame_id '' (8 with padding), joint_names ['bend'] (16 with padding)."""


def _cdr_trajectory(n_points: int) -> bytes:
    """A serialised ``n_points``-point JointTrajectory of ``bend``, built without rclpy.

    rclpy needs about 18 us a point to build or serialise one (13 s for 10^6 on this machine),
    which would stall the probe; the wire form of a one-position point is 32 fixed bytes.
    """
    head = serialize_message(trajectory_msg([(1.0, 5.0)]))[:_POINTS_AT]
    # positions [0.1 rad], no velocities, accelerations or effort, time_from_start 1 s
    point = struct.pack("<Id3I2I", 1, 0.1, 0, 0, 0, 1, 0)
    return head + struct.pack("<I", n_points) + point * n_points


def _missed(status: object) -> int:
    return int(diagnostic_values(status)["missed_deadlines"])


def _run_and_count_missed(
    probe: Probe, pub: object, diags: list[Stamped], inject: bytes | None
) -> tuple[int, list[object]]:
    """Send RUN; with ``inject``, publish it 2 s in. The deadlines the loop missed meanwhile,
    and the compensator's statuses from the run's start until it is idle again."""
    n_diag = len(diags)
    assert probe.spin_until(lambda: bool(statuses(diags[n_diag:], COMPENSATOR)), 5.0)
    before = _missed(statuses(diags[n_diag:], COMPENSATOR)[-1])
    n_run = len(diags)
    pub.publish(trajectory_msg(RUN))  # type: ignore[attr-defined]
    following = probe.spin_until(
        lambda: any(
            diagnostic_values(s)["state"] == "following"
            for s in statuses(diags[n_run:], COMPENSATOR)
        ),
        5.0,
    )
    assert following, [s.message for s in statuses(diags, COMPENSATOR)[-3:]]
    if inject is not None:
        probe.spin_for(1.0)
        pub.publish(inject)  # type: ignore[attr-defined]

    def idle_again() -> bool:
        seen = [diagnostic_values(s)["state"] for s in statuses(diags[n_run:], COMPENSATOR)]
        return "following" in seen and seen[-1] == "idle"

    assert probe.spin_until(idle_again, 20.0), [
        diagnostic_values(s) for s in statuses(diags, COMPENSATOR)[-2:]
    ]
    run = statuses(diags[n_run:], COMPENSATOR)
    return _missed(run[-1]) - before, run


def _vents(probe: Probe, diags: list[Stamped]) -> int:
    """sim_hardware's watchdog vents so far, once its watchdog has had time to act."""
    probe.spin_for(1.5)  # over COMMAND_TIMEOUT_S and one diagnostics period
    return int(diagnostic_values(statuses(diags, SIM)[-1])["watchdog_vents"])


def test_the_cdr_builder_writes_what_rclpy_reads() -> None:
    msg = deserialize_message(_cdr_trajectory(3), JointTrajectory)
    assert list(msg.joint_names) == ["bend"]
    assert [list(p.positions) for p in msg.points] == [[0.1]] * 3
    assert msg.points[2].time_from_start.sec == 1


@pytest.mark.fault(
    "a 10^6-point trajectory (32 MB) on the trajectory topic mid-run",
    safe=(
        "refused by its length in the compensator's intake process, never taken into the "
        "compensator's; the run goes on, as many deadlines kept"
    ),
)
def test_a_huge_trajectory_mid_run_is_refused_and_the_loop_keeps_its_deadlines(
    children: Children, fault: FaultRecord
) -> None:
    huge = _cdr_trajectory(HUGE_POINTS)
    assert len(huge) > MAX_TRAJECTORY_MESSAGE_BYTES
    children.start("sim_hardware", node_argv("catheter_driver.sim_hardware_node"))
    children.start("compensator", node_argv("catheter_control.compensator_node", {}))
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, qos.KEEP_EVERY_SAMPLE)
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        ready = probe.spin_until(
            lambda: (
                pub.get_subscription_count() > 0
                and bool(statuses(diags, COMPENSATOR))
                and bool(statuses(diags, SIM))
            ),
            40.0,
        )
        assert ready, f"graph not up:\n{children.all_logs()}"

        # What a normal run misses on this machine now, then the same run with the fault.
        # The driver's watchdog vents once at each run's end (the compensator falls silent
        # between runs); one more is a vent mid-run (printed, see below).
        vents = [_vents(probe, diags)]
        missed_normal, _ = _run_and_count_missed(probe, pub, diags, None)
        vents.append(_vents(probe, diags))
        missed_huge, run = _run_and_count_missed(probe, pub, diags, huge)
        vents.append(_vents(probe, diags))
        print(f"missed deadlines: normal run {missed_normal}, with the huge message {missed_huge}")
        print(f"watchdog vents (start, after the normal run, after the other): {vents}")
        print(f"behind_max_ms in the run: {[diagnostic_values(s)['behind_max_ms'] for s in run]}")

        last = diagnostic_values(run[-1])
        fault.check(
            "reported",
            last["trajectories_refused"] == "1"
            and "MAX_TRAJECTORY_MESSAGE_BYTES" in last["last_refusal"]
            and "not deserialised" in last["last_refusal"],
            str(last),
        )
        # Refused while the run went on, and the run then ended by itself, with no fault.
        refused_at = next(
            diagnostic_values(s) for s in run if diagnostic_values(s)["trajectories_refused"] == "1"
        )
        assert refused_at["state"] == "following", refused_at
        assert all(diagnostic_values(s)["fault"] == "" for s in run), [
            diagnostic_values(s)["fault"] for s in run
        ]
        assert last["trajectories_accepted"] == "2", last
        assert last["state"] == "idle", last
        # Within what a normal run misses: normal 8 s runs on the busy 2-core test machine
        # missed 0 to 47 of their 2,000 deadlines, so twice it or 60 more; the unbounded
        # intake missed 842.
        fault.check(
            "the loop missed no more deadlines than in a normal run",
            missed_huge <= max(2 * missed_normal, missed_normal + 60),
            f"normal run {missed_normal}, with the huge message {missed_huge}",
        )
        # Not asserted, printed above: how far behind the loop fell (behind_max_ms) and whether
        # the driver vented mid-run. With the intake in its own process the 32 MB never enters
        # the compensator's: 1-6 ms behind, as in a normal run, idle or beside two busy loops.
        assert commands, "no pressure command at all"
        fault.safe_after(0.0)  # the run never left its course


@pytest.mark.fault(
    "kill -9 of the compensator's trajectory intake process",
    safe="/diagnostics ERROR naming the process and its exit; the compensator goes on",
)
def test_a_killed_intake_process_is_reported_and_the_compensator_goes_on(
    children: Children, fault: FaultRecord
) -> None:
    """The topic's intake runs in a child process; if it dies, /diagnostics says so at once."""
    children.start("compensator", node_argv("catheter_control.compensator_node", {}))
    with Probe(children.domain_id) as probe:
        diags = probe.subscribe(DiagnosticArray, DIAGNOSTICS.name, 10)
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)

        def intake_pid() -> int:
            seen = statuses(diags, COMPENSATOR)
            pid = diagnostic_values(seen[-1]).get("trajectory_intake_pid", "") if seen else ""
            return int(pid) if pid.isdigit() else 0

        assert probe.spin_until(lambda: intake_pid() > 0 and pub.get_subscription_count(), 40.0)
        pid = intake_pid()
        os.kill(pid, signal.SIGKILL)
        killed_s = time.monotonic()

        def lost() -> list[object]:
            return [
                s
                for s in statuses(diags, COMPENSATOR)
                if diagnostic_values(s).get("trajectory_intake_lost")
            ]

        assert probe.spin_until(lambda: bool(lost()), 10.0), [
            diagnostic_values(s) for s in statuses(diags, COMPENSATOR)[-2:]
        ]
        fault.safe_after(time.monotonic() - killed_s)
        status = lost()[-1]
        fault.check(
            "reported",
            status.level == DiagnosticStatus.ERROR
            and status.message == f"trajectory intake process (pid {pid}) exited with code -9",
            f"{status.level!r} {status.message}",
        )
        # The compensator itself goes on: it still reports, armed, with its loop running.
        n_seen = len(diags)
        assert probe.spin_until(lambda: bool(statuses(diags[n_seen:], COMPENSATOR)), 5.0)
        assert diagnostic_values(statuses(diags[n_seen:], COMPENSATOR)[-1])["state"] == "idle"
