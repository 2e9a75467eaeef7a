"""Input a person hands the tools, at its worst: refused whole, with the limit named.

Rows of docs/reliability.md's fault table (``make faults``); each runs the real command line.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import pytest
from fault_log import FaultRecord
from graph_utils import Children

from catheter_control.follow_trajectory import EXIT_REFUSED
from catheter_models.contract import MAX_TRAJECTORY_FILE_BYTES

pytestmark = [pytest.mark.slow]

FOLLOW = [sys.executable, "-m", "catheter_control.follow_trajectory"]


@pytest.mark.fault(
    "a 10^7-row trajectory CSV (100 MB) given to follow_trajectory --sim",
    safe="refused unread by its size, with the limit named; no node starts",
    category="input",
)
def test_a_ten_million_row_csv_is_refused_unread(
    children: Children, fault: FaultRecord, tmp_path: Path
) -> None:
    csv = tmp_path / "huge.csv"
    row = b"0.001,1.0\n"
    with csv.open("wb") as out:
        out.write(b"t_s,angle_deg\n")
        for _ in range(100):
            out.write(row * 100_000)
    assert csv.stat().st_size > 40 * MAX_TRAJECTORY_FILE_BYTES
    run_dir = tmp_path / "run"
    start = time.monotonic()
    done = children.run(
        "follow_trajectory",
        [*FOLLOW, "--sim", "--file", str(csv), "--out", str(run_dir), "--no-progress"],
        timeout_s=120.0,
    )
    fault.safe_after(time.monotonic() - start)
    said = done.stdout + done.stderr
    fault.check("exit code 2 (refused)", done.returncode == EXIT_REFUSED, said)
    fault.check(
        "reported",
        "MAX_TRAJECTORY_FILE_BYTES" in said and "Traceback" not in said,
        said,
    )
    fault.check("nothing moved: no graph started", not run_dir.exists(), said)
