"""bench/bench_soak.py: the pure analysis on synthetic inputs (no graph, no /proc walk)."""

import importlib
import math
import struct
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

BENCH_DIR = Path(__file__).resolve().parents[2] / "bench"


@pytest.fixture
def soak(monkeypatch: pytest.MonkeyPatch) -> ModuleType:
    # The benches import each other as scripts do: with bench/ on the path.
    monkeypatch.syspath_prepend(str(BENCH_DIR))
    return importlib.import_module("bench_soak")


def test_parse_stat_survives_parentheses_and_spaces_in_comm(soak: ModuleType):
    text = "4242 (python3 (x) y) S 17 4242 4242 0 -1 4194560 1234 0 0 0"
    assert soak.parse_stat(text) == (4242, 17)
    assert soak.parse_stat("1 (init) S 0 1 1 0") == (1, 0)


def test_descendants_walks_the_whole_tree_and_nothing_else(soak: ModuleType):
    ppid_of = {1: 0, 10: 1, 11: 10, 12: 10, 13: 12, 20: 1, 21: 20}
    assert soak.descendants(10, ppid_of) == [10, 11, 12, 13]
    assert soak.descendants(13, ppid_of) == [13]
    assert soak.descendants(99, ppid_of) == [99]  # gone: only itself


def test_vmrss_and_process_names(soak: ModuleType):
    status = "Name:\tpython\nVmPeak:\t  9000 kB\nVmRSS:\t   51234 kB\nThreads:\t9\n"
    assert soak.parse_vmrss_kb(status) == 51234
    assert soak.parse_vmrss_kb("Name:\tkthreadd\nState:\tS\n") is None
    cmd = b"/v/bin/python\0-m\0catheter_control.recorder_node\0--ros-args\0-r\0__ns:=/c\0"
    assert soak.process_name(cmd) == "recorder"
    assert soak.process_name(b"python\0-m\0catheter_driver.sim_hardware_node\0") == "sim_hardware"
    assert soak.process_name(b"python\0-m\0catheter_control.follow_trajectory\0--sim\0") == (
        "follow_trajectory"
    )
    assert soak.process_name(b"/usr/bin/python3\0bench/x.py\0") == "x"
    assert soak.process_name(b"/usr/bin/sleep\x0010\0") == "sleep"
    assert soak.process_name(b"") == "?"


def test_repeat_knots_joins_copies_one_spacing_apart(soak: ModuleType):
    t = np.arange(0.0, 3.0, 1.0)  # 0 1 2: a 3 s block
    t_out, a_out = soak.repeat_knots(t, [0.0, 1.0, 0.0], 7.0)
    np.testing.assert_allclose(t_out, np.arange(8.0))
    np.testing.assert_allclose(a_out, [0, 1, 0, 0, 1, 0, 0, 1])
    assert np.all(np.diff(t_out) > 0)


def _series(missed_at: list[float], duration_s: float) -> list[dict[str, object]]:
    """Reports each second from -1 s to duration + 1 s, cumulative, as strings, one blank."""
    rows: list[dict[str, object]] = []
    for i in range(-1, int(duration_s) + 2):
        t = i + 0.3
        rows.append(
            {
                "t_s": t,
                "state": "following",
                "ticks": str(1000 * (i + 5)),
                "missed_deadlines": str(sum(m <= t for m in missed_at)),
            }
        )
    rows[3]["missed_deadlines"] = ""  # a report that lacks the value is skipped
    return rows


def test_per_minute_bins_add_up_and_fold_the_edges(soak: ModuleType):
    # -0.5 arrives with the report at 0.3; 180.5 with the one after the end (ramp-down).
    missed_at = [-0.5, 10.0, 70.0, 71.0, 170.0, 180.5]
    pts = soak.counter_points(_series(missed_at, 180.0), "missed_deadlines")
    assert soak.per_bin(pts, 60.0, 180.0) == [2, 2, 2]
    assert sum(soak.per_bin(pts, 10.0, 180.0)) == 6
    ticks = soak.counter_points(_series([], 180.0), "ticks")
    assert soak.per_bin(ticks, 60.0, 180.0) == [60000, 60000, 62000]


