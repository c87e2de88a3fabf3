"""Shared fixtures of the realism tests: ``folder``, a fresh copy (no ratings) of the module's ``pair_folder``
(each test module writes its own pair set)."""

from __future__ import annotations

import shutil

import pytest


@pytest.fixture
def folder(pair_folder, tmp_path):
    """A fresh copy of the module's pair set (pairs.json and its clips), no ratings."""
    dst = tmp_path / "set"
    shutil.copytree(pair_folder, dst)
    return dst
