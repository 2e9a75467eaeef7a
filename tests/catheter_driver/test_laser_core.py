"""Laser core: sample clock, eqs. 3.1-3.3 with a stored reference, zeroing."""

import math

import pytest

from catheter_driver.devices.base import LaserAdc, LaserSample
from catheter_driver.laser_core import (
    Calibration,
    LaserAngleCore,
    SampleClock,
    ZeroingError,
)
from catheter_models.errors import CatheterError
from catheter_models.geometry import LaserGeometry

GEOM = LaserGeometry()
P = 0.004


class FakeAdc(LaserAdc):
    def __init__(self) -> None:
        super().__init__()
        self.queue: list[LaserSample] = []

    def _open(self) -> None: ...

    def close(self) -> None: ...

    @property
    def is_open(self) -> bool:
        return True

    def read_samples(self, timeout_s: float) -> list[LaserSample]:
        out, self.queue = self.queue, []
        return out


def test_sample_clock_removes_jitter_and_counts_losses() -> None:
    clock = SampleClock(P)
    delays = [0.003, 0.001, 0.004, 0.002, 0.001]
    stamps = [clock.stamp(LaserSample(k, 1.0, 10.0 + k * P + d)) for k, d in enumerate(delays)]
    # Once the least-delayed sample is seen, stamps are regular at the true instants + 1 ms.
    assert stamps[-1] == pytest.approx(10.0 + 4 * P + 0.001)
    assert stamps[-1] - stamps[-2] == pytest.approx(P)
    clock.stamp(LaserSample(8, 1.0, 10.0 + 8 * P + 0.001))
    assert clock.lost == 3
    # The 16-bit counter wraps.
    c2 = SampleClock(P)
    c2.stamp(LaserSample(65535, 1.0, 0.0))
    assert c2.stamp(LaserSample(0, 1.0, P)) == pytest.approx(P) and c2.lost == 0


def test_angle_uses_the_stored_reference_not_the_running_max() -> None:
    adc = FakeAdc()
    straight = 0.060
    core = LaserAngleCore(adc, GEOM, P, Calibration(straight, 1e-6, 100, "t"))
    target = math.radians(20.0)
    s = straight - float(GEOM.angle_to_displacement_m(target))
    adc.queue = [LaserSample(0, float(GEOM.distance_to_voltage_v(s)), 0.0)]
    (reading,) = core.poll(0.0)
    assert reading.angle_rad == pytest.approx(target, abs=1e-9)
    assert reading.distance_m == pytest.approx(s)
    # With no calibration there is a distance but no angle.
    adc.queue = [LaserSample(1, 3.0, P)]
    assert LaserAngleCore(adc, GEOM, P).poll(0.0)[0].angle_rad is None


def test_zeroing_averages_and_refuses_motion(tmp_path) -> None:
    adc = FakeAdc()
    core = LaserAngleCore(adc, GEOM, P)
    core.start_zeroing()
    u = float(GEOM.distance_to_voltage_v(0.0612))
    adc.queue = [LaserSample(k, u, k * P) for k in range(100)]
    core.poll(0.0)
    cal = core.finish_zeroing()
    assert cal.straight_distance_m == pytest.approx(0.0612) and cal.samples == 100
    cal.save(tmp_path / "cal.json")
    assert Calibration.load(tmp_path / "cal.json") == cal
    core.start_zeroing()
    adc.queue = [LaserSample(k, 2.0 + 0.1 * k, k * P) for k in range(100)]
    core.poll(0.0)
    with pytest.raises(ZeroingError, match="moved"):
        core.finish_zeroing()
    core.start_zeroing()
    with pytest.raises(ZeroingError, match="collected 0"):
        core.finish_zeroing()


def test_unreadable_calibration_names_the_file(tmp_path) -> None:
    bad = tmp_path / "cal.json"
    bad.write_text("{}")
    with pytest.raises(CatheterError, match=r"cal\.json is unreadable"):
        Calibration.load(bad)
