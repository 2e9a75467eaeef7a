"""bench/bench_clstm_step.py: a tiny run writes finite timings, ratios and the targets."""

import importlib
import json
import math
from pathlib import Path
from types import ModuleType

import pytest
import torch

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture
def bench(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    # The benches import each other as scripts do: with bench/ on the path.
    monkeypatch.syspath_prepend(str(BENCH_DIR))
    return importlib.import_module("bench_clstm_step")


def test_quick_run_writes_finite_percentiles_and_ratios(
    bench: ModuleType, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
):
    out = tmp_path / "clstm_step.json"
    monkeypatch.setattr(bench, "BLOCK_STEPS", 100)  # three rounds of interleaving, the last short
    monkeypatch.setattr(bench, "WARMUP_STEPS", 100)
    threads_before = torch.get_num_threads()
    args = ["--quick", "--steps", "250", "--torch-threads", "1", "2", "--out", str(out)]
    assert bench.main(args) == 0
    assert torch.get_num_threads() == threads_before

    result = json.loads(out.read_text())
    assert result["quick"] is True
    assert result["input"]["timed_steps"] == 250
    rows = result["rows"]
    assert [r["role"] for r in rows].count("ours") == 1
    assert rows[0]["role"] == "ours"
    assert rows[0]["runtime"] == "onnxruntime"
    assert rows[0]["form"] == "streaming"
    baselines = [r for r in rows if r["role"] == "baseline"]
    assert {(r["hidden_size"], r["threads"]) for r in baselines} == {
        (size, threads) for size in (64, 128) for threads in (1, 2)
    }
    for row in rows:
        # Rows with more than one torch thread get a quarter of the steps.
        assert row["steps"] == (250 if row["threads"] == 1 else 62), row
        stats = [row[k] for k in ("p50_us", "p99_us", "p999_us", "max_us")]
        assert all(math.isfinite(v) and v > 0.0 for v in stats), row
        assert stats == sorted(stats), row
        if row["role"] == "ours":
            assert row["p50_ratio_vs_ours"] is None
        else:
            for key in ("p50_ratio_vs_ours", "p99_ratio_vs_ours"):
                assert math.isfinite(row[key]) and row[key] > 0.0, row

    # The torch copy of the shipped weights computes what the ONNX graph computes.
    assert result["weights_check"]["max_abs_diff"] <= bench.WEIGHT_CHECK_TOL
    speedup = result["targets"]["speedup_ge_10x"]
    assert math.isfinite(speedup["p50_ratio"]) and math.isfinite(speedup["p99_ratio"])
    assert speedup["met"] == (speedup["p50_met"] and speedup["p99_met"])
    assert isinstance(result["targets"]["p99_le_200us"]["met"], bool)
    assert result["machine"]["onnxruntime"] and result["machine"]["torch"]
    assert "--quick" in result["command"]


def test_quick_runs_do_not_overwrite_the_documented_results(bench: ModuleType):
    assert bench.default_out(quick=False).name == "clstm_step.json"
    assert bench.default_out(quick=True).name == "clstm_step.quick.json"
