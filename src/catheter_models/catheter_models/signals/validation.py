"""Checks that refuse a pressure signal or an angle trajectory before anything is driven.

The excitation node checks a pressure signal against its ceiling and the trajectory follower
checks an angle trajectory against the catheter's limits; the tests check every preset with
the same functions. They take plain arrays, not presets, so they are their own module.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from catheter_models.errors import SignalError
from catheter_models.units import bar_to_pa, deg_to_rad, pa_to_bar, rad_to_deg

THESIS_MAX_PRESSURE_PA: Final = bar_to_pa(3.0)
"""Highest gauge pressure the thesis commands (A = 1.5 bar in eq. 4.1 peaks at 3 bar)."""
THESIS_MAX_ANGLE_RAD: Final = deg_to_rad(35.0)
"""Upper bound for desired angles: the rig bends about 30 deg at 3 bar; 35 deg leaves margin."""


def check_pressure_signal(values_pa: npt.ArrayLike, min_pa: float, max_pa: float) -> None:
    """Refuse a pressure signal with a non-finite or out-of-range sample.

    Args:
        values_pa: Gauge pressure samples [Pa].
        min_pa: Lowest allowed gauge pressure [Pa].
        max_pa: Highest allowed gauge pressure [Pa].

    Raises:
        SignalError: Naming the first offending sample, its value and the limit.
    """
    p = np.asarray(values_pa, dtype=np.float64).ravel()
    if p.size == 0:
        raise SignalError("pressure signal is empty; it needs at least one sample")
    if not min_pa <= max_pa:
        raise SignalError(f"pressure limits must satisfy min_pa <= max_pa, got {min_pa}, {max_pa}")
    finite = np.isfinite(p)
    bad = np.flatnonzero(~finite | (p < min_pa) | (p > max_pa))
    if bad.size == 0:
        return
    i = int(bad[0])
    value = p[i]
    if not finite[i]:
        raise SignalError(f"pressure sample {i} is {value}; every sample must be finite")
    limit_pa, side = (
        (min_pa, "below the minimum") if value < min_pa else (max_pa, "above the maximum")
    )
    raise SignalError(
        f"pressure sample {i} is {value:.6g} Pa ({pa_to_bar(value):.4g} bar), {side} "
        f"{limit_pa:.6g} Pa ({pa_to_bar(limit_pa):.4g} bar)"
    )


def check_trajectory(
    t_s: npt.ArrayLike,
    angle_rad: npt.ArrayLike,
    max_angle_rad: float,
    max_rate_rad_s: float,
    max_accel_rad_s2: float,
    *,
    min_angle_rad: float = 0.0,
) -> None:
    """Refuse a trajectory the catheter cannot or must not follow.

    Rates and accelerations are finite differences of the samples, so the limits apply to
    what a controller would be asked to do, sample by sample.

    Args:
        t_s: Sample times [s], strictly increasing.
        angle_rad: Desired bending angle [rad].
        max_angle_rad: Largest allowed angle [rad].
        max_rate_rad_s: Largest allowed |angular rate| [rad/s].
        max_accel_rad_s2: Largest allowed |angular acceleration| [rad/s^2].
        min_angle_rad: Smallest allowed angle [rad]; 0 (straight) by default.

    Raises:
        SignalError: Naming the first offending sample (index and time), its value and the
            limit: non-finite, out of range, time not increasing, too fast, or too abrupt.
    """
    t = np.asarray(t_s, dtype=np.float64).ravel()
    a = np.asarray(angle_rad, dtype=np.float64).ravel()
    if t.shape != a.shape:
        raise SignalError(
            f"trajectory t_s and angle_rad must have equal length, got {t.size} and {a.size}"
        )
    if t.size < 3:
        raise SignalError(f"a trajectory needs at least 3 samples to check rates, got {t.size}")
    for name, arr in (("t_s", t), ("angle_rad", a)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            i = int(bad[0])
            raise SignalError(f"trajectory {name}[{i}] is {arr[i]}; every sample must be finite")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise SignalError(
            f"trajectory time must increase strictly; t_s[{i}] = {t[i]} s follows "
            f"t_s[{i - 1}] = {t[i - 1]} s"
        )

    out_of_range = np.flatnonzero((a < min_angle_rad) | (a > max_angle_rad))
    if out_of_range.size:
        i = int(out_of_range[0])
        limit = min_angle_rad if a[i] < min_angle_rad else max_angle_rad
        raise SignalError(
            f"trajectory angle at sample {i} (t = {t[i]:.4f} s) is {rad_to_deg(a[i]):.4g} deg, "
            f"outside the allowed [{rad_to_deg(min_angle_rad):.4g}, "
            f"{rad_to_deg(max_angle_rad):.4g}] deg (limit {rad_to_deg(limit):.4g} deg)"
        )

    rate = np.diff(a) / dt
    too_fast = np.flatnonzero(np.abs(rate) > max_rate_rad_s)
    if too_fast.size:
        i = int(too_fast[0]) + 1
        raise SignalError(
            f"trajectory rate at sample {i} (t = {t[i]:.4f} s) is "
            f"{rad_to_deg(rate[i - 1]):.4g} deg/s, beyond the limit "
            f"{rad_to_deg(max_rate_rad_s):.4g} deg/s"
        )

    # Acceleration between consecutive rate estimates, which sit at the interval midpoints.
    accel = np.diff(rate) / (0.5 * (dt[1:] + dt[:-1]))
    too_abrupt = np.flatnonzero(np.abs(accel) > max_accel_rad_s2)
    if too_abrupt.size:
        i = int(too_abrupt[0]) + 1
        raise SignalError(
            f"trajectory acceleration at sample {i} (t = {t[i]:.4f} s) is "
            f"{rad_to_deg(accel[i - 1]):.4g} deg/s^2, beyond the limit "
            f"{rad_to_deg(max_accel_rad_s2):.4g} deg/s^2"
        )
