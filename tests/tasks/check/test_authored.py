"""Authored equals simulated: every engine holds the masses, COMs, principal
moments, limits, damping, friction, springs and initial positions the files
say; a dropped or rescaled value is named."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from asset2sim.engines.registry import available_engines
from tests.contract_asset import write_contract_asset
from asset2sim.tasks.check.authored import Tolerances, authored_physics, compare_physics, held_by_engines

FAST_ENGINES = [e for e in ("pybullet", "physx", "mujoco") if e in available_engines()]


def _rotated_inertial(folder):
    """Give the lid an inertia tensor with products of inertia in a rotated
    inertial frame (the engines must diagonalise it) and an off-axis COM."""
    p = folder / "mobility.urdf"
    text = p.read_text()
    old = ('<origin xyz="0.0 -0.1 0.0055000000000000005" rpy="0.0 -0.0 0.0"/>\n      <mass value="0.2"/>\n'
           '      <inertia ixx="0.0006683333333333335" ixy="0.0" ixz="0.0"')
    assert old in text
    text = text.replace(old, '<origin xyz="0.01 -0.1 0.0055" rpy="0.3 0.2 0.1"/>\n      <mass value="0.2"/>\n'
                             '      <inertia ixx="0.0006683333333333335" ixy="0.0002" ixz="0.0"')
    p.write_text(text)


def test_authored_physics_reads_the_files(tmp_path):
    write_contract_asset(tmp_path, lid_angle=0.4, lid_stiffness=0.3, lid_spring_reference=0.2)
    a = authored_physics(tmp_path)
    assert a.links["body"].mass == 1.5
    assert a.joints["lid_hinge"].position == 0.4
    assert a.joints["lid_hinge"].stiffness == 0.3 and a.joints["lid_hinge"].reference == 0.2
    assert a.joints["post_slide"].friction == 2.0 and a.joints["post_slide"].damping == 1.0
    assert a.joints["lid_hinge"].upper == 2.0


@pytest.mark.skipif(not FAST_ENGINES, reason="no engine installed")
def test_every_engine_holds_what_the_files_say(tmp_path):
    """PyBullet, PhysX and MuJoCo (those installed), and the exported MJCF in
    MuJoCo: no mismatch at the stated tolerances, a rotated inertial frame
    with products of inertia included."""
    write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02, lid_stiffness=0.3, lid_spring_reference=0.2)
    _rotated_inertial(tmp_path)
    checks = held_by_engines(tmp_path, FAST_ENGINES)
    by = {(c.engine, c.source.split(" ")[0]): c for c in checks}
    for e in FAST_ENGINES:
        c = by[(e, "urdf")]
        assert c.status == "ok", c.reason
        assert c.links == 4 and c.joints == 2
        assert c.passed, [str(m) for m in c.mismatches]
        assert set(c.max_error) >= {"mass", "com", "inertia", "limits", "damping", "friction", "stiffness", "position"}
    if "mujoco" in FAST_ENGINES:  # not exported yet: the MJCF row says so
        assert by[("mujoco", "mjcf")].status == "skipped" and "not exported" in by[("mujoco", "mjcf")].reason


@pytest.mark.skipif("mujoco" not in available_engines(), reason="mujoco not installed")
def test_the_exported_mjcf_holds_what_the_files_say(tmp_path):
    from asset2sim.formats.mjcf.export import export_mjcf

    write_contract_asset(tmp_path, lid_angle=0.4, lid_stiffness=0.3, lid_spring_reference=0.2)
    export_mjcf(tmp_path)
    (c,) = [c for c in held_by_engines(tmp_path, ["mujoco"]) if c.source.startswith("mjcf")]
    assert c.status == "ok" and c.passed, [str(m) for m in c.mismatches]


def test_a_dropped_or_rescaled_value_is_named(tmp_path):
    """The class of importer bug the check exists for: damping dropped,
    a spring converted per degree, a limit in degrees, a mass rescaled by
    shape density; each named by joint or link and quantity."""
    write_contract_asset(tmp_path, lid_angle=0.4, lid_stiffness=0.3, lid_spring_reference=0.2)
    a = authored_physics(tmp_path)
    assert compare_physics(a, a).passed
    held = replace(a, engine="importer", links=dict(a.links), joints=dict(a.joints))
    held.joints["lid_hinge"] = replace(a.joints["lid_hinge"], damping=0.0, stiffness=0.3 * math.pi / 180,
                                       upper=math.degrees(a.joints["lid_hinge"].upper))
    held.links["body"] = replace(a.links["body"], mass=3.156)
    held.links["lid"] = replace(a.links["lid"], principal=a.links["lid"].principal * (1 + 1e-3))
    held.joints["post_slide"] = replace(a.joints["post_slide"], position=0.001)
    del held.links["post"]
    c = compare_physics(held, a)
    got = {(m.item, m.quantity) for m in c.mismatches}
    assert got == {
        ("joint lid_hinge", "damping"),
        ("joint lid_hinge", "stiffness"),
        ("joint lid_hinge", "upper limit"),
        ("link body", "mass (kg)"),
        ("link lid", "principal moments (kg*m^2)"),
        ("joint post_slide", "initial position"),
        ("link post", "missing"),
    }
    assert c.passed is False
    # float32 storage of every value stays inside the tolerance
    f32 = replace(a, links={n: replace(lk, mass=float(np.float32(lk.mass)), com=lk.com.astype(np.float32).astype(float),
                                       principal=lk.principal.astype(np.float32).astype(float)) for n, lk in a.links.items()})
    assert compare_physics(f32, a, Tolerances()).passed


@pytest.mark.skipif("pybullet" not in available_engines(), reason="pybullet not installed")
def test_a_fixed_root_mass_is_noted_not_compared(tmp_path):
    """PyBullet stores 0 kg for a fixed base: not simulated, so noted, not a
    mismatch."""
    import json

    write_contract_asset(tmp_path, lid_angle=0.4)
    state = json.loads((tmp_path / "initial_state.json").read_text())
    state["root"] = {"fixed": True, "mounting": "wall-mounted", "source": "test"}
    (tmp_path / "initial_state.json").write_text(json.dumps(state))
    (c,) = held_by_engines(tmp_path, ["pybullet"])
    assert c.passed, [str(m) for m in c.mismatches]
    assert any("base" in n and "welded" in n for n in c.notes)


@pytest.mark.slow
def test_newton_holds_what_the_files_say(tmp_path):
    """Newton's model built by the engine from the URDF, and Newton's own USD
    importer on the exported USD (Kamino solver construction: about a
    minute on the CPU)."""
    pytest.importorskip("newton")
    pytest.importorskip("pxr")
    from asset2sim.formats.usd.export import export_usd

    write_contract_asset(tmp_path, lid_angle=0.4, post_height=0.02, lid_stiffness=0.3, lid_spring_reference=0.2)
    export_usd(tmp_path)
    checks = {c.source.split(" ")[0]: c for c in held_by_engines(tmp_path, ["newton"])}
    for src in ("urdf", "usd"):
        assert checks[src].status == "ok", checks[src].reason
        assert checks[src].passed, [str(m) for m in checks[src].mismatches]