def test_thirds_growth_flags_a_rising_rate_only(soak: ModuleType):
    steady = [float(s) for s in range(1, 300, 3)]  # one every 3 s throughout
    pts = soak.counter_points(_series(steady, 300.0), "missed_deadlines")
    g = soak.thirds_growth(pts, 0.0, 300.0)
    assert abs(g["first_third"] - g["last_third"]) <= 1
    assert not g["growth"]
    assert g["first_third_per_min"] == pytest.approx(20.0, abs=0.7)

    rising = [float(s) for s in range(200, 300)] + [5.0]  # 1/s in the last third only
    g = soak.thirds_growth(soak.counter_points(_series(rising, 300.0), "missed_deadlines"), 0, 300)
    assert g["first_third"] == 1 and g["last_third"] >= 99
    assert g["growth"]

    # A start-up burst inside the warm-up neither counts nor hides growth.
    burst = [1.0 + 0.01 * i for i in range(500)] + [float(s) for s in range(250, 300)]
    pts = soak.counter_points(_series(burst, 300.0), "missed_deadlines")
    g = soak.thirds_growth(pts, 60.0, 300.0)
    assert g["warmup"] == 500 and g["first_third"] == 0 and g["last_third"] == 50
    assert g["growth"]
    assert not soak.thirds_growth(pts, 0.0, 300.0)["growth"]  # what counting it would do

    none = soak.thirds_growth(soak.counter_points(_series([], 60.0), "missed_deadlines"), 12, 60)
    assert none["first_third"] == none["last_third"] == 0
    assert not none["growth"]


def test_rss_growth_flags_a_leak_not_a_step_or_noise(soak: ModuleType):
    rng = np.random.default_rng(0)
    t = np.arange(-10.0, 601.0)
    base = 80.0 + 0.05 * rng.standard_normal(t.size)

    flat = soak.rss_growth(t, base, 60.0, 600.0)
    assert not flat["growth"]
    assert abs(flat["slope_mb_per_min"]) < 0.01
    assert flat["window_s"] == 540.0 and flat["samples"] == 541

    # One-off steps (an arena grown once) are not growth; least squares would call the
    # 2 MB one 20 MB/h.
    for at_s, mb in ((200.0, 2.0), (300.0, 0.9), (550.0, 5.0)):
        step = base + np.where(t > at_s, mb, 0.0)
        assert not soak.rss_growth(t, step, 60.0, 600.0)["growth"], (at_s, mb)
    # Steps every 30 s are a leak, however they come.
    stairs = base + np.floor(t / 30.0) * 0.25  # 30 MB/h
    fit = soak.rss_growth(t, stairs, 60.0, 600.0)
    assert fit["growth"] and fit["slope_mb_per_h"] == pytest.approx(30.0, rel=0.15)

    leak = base + t * (20.0 / 3600.0)  # 20 MB/h
    fit = soak.rss_growth(t, leak, 60.0, 600.0)
    assert fit["growth"]
    assert fit["slope_mb_per_h"] == pytest.approx(20.0, rel=0.05)
    assert fit["fitted_growth_mb"] == pytest.approx(3.0, rel=0.05)

    # Start-up growth before the warm-up ends does not count.
    startup = base + np.clip(t, None, 50.0) * 0.5
    assert not soak.rss_growth(t, startup, 60.0, 600.0)["growth"]
    # A short window cannot resolve 20 MB/h: the floor decides.
    short = soak.rss_growth(t, leak, 12.0, 60.0)
    assert not short["growth"]
    assert short["resolvable_mb_per_h"] == pytest.approx(75.0)
    # Missing samples (the process not yet started) are ignored; too few gives no verdict.
    assert soak.rss_growth([0.0, 1.0], [1.0, math.nan], 0.0, 10.0)["growth"] is None


def test_cdr_header_stamp_both_endiannesses(soak: ModuleType):
    le = b"\x00\x01\x00\x00" + struct.pack("<iI", 1700000000, 123456789) + b"\x05\x00"
    be = b"\x00\x00\x00\x00" + struct.pack(">iI", 12, 5)
    assert soak.cdr_header_stamp_ns(le) == 1700000000_123456789
    assert soak.cdr_header_stamp_ns(be) == 12_000_000_005


def test_stamp_gaps_counts_missing_duplicates_and_jitter(soak: ModuleType):
    period = 1_000_000  # 1 kHz
    s = np.arange(1000, dtype=np.int64) * period + 5_000_000_000
    s = s + np.random.default_rng(1).integers(-2, 3, s.size)  # ns rounding jitter
    clean = soak.stamp_gaps(s, 1000.0)
    assert clean["messages"] == clean["expected"] == 1000
    assert clean["missing"] == clean["gaps"] == clean["duplicates"] == 0
    assert clean["span_s"] == pytest.approx(0.999, abs=1e-6)

    holed = np.delete(s, [100, 500, 501, 502])  # one single and one triple hole
    holed = np.concatenate([holed, holed[:2]])  # two duplicates, out of order at the end
    g = soak.stamp_gaps(holed, 1000.0)
    assert g["messages"] == 998
    assert g["duplicates"] == 2
    assert g["out_of_order"] == 1
    assert g["expected"] == 1000
    assert g["missing"] == 4
    assert g["gaps"] == 2
    assert g["max_gap_periods"] == pytest.approx(4.0, abs=1e-5)
    assert soak.stamp_gaps([], 250.0)["messages"] == 0


