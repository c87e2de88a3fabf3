"""The flow tests' call log is one file per process tree, however often its module is imported: a test outside
tests/flows imports it as ``tests.flows.flowproject``, a second module object, and the flow tests that ran
before or after it in the same pytest worker must still read the calls their fake refine function logged."""

from __future__ import annotations

import importlib.util
from pathlib import Path

try:
    from . import flowfakes  # type: ignore[no-redef]
    from .flowproject import CALLS_PATH
except ImportError:
    import flowfakes  # type: ignore[no-redef]
    from flowproject import CALLS_PATH


def test_a_second_import_under_another_name_keeps_the_call_log():
    path = Path(__file__).with_name("flowproject.py")
    spec = importlib.util.spec_from_file_location("flowproject_second_name", path)
    second = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(second)
    assert second.CALLS_PATH == CALLS_PATH
    CALLS_PATH.write_text("")
    assert flowfakes._log_call("box_lid", "a box, lid shut") == 1  # as the fake refine logs, through the environment
    assert [c["asset_id"] for c in flowfakes.calls(CALLS_PATH)] == ["box_lid"]
    CALLS_PATH.write_text("")
