"""A joint polish keeps what its finite differences would recompute, and changes nothing."""

import numpy as np
import pytest

from catheter_models.models.cores import base as core_base
from catheter_models.models.cores.base import _BytesLRU
from catheter_models.models.cores.boucwen import BoucWen
from catheter_models.models.data import simulate_recordings
from catheter_models.models.greybox import GreyBox


@pytest.fixture(scope="module")
def recordings() -> list:
    return simulate_recordings(["model_test_arbitrary_plateaus"])


@pytest.fixture(scope="module")
def boucwen_chain(recordings: list) -> tuple[GreyBox, list]:
    base = GreyBox(effects=[], core="boucwen", core_settings={"starts": 1})
    return base.fit(recordings, progress=False), recordings


def _refit(
    base: GreyBox, recs: list, effect: str, monkeypatch: pytest.MonkeyPatch, *, kept: bool
) -> tuple[dict, dict, int]:
    """The chain with ``effect`` refitted warm; its values and the Bouc-Wen kernel's runs."""
    runs = [0]
    columns = BoucWen.columns

    def counted(self: BoucWen, *args: object) -> np.ndarray:
        runs[0] += 1
        return columns(self, *args)  # type: ignore[arg-type]

    with monkeypatch.context() as m:
        m.setattr(BoucWen, "columns", counted)
        if not kept:  # no budget: the polish as it was
            m.setattr(core_base, "POLISH_CACHE_BYTES", 0)
        model = base.with_effect(effect)
        model.polish_evals = 40
        model.fit(recs, progress=False)
    return model.block_values(), model.core_.values(), runs[0]


@pytest.mark.parametrize("effect", ["creep", "tip_dynamics", "transport_delay"])
def test_the_polish_gives_the_same_chain_with_fewer_runs_of_the_core(
    boucwen_chain, monkeypatch: pytest.MonkeyPatch, effect: str
) -> None:
    base, recs = boucwen_chain
    blocks, core, runs = _refit(base, recs, effect, monkeypatch, kept=True)
    blocks_0, core_0, runs_0 = _refit(base, recs, effect, monkeypatch, kept=False)
    # The same arithmetic on the same numbers: equal to the last bit, not approximately.
    assert (blocks, core) == (blocks_0, core_0)
    # The five output weights' differences (and an output block's) reuse the point's state.
    assert runs < 0.75 * runs_0, (runs, runs_0)


@pytest.fixture(scope="module")
def drdpi_chain(recordings: list) -> GreyBox:
    return GreyBox(effects=[], core="drdpi").fit(recordings, progress=False)


@pytest.mark.parametrize("effect", ["creep", "transport_delay"])
def test_a_drdpi_core_polishes_to_the_same_chain_on_what_was_kept(
    drdpi_chain: GreyBox, recordings: list, monkeypatch: pytest.MonkeyPatch, effect: str
) -> None:
    # The DRDPI's own coordinates reuse the input blocks' output, an output block's
    # coordinates the DRDPI's: both read-only, which its operators must take as they are.
    base = drdpi_chain
    blocks, core, _ = _refit(base, recordings, effect, monkeypatch, kept=True)
    assert (blocks, core) == _refit(base, recordings, effect, monkeypatch, kept=False)[:2]


def test_what_is_kept_is_dropped_oldest_first_beyond_its_budget() -> None:
    one = np.zeros(100)  # 800 bytes
    kept = _BytesLRU(budget_bytes=2000)
    kept.put("a", one.copy())
    kept.put("b", one.copy())
    assert kept.get("a") is not None  # now the most recent
    kept.put("c", one.copy())  # 2,400 bytes: the least recent ("b") goes
    assert kept.get("b") is None
    assert kept.get("a") is not None and kept.get("c") is not None


def test_what_is_kept_cannot_be_changed_by_a_caller() -> None:
    kept = _BytesLRU(budget_bytes=10_000)
    kept.put("a", np.zeros(10))
    hit = kept.get("a")
    assert hit is not None
    with pytest.raises(ValueError, match="read-only"):
        hit[0] = 1.0


def test_one_array_larger_than_the_budget_is_still_kept_and_no_budget_keeps_nothing() -> None:
    # A polish on hours of data must still reuse the point it differences.
    kept = _BytesLRU(budget_bytes=10)
    kept.put("a", np.zeros(100))
    assert kept.get("a") is not None
    none = _BytesLRU(budget_bytes=0)
    none.put("a", np.zeros(1))
    assert none.get("a") is None
