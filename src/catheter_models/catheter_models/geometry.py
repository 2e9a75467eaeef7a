"""Laser measurement geometry of the thesis (eqs. 3.1-3.3) and its inverse.

A laser distance sensor beside the tip reads a voltage ``U``. Eq. 3.1 turns it into the
distance ``s = m U + n`` to the tip marker; eq. 3.2 turns that into the tip displacement
``d' = s_straight - s`` from the straight pose; eq. 3.3, a constant-curvature model, turns the
displacement into the bending angle ``theta = 2 d' L / (H^2 + d'^2)``.

The thesis takes ``s_straight`` as the largest distance in each recorded data group (eq. 3.2).
A live system cannot look ahead, and one large noisy sample would shift every angle, so here
the straight-tip distance is a calibration stored when the laser is zeroed with the catheter
straight. :func:`straight_reference_from_samples` gives the thesis's per-group maximum for
reproducing its offline numbers.

Eq. 3.3 is monotonic only for ``|d'| < H``: its largest angle is ``L / H`` rad (about 67.9 deg
for the thesis's segment) at ``d' = H``, beyond which two displacements give one angle. The
functions here refuse displacements and angles outside that branch rather than fold them.
Both directions are odd functions, so the branch is symmetric: a slightly negative angle
(the tip a little past straight, or noise) maps through unchanged.

Every function accepts a float or a numpy array and returns the same kind.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Final

import numpy as np
import numpy.typing as npt

from .errors import CatheterError, ParameterError
from .units import FloatOrArray, m_to_mm, mm_to_m, rad_to_deg

FloatArray = npt.NDArray[np.float64]


def _require_finite(values: float | FloatArray, name: str) -> None:
    arr = np.asarray(values, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(arr.ravel()))
    if bad.size:
        i = int(bad[0])
        where = "" if arr.ndim == 0 else f"[{i}]"
        raise ParameterError(
            f"{name}{where} is {arr.ravel()[i]}; geometry needs finite values (a laser "
            "dropout must be handled before conversion)"
        )


@dataclass(frozen=True)
class LaserGeometry:
    """Laser calibration (eq. 3.1) and segment geometry (eq. 3.3), in SI.

    Defaults are the thesis's values: m = 4.05 mm/V, n = 29.36 mm, L = 77 mm, H = 65 mm.

    Attributes:
        m_per_v: Sensor slope m [m/V].
        offset_m: Sensor offset n [m] (distance at 0 V).
        length_m: L [m], eq. 3.3 (bending segment length term).
        height_m: H [m], eq. 3.3 (laser-to-segment geometry term).
    """

    m_per_v: float = mm_to_m(4.05)
    offset_m: float = mm_to_m(29.36)
    length_m: float = mm_to_m(77.0)
    height_m: float = mm_to_m(65.0)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.m_per_v) and self.m_per_v != 0.0):
            raise ParameterError(
                f"m_per_v must be finite and non-zero (thesis: 4.05e-3 m/V), got {self.m_per_v!r}"
            )
        if not math.isfinite(self.offset_m):
            raise ParameterError(
                f"offset_m must be finite (thesis: 29.36e-3 m), got {self.offset_m!r}"
            )
        for name, value, thesis in (
            ("length_m", self.length_m, "0.077"),
            ("height_m", self.height_m, "0.065"),
        ):
            if not (math.isfinite(value) and value > 0.0):
                raise ParameterError(
                    f"{name} must be finite and > 0 (thesis: {thesis} m), got {value!r}"
                )

    @property
    def max_angle_rad(self) -> float:
        """Largest angle eq. 3.3 can give, ``L / H`` [rad], reached at ``d' = H``."""
        return self.length_m / self.height_m

    def voltage_to_distance_m(self, voltage_v: FloatOrArray) -> FloatOrArray:
        """Eq. 3.1: laser voltage [V] to distance to the tip marker [m].

        Raises:
            ParameterError: If a voltage is not finite.
        """
        _require_finite(voltage_v, "voltage_v")
        return voltage_v * self.m_per_v + self.offset_m

    def distance_to_voltage_v(self, distance_m: FloatOrArray) -> FloatOrArray:
        """Inverse of eq. 3.1: distance [m] to the voltage [V] the laser would read.

        Raises:
            ParameterError: If a distance is not finite.
        """
        _require_finite(distance_m, "distance_m")
        return (distance_m - self.offset_m) / self.m_per_v

    def displacement_to_angle_rad(self, displacement_m: FloatOrArray) -> FloatOrArray:
        """Eq. 3.3 in radians: ``theta = 2 d' L / (H^2 + d'^2)``.

        Args:
            displacement_m: Tip displacement d' from straight [m], ``|d'| < H``.

        Returns:
            Bending angle [rad].

        Raises:
            ParameterError: If a displacement is not finite or ``|d'| >= H`` (off the
                monotonic branch; the angle would fold back).
        """
        _require_finite(displacement_m, "displacement_m")
        d = np.asarray(displacement_m, dtype=np.float64)
        bad = np.flatnonzero(np.abs(d.ravel()) >= self.height_m)
        if bad.size:
            i = int(bad[0])
            where = "" if d.ndim == 0 else f"[{i}]"
            raise ParameterError(
                f"displacement_m{where} = {m_to_mm(float(d.ravel()[i])):.4g} mm is outside "
                f"eq. 3.3's monotonic range |d'| < H = {m_to_mm(self.height_m):.4g} mm"
            )
        h2 = self.height_m * self.height_m
        return 2.0 * self.length_m * displacement_m / (h2 + displacement_m * displacement_m)

    def angle_to_displacement_m(self, angle_rad: FloatOrArray) -> FloatOrArray:
        """Inverse of eq. 3.3: ``d' = (L - sqrt(L^2 - theta^2 H^2)) / theta``, the small root.

        Evaluated as ``theta H^2 / (L + sqrt(L^2 - theta^2 H^2))``, the same value without the
        cancellation near 0, where it goes smoothly to 0 (the straight tip).

        Args:
            angle_rad: Bending angle [rad], ``|theta| < L / H`` (about 67.9 deg by default).

        Returns:
            Tip displacement d' from straight [m].

        Raises:
            ParameterError: If an angle is not finite or ``|theta| >= L / H``.
        """
        _require_finite(angle_rad, "angle_rad")
        a = np.asarray(angle_rad, dtype=np.float64)
        bad = np.flatnonzero(np.abs(a.ravel()) >= self.max_angle_rad)
        if bad.size:
            i = int(bad[0])
            where = "" if a.ndim == 0 else f"[{i}]"
            raise ParameterError(
                f"angle_rad{where} = {a.ravel()[i]:.6g} rad ({rad_to_deg(float(a.ravel()[i])):.4g} "
                f"deg) is outside eq. 3.3's range |theta| < L/H = {self.max_angle_rad:.6g} rad "
                f"({rad_to_deg(self.max_angle_rad):.4g} deg)"
            )
        h2 = self.height_m * self.height_m
        root = np.sqrt(self.length_m * self.length_m - angle_rad * angle_rad * h2)
        out: FloatOrArray = angle_rad * h2 / (self.length_m + root)
        return out

    def angle_from_voltage(
        self, voltage_v: FloatOrArray, straight_distance_m: float
    ) -> FloatOrArray:
        """Eqs. 3.1-3.3: laser voltage [V] to bending angle [rad].

        Args:
            voltage_v: Laser output [V].
            straight_distance_m: Calibrated distance [m] with the tip straight (from zeroing).

        Raises:
            ParameterError: If an input is not finite or off eq. 3.3's monotonic branch.
        """
        distance = self.voltage_to_distance_m(voltage_v)
        return self.displacement_to_angle_rad(displacement_m(distance, straight_distance_m))

    def voltage_from_angle(
        self, angle_rad: FloatOrArray, straight_distance_m: float
    ) -> FloatOrArray:
        """Inverse of eqs. 3.1-3.3: the voltage [V] the laser reads at bending angle [rad].

        For the simulator: it knows the angle and must publish what the sensor would see.

        Args:
            angle_rad: Bending angle [rad], ``|theta| < L / H``.
            straight_distance_m: Calibrated distance [m] with the tip straight.

        Raises:
            ParameterError: If an input is not finite or the angle is out of range.
        """
        _require_finite(straight_distance_m, "straight_distance_m")
        distance = straight_distance_m - self.angle_to_displacement_m(angle_rad)
        return self.distance_to_voltage_v(distance)


