"""bag_info: the summary a person reads, for whole and for truncated bags."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from catheter_models.bag import bag_info, write_bag_from_arrays

EPOCH_NS = 1_700_000_000_000_000_000


def _bag(tmp_path: Path) -> Path:
    t = np.arange(500) / 250.0
    return write_bag_from_arrays(
        tmp_path / "info",
        t,
        1e5 * t,
        1e5 * t,
        0.1 * t,
        distance_m=0.05 + 0 * t,
        custom_data={"signal": "ramp", "model": "none"},
        start_time_ns=EPOCH_NS,
    )


def test_info_of_complete_bag(tmp_path: Path) -> None:
    text = bag_info(_bag(tmp_path))
    assert "messages:  2000" in text
    assert "duration:  1.996 s" in text
    assert "2023-11-14T22:13:20.000+00:00" in text
    line = next(x for x in text.splitlines() if "/catheter/tip/distance" in x)
    assert "sensor_msgs/msg/Range" in line
    assert "500 msgs" in line
    assert "250.0 Hz" in line
    assert "  signal: ramp" in text
    assert "TRUNCATED" not in text


def test_info_of_truncated_bag_gives_repair_command(tmp_path: Path) -> None:
    bag = _bag(tmp_path)
    mcap = bag / "info_0.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: len(data) // 2])
    text = bag_info(bag)
    assert text.startswith("TRUNCATED: info_0.mcap has no MCAP footer")
    assert f"catheter-lab bag repair {bag}" in text
    assert "  signal: ramp" in text  # from metadata.yaml, which survives a kill
