"""Resampling a bag onto a grid: a set-point sampled at the grid rate maps one to one.

Bags from the live graph have their own stamps per stream: the excitation's commands exactly
4 ms apart but at another phase than the sensors', and the bag's start (the earliest log time)
on neither. Before, the 250 Hz grid fell on the command stamps only up to float rounding, so
the zero-order hold took the previous command at about every 4th point and skipped one later:
every ramp of a steps excitation came apart and `catheter-lab tune` found no step at all.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from catheter_models.bag import BagRecorder, load_bag
from catheter_models.bag.messages import fluid_pressure_cdr, joint_state_cdr
from catheter_models.bag.series import HOLD_TOLERANCE, BagData
from catheter_models.contract import ANGLE_DESIRED, PRESSURE_COMMAND, PRESSURE_MEASURED, TIP_ANGLE
from catheter_models.feedback.tune import find_steps
from catheter_models.lab.signals import lab_spec
from catheter_models.models.base import Recording
from catheter_models.units import AMBIENT_PRESSURE_PA

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]

EPOCH_NS = 1_700_000_000_123_456_789
"""The bag's first log time: on no stream's phase, as on the live graph."""
PERIOD_NS = 4_000_000  # 250 Hz
COMMAND_PHASE_NS = 2_345_671
"""The commands' stamps are this far from the bag start (modulo the period)."""
SENSOR_PHASE_NS = 1_000_000


def _ramp(n: int) -> FloatArray:
    """A command that changes at every sample, so a repeat or a skip shows in its differences."""
    return 1.0e3 * np.arange(n, dtype=np.float64)


def _bag(
    path: Path,
    command_ns: IntArray,
    command_pa: FloatArray,
    sensor_ns: IntArray,
    *,
    desired_ns: IntArray | None = None,
    angle_age_ns: int = 0,
) -> Path:
    """A bag with each stream on its own stamps (integer ns); the sensors read ``1e6 * t``."""
    names = {s.name: f"/catheter/{s.name}" for s in (PRESSURE_COMMAND, PRESSURE_MEASURED)}
    with BagRecorder(path, flush_period_s=None) as rec:
        rec.add_topic(names["pressure/command"], PRESSURE_COMMAND.msgtype)
        rec.add_topic(names["pressure/measured"], PRESSURE_MEASURED.msgtype)
        rec.add_topic("/catheter/tip/angle", TIP_ANGLE.msgtype)
        if desired_ns is not None:
            rec.add_topic("/catheter/angle/desired", ANGLE_DESIRED.msgtype)
        # The recorder's first message sets the bag start: a log time on no stream's phase.
        first = min(int(command_ns[0]), int(sensor_ns[0]))
        for stamp, value in zip(command_ns.tolist(), command_pa.tolist(), strict=True):
            log = max(stamp, EPOCH_NS) if stamp != first else EPOCH_NS
            cdr = fluid_pressure_cdr(stamp, value, ambient_pa=AMBIENT_PRESSURE_PA)
            rec.write(names["pressure/command"], cdr, log, log)
        for stamp in sensor_ns.tolist():
            t_s = (stamp - EPOCH_NS) / 1e9
            log = max(stamp, EPOCH_NS) if stamp != first else EPOCH_NS
            cdr = fluid_pressure_cdr(stamp, 1e6 * t_s, ambient_pa=AMBIENT_PRESSURE_PA)
            rec.write(names["pressure/measured"], cdr, log, log)
            angle_log = log + angle_age_ns  # a driver that back-dates its samples
            angle = joint_state_cdr(stamp, 1e-3 * t_s)
            rec.write("/catheter/tip/angle", angle, angle_log, angle_log)
        if desired_ns is not None:
            for i, stamp in enumerate(desired_ns.tolist()):
                log = max(stamp, EPOCH_NS)
                rec.write("/catheter/angle/desired", joint_state_cdr(stamp, float(i)), log, log)
    return path


def _stamps(n: int, phase_ns: int, period_ns: int = PERIOD_NS, first: int = 0) -> IntArray:
    return EPOCH_NS + phase_ns + period_ns * np.arange(first, first + n, dtype=np.int64)


def _one_to_one(held: FloatArray, values: FloatArray) -> None:
    """``held`` is a run of consecutive ``values``: each once, none repeated, none skipped."""
    k0 = int(np.flatnonzero(values == held[0])[0])
    np.testing.assert_array_equal(held, values[k0 : k0 + held.size])