THESIS_GEOMETRY: Final = LaserGeometry()
"""The thesis's rig: m = 4.05 mm/V, n = 29.36 mm, L = 77 mm, H = 65 mm."""


def displacement_m(distance_m: FloatOrArray, straight_distance_m: float) -> FloatOrArray:
    """Eq. 3.2 with a stored reference: ``d' = s_straight - s`` [m].

    Args:
        distance_m: Laser distance s to the tip marker [m].
        straight_distance_m: Distance [m] with the tip straight, stored when the laser was
            zeroed (not the running maximum of the data: see the module docstring).

    Returns:
        Tip displacement d' [m]; positive as the catheter bends towards the laser.

    Raises:
        ParameterError: If an input is not finite.
    """
    _require_finite(distance_m, "distance_m")
    _require_finite(straight_distance_m, "straight_distance_m")
    return straight_distance_m - distance_m


def straight_reference_from_samples(distance_m: npt.ArrayLike) -> float:
    """Eq. 3.2's reference as the thesis computed it: the largest distance in a data group [m].

    For reproducing the thesis offline on a whole recorded group. Live code uses the
    calibration stored at zeroing instead, which neither needs the future samples nor moves
    with one noisy sample.

    Raises:
        ParameterError: If the samples are empty or not finite.
    """
    s = np.asarray(distance_m, dtype=np.float64)
    if s.size == 0:
        raise ParameterError("distance_m is empty; the straight reference needs samples")
    _require_finite(s, "distance_m")
    return float(np.max(s))


@dataclass(frozen=True)
class Calibration:
    """The stored straight-tip reference of eq. 3.2.

    The laser node's zeroing service writes it and the laser node reads it at start;
    ``follow_trajectory --sim`` writes one for the emulated rig.
    """

    straight_distance_m: float
    std_m: float
    samples: int
    zeroed_at: str

    def save(self, path: Path) -> None:
        """Write atomically (a crash mid-write must not leave a half file)."""
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(path.suffix + ".tmp")
        tmp.write_text(json.dumps(self.__dict__, indent=2) + "\n")
        tmp.replace(path)

    @classmethod
    def load(cls, path: Path) -> Calibration:
        """Read a calibration file; CatheterError names what is wrong with it."""
        try:
            raw = json.loads(path.read_text())
            cal = cls(
                straight_distance_m=float(raw["straight_distance_m"]),
                std_m=float(raw["std_m"]),
                samples=int(raw["samples"]),
                zeroed_at=str(raw["zeroed_at"]),
            )
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise CatheterError(f"laser calibration {path} is unreadable: {exc}") from None
        if not (math.isfinite(cal.straight_distance_m) and cal.straight_distance_m > 0):
            raise CatheterError(
                f"laser calibration {path}: straight_distance_m {cal.straight_distance_m} "
                "is not a positive distance"
            )
        return cal
