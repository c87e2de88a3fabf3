"""The version is declared once (``asset2sim.__version__``); the package
metadata, the changelog and a release tag follow it.

The version is not derived from git tags: outputs record it (``overlay.json``
``estimator.version``, the run hash), so a version that changed with every
commit would change every output and undo the flow's ``code_change: keep``.
A release is the commit that sets the version, tagged ``v<version>``.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import asset2sim

ROOT = Path(__file__).resolve().parents[1]


def test_the_package_metadata_takes_the_declared_version():
    text = (ROOT / "pyproject.toml").read_text()  # read as text: tomllib is Python 3.11+, and 3.10 is supported
    assert re.search(r'^dynamic = \["version"\]$', text, re.M)
    assert re.search(r'^\[tool\.setuptools\.dynamic\]\nversion = \{ attr = "asset2sim\.__version__" \}$', text, re.M)
    assert re.fullmatch(r"\d+\.\d+\.\d+", asset2sim.__version__)


def test_the_changelog_starts_with_the_declared_version():
    first = re.search(r"^## (\d+\.\d+\.\d+)", (ROOT / "CHANGELOG.md").read_text(), re.M)
    assert first and first.group(1) == asset2sim.__version__


def test_a_release_tag_on_this_commit_names_the_declared_version():
    tags = subprocess.run(["git", "tag", "--points-at", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    releases = [t for t in tags.stdout.split() if re.fullmatch(r"v\d+\.\d+\.\d+", t)] if tags.returncode == 0 else []
    assert all(t == f"v{asset2sim.__version__}" for t in releases), releases
