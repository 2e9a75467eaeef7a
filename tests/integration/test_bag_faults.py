"""Bad bags given to the lab (issue 31's probes): each a row of docs/reliability.md's fault table.

No graph (the three that start several ``catheter-lab`` processes are marked slow for their
10-15 s): each test makes a bad bag from a shipped one (``bad_bags``), runs the ``catheter-lab``
command a person would, as a process, and checks what it says and how it exits. The unit tests
(tests/catheter_models/bag/test_bag_plausible.py, test_bag_repair_honest.py) cover each probe
in detail; these prove the commands' behaviour end to end.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import bad_bags as bb
import numpy as np
import pytest
import yaml
from fault_log import FaultRecord

from catheter_models.units import deg_to_rad

CATHETER_LAB = Path(sys.executable).with_name("catheter-lab")
EXIT_REFUSED = 2
EXIT_BAG_PROBLEM = 3


def _lab(*argv: str | Path) -> tuple[int, str]:
    result = subprocess.run(
        [str(CATHETER_LAB), *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=300.0,
        check=False,
    )
    return result.returncode, result.stdout + result.stderr


def _no_traceback(fault: FaultRecord, said: str) -> None:
    fault.check("no traceback", "Traceback" not in said, said[-600:])


def _refused_by_train(fault: FaultRecord, bag: Path, tmp_path: Path, *words: str) -> str:
    """``catheter-lab train`` refuses the bag, exit 2, naming every word; nothing is written."""
    out = tmp_path / f"model_{bag.name}"
    code, said = _lab("train", "drdpi", "--train", bag, "-o", out, "--quiet")
    print(said.strip().splitlines()[-1][:600])
    _no_traceback(fault, said)
    fault.check("refused", code == EXIT_REFUSED, f"exit code {code}: {said[-400:]}")
    missing = [w for w in (str(bag), *words) if w not in said]
    fault.check("reported", not missing, f"the refusal does not say {missing}: {said[-600:]}")
    fault.check("no model written", not out.exists(), f"{out} exists")
    return said


@pytest.mark.slow  # several catheter-lab processes: 10-15 s on the 2-core machine
@pytest.mark.fault(
    "bags with 300 bar, 1,574 deg bends, bar stored as Pa, degrees stored as radians, given "
    "to catheter-lab train",
    safe="refused (exit 2), naming topic, check, count and first time, the unit slip where "
    "recognisable; --accept-implausible goes on and says each finding",
    category="offline",
)
def test_implausible_values_are_refused(tmp_path: Path, fault: FaultRecord) -> None:
    edits = {
        "300bar": (
            bb.values("pressure/measured", lambda v: v * (300e5 / v.max())),
            ("/catheter/pressure/measured: range:", "(300 bar)"),
        ),
        "1574deg": (
            bb.values("tip/angle", lambda v: v * (deg_to_rad(1574.0) / v.max())),
            ("/catheter/tip/angle: units:", "(1574 deg)"),
        ),
        "bar_as_pa": (
            bb.values("pressure/command", lambda v: v / 1e5),
            ("/catheter/pressure/command: units:", "bar stored as Pa"),
        ),
        "deg_as_rad": (
            bb.values("tip/angle", np.degrees),
            ("/catheter/tip/angle: units:", "degrees stored as radians"),
        ),
    }
    for name, (edit, words) in edits.items():
        bag = bb.rewrite(tmp_path / name, edit)
        _refused_by_train(fault, bag, tmp_path, *words, "first at")
    bag = tmp_path / "deg_as_rad"
    code, said = _lab(
        "train", "drdpi", "--train", bag, "-o", tmp_path / "accepted", "--quiet",
        "--accept-implausible",
    )  # fmt: skip
    fault.check("accepted knowingly", code == 0, f"exit code {code}: {said[-400:]}")
    fault.check(
        "reported", "implausible, accepted knowingly" in said, f"not said when accepted: {said}"
    )


@pytest.mark.slow  # several catheter-lab processes: 10-15 s on the 2-core machine
@pytest.mark.fault(
    "bags with duplicate stamps, half the bag re-using stamps, a time-reversed bag, given to "
    "catheter-lab train",
    safe="refused (exit 2), naming the topic, the stamp check, the count and the first time",
    category="offline",
)
def test_broken_stamps_are_refused(tmp_path: Path, fault: FaultRecord) -> None:
    def half_reused(s: np.ndarray) -> np.ndarray:
        half = s.size // 2
        return np.concatenate([s[:half], s[: s.size - half]])

    edits = {
        "duplicated": (bb.duplicated, "repeated stamps"),
        "half_reused": (bb.stamps(half_reused), "stamps not increasing"),
        "reversed": (bb.stamps(lambda s: s[::-1]), "stamps not increasing"),
    }
    for name, (edit, check) in edits.items():
        bag = bb.rewrite(tmp_path / name, edit)
        _refused_by_train(fault, bag, tmp_path, f"/catheter/tip/angle: {check}:", "first at")


@pytest.mark.fault(
    "every other tip/angle sample NaN, given to catheter-lab train and bag info",
    safe="refused (exit 2) for the non-finite share; bag info shows it (exit 3), not 'gaps none'",
    category="offline",
)
def test_half_nan_is_refused_and_shown(tmp_path: Path, fault: FaultRecord) -> None:
    def every_other(v: np.ndarray) -> np.ndarray:
        v[1::2] = np.nan
        return v

    bag = bb.rewrite(tmp_path / "half_nan", bb.values("tip/angle", every_other))
    _refused_by_train(fault, bag, tmp_path, "/catheter/tip/angle: non-finite:", "50.0%")
    code, said = _lab("bag", "info", bag)
    _no_traceback(fault, said)
    fault.check("bag info exits 3", code == EXIT_BAG_PROBLEM, f"exit code {code}")
    fault.check(
        "reported",
        "REFUSE /catheter/tip/angle: non-finite: 2834 of 5669 samples" in said,
        f"bag info does not show the finding: {said[-800:]}",
    )


@pytest.mark.fault(
    "a zstd chunk with CRC 0 and flipped bits (framing broken; payload only)",
    safe="bag info and repair name the chunk, its time span and the 499 messages lost (exit "
    "3, never 'complete'); a flip that still decodes is said unverifiable",
    category="offline",
)
def test_crc0_chunk_with_flipped_bits(tmp_path: Path, fault: FaultRecord) -> None:
    bag = bb.copy_good(tmp_path / "reframed")
    where = bb.zero_crc(bag, 20)
    bb.flip_bit(bag, *bb.find_flip(where, bag, "reframed"))
    code, said = _lab("bag", "info", bag)
    _no_traceback(fault, said)
    fault.check("bag info exits 3", code == EXIT_BAG_PROBLEM, f"exit code {code}")
    fault.check(
        "reported",
        "CORRUPT: model_test_up_chirp_0.mcap: chunk 20" in said
        and f"its {where.messages} messages are lost" in said,
        said[:800],
    )
    code, said = _lab("bag", "repair", bag)
    _no_traceback(fault, said)
    fault.check("bag repair exits 3", code == EXIT_BAG_PROBLEM, f"exit code {code}")
    first = said.splitlines()[0]
    fault.check(
        "never called complete",
        "was corrupt" in first and "whole" not in said and "complete" not in said,
        first,
    )
    fault.check("loss counted", f"{where.messages} messages lost" in said, said[:800])

    quiet = bb.copy_good(tmp_path / "decodes")
    where = bb.zero_crc(quiet, 20)
    bb.flip_bit(quiet, *bb.find_flip(where, quiet, "decodes"))
    code, said = _lab("bag", "info", quiet)
    _no_traceback(fault, said)
    fault.check("reported", "chunks carry no CRC (0), so their bytes cannot be verified" in said)


@pytest.mark.slow  # several catheter-lab processes: 10-15 s on the 2-core machine
@pytest.mark.fault(
    "a CRC-failing chunk, and a frame zstd rejects, given to bag repair and bag info",
    safe="said as corruption (not truncation) with the chunk and its time span, exit 3, no "
    "traceback",
    category="offline",
)
def test_crc_failing_and_rejected_chunks(tmp_path: Path, fault: FaultRecord) -> None:
    for want, words in (("decodes", "its CRC does not match"), ("rejected", "cannot be decom")):
        bag = bb.copy_good(tmp_path / want)
        where = bb.chunk_at(bag, 20)
        bb.flip_bit(bag, *bb.find_flip(where, bag, want))
        for verb in ("info", "repair"):
            code, said = _lab("bag", verb, bag)
            _no_traceback(fault, said)
            fault.check(f"bag {verb} exits 3", code == EXIT_BAG_PROBLEM, f"exit code {code}")
            fault.check("reported", words in said and "chunk 20" in said, said[:800])
            fault.check(
                "corruption, not truncation",
                "TRUNCATED" not in said and "was truncated" not in said,
                said[:800],
            )


@pytest.mark.fault(
    "a 0-byte .mcap given to bag repair",
    safe="refused (exit 2), 'nothing to recover'; no bag written",
    category="offline",
)
def test_empty_mcap(tmp_path: Path, fault: FaultRecord) -> None:
    lone = tmp_path / "empty.mcap"
    lone.write_bytes(b"")
    code, said = _lab("bag", "repair", lone)
    _no_traceback(fault, said)
    fault.check("refused", code == EXIT_REFUSED, f"exit code {code}: {said}")
    fault.check("reported", "empty (0 bytes)" in said and "nothing to recover" in said, said)
    fault.check("no bag written", not (tmp_path / "empty_repaired").exists(), "a bag was written")


@pytest.mark.fault(
    "metadata.yaml claiming 999,999 messages",
    safe="bag info names the topic and both counts (exit 3); train refuses it (exit 2)",
    category="offline",
)
def test_metadata_claims(tmp_path: Path, fault: FaultRecord) -> None:
    bag = bb.copy_good(tmp_path / "claims")
    meta_path = bag / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    info = meta["rosbag2_bagfile_information"]
    for entry in info["topics_with_message_count"]:
        if entry["topic_metadata"]["name"] == "/catheter/tip/angle":
            entry["message_count"] = 999_999
    meta_path.write_text(yaml.safe_dump(meta, sort_keys=False))
    code, said = _lab("bag", "info", bag)
    _no_traceback(fault, said)
    fault.check("bag info exits 3", code == EXIT_BAG_PROBLEM, f"exit code {code}")
    fault.check(
        "reported",
        "/catheter/tip/angle: metadata.yaml says 999999, the data holds 5669" in said,
        said[:800],
    )
    _refused_by_train(fault, bag, tmp_path, "metadata.yaml: message counts")