def _loaded(path: Path) -> BagData:
    data = load_bag(path)
    assert data.start_time_ns == EPOCH_NS
    return data


def test_exact_4ms_commands_off_the_bag_start_map_one_to_one(tmp_path: Path) -> None:
    n = 5000
    values = _ramp(n)
    # Sensors run from before the commands (the graph is up before `excite` starts).
    data = _loaded(
        _bag(
            tmp_path / "b",
            _stamps(n, 20 * PERIOD_NS + COMMAND_PHASE_NS),
            values,
            _stamps(n + 40, SENSOR_PHASE_NS),
        )
    )
    aligned = data.aligned(rate_hz=250.0)
    assert len(aligned) == n  # the first command to the last: nothing lost at either end
    step = np.diff(aligned.pressure_command_pa)
    assert np.count_nonzero(step == 0.0) == 0, "a command sample repeated"
    assert np.count_nonzero(step > 1.0e3) == 0, "a command sample dropped"
    np.testing.assert_array_equal(aligned.pressure_command_pa, values)
    # The grid lies on the commands' stamps; measurements are interpolated there.
    np.testing.assert_allclose(aligned.t_s, data.pressure_command.t_s, rtol=0.0, atol=1e-12)
    np.testing.assert_allclose(aligned.pressure_measured_pa, 1e6 * aligned.t_s, rtol=1e-9)


def test_a_steps_excitation_from_the_live_graph_keeps_every_step(tmp_path: Path) -> None:
    spec = lab_spec("lab_steps_7")
    assert spec is not None
    values = np.asarray(spec.generate(250.0).values_si, dtype=np.float64)
    n = values.size
    data = _loaded(
        _bag(
            tmp_path / "b",
            _stamps(n, 5 * PERIOD_NS + COMMAND_PHASE_NS),
            values,
            _stamps(n + 10, SENSOR_PHASE_NS),
        )
    )
    aligned = data.aligned(rate_hz=250.0)
    # Equal up to the gauge-absolute round trip of FluidPressure (~1e-11 Pa).
    np.testing.assert_allclose(aligned.pressure_command_pa, values, rtol=0.0, atol=1e-6)

    def steps(p: FloatArray) -> int:
        return len(find_steps(Recording("r", 250.0, p, np.zeros_like(p))))

    assert steps(np.asarray(aligned.pressure_command_pa)) == steps(values) >= 10


@pytest.mark.parametrize("sensors_first", [True, False])
def test_jittered_commands_map_one_to_one(tmp_path: Path, sensors_first: bool) -> None:
    """Jitter of most of a tolerance around the nominal instants, whichever stream starts last.

    When the commands start first, the span starts on a sensor stamp at another phase; the
    grid still lies on the commands' nominal instants.
    """
    rng = np.random.default_rng(3)
    n = 3000
    jitter_ns = int(0.9 * HOLD_TOLERANCE * PERIOD_NS)
    nominal = _stamps(n, (7 if sensors_first else 0) * PERIOD_NS + COMMAND_PHASE_NS)
    command_ns = nominal + rng.integers(-jitter_ns, jitter_ns + 1, n)
    sensor_ns = _stamps(n + 7, SENSOR_PHASE_NS + (0 if sensors_first else 7 * PERIOD_NS))
    sensor_ns = sensor_ns + rng.integers(-jitter_ns, jitter_ns + 1, sensor_ns.size)
    values = _ramp(n)
    data = _loaded(_bag(tmp_path / "b", command_ns, values, sensor_ns))
    aligned = data.aligned(rate_hz=250.0)
    assert len(aligned) >= n - 9
    _one_to_one(np.asarray(aligned.pressure_command_pa), values)


def test_a_gap_is_held_over_and_nothing_else_changes(tmp_path: Path) -> None:
    n = 2000
    keep = np.ones(n, bool)
    keep[1000:1003] = False  # three commands lost, inside the ramp
    sensor_keep = np.ones(n + 6, bool)
    sensor_keep[1500:1510] = False  # ten sensor samples lost
    values = _ramp(n)
    data = _loaded(
        _bag(
            tmp_path / "b",
            _stamps(n, 5 * PERIOD_NS + COMMAND_PHASE_NS)[keep],
            values[keep],
            _stamps(n + 6, SENSOR_PHASE_NS)[sensor_keep],
        )
    )
    aligned = data.aligned(rate_hz=250.0)
    assert len(aligned) == n  # the grid is not cut at a gap
    held = np.asarray(aligned.pressure_command_pa)
    # The last command before the gap holds over the three lost instants, as the valve held it.
    expected = values.copy()
    expected[1000:1003] = values[999]
    np.testing.assert_array_equal(held, expected)
    # Each received command appears on the grid, once where it was received, never more.
    received, counts = np.unique(held, return_counts=True)
    np.testing.assert_array_equal(received, values[keep])
    assert counts.tolist().count(4) == 1 and set(counts.tolist()) == {1, 4}
    # Measurements across their gap are interpolated linearly (here: exactly the line).
    np.testing.assert_allclose(aligned.pressure_measured_pa, 1e6 * aligned.t_s, rtol=1e-9)


