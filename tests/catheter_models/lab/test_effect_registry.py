"""One description per effect: the lab's blocks say their evidence, regimes and plant
counterpart, and the lab's tables and ``catheter-lab effects`` are read from them."""

from __future__ import annotations

import pytest

from catheter_models import cli
from catheter_models.lab import diagnose
from catheter_models.lab.residuals import TEST_LABELS, TEST_NAMES
from catheter_models.metrics import REGIMES
from catheter_models.models.blocks import BLOCKS, CHECKS, DEFAULT_CHAIN_EFFECTS, FORMS, block
from catheter_models.plant.config import EFFECTS


@pytest.mark.parametrize("effect", list(BLOCKS))
def test_a_catalogue_block_says_its_evidence_regimes_and_plant_counterpart(effect: str) -> None:
    cls = BLOCKS[effect]
    assert cls.evidence_test in TEST_NAMES, cls.evidence_test
    assert cls.regimes, f"{effect} names no regime where it shows"
    assert set(cls.regimes) <= {*REGIMES, "vented"}, cls.regimes
    assert cls.plant_effect in EFFECTS, cls.plant_effect
    # The diagnosis's tables are the blocks' own words, not a copy.
    assert diagnose.EVIDENCE_TEST[effect] == cls.evidence_test
    assert diagnose.EFFECT_REGIMES[effect] == cls.regimes


def test_every_plant_effect_is_in_the_core_or_has_a_block_and_none_twice() -> None:
    counterparts = [b.plant_effect for b in BLOCKS.values()]
    assert len(counterparts) == len(set(counterparts))
    assert set(EFFECTS) == set(DEFAULT_CHAIN_EFFECTS) | set(counterparts)
    assert set(diagnose.EVIDENCE_TEST) == set(BLOCKS)


def test_catheter_lab_effects_offers_what_add_takes(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli._cmd_effects(None) == 0  # type: ignore[arg-type]
    out = capsys.readouterr().out
    for effect in FORMS:
        assert f"catheter-lab add {effect})" in out, effect
        assert block(effect).effect == effect  # and add takes it
    for cls in BLOCKS.values():
        assert TEST_LABELS[cls.evidence_test] in out
    for cls in CHECKS.values():
        assert cls.stands_for in out
    for name in DEFAULT_CHAIN_EFFECTS:
        assert f"{name}  (thesis rig:" in out
