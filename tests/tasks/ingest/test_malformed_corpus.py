"""The malformed corpus: every generated broken asset gets its expected code,
fast, without crash or hang, and extraction (hence ``refine``) refuses it."""

from __future__ import annotations

import collections
import signal
import time
from contextlib import contextmanager

import pytest

from asset2sim import atomic
from asset2sim.tasks.ingest import validate_input as vi
from asset2sim.tasks.ingest.extract import AssetError, extract_asset_checked
from tests import corpus_builder as cb

TIME_LIMIT_S = 5.0
HANG_LIMIT_S = 30


@contextmanager
def _no_hang(seconds: int):
    """Fail the test (instead of hanging the suite) after ``seconds``."""

    def on_alarm(signum, frame):
        raise TimeoutError(f"validation still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def test_corpus_size_and_coverage():
    assert len(cb.CASES) >= 60
    assert len(cb.CASES_BY_NAME) == len(cb.CASES), "case names must be unique"
    topics = collections.Counter(c.topic for c in cb.CASES)
    for topic in ("xml", "structure", "numbers", "inertials", "mesh_paths", "mesh_contents"):
        assert topics[topic] >= 5, topics
    unknown = [c.code for c in cb.CASES if c.code not in vi.CODES]
    assert unknown == []


def test_base_asset_is_valid(tmp_path):
    assert not vi.has_errors(vi.validate_asset(cb.build_valid(tmp_path / "a")))


@pytest.mark.parametrize("case", cb.CASES, ids=[c.name for c in cb.CASES])
def test_case_gets_its_code(case, tmp_path):
    asset = case.build(tmp_path / "asset")
    policy = vi.ValidationPolicy(**(case.policy or {}))
    before = atomic.tree_hashes(asset)
    with _no_hang(HANG_LIMIT_S):
        t = time.perf_counter()
        findings = vi.validate_asset(asset, policy)
        elapsed = time.perf_counter() - t
    assert elapsed < TIME_LIMIT_S, f"{case.name}: {elapsed:.2f} s"
    hits = [f for f in findings if f.code == case.code]
    assert hits, f"{case.name}: expected {case.code}, got {[f.describe() for f in findings]}"
    assert "INTERNAL_ERROR" not in {f.code for f in findings}
    for f in hits:
        assert f.file and f.message
    if case.refused:
        assert any(f.severity == "error" for f in hits), [f.describe() for f in hits]
    else:
        assert not vi.has_errors(findings), [f.describe() for f in findings if f.severity == "error"]
    # extraction (what refine calls first) agrees, and nothing was written
    with _no_hang(HANG_LIMIT_S):
        if case.refused:
            with pytest.raises(AssetError) as info:
                extract_asset_checked(asset, policy=policy)
            assert case.code in info.value.codes
            assert case.code in str(info.value)
        else:
            desc, found = extract_asset_checked(asset, policy=policy)
            assert case.code in {f.code for f in found}
            replaced = {f.link for f in found if f.action == "replace_with_estimate"}
            assert all(desc.link(n).given_inertial is None for n in replaced)
            if case.topic == "inertials" and vi.CODES[case.code].severity == "warning":
                assert replaced, "an invalid inertial must be marked for replacement"
    assert atomic.tree_hashes(asset) == before
