"""A refine function for the regression tests: :func:`flowfakes.refine_fake`,
except that a request containing :data:`FAIL_MARK` fails (failure mode
``unstable``), so a test can make chosen assets fail in a later run by
editing their prompts in the manifest."""

from __future__ import annotations

try:  # package layout (tests/flows/__init__.py) or rootdir-on-sys.path layout
    from . import flowfakes  # type: ignore[no-redef]
except ImportError:
    import flowfakes  # type: ignore[no-redef]

FAIL_MARK = "[made to fail]"


def refine_failing(asset_dir, prompt, out_dir, config=None, *, category=None, asset_id=None, progress=None, extras=True):
    """Same signature and output contract as ``asset2sim.tasks.refine.refine_asset``."""
    if FAIL_MARK in prompt:
        flowfakes._log_call(asset_id or str(asset_dir), prompt)
        raise flowfakes.FakeRefineError("made to fail by the regression test", "unstable")
    return flowfakes.refine_fake(asset_dir, prompt, out_dir, config, category=category, asset_id=asset_id,
                                 progress=progress, extras=extras)