def test_bag_table_splits_skipped_ticks_from_drops(soak: ModuleType):
    ms, ns4 = 1_000_000, 4_000_000
    ticks = np.arange(10_000, dtype=np.int64) * ms
    skipped = np.delete(ticks, [1000, 2000, 2001])  # 3 missed deadlines, in both streams
    desired = np.delete(skipped, [5000])  # and one drop in angle/desired only
    sensor = np.delete(np.arange(2500, dtype=np.int64) * ns4, [7])
    stamps = {
        "/catheter/pressure/command": skipped,
        "/catheter/angle/desired": desired,
        "/catheter/pressure/measured": sensor,
        "/catheter/tip/angle": np.arange(2500, dtype=np.int64) * ns4,
    }
    rows = soak.bag_table(stamps, "/catheter", compensator_skipped=3)
    cmd, des = rows["pressure/command"], rows["angle/desired"]
    assert cmd["missing"] == 3 and cmd["explained_by_skipped_ticks"] == 3 and cmd["dropped"] == 0
    assert des["missing"] == 4 and des["dropped"] == 1
    assert des["missing_in_this_not_sibling"] == 1 and cmd["missing_in_this_not_sibling"] == 0
    assert rows["pressure/measured"]["dropped"] == 1  # sim_hardware publishes its backlog
    assert rows["tip/angle"]["dropped"] == 0
    assert rows["tip/distance"]["messages"] == 0  # not recorded: nothing to drop
    # The same drop in both streams hides behind a missed deadline only up to the count.
    unexplained = soak.bag_table(stamps, "/catheter/", compensator_skipped=0)
    assert unexplained["pressure/command"]["dropped"] == 3


def test_downsample_keeps_one_sample_per_slot(soak: ModuleType):
    t = [-1.5, -0.5, 0.4, 1.4, 9.9, 10.1, 19.0, 20.5]
    out = soak.downsample(t, {"a": [1.0, 2.0, math.nan, 4.0, 5.0, 6.0, 7.0, 8.0]}, 10.0)
    assert out["t_s"] == [-1.5, 0.4, 10.1, 20.5]
    assert out["rss_mb"]["a"] == [1.0, None, 6.0, 8.0]


def test_early_stop_and_log_problems(soak: ModuleType):
    rows = [{"t_s": t + 0.3, "state": "following"} for t in range(-1, 61)]
    rows[0]["state"] = rows[-1]["state"] = "idle"  # before the start, after the end
    assert soak.early_stop_s(rows, 60.0) is None
    for row in rows[11:]:
        row["state"] = "idle"  # a stale sensor ramped it down at about 10 s
    rows[10]["state"] = "ramping_down"
    assert soak.early_stop_s(rows, 60.0) == pytest.approx(9.3)
    log = (
        "[INFO] [1.0] [catheter.compensator]: compensator 'clstm' at 1000 Hz\n"
        "[ERROR] [9.2] [catheter.compensator]: ramping down: tip/angle stale: no sample\n"
        "[WARN] [9.3] [catheter.sim_hardware]: watchdog\n"
    )
    assert soak.log_problems(log) == log.splitlines()[1:]
    assert soak.log_problems(log, limit=1) == log.splitlines()[1:2]


