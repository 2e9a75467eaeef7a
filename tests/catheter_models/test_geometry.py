"""Tests of the laser geometry, eqs. 3.1-3.3 and inverse (catheter_models.geometry)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.geometry import (
    THESIS_GEOMETRY,
    LaserGeometry,
    displacement_m,
    straight_reference_from_samples,
)

G = THESIS_GEOMETRY
STRAIGHT_M = 0.06  # a calibrated straight-tip distance, 60 mm


def test_defaults_are_the_thesis_values_in_si() -> None:
    assert LaserGeometry() == LaserGeometry(
        m_per_v=4.05e-3, offset_m=29.36e-3, length_m=0.077, height_m=0.065
    )
    assert G.max_angle_rad == pytest.approx(77.0 / 65.0)
    assert math.degrees(G.max_angle_rad) == pytest.approx(67.87, abs=0.01)


def test_eq31_hand_values() -> None:
    # s = 4.05 mm/V * U + 29.36 mm
    np.testing.assert_allclose(
        G.voltage_to_distance_m(np.array([0.0, 1.0, 10.0])),
        [0.02936, 0.03341, 0.06986],
        rtol=0,
        atol=1e-15,
    )
    assert G.distance_to_voltage_v(0.03341) == pytest.approx(1.0, abs=1e-12)


def test_eq33_hand_values() -> None:
    # theta = 2 d' L / (H^2 + d'^2) with L = 77 mm, H = 65 mm
    d_m = np.array([0.0, 0.010, 0.030])
    expected_rad = [0.0, 1540.0 / 4325.0, 4620.0 / 5125.0]
    np.testing.assert_allclose(G.displacement_to_angle_rad(d_m), expected_rad, rtol=1e-14)


def test_inverse_matches_the_printed_closed_form() -> None:
    theta = np.linspace(0.05, 0.99 * G.max_angle_rad, 50)
    length, height = G.length_m, G.height_m
    printed = (length - np.sqrt(length**2 - theta**2 * height**2)) / theta
    np.testing.assert_allclose(G.angle_to_displacement_m(theta), printed, rtol=1e-12)


def test_inverse_goes_smoothly_to_zero_at_straight() -> None:
    assert G.angle_to_displacement_m(0.0) == 0.0
    tiny = 1e-12
    # Small-angle limit of eq. 3.3: theta ~ 2 d' L / H^2.
    assert G.angle_to_displacement_m(tiny) == pytest.approx(
        tiny * G.height_m**2 / (2 * G.length_m), rel=1e-9
    )


def test_round_trip_angle_voltage_angle() -> None:
    theta = np.linspace(-0.05, 0.999 * G.max_angle_rad, 2001)
    voltage = G.voltage_from_angle(theta, STRAIGHT_M)
    np.testing.assert_allclose(G.angle_from_voltage(voltage, STRAIGHT_M), theta, rtol=0, atol=1e-12)
    d = np.linspace(-0.06, 0.064, 1001)
    np.testing.assert_allclose(
        G.angle_to_displacement_m(G.displacement_to_angle_rad(d)), d, rtol=0, atol=1e-12
    )


def test_straight_tip_reads_zero_angle() -> None:
    u_straight = G.distance_to_voltage_v(STRAIGHT_M)
    assert G.angle_from_voltage(u_straight, STRAIGHT_M) == pytest.approx(0.0, abs=1e-15)
    # Bending moves the tip towards the laser: shorter distance, lower voltage.
    assert G.voltage_from_angle(math.radians(30.0), STRAIGHT_M) < u_straight


def test_eq33_is_monotonic_below_h() -> None:
    d = np.linspace(-0.999 * G.height_m, 0.999 * G.height_m, 5001)
    assert np.all(np.diff(G.displacement_to_angle_rad(d)) > 0.0)


def test_floats_in_floats_out_arrays_in_arrays_out() -> None:
    assert isinstance(G.displacement_to_angle_rad(0.01), float)
    assert isinstance(G.angle_to_displacement_m(0.3), float)
    assert isinstance(G.angle_from_voltage(3.0, STRAIGHT_M), float)
    out = G.angle_from_voltage(np.array([3.0, 4.0]), STRAIGHT_M)
    assert isinstance(out, np.ndarray) and out.shape == (2,)


def test_off_branch_displacement_and_angle_are_refused() -> None:
    with pytest.raises(ParameterError, match=r"displacement_m\[1\] = 65 mm .*\|d'\| < H = 65 mm"):
        G.displacement_to_angle_rad(np.array([0.01, 0.065]))
    with pytest.raises(ParameterError, match=r"67\.87 deg"):
        G.angle_to_displacement_m(G.max_angle_rad)
    with pytest.raises(ParameterError, match=r"angle_rad\[2\]"):
        G.voltage_from_angle(np.array([0.1, 0.2, -1.2]), STRAIGHT_M)


def test_non_finite_inputs_are_refused() -> None:
    with pytest.raises(ParameterError, match=r"voltage_v\[1\] is nan"):
        G.angle_from_voltage(np.array([1.0, np.nan]), STRAIGHT_M)
    with pytest.raises(ParameterError, match="angle_rad is inf"):
        G.angle_to_displacement_m(math.inf)
    with pytest.raises(ParameterError, match="straight_distance_m is nan"):
        displacement_m(0.05, math.nan)


def test_displacement_uses_the_stored_straight_reference() -> None:
    s = np.array([0.060, 0.055, 0.0605, 0.050])  # one sample a little past straight (noise)
    np.testing.assert_allclose(displacement_m(s, STRAIGHT_M), [0.0, 0.005, -0.0005, 0.010])
    # The thesis's offline reference is the group's maximum distance (eq. 3.2).
    assert straight_reference_from_samples(s) == 0.0605
    np.testing.assert_allclose(
        displacement_m(s, straight_reference_from_samples(s)), [0.0005, 0.0055, 0.0, 0.0105]
    )


def test_straight_reference_refuses_empty_or_nan() -> None:
    with pytest.raises(ParameterError, match="empty"):
        straight_reference_from_samples(np.array([]))
    with pytest.raises(ParameterError, match=r"distance_m\[1\] is nan"):
        straight_reference_from_samples([0.05, math.nan])


@pytest.mark.parametrize(
    ("field", "value"),
    [("m_per_v", 0.0), ("offset_m", math.nan), ("length_m", -0.077), ("height_m", 0.0)],
)
def test_bad_geometry_is_refused(field: str, value: float) -> None:
    with pytest.raises(ParameterError, match=field):
        LaserGeometry(**{field: value})
