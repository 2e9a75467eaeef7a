"""Explained chains as the lab would write them, for the tests and benchmarks of ``tune --chain``.

A foreign plant's case knows its own physics; these put that physics into the lab's block
forms, so the loop can be shaped from the chain an explanation would have found. The test
(tests/catheter_models/feedback/test_chain_loop.py) and the benchmark
(bench/bench_chain_rule.py) share them: the bench's figures are about the same chains the
tests assert on."""

from __future__ import annotations

from foreign_plants.cases import Case

from catheter_models.models.cores import make_core
from catheter_models.models.greybox import GreyBox

Blocks = dict[str, list[float]]


def chain(blocks: Blocks) -> GreyBox:
    """A grey box holding these blocks; the loop's shape reads the blocks only, so the core's
    values do not enter it."""
    model = GreyBox(effects=list(blocks), core="free_pi")
    model._set(make_core("free_pi"), blocks, 250.0)
    return model


def lag_block(time_constant_s: float) -> list[float]:
    """The lab's pneumatic-lag block at its plainest: a linear fill, no flow limit, equal fill
    and vent."""
    return [time_constant_s, 1.0, 1e8, 1.0, 0.0, 0.0, 0.0]


def true_blocks(case: Case) -> Blocks:
    """The chain of the plant's hidden effects, at the values the case drew."""
    blocks: Blocks = {}
    for effect in case.effects:
        p = effect.params
        if effect.name == "transport_delay":
            blocks["transport_delay"] = [p["delay_s"]]
        elif effect.name == "pneumatic_lag":
            blocks["pneumatic_lag"] = lag_block(p["time_constant_s"])
        elif effect.name == "tip_dynamics":
            blocks["tip_dynamics"] = [p["natural_frequency_hz"], p["damping_ratio"], 0.0]
    return blocks