def _synthetic_run(stop_s: float | None) -> dict[str, object]:
    """report.json, RSS samples and bag of a 60 s run; the compensator stops at stop_s."""
    ms = 1_000_000
    end_ms = 60_000 if stop_s is None else int(stop_s * 1000)
    cmd = np.delete(np.arange(end_ms, dtype=np.int64) * ms + 10**18, [5000, 5001])
    sensors = np.arange(-2_000, 62_000, 4, dtype=np.int64) * ms + 10**18
    sensors_holed = np.delete(sensors, [100])
    ns = "/catheter"
    stamps = {
        f"{ns}/pressure/command": cmd,
        f"{ns}/angle/desired": cmd,
        f"{ns}/pressure/measured": sensors_holed,
        f"{ns}/tip/distance": sensors,
        f"{ns}/tip/angle": sensors,
        f"{ns}/trajectory": np.zeros(1, np.int64),
    }
    series = []
    for i in range(-1, 62):
        t = i + 0.3
        running = 0 < t < 60 and (stop_s is None or t < stop_s)
        series.append(
            {
                "t_s": t,
                "state": "following" if running else "idle",
                "ticks": str(1000 * (i + 1)),
                "missed_deadlines": str(0 if t < 5 else 2),
            }
        )
    report = {
        "timing": {"ticks": 62000, "missed_deadlines": 2, "missed_fraction": 2 / 62002},
        "timing_series": series,
        "overall": {"rmse_deg": 0.4},
    }
    samples = [
        (float(t), {"compensator": 200.0, "follow_trajectory": 100.0 + t * 0.2}) for t in range(70)
    ]
    bag = {
        "stamps": stamps,
        "summary_counts": {k: v.size for k, v in stamps.items()},
        "decode_check": dict.fromkeys(stamps, True),
        "read_s": 0.1,
    }
    return {"report": report, "samples": samples, "bag": bag}


def test_analyse_a_clean_run_and_one_that_stopped(
    soak: ModuleType, capsys: pytest.CaptureFixture[str]
):
    run = _synthetic_run(None)
    result = soak.analyse(
        run["report"],
        run["samples"],
        5.0,
        run["bag"],
        duration_s=60.0,
        warmup_s=12.0,
        namespace="/catheter",
    )
    v = result["verdicts"]
    assert v["run_completed"] and v["compensator_stopped_at_s"] is None
    assert v["missed_deadlines_growth"] is False
    assert result["missed_deadlines"]["warmup"] == 2
    assert not v["memory_growth"]
    assert v["memory_growth_by_process"]["follow_trajectory"]  # reported, not judged
    topics = result["bag"]["topics"]
    assert topics["pressure/command"]["explained_by_skipped_ticks"] == 2
    assert topics["pressure/command"]["dropped"] == 0
    assert topics["pressure/measured"]["dropped"] == 1
    assert v["dropped_messages"] == 1 and not v["ok"]
    assert v["bag_counts_consistent"]
    assert result["bag"]["trajectory_messages"] == 1
    assert result["rss"]["t_s"][0] == -5.0
    soak.print_table(result)
    assert "followed all of it" in capsys.readouterr().out

    stopped = _synthetic_run(9.3)
    result = soak.analyse(
        stopped["report"],
        stopped["samples"],
        5.0,
        stopped["bag"],
        duration_s=60.0,
        warmup_s=12.0,
        namespace="/catheter",
    )
    assert not result["verdicts"]["run_completed"]
    assert result["verdicts"]["compensator_stopped_at_s"] == pytest.approx(9.3)
    assert result["bag"]["compensator_span_s"] == pytest.approx(9.299)
    soak.print_table(result)
    assert "STOPPED EARLY" in capsys.readouterr().out


def test_stalls_are_placed_against_the_loop_that_fell_behind(soak: ModuleType):
    series = [
        {"t_s": 1.0, "behind_max_ms": "2", "tip_angle_longest_silence_ms": "8"},
        {"t_s": 2.0, "behind_max_ms": "3", "tip_angle_longest_silence_ms": "104"},
        {"t_s": 3.0, "behind_max_ms": "90", "pressure_measured_longest_silence_ms": "95"},
        {"t_s": 4.0, "behind_max_ms": "1", "tip_angle_longest_silence_ms": "70"},
        {"t_s": 5.0, "behind_max_ms": "1"},  # an older compensator: no silences reported
    ]
    # Reports on the driver's own 1 Hz clock; one covers the second before it, so the one at
    # 1.9 s overlaps the compensator's report at 2 s (and the one at 1 s), not the one at 3 s.
    driver = [
        {"t_s": 0.9, "behind_max_ms": "1"},
        {"t_s": 1.9, "behind_max_ms": "100"},
        {"t_s": 3.9, "behind_max_ms": "1"},
        {"t_s": 4.9, "behind_max_ms": "2"},
    ]
    stalls = soak.stall_table(series, driver)
    assert stalls["measured"] and stalls["seconds_with_a_stall"] == 3
    assert [r["where"] for r in stalls["rows"]] == [
        "driver behind",
        "compensator behind",
        "neither loop behind",
    ]
    assert stalls["rows"][0]["silence_ms"] == {"tip_angle": 104.0}
    assert not soak.stall_table(series[-1:], driver)["measured"]
