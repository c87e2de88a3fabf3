"""Shared fixtures: the dev dataset location and generated demo assets; the
test-only "fake" engine registered (:mod:`tests.fake_engine`)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from asset2sim.engines.base import register_engine
from tests.fake_engine import FakeSession

register_engine("fake", FakeSession)  # every test of the process can open_session("fake", ...)

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ASSET2SIM_SHARED", ROOT.parent / "shared")) / "datasets" / "partnet_mobility"

needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=f"dev dataset not found at {SHARED}")


@pytest.fixture(scope="session")
def shared_dataset() -> Path:
    if not SHARED.is_dir():
        pytest.skip(f"dev dataset not found at {SHARED}")
    return SHARED


@pytest.fixture(scope="session")
def demo_root(tmp_path_factory) -> Path:
    """The generated demo dataset (boxes with lids, cabinet, laptop ...)."""
    from asset2sim import demo_assets

    root = tmp_path_factory.mktemp("demo")
    demo_assets.build_demo_dataset(root)
    return root
