"""Honest repair and info: each damaged-bag probe of issue 31, told as what it is.

Every damaged bag is a copy of the shipped ``model_test_up_chirp`` (zstd chunks with CRCs)
with bytes of one chunk changed (``bad_bags``). ``bag info`` and ``bag repair`` must tell
truncation from corruption, name the chunk and its time span, count what is lost, say when a
chunk cannot be verified, never call a bag that lost messages complete, exit with their
documented codes and never print a traceback.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import bad_bags as bb
import pytest
import yaml

from catheter_models import cli
from catheter_models.bag import load_bag
from catheter_models.bag.plausible import ImplausibleBagError
from catheter_models.bag.verify import verify_bag
from catheter_models.errors import BagError, TruncatedBagError
from catheter_models.models.data import recording_from_bag

CHUNK = 20
"""The damaged chunk: one in the middle of the recording (t = 9.5 to 10.0 s)."""
GOOD_MESSAGES = 22070


def _lab(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as done:
        cli.main(argv)
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    return int(done.value.code or 0), out, err


def _flipped(tmp_path: Path, want: str, *, crc: bool) -> tuple[Path, bb.ChunkAt]:
    bag = bb.copy_good(tmp_path / f"{want}_{'crc' if crc else 'nocrc'}")
    where = bb.chunk_at(bag, CHUNK) if crc else bb.zero_crc(bag, CHUNK)
    byte, bit = bb.find_flip(where, bag, want)
    bb.flip_bit(bag, byte, bit)
    return bag, where


def _span_text(where: bb.ChunkAt, bag: Path) -> str:
    first_ns = verify_bag(bag).first_ns
    assert first_ns is not None
    return f"t = {(where.start_ns - first_ns) / 1e9:.3f} to {(where.end_ns - first_ns) / 1e9:.3f} s"


def test_a_whole_bag_is_called_whole(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, out, _err = _lab(["bag", "repair", str(bb.GOOD_BAG), "-o", str(tmp_path / "r")], capsys)
    assert code == 0
    assert "was whole (every chunk verified, nothing lost)" in out
    assert f"recovered {GOOD_MESSAGES} messages" in out
    code, out, _err = _lab(["bag", "info", str(bb.GOOD_BAG)], capsys)
    assert code == 0
    assert "CORRUPT" not in out and "UNVERIFIED" not in out and "LOST" not in out


def test_crc0_chunk_with_a_flip_that_breaks_its_framing_is_corrupt_and_counted(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The probe: an index-based reader skipped messages of such a chunk without a word,
    # "bag info" showed fewer messages and "gaps none", "bag repair" said "already complete".
    bag, where = _flipped(tmp_path, "reframed", crc=False)
    code, out, _err = _lab(["bag", "info", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    assert f"CORRUPT: model_test_up_chirp_0.mcap: chunk {CHUNK}" in out
    assert _span_text(where, bag) in out
    assert f"its {where.messages} messages are lost" in out
    assert f"messages:  {GOOD_MESSAGES - where.messages}" in out
    # The hole shows in the gaps, where the probe saw "none".
    angle_gap = next(x for x in out.splitlines() if "/catheter/tip/angle" in x and "lost" in x)
    assert "lost 125 samples" in angle_gap

    code, out, _err = _lab(["bag", "repair", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    assert "was corrupt" in out and "truncated" not in out.splitlines()[0]
    assert "whole" not in out and "complete" not in out
    assert f"{where.messages} messages lost" in out
    repaired = tmp_path / f"{bag.name}_repaired"
    assert sum(verify_bag(repaired).recovered_by_topic().values()) == GOOD_MESSAGES - where.messages
    assert load_bag(repaired).custom_data["repair_lost_messages"] == str(where.messages)

    with pytest.raises(BagError, match="is damaged") as refused:
        load_bag(bag)
    assert f"chunk {CHUNK}" in str(refused.value)


def test_crc0_chunk_with_a_flip_that_still_decodes_is_said_unverified(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # The probe: such a flip changed a command by 2,048 Pa and was trained on, unsaid.
    bag, where = _flipped(tmp_path, "decodes", crc=False)
    code, out, _err = _lab(["bag", "info", str(bag)], capsys)
    assert "UNVERIFIED: model_test_up_chirp_0.mcap: 1 of 47 chunks carry no CRC (0)" in out
    assert _span_text(where, bag) in out
    assert code == 0  # nothing is known lost: said, not a problem
    code, out, _err = _lab(["bag", "repair", str(bag), "-o", str(tmp_path / "r")], capsys)
    assert code == 0
    assert "1 chunk(s) carry no CRC and could not be verified" in out
    assert "was whole" not in out
    with pytest.warns(UserWarning, match="unverified chunks: 1 of 47"):
        recording_from_bag(bag)


def test_a_chunk_failing_its_crc_is_corruption_not_truncation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag, where = _flipped(tmp_path, "decodes", crc=True)
    code, out, _err = _lab(["bag", "repair", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    first = out.splitlines()[0]
    assert "was corrupt" in first and "truncated" not in first
    assert f"chunk {CHUNK} at byte {where.offset}" in out
    assert "its CRC does not match" in out
    assert _span_text(where, bag) in out


@pytest.mark.parametrize("crc", [True, False], ids=["crc", "crc0"])
def test_a_frame_zstd_rejects_is_said_without_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], crc: bool
) -> None:
    bag, where = _flipped(tmp_path, "rejected", crc=crc)
    code, out, _err = _lab(["bag", "info", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    assert f"chunk {CHUNK}" in out and "its zstd data cannot be decompressed" in out
    code, out, _err = _lab(["bag", "repair", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    assert f"{where.messages} messages lost" in out
    code, _out, err = _lab(
        [
            "compare",
            str(bb.REPO / "src/catheter_control/catheter_control/data/idrdpi"),
            str(bag),
            "-o",
            str(tmp_path / "c"),
        ],
        capsys,
    )
    assert code == 2
    assert "is damaged" in err


@pytest.mark.parametrize(
    "content",
    [b"", bb.GOOD_BAG.joinpath("model_test_up_chirp_0.mcap").read_bytes()[:30]],
    ids=["0 bytes", "header cut"],
)
def test_a_file_with_nothing_to_recover_is_refused_not_recovered(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], content: bytes
) -> None:
    lone = tmp_path / "empty.mcap"
    lone.write_bytes(content)
    code, _out, err = _lab(["bag", "repair", str(lone)], capsys)
    assert code == 2
    assert "nothing to recover" in err
    assert not (tmp_path / "empty_repaired").exists()
    code, _out, err = _lab(["bag", "info", str(lone)], capsys)
    assert code in (2, cli.EXIT_BAG_PROBLEM)
    with pytest.raises(TruncatedBagError, match="nothing to repair"):
        load_bag(lone)


def test_metadata_claiming_messages_the_data_lacks_is_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = bb.copy_good(tmp_path / "claims")
    meta_path = bag / "metadata.yaml"
    meta = yaml.safe_load(meta_path.read_text())
    info = meta["rosbag2_bagfile_information"]
    entry = next(
        t
        for t in info["topics_with_message_count"]
        if t["topic_metadata"]["name"] == "/catheter/pressure/command"
    )
    entry["message_count"] = 999_999
    meta_path.write_text(yaml.safe_dump(meta, sort_keys=False))
    code, out, _err = _lab(["bag", "info", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    assert (
        "METADATA: metadata.yaml does not match the data: /catheter/pressure/command: "
        "metadata.yaml says 999999, the data holds 5063"
    ) in out
    with pytest.raises(ImplausibleBagError, match=r"metadata\.yaml: message counts"):
        recording_from_bag(bag)


def test_a_truncated_bag_is_called_truncated_not_corrupt(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = bb.copy_good(tmp_path / "cut")
    mcap = bb.mcap_of(bag)
    where = bb.chunk_at(bag, CHUNK)
    mcap.write_bytes(mcap.read_bytes()[: where.offset + 100])  # the recorder died in chunk 20
    code, out, _err = _lab(["bag", "info", str(bag)], capsys)
    assert code == cli.EXIT_BAG_PROBLEM
    assert out.startswith("TRUNCATED: model_test_up_chirp_0.mcap has no MCAP footer")
    assert "CORRUPT" not in out
    code, out, _err = _lab(["bag", "repair", str(bag)], capsys)
    first = out.splitlines()[0]
    assert "was truncated" in first and "corrupt" not in first
    # metadata.yaml still counts the whole recording: the loss is counted and placed.
    assert code == cli.EXIT_BAG_PROBLEM
    assert "LOST:" in out and "the readable data ends at t = 9.5" in out
    shutil.rmtree(tmp_path / "cut_repaired")
