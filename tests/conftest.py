"""Shared fixtures: the dev dataset location and generated demo assets; the
session's shared refines (``refine_once``, :class:`tests.helpers.RefineFactory`);
the test-only "fake" engine registered (:mod:`tests.fake_engine`); tests that
use the shared refines marked ``integration``."""

from __future__ import annotations

import collections
import os
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from asset2sim import atomic
from asset2sim.engines.base import register_engine
from tests.fake_engine import FakeSession
from tests.helpers import RefineFactory, Refined

register_engine("fake", FakeSession)  # every test of the process can open_session("fake", ...)

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("ASSET2SIM_SHARED", ROOT.parent / "shared")) / "datasets" / "partnet_mobility"

#: The one reason a test that needs the dev dataset (or a row of it) skips with when it is not here: the skip summary
#: counts them as one cause.
NO_SHARED = f"dev dataset not found at {SHARED}"
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason=NO_SHARED)
#: CI sets CI=true and always lays the dev dataset beside the clone: there a missing dataset (or a row of its manifest)
#: fails the run instead of skipping every test that needs it; a plain ``make test`` without ``../shared`` skips them.
IN_CI = os.environ.get("CI", "").strip().lower() in ("1", "true", "yes")


def pytest_sessionstart(session):
    """Under CI (:data:`IN_CI`) the dev dataset must be there, every row of its manifest included."""
    if not IN_CI:
        return
    manifest = SHARED / "manifest.csv"
    rows = [line.split(",", 1)[0] for line in manifest.read_text().splitlines()[1:] if line] if manifest.is_file() else []
    missing = [r for r in rows if not (SHARED / r).is_dir()]
    if not rows or missing:
        raise pytest.UsageError(f"CI=true but the dev dataset is missing at {SHARED}" + (f" (rows {missing})" if missing else "")
                                + ": CI lays ../shared beside the clone; its tests fail instead of skipping")


@pytest.fixture(scope="session", autouse=True)
def scratch_temp_folders(tmp_path_factory) -> Iterator[list[Path]]:
    """The session's temporary folders (this process's and, under pytest-xdist, the run's, which holds the shared
    refines) as scratch (``asset2sim.atomic.add_scratch``): files written there are atomic without ``fsync``, which
    guards only against a crash of the machine, and no test's folder has to outlive one (the ``fsync`` calls were a
    good part of the tier's wall time). A test of the durable writes opts out (``durable_writes``)."""
    base = tmp_path_factory.getbasetemp()
    folders = [base.parent] if os.environ.get("PYTEST_XDIST_WORKER") else [base]
    for folder in folders:
        atomic.add_scratch(folder)
    yield folders
    for folder in folders:
        atomic.remove_scratch(folder)


@pytest.fixture()
def durable_writes(scratch_temp_folders) -> Iterator[None]:
    """Writes with ``fsync`` again (:func:`scratch_temp_folders` undone) for one test of the durable writes."""
    for folder in scratch_temp_folders:
        atomic.remove_scratch(folder)
    yield
    for folder in scratch_temp_folders:
        atomic.add_scratch(folder)


@pytest.fixture(scope="session")
def shared_dataset() -> Path:
    if not SHARED.is_dir():
        pytest.skip(NO_SHARED)
    return SHARED


@pytest.fixture(scope="session")
def demo_root(tmp_path_factory) -> Path:
    """The generated demo dataset (boxes with lids, cabinet, laptop ...)."""
    from asset2sim import demo_assets

    root = tmp_path_factory.mktemp("demo")
    demo_assets.build_demo_dataset(root)
    return root


@pytest.fixture(scope="session")
def refine_factory(tmp_path_factory) -> Iterator[RefineFactory]:
    """The session's :class:`~tests.helpers.RefineFactory` (module-scoped fixtures use it directly), its refines shared
    with the other workers of the run under pytest-xdist; at the end of the session every shared output and input it
    handed out is checked unchanged."""
    shared = None
    if os.environ.get("PYTEST_XDIST_WORKER"):  # the workers' temporary folders share a parent: one refine per run
        shared = tmp_path_factory.getbasetemp().parent / "shared_refines"
    factory = RefineFactory(tmp_path_factory.mktemp("shared_refines"), shared)
    yield factory
    factory.assert_all_untouched()


@pytest.fixture()
def refine_once(refine_factory) -> Iterator[Callable[..., Refined]]:
    """``refine_once(asset, prompt, config=None, **options)``: the session's one refine of that asset, request and
    options (:class:`~tests.helpers.RefineFactory`), its output folder read-only; after the test each folder handed
    out is checked unchanged (a test that changes an output works on ``Refined.copy_to``)."""
    handed: list[Refined] = []

    def get(asset, prompt: str, config=None, **options) -> Refined:
        handed.append(refine_factory(asset, prompt, config, **options))
        return handed[-1]

    yield get
    for r in handed:
        refine_factory.assert_untouched(r)


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """The skipped tests counted by reason at the end of every run, most first: what this machine did not run and why
    (the dev dataset not beside the clone, an extra not installed), instead of a bare count."""
    skipped = terminalreporter.stats.get("skipped", [])
    if not skipped:
        return
    reasons = collections.Counter(
        (rep.longrepr[2] if isinstance(rep.longrepr, tuple) else str(rep.longrepr)).removeprefix("Skipped: ") for rep in skipped)
    terminalreporter.write_sep("-", f"{len(skipped)} skipped, by reason")
    for reason, n in reasons.most_common():
        terminalreporter.write_line(f"{n:5d}  {reason}")


def pytest_collection_modifyitems(config, items):
    """Tests on the shared refines are the ``integration`` tier (``-m "not slow and not integration"``: the unit tests)."""
    for item in items:
        if {"refine_once", "refine_factory"} & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.integration)
