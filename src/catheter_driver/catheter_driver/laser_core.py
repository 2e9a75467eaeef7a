"""The laser-angle node without ROS: ADC samples to stamped distance and bend (eqs. 3.1-3.3).

Eq. 3.2's straight-tip reference is a *calibration*: the distance measured while the muscle
is vented, stored to a file by the zeroing service, and loaded at start. It is never the
running maximum of the data (which would move whenever the tip does, e.g. with drift).
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from catheter_driver.devices.base import LaserAdc, LaserSample
from catheter_models.errors import CatheterError
from catheter_models.geometry import Calibration, LaserGeometry

SEQ_MODULUS = 1 << 16
"""The bridge's sample counter is 16 bits and wraps."""


class ZeroingError(CatheterError):
    """Zeroing was refused (pressure not vented, too few or too noisy samples)."""


class SampleClock:
    """Sampling instants from the bridge's counter and the receive times.

    Samples are taken on the bridge's clock every ``period_s``; they arrive late by a
    varying transport delay. The earliest arrival in a sliding window is the best estimate
    of the offset (least delayed), so stamps are ``offset + n * period``: regular, and never
    later than the truth by more than the smallest delay seen.

    Args:
        period_s: the bridge's sample period [s].
        window: number of recent samples over which the offset is estimated.
    """

    def __init__(self, period_s: float, window: int = 250) -> None:
        self.period_s = period_s
        self._offsets: deque[float] = deque(maxlen=window)
        self._last_seq: int | None = None
        self._n = 0
        self.lost = 0

    def stamp(self, sample: LaserSample) -> float:
        """Monotonic sampling instant [s] of ``sample``; counts samples lost on the wire."""
        if self._last_seq is not None:
            step = (sample.seq - self._last_seq) % SEQ_MODULUS
            if step == 0:
                step = 1  # a repeated counter is a bridge fault; keep time moving
            self.lost += step - 1
            self._n += step
        self._last_seq = sample.seq
        self._offsets.append(sample.receive_s - self._n * self.period_s)
        return min(self._offsets) + self._n * self.period_s


@dataclass(frozen=True)
class LaserReading:
    """One stamped reading.

    Attributes:
        sample_s: sampling instant on the monotonic clock [s].
        distance_m: laser distance to the tip marker (eq. 3.1) [m].
        angle_rad: bend (eqs. 3.2-3.3) [rad], or None before the laser is zeroed.
    """

    sample_s: float
    distance_m: float
    angle_rad: float | None


class LaserAngleCore:
    """ADC samples in, stamped distance and bend out; zeroing.

    Args:
        adc: the laser ADC bridge.
        geometry: eqs. 3.1-3.3 constants.
        period_s: the bridge's sample period [s] (250 Hz on the thesis's rig).
        calibration: the stored straight-tip reference, if any.
    """

    def __init__(
        self,
        adc: LaserAdc,
        geometry: LaserGeometry,
        period_s: float,
        calibration: Calibration | None = None,
    ) -> None:
        self.adc = adc
        self.geometry = geometry
        self.clock = SampleClock(period_s)
        self.calibration = calibration
        self._zeroing: list[float] | None = None

    def poll(self, timeout_s: float) -> list[LaserReading]:
        """Read whatever samples arrived (waiting up to ``timeout_s``) and convert them."""
        readings = []
        for sample in self.adc.read_samples(timeout_s):
            distance_m = float(self.geometry.voltage_to_distance_m(sample.voltage_v))
            if self._zeroing is not None:
                self._zeroing.append(distance_m)
            angle = None
            if self.calibration is not None:
                displacement = self.calibration.straight_distance_m - distance_m
                angle = float(self.geometry.displacement_to_angle_rad(displacement))
            readings.append(LaserReading(self.clock.stamp(sample), distance_m, angle))
        return readings

    def start_zeroing(self) -> None:
        """Begin collecting distances for a new straight-tip reference."""
        self._zeroing = []

    def finish_zeroing(self, min_samples: int = 50, max_std_m: float = 0.2e-3) -> Calibration:
        """Average what was collected into a new calibration (not yet saved).

        Raises:
            ZeroingError: too few samples, or the tip moved while zeroing (std too large).
        """
        samples = np.asarray(self._zeroing or [], dtype=float)
        self._zeroing = None
        if samples.size < min_samples:
            raise ZeroingError(
                f"zeroing collected {samples.size} laser samples, need at least {min_samples}; "
                "is the laser ADC streaming?"
            )
        std = float(samples.std())
        if std > max_std_m:
            raise ZeroingError(
                f"the tip moved while zeroing (distance std {std * 1e3:.3f} mm > "
                f"{max_std_m * 1e3:.3f} mm); vent the muscle and let the tip settle"
            )
        return Calibration(
            straight_distance_m=float(samples.mean()),
            std_m=std,
            samples=int(samples.size),
            zeroed_at=time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        )
