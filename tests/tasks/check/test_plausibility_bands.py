"""The audit's verdict rules on numbers: every band's edge, the triangle inequality, centers of mass outside the
geometry, unit mistakes in size, damping ratios of springs, friction a hand cannot overcome, limits."""

from __future__ import annotations

import math

import numpy as np
import pytest

from asset2sim.tasks.check import plausibility_bands as bands


def test_mass_inside_the_shell_to_solid_span_widened_by_the_tolerance_is_plausible():
    # estimate 1 kg, shell 0.5 kg, solid 2 kg: plausible 0.5/3 .. 2*3
    ok = bands.mass_verdict("link a", 5.9, 1.0, [2.0, 0.5], "ABS")
    assert ok.verdict == "plausible" and ok.low == pytest.approx(0.5 / 3) and ok.high == pytest.approx(6.0)
    heavy = bands.mass_verdict("link a", 100.0, 1.0, [2.0, 0.5], "ABS")
    light = bands.mass_verdict("link a", 0.01, 1.0, [2.0, 0.5], "ABS")
    assert heavy.verdict == light.verdict == "implausible"
    assert heavy.factor == pytest.approx(100.0) and light.factor == pytest.approx(0.01)
    assert "above" in heavy.reason and "below" in light.reason
    assert bands.mass_verdict("link a", None, 1.0, [2.0], "ABS").verdict == "not_declared"


def test_density_of_lead_on_a_plastic_part_is_implausible_and_any_material_caps_at_brass():
    lead = bands.density_verdict("link lid", 11340.0, "ABS plastic", 1050.0, declared_directly=True)
    assert lead.verdict == "implausible" and lead.factor == pytest.approx(11340 / 1050)
    assert bands.density_verdict("link lid", 2900.0, "ABS plastic", 1050.0, False).verdict == "plausible"
    # steel's 3x would allow 23550 kg/m^3: the cap of any household material holds
    assert bands.density_verdict("link a", 11340.0, "steel", 7850.0, True).verdict == "implausible"
    assert bands.density_verdict("link a", 9000.0, "steel", 7850.0, True).verdict == "plausible"


def test_inertia_validity_and_consistency_with_the_geometry():
    per_kg = [np.diag([0.02, 0.02, 0.03]), np.diag([0.01, 0.01, 0.015])]  # shell, solid per kg
    good = bands.inertia_verdict("link a", np.diag([0.01, 0.01, 0.015]) * 2.0, 2.0, per_kg)
    assert good.verdict == "plausible"
    triangle = bands.inertia_verdict("link a", np.diag([0.001, 0.001, 0.01]), 1.0, per_kg)
    assert triangle.verdict == "implausible" and "triangle inequality" in triangle.reason
    negative = bands.inertia_verdict("link a", np.diag([0.01, 0.01, -0.001]), 1.0, per_kg)
    assert negative.verdict == "implausible" and "positive definite" in negative.reason
    asym = np.diag([0.01, 0.01, 0.015])
    asym[0, 1] = 0.004
    assert bands.inertia_verdict("link a", asym, 1.0, per_kg).verdict == "implausible"
    stale = bands.inertia_verdict("link a", np.diag([0.01, 0.01, 0.015]), 0.01, per_kg)  # the mass edited, the tensor not
    assert stale.verdict == "implausible" and stale.factor == pytest.approx(0.035 / (0.035 * 0.01))
    # written moments (what MuJoCo's balanceinertia changed) are judged, not the loaded tensor
    balanced = bands.inertia_verdict("link a", np.diag([0.004, 0.004, 0.004]), 1.0, per_kg, written=np.array([0.001, 0.001, 0.01]))
    assert balanced.verdict == "implausible" and "changed them on loading" in balanced.reason


def test_center_of_mass_outside_the_grown_geometry_box_is_implausible():
    lo, hi, c = np.zeros(3), np.array([0.3, 0.2, 0.1]), np.array([0.15, 0.1, 0.05])
    margin = bands.COM_MARGIN * float(np.linalg.norm(hi - lo))
    assert bands.com_verdict("link a", np.array([0.3 + 0.9 * margin, 0.1, 0.05]), lo, hi, c).verdict == "plausible"
    out = bands.com_verdict("link a", np.array([0.3 + 1.5 * margin, 0.1, 0.05]), lo, hi, c)
    assert out.verdict == "implausible" and out.declared == pytest.approx(0.15 + 1.5 * margin)