def test_1khz_commands_onto_a_250hz_grid_take_every_fourth(tmp_path: Path) -> None:
    n = 8000
    values = _ramp(n)
    period_ns = PERIOD_NS // 4
    data = _loaded(
        _bag(
            tmp_path / "b",
            _stamps(n, 3 * PERIOD_NS + 345_671, period_ns),
            values,
            _stamps(n // 4 + 4, SENSOR_PHASE_NS),
        )
    )
    held = np.asarray(data.aligned(rate_hz=250.0).pressure_command_pa)
    # Every grid point falls on a command stamp and takes that command: every 4th, regularly.
    np.testing.assert_array_equal(np.diff(held), 4.0e3)
    _one_to_one(held, values[int(held[0] / 1.0e3) % 4 :: 4])


def test_250hz_commands_onto_a_1khz_grid_hold_each_for_four_points(tmp_path: Path) -> None:
    n = 1000
    values = _ramp(n)
    data = _loaded(
        _bag(
            tmp_path / "b",
            _stamps(n, 3 * PERIOD_NS + COMMAND_PHASE_NS),
            values,
            _stamps(n + 4, SENSOR_PHASE_NS),
        )
    )
    aligned = data.aligned(rate_hz=1000.0)
    held = np.asarray(aligned.pressure_command_pa)
    received, counts = np.unique(held, return_counts=True)
    # Each command for its 4 ms, from its own stamp; only the last is cut by the span's end.
    np.testing.assert_array_equal(received, values)
    assert set(counts[:-1].tolist()) == {4}
    command_s = data.pressure_command.t_s
    first_point = np.searchsorted(aligned.t_s, command_s[:-1] - 1e-12)
    np.testing.assert_array_equal(held[first_point], values[:-1])


@pytest.mark.parametrize(("offset_ns", "applies_early"), [(500_000, True), (1_600_000, False)])
def test_a_set_point_applies_from_its_stamp_within_the_tolerance(
    tmp_path: Path, offset_ns: int, applies_early: bool
) -> None:
    """``angle/desired`` stamped after the grid's points: taken early only within tolerance."""
    n = 500
    command_ns = _stamps(n, COMMAND_PHASE_NS)
    desired_ns = command_ns + offset_ns
    data = _loaded(
        _bag(
            tmp_path / "b",
            command_ns,
            _ramp(n),
            _stamps(n + 2, SENSOR_PHASE_NS),
            desired_ns=desired_ns,
        )
    )
    aligned = data.aligned(rate_hz=250.0)
    assert aligned.angle_desired_rad is not None
    taken = np.asarray(aligned.angle_desired_rad).astype(np.int64)
    np.testing.assert_array_equal(np.diff(taken), 1)  # one to one all the same
    # How far after each grid point the value it takes was stamped: 0.5 ms is within a
    # quarter of the 4 ms period, so the grid point takes it at once; 1.6 ms is not, so the
    # value applies from the next grid point after its stamp, 2.4 ms after it.
    lead_ms = 1e3 * (data.series["angle/desired"].t_s[taken] - aligned.t_s)
    np.testing.assert_allclose(lead_ms, 0.5 if applies_early else -2.4, atol=1e-6)


def test_how_late_a_back_dated_bend_arrives_is_kept(tmp_path: Path) -> None:
    """The laser driver stamps when the bend was true; the recorder logs when it came: the
    difference is the loop's measurement delay, which ``tune`` designs for."""
    n = 3000
    data = _loaded(
        _bag(
            tmp_path / "b",
            _stamps(n, COMMAND_PHASE_NS),
            _ramp(n),
            _stamps(n, SENSOR_PHASE_NS),
            angle_age_ns=11_600_000,
        )
    )
    assert data.tip_angle.arrival_age_s == pytest.approx(0.0116)
    assert data.pressure_measured.arrival_age_s == pytest.approx(0.0, abs=1e-6)
