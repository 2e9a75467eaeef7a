"""A bag that cannot be written (disk full, I/O error) stops, says why, and stays recoverable.

The failure is injected by a file object that refuses writes once told to (as a full disk
refuses them: ENOSPC, after taking part of the data), and, as root, by a real tmpfs that
fills up. Either way the writer raises BagWriteError naming the error, the file and the time,
writes nothing more, and close() leaves the file as its last complete flush left it:
``bag repair`` recovers exactly what metadata.yaml counts.
"""

from __future__ import annotations

import errno
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import pytest
import yaml
from tmpfs import mounted_tmpfs

from catheter_models.bag import BagRecorder, repair_bag
from catheter_models.bag.messages import fluid_pressure_cdr
from catheter_models.bag.space import (
    SPACE_MARGIN,
    DiskSpaceError,
    check_free_space,
    contract_streams,
    need_for,
)
from catheter_models.bag.write_failure import BagWriteError
from catheter_models.contract import PRESSURE_COMMAND

EPOCH_NS = 1_700_000_000_000_000_000
CMD = "/catheter/pressure/command"
PERIOD_NS = 4_000_000


class RefusingFile:
    """A binary file that writes through until ``refuse`` is set, then writes part of what
    it is given and raises ``OSError(code)``, as a disk that just filled up does."""

    def __init__(self, inner: IO[bytes]) -> None:
        self.inner = inner
        self.refuse: int | None = None

    def write(self, data: Any) -> int:
        if self.refuse is not None:
            view = memoryview(data)
            self.inner.write(view[: len(view) // 2])
            self.inner.flush()
            raise OSError(self.refuse, os.strerror(self.refuse))
        return self.inner.write(data)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


@pytest.fixture
def refusing(monkeypatch: pytest.MonkeyPatch) -> Iterator[list[RefusingFile]]:
    """Every .mcap file a BagRecorder opens is a RefusingFile (listed here)."""
    opened: list[RefusingFile] = []
    real_open = Path.open

    def fake_open(self: Path, mode: str = "r", *args: Any, **kwargs: Any) -> Any:
        stream = real_open(self, mode, *args, **kwargs)
        if mode == "xb" and self.suffix == ".mcap":
            opened.append(RefusingFile(stream))
            return opened[-1]
        return stream

    monkeypatch.setattr(Path, "open", fake_open)
    yield opened


def _write(rec: BagRecorder, i: int) -> None:
    stamp = EPOCH_NS + i * PERIOD_NS
    rec.write(CMD, fluid_pressure_cdr(stamp, 1.0e5, ambient_pa=0.0), stamp, stamp)


def _meta_count(bag: Path) -> int:
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    return int(info["message_count"])


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EIO])
def test_a_refused_flush_stops_the_bag_and_leaves_its_flushed_part_recoverable(
    tmp_path: Path, refusing: list[RefusingFile], code: int
) -> None:
    rec = BagRecorder(tmp_path / "bag", flush_period_s=0.5)
    rec.add_topic(CMD, PRESSURE_COMMAND.msgtype)
    for i in range(300):  # flushes at 0.5 s and 1.0 s of log time: 251 messages on disk
        _write(rec, i)
    assert _meta_count(rec.path) == 251
    flushed_size = rec.mcap_path.stat().st_size
    refusing[0].refuse = code
    before_ns = time.time_ns()
    with pytest.raises(BagWriteError) as raised:
        for i in range(300, 500):  # the next flush (at 1.5 s) meets the full disk
            _write(rec, i)
    failure = raised.value.failure
    assert failure.errno == code
    assert failure.path == rec.mcap_path
    assert before_ns <= failure.at_ns <= time.time_ns()
    said = str(raised.value)
    assert os.strerror(code) in said and str(rec.mcap_path) in said
    assert errno.errorcode[code] in said
    assert rec.failure == failure
    # Nothing more goes in: the same failure, every time, and no byte more on the disk.
    with pytest.raises(BagWriteError):
        _write(rec, 600)
    rec.set_custom_data("samples_lost", "124")  # the recorder's counts still reach the bag

    outcome = rec.close()
    assert not outcome.finished
    assert outcome.failure == failure
    assert outcome.messages == 251
    assert outcome.until_ns == EPOCH_NS + 250 * PERIOD_NS
    assert "bag repair" in outcome.note and "not finished" in outcome.note
    assert rec.close() is outcome
    # Cut back to the last complete flush: the half-written chunk is gone.
    assert rec.mcap_path.stat().st_size == flushed_size
    meta = yaml.safe_load((rec.path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert meta["message_count"] == 251
    assert meta["custom_data"]["samples_lost"] == "124"
    report = repair_bag(rec.path)
    assert report.message_count == 251
    assert report.bytes_discarded == 0


def test_a_failed_finish_is_cut_back_too(tmp_path: Path, refusing: list[RefusingFile]) -> None:
    rec = BagRecorder(tmp_path / "bag", flush_period_s=0.5)
    rec.add_topic(CMD, PRESSURE_COMMAND.msgtype)
    for i in range(200):
        _write(rec, i)
    refusing[0].refuse = errno.EIO
    outcome = rec.close()
    assert not outcome.finished
    assert outcome.failure is not None and outcome.failure.operation == "close"
    assert outcome.messages == 126  # the flush at 0.5 s
    assert repair_bag(rec.path).message_count == 126


def test_a_bag_closed_as_planned_is_finished(tmp_path: Path) -> None:
    rec = BagRecorder(tmp_path / "bag", flush_period_s=0.5)
    rec.add_topic(CMD, PRESSURE_COMMAND.msgtype)
    for i in range(200):
        _write(rec, i)
    outcome = rec.close()
    assert outcome.finished and outcome.failure is None and outcome.messages == 200
    assert "finished" in outcome.note


@pytest.fixture
def tiny_tmpfs(tmp_path: Path) -> Iterator[Path]:
    """A 512 kB tmpfs (root only: skipped otherwise, with the reason)."""
    with mounted_tmpfs(tmp_path, "512k", "the injected failures above cover the path") as mount:
        yield mount


def test_a_full_disk_for_real(tiny_tmpfs: Path) -> None:
    rec = BagRecorder(tiny_tmpfs / "bag", flush_period_s=0.5)
    rec.add_topic(CMD, PRESSURE_COMMAND.msgtype)
    written = 0
    with pytest.raises(BagWriteError) as raised:
        for i in range(100_000):  # ~11 MB: far beyond 512 kB
            _write(rec, i)
            written += 1
    assert raised.value.failure.errno == errno.ENOSPC
    outcome = rec.close()
    assert not outcome.finished
    assert 0 < outcome.messages <= written
    # What it says it kept is what a repair recovers, and metadata.yaml says the same.
    assert _meta_count(rec.path) == outcome.messages
    out = tiny_tmpfs.parent / "repaired"
    assert repair_bag(rec.path, out).message_count == outcome.messages


def test_free_space_check_names_the_figures_and_the_path(tmp_path: Path) -> None:
    need = need_for(tmp_path / "run" / "bag", 100.0, extra_bytes=1_000_000)
    per_s = sum(s.bytes_per_s for s in contract_streams())
    # Five streams at 250 Hz, 115-140 bytes a message on disk.
    assert 120e3 < per_s < 200e3
    assert need.need_bytes == int(SPACE_MARGIN * (per_s * 100.0 + 1_000_000))
    with pytest.raises(DiskSpaceError) as refused:
        check_free_space(need, free_bytes=need.need_bytes - 1)
    said = str(refused.value)
    assert str(tmp_path / "run" / "bag") in said
    assert f"{(need.need_bytes - 1) / 1e6:.1f} MB free" in said
    assert f"{need.need_bytes / 1e6:.1f} MB needed" in said
    assert check_free_space(need, free_bytes=need.need_bytes) == need.need_bytes
    # Asked of the OS for a directory not made yet: its nearest existing parent's disk.
    assert check_free_space(need_for(tmp_path / "a" / "b", 1.0)) > 0


def test_a_refused_metadata_rewrite_cuts_back_to_what_metadata_yaml_counts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import catheter_models.bag.writer as writer_module

    real = writer_module.write_metadata
    refuse = [False]

    def refusing_metadata(*args: Any, **kwargs: Any) -> None:
        if refuse[0]:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real(*args, **kwargs)

    monkeypatch.setattr(writer_module, "write_metadata", refusing_metadata)
    rec = BagRecorder(tmp_path / "bag", flush_period_s=0.5)
    rec.add_topic(CMD, PRESSURE_COMMAND.msgtype)
    for i in range(200):  # the flush at 0.5 s: 126 messages
        _write(rec, i)
    refuse[0] = True
    with pytest.raises(BagWriteError):
        for i in range(200, 300):  # the data of the flush at 1.0 s goes out, its metadata not
            _write(rec, i)
    outcome = rec.close()
    # metadata.yaml still says 126: the file is cut back to the same flush, and they agree.
    assert _meta_count(rec.path) == outcome.messages == 126
    refuse[0] = False  # room again for the repaired copy
    assert repair_bag(rec.path).message_count == 126
