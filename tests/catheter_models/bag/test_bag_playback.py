"""Reading a bag for playback: order, selection, offered QoS, refusals (no ROS needed)."""

from __future__ import annotations

from pathlib import Path

import pytest

from catheter_models.bag.playback import Player
from catheter_models.errors import BagError, ParameterError

BAG = Path(__file__).resolve().parents[3] / "bags" / "model_test_descending_sine"


def test_messages_come_in_log_time_order_from_the_offset_on() -> None:
    player = Player(BAG, topics=["tip/angle"], remap={"/catheter/tip/angle": "/x/angle"})
    assert list(player.topics) == ["/catheter/tip/angle"]
    assert player.topics["/catheter/tip/angle"].out == "/x/angle"
    assert player.topics["/catheter/tip/angle"].qos["reliability"] in {"reliable", "best_effort"}
    times = [t for _, t, _ in player.messages(start_offset_s=5.0)]
    assert times == sorted(times)
    assert times[0] >= player.start_ns + 5_000_000_000
    assert len(times) < player.count


def test_refusals_name_what_was_wrong() -> None:
    with pytest.raises(BagError, match="no topic 'tip/nope'"):
        Player(BAG, topics=["tip/nope"])
    with pytest.raises(ParameterError, match="not among the topics played"):
        Player(BAG, topics=["tip/angle"], remap={"/catheter/pressure/command": "/y"})
