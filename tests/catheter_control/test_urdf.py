"""The catheter's URDF agrees with the thesis's geometry, and TF agrees with the URDF."""

from __future__ import annotations

import math

import numpy as np
import pytest

from catheter_control.tip_tf import BendChain, chain, urdf_text
from catheter_models.contract import BEND_JOINT
from catheter_models.errors import ParameterError
from catheter_models.geometry import THESIS_GEOMETRY


def test_the_bending_section_is_the_thesis_segment() -> None:
    bend = chain()
    assert bend.pivot_m + bend.distal_m == pytest.approx(THESIS_GEOMETRY.length_m)
    # Limits: eq. 3.3's monotonic branch, beyond which the laser cannot tell two bends apart.
    assert bend.upper_rad == pytest.approx(THESIS_GEOMETRY.max_angle_rad, abs=1e-4)
    assert bend.lower_rad == pytest.approx(-THESIS_GEOMETRY.max_angle_rad, abs=1e-4)


@pytest.mark.parametrize(("angle_deg", "bound_mm"), [(10.0, 0.25), (30.0, 1.8), (60.0, 6.9)])
def test_the_tip_lies_near_the_constant_curvature_arc(angle_deg: float, bound_mm: float) -> None:
    """The documented error of the one-joint model against the arc (the URDF's comment)."""
    theta = math.radians(angle_deg)
    length = THESIS_GEOMETRY.length_m
    arc_xy = (length * math.sin(theta) / theta, length * (1.0 - math.cos(theta)) / theta)
    error_mm = 1e3 * math.dist(chain().tip_xy_m(theta), arc_xy)
    assert error_mm <= bound_mm


def test_transforms_compose_to_the_tip() -> None:
    """What TF says (base -> distal -> tip) is where the model puts the tip, turned by theta."""
    theta = math.radians(-25.0)
    poses = chain().transforms(theta)
    (px, _, _), (_, _, qz, qw) = poses[("base_link", "bend_distal")]
    (dx, _, _), tip_q = poses[("bend_distal", "tip")]
    yaw = 2.0 * math.atan2(qz, qw)
    tip = (px + dx * math.cos(yaw), dx * math.sin(yaw))
    assert yaw == pytest.approx(theta)
    assert tip_q == (0.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(tip, chain().tip_xy_m(theta), atol=1e-12)


def test_a_model_without_the_bend_joint_is_refused_by_name() -> None:
    renamed = urdf_text().replace(f'joint name="{BEND_JOINT}"', 'joint name="flex"')
    with pytest.raises(ParameterError, match=f"no revolute joint named '{BEND_JOINT}'"):
        BendChain.from_urdf(renamed)
