"""A hand-edited ``feedback.json`` over DDS: the compensator refuses it at configure, names
each field, and nothing moves, even with a trajectory waiting for it on the topic.

The probe this answers: the shipped gains x100, a 6 bar authority and a 10^6 s authority
timeout, typed into the file, ran without a word and chattered the valve (347 reversals in
1,258 ticks) through a run that "passed".
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from fault_log import FaultRecord
from graph_utils import NOISE_MARGIN_PA, Children, Probe, gauge_pa, node_argv, trajectory_msg
from sensor_msgs.msg import FluidPressure
from trajectory_msgs.msg import JointTrajectory

from catheter_control.models import SHIPPED_GAINS, shipped_model_dir
from catheter_models.contract import PRESSURE_COMMAND, PRESSURE_MEASURED, TRAJECTORY
from catheter_models.feedback import GAINS_FILE
from catheter_ros import qos
from catheter_ros.qos import RECORD

pytestmark = [
    pytest.mark.slow,
    pytest.mark.filterwarnings("ignore:module 'sre_:DeprecationWarning"),
]

FIELDS = ("kp_pa_per_rad", "ki_pa_per_rad_s", "max_correction_pa", "authority_timeout_s")
"""What the probe changed; the refusal must name each."""


@pytest.mark.fault(
    "feedback.json edited by hand: gains x100, a 6 bar authority, a 10^6 s authority timeout",
    safe="compensator refuses it at configure, naming each field and the broken seal; "
    "no command is sent, the muscle stays at rest",
)
def test_an_edited_feedback_file_is_refused_at_configure_and_nothing_moves(
    children: Children, fault: FaultRecord, tmp_path: Path
) -> None:
    raw = json.loads((shipped_model_dir(SHIPPED_GAINS) / GAINS_FILE).read_text())
    raw["kp_pa_per_rad"] *= 100.0
    raw["ki_pa_per_rad_s"] *= 100.0
    raw["max_correction_pa"] = 6.0e5
    raw["authority_timeout_s"] = 1.0e6
    bad = tmp_path / GAINS_FILE
    bad.write_text(json.dumps(raw, indent=2))
    children.start("sim_hardware", node_argv("catheter_driver.sim_hardware_node"))
    with Probe(children.domain_id) as probe:
        commands = probe.subscribe(FluidPressure, PRESSURE_COMMAND.name, RECORD)
        measured = probe.subscribe(FluidPressure, PRESSURE_MEASURED.name, RECORD)
        assert probe.spin_until(lambda: len(measured) > 50, 30.0), children.all_logs()
        # A trajectory waits, latched, for a compensator that would take it.
        pub = probe.node.create_publisher(JointTrajectory, TRAJECTORY.name, qos.TRAJECTORY)
        pub.publish(trajectory_msg([(0.0, 0.0), (1.0, 10.0), (3.0, 10.0)]))
        t_start = time.monotonic()
        compensator = children.start(
            "compensator",
            node_argv(
                "catheter_control.compensator_node",
                {"compensator": "none", "feedback": "pi", "feedback_gains": str(bad)},
            ),
        )
        assert probe.spin_until(lambda: compensator.poll() is not None, 60.0), children.all_logs()
        t_refused = time.monotonic()
        # Anything it had sent would still be arriving: listen on a while.
        probe.spin_for(2.0)
    said = (children.log_dir / "compensator.log").read_text()
    assert compensator.returncode != 0, said
    assert "configure failed" in said and str(bad) in said, said
    for name in FIELDS:
        assert name in said, f"{name} not named:\n{said}"
    assert "6 bar is beyond the safety envelope" in said, said
    assert "feedback_sha256 does not match" in said, said
    fault.check("reported", all(name in said for name in FIELDS), said[-600:])
    rest = gauge_pa([m for m in measured if m.mono_s > t_start])
    fault.check(
        "nothing moved (no command sent, the muscle at rest)",
        not commands and rest.size > 0 and float(np.max(np.abs(rest))) < NOISE_MARGIN_PA,
        f"{len(commands)} commands; measured up to {np.max(np.abs(rest), initial=0.0):.0f} Pa",
    )
    # The rig never left rest: safe from the start. How long the refusal took is said.
    print(f"refused {t_refused - t_start:.2f} s after the compensator started")
    fault.safe_after(0.0)
