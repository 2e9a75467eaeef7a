"""One description per effect: each block says its evidence, regimes and plant counterpart;
the diagnosis, ``catheter-lab effects`` and ``catheter-lab add`` read the one catalogue, so an
effect added in one file (``tests/support/toy_effect.py``) is offered, fitted and ranked."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from catheter_models import cli, cli_lab
from catheter_models.bag.from_arrays import write_bag_from_arrays
from catheter_models.lab.residuals import TEST_LABELS, TEST_NAMES
from catheter_models.metrics import REGIMES
from catheter_models.models.base import Recording
from catheter_models.models.blocks import (
    BLOCKS,
    CHECKS,
    DEFAULT_CHAIN_EFFECTS,
    FORMS,
    block,
    register,
    unregister,
)
from catheter_models.plant.config import EFFECTS


@pytest.mark.parametrize("effect", list(BLOCKS))
def test_a_catalogue_block_says_its_evidence_regimes_and_plant_counterpart(effect: str) -> None:
    cls = BLOCKS[effect]
    assert cls.evidence_test in TEST_NAMES, cls.evidence_test
    assert cls.regimes, f"{effect} names no regime where it shows"
    assert set(cls.regimes) <= {*REGIMES, "vented"}, cls.regimes
    assert cls.plant_effect in EFFECTS, cls.plant_effect


def test_every_plant_effect_is_in_the_core_or_has_a_block_and_none_twice() -> None:
    counterparts = [b.plant_effect for b in BLOCKS.values()]
    assert len(counterparts) == len(set(counterparts))
    assert set(EFFECTS) == set(DEFAULT_CHAIN_EFFECTS) | set(counterparts)


def test_catheter_lab_effects_offers_what_add_takes(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli_lab._cmd_effects(None) == 0  # type: ignore[arg-type]
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


# -- a toy effect, added in one file, is offered, fitted and ranked -------------------------------

LATENCY_S = 0.12


@pytest.fixture
def toy() -> Iterator[type]:
    from toy_effect import SensorLatency

    register(SensorLatency)
    try:
        yield SensorLatency
    finally:
        unregister(SensorLatency.effect)


def _late(recordings: list[Recording]) -> list[Recording]:
    """Recordings whose bend was read ``LATENCY_S`` late (what the toy effect models)."""
    out = []
    for r in recordings:
        n = round(LATENCY_S * r.rate_hz)
        late = np.concatenate([np.full(n, r.angle_rad[0]), r.angle_rad[: r.angle_rad.size - n]])
        out.append(Recording(r.name, r.rate_hz, r.pressure_pa, late))
    return out


def _bag(path: Path, rec: Recording) -> Path:
    t_s = np.arange(rec.pressure_pa.size) / rec.rate_hz
    return write_bag_from_arrays(
        path, t_s, rec.pressure_pa, rec.pressure_pa, rec.angle_rad, start_time_ns=10**18
    )


def test_a_toy_effect_in_one_file_is_offered_fitted_and_ranked(
    toy: type, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from catheter_models.lab.diagnose import diagnose
    from catheter_models.models import load_model
    from catheter_models.models.data import simulate_recordings
    from catheter_models.models.greybox import GreyBox

    train = _late(simulate_recordings(["train_zero_f0.8", "train_nonzero_f0.6"]))
    test = _late(simulate_recordings(["model_test_up_chirp"], seed0=7))
    # Offered: catheter-lab effects lists it, with the command that adds it.
    assert cli_lab._cmd_effects(None) == 0  # type: ignore[arg-type]
    assert f"catheter-lab add {toy.effect})" in capsys.readouterr().out
    # Fitted: catheter-lab add puts it in the chain, with the latency it was made with.
    base = GreyBox(core="free_pi").fit(train, progress=False)
    base.save(tmp_path / "base", training=train)
    bags = [_bag(tmp_path / f"train{i}", r) for i, r in enumerate(train)]
    argv = ["add", toy.effect, str(tmp_path / "base"), "-o", str(tmp_path / "new")]
    argv += ["--train", *map(str, bags), "--lab", str(tmp_path / "lab"), "--no-progress"]
    with pytest.raises(SystemExit) as exited:
        cli.main(argv)
    assert exited.value.code in (0, None), capsys.readouterr()
    added = load_model(tmp_path / "new")
    assert isinstance(added, GreyBox) and toy.effect in added.effects
    # Part of a latency is taken up by the core's rate-dependent thresholds (a late loop looks
    # like a wider one): 60 ms of the 120 ms made here land in the block.
    assert 0.25 * LATENCY_S < added.blocks_[toy.effect][0] < 1.25 * LATENCY_S, added.blocks_
    # Ranked: the diagnosis tries it on held-out data and finds the error it removes.
    found = diagnose(base, train, test, effects=[toy.effect], cores=[], reference=False, workers=1)
    (candidate,) = found.candidates
    assert candidate.effect == toy.effect
    assert candidate.rmse_test_deg < 0.9 * found.rmse_test_deg, found.text()
