"""refine verifies in PyBullet and, where SAPIEN is installed, in PhysX by default."""

from __future__ import annotations

import importlib.util

from asset2sim.schemas.config import RefineConfig, default_engines


def test_physx_is_a_default_engine_where_sapien_is_installed():
    want = ["pybullet", "physx"] if importlib.util.find_spec("sapien") else ["pybullet"]
    assert default_engines() == want
    assert RefineConfig().engines == want
    assert RefineConfig(engines=["pybullet"]).engines == ["pybullet"]


def test_without_sapien_pybullet_alone(monkeypatch):
    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "sapien" else real(name, *a))
    assert default_engines() == ["pybullet"]