@pytest.mark.parametrize("factor", [10.0, 25.4, 100.0, 0.01])
def test_unit_mistakes_in_size_are_implausible(factor):
    assert bands.scale_verdict(0.35 * factor, 0.35, "Box").verdict == "implausible"


def test_a_size_within_the_category_span_and_unknown_categories():
    assert bands.scale_verdict(0.35 * 4.9, 0.35, "Box").verdict == "plausible"
    assert bands.scale_verdict(0.35 / 4.9, 0.35, "Box").verdict == "plausible"
    assert bands.scale_verdict(2.5, None, "Generic").verdict == "plausible"
    assert bands.scale_verdict(35.0, None, "Generic").verdict == "implausible"


def test_a_spring_lid_without_damping_rings_and_one_past_critical_is_kept():
    I, k = 0.01, 0.6
    crit = 2 * math.sqrt(I * k)
    zero = bands.spring_damping_verdict("joint j", 0.0, I, k, 0.7 * crit, "N*m*s/rad")
    assert zero.verdict == "implausible" and zero.low == pytest.approx(bands.ZETA_MIN_SPRING * crit)
    assert bands.spring_damping_verdict("joint j", 0.3 * crit, I, k, 0.7 * crit, "N*m*s/rad").verdict == "plausible"
    assert bands.spring_damping_verdict("joint j", 20 * crit, I, k, 0.7 * crit, "N*m*s/rad").verdict == "implausible"
    # a hand's torque that still sweeps the range in OPERATE_SECONDS raises the upper end
    c_op = bands.operating_damping(10.0, 2.0)
    assert c_op == pytest.approx(10.0 * bands.OPERATE_SECONDS / 2.0)
    assert bands.spring_damping_verdict("joint j", 0.9 * c_op, I, k, 0.7 * crit, "N*m*s/rad", c_op).verdict == "plausible"


def test_a_joint_with_no_damping_and_no_friction_never_stops():
    assert bands.damping_verdict("joint j", 0.0, 0.01, 1.0, 0.1, 0.0, "N*m*s/rad").verdict == "implausible"
    assert bands.damping_verdict("joint j", 0.0, 0.01, 1.0, 0.1, 0.2, "N*m*s/rad").verdict == "plausible"
    creeping = bands.damping_verdict("joint j", 50.0, 0.01, 1.0, 0.1, 0.2, "N*m*s/rad", bands.operating_damping(5.0, 1.5))
    assert creeping.verdict == "implausible" and creeping.high == pytest.approx(10.0)


def test_friction_a_hand_cannot_overcome_is_implausible():
    assert bands.friction_verdict("joint j", 20.0, 0.5, 5.0, "N*m").verdict == "implausible"
    assert bands.friction_verdict("joint j", 14.0, 0.5, 5.0, "N*m").verdict == "plausible"
    assert bands.friction_verdict("joint j", 0.0, 0.5, 5.0, "N*m").verdict == "plausible"
    assert bands.stiffness_verdict("joint j", 100.0, 1.5, 5.0, "N*m/rad").verdict == "implausible"
    assert bands.stiffness_verdict("joint j", 5.0, 1.5, 5.0, "N*m/rad").verdict == "plausible"
    # a balance pulls against the part's weight: 150 N of spring over 1.5 m carrying 140 N of sash is a hand's 10 N net
    assert bands.stiffness_verdict("joint j", 100.0, 1.5, 5.0, "N/m", carried=140.0).verdict == "plausible"
    assert bands.stiffness_verdict("joint j", 100.0, 1.5, 5.0, "N/m", carried=40.0).verdict == "implausible"


def test_limits():
    assert bands.limits_verdict("joint j", "revolute", 0.0, 1.6, 0.5).verdict == "plausible"
    assert bands.limits_verdict("joint j", "revolute", 0.0, 7.0, 0.5).verdict == "implausible"
    assert bands.limits_verdict("joint j", "revolute", 1.0, 0.5, 0.5).verdict == "implausible"
    assert bands.limits_verdict("joint j", "prismatic", 0.0, 0.9, 0.5).verdict == "implausible"
    assert bands.limits_verdict("joint j", "prismatic", 0.0, 0.7, 0.5).verdict == "plausible"
    assert bands.limits_verdict("joint j", "continuous", None, None, 0.5).verdict == "not_declared"
