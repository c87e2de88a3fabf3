"""The engine's friction motor locks a light part's joint above
``max_stable_friction``: a suitcase handle (47 g) whose friction escalation
raised to 1.48 N*m could not be opened by any force."""

from __future__ import annotations

from pathlib import Path

import pytest

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import open_session
from asset2sim.tasks.synthesize.physics import FRICTION_LOCK_SHARE, JointLoad, joint_dynamics, max_stable_friction

#: Inertia of the handle about its hinge (kg*m^2): a 47 g bar 5 cm from the axis.
HANDLE_MASS, HANDLE_ARM = 0.047, 0.0316
HANDLE_I = HANDLE_MASS * HANDLE_ARM ** 2 + 1.0e-6


def handle(folder: Path, friction: float) -> Path:
    """A 2 kg case with a 47 g handle on a hinge along x (limits +-1.57 rad)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "mobility.urdf").write_text(
        '<?xml version="1.0"?><robot name="case">'
        '<link name="case"><inertial><mass value="2"/><inertia ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial>'
        '<collision><geometry><box size="0.4 0.3 0.1"/></geometry></collision></link>'
        f'<link name="handle"><inertial><origin xyz="0 {HANDLE_ARM} 0"/><mass value="{HANDLE_MASS}"/>'
        '<inertia ixx="1e-6" iyy="1e-6" izz="1e-6" ixy="0" ixz="0" iyz="0"/></inertial>'
        f'<collision><origin xyz="0 {HANDLE_ARM} 0"/><geometry><box size="0.1 0.02 0.01"/></geometry></collision></link>'
        '<joint name="hinge" type="revolute"><parent link="case"/><child link="handle"/><origin xyz="0 0.2 0"/>'
        '<axis xyz="1 0 0"/><limit lower="-1.57" upper="1.57" effort="100" velocity="10"/>'
        f'<dynamics damping="0" friction="{friction}"/></joint></robot>')
    return folder / "mobility.urdf"


def _moved(urdf: Path, effort: float) -> float:
    with open_session("pybullet", urdf, SessionOptions(fixed_base=True, ground=False, gravity=False)) as s:
        q0, _ = s.joint_state("hinge")
        for _ in range(48):
            s.apply_joint_effort("hinge", effort)
            s.step(1)
        return abs(s.joint_state("hinge")[0] - q0)


def test_friction_above_the_lock_bound_holds_the_joint_against_any_effort(tmp_path):
    bound = max_stable_friction(HANDLE_I) / FRICTION_LOCK_SHARE  # the locking threshold itself
    locked = handle(tmp_path / "locked", 1.3 * bound)
    assert _moved(locked, 50.0 * bound) < 1e-6  # 50x the friction: nothing moves
    free = handle(tmp_path / "free", max_stable_friction(HANDLE_I))
    assert _moved(free, 2.0 * max_stable_friction(HANDLE_I)) > 0.3


def test_estimated_friction_never_exceeds_the_lock_bound():
    load = JointLoad(joint="hinge", mass=HANDLE_MASS, inertia_axis=HANDLE_I, gravity_load=0.0, gravity_stiffness=0.0)
    jd = joint_dynamics(load, hold_load=10.0, prismatic=False)  # a hold load far beyond what the part can take
    assert jd.friction == pytest.approx(max_stable_friction(HANDLE_I))
