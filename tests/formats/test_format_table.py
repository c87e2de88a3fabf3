"""The format table: every format the input sniffer names (besides URDF) has one registered reader, the
three callers (extraction, validation, declared physics) read through it, and a format without a reader is a
StagingError naming the formats read."""

from __future__ import annotations

import math

import pytest

from asset2sim import formats
from asset2sim.formats import ReadOptions, staging
from tests.planted_assets import storage_box, write_mjcf

pytest.importorskip("mujoco", reason="the MJCF reader needs MuJoCo (the mujoco extra)")


def test_every_sniffed_format_has_one_reader(tmp_path):
    xml = write_mjcf(tmp_path / "box", "box", storage_box())
    usd = tmp_path / "stage.usda"
    usd.write_text("#usda 1.0\n")
    sniffed = {staging.input_format(xml), staging.input_format(usd), staging.input_format(tmp_path)}
    assert sniffed == {"mjcf", "usd", "urdf"}
    assert set(formats.FORMATS) == sniffed - {"urdf"}


def test_an_mjcf_file_is_read_with_the_options_given(tmp_path):
    """The registered MJCF reader gets the reading options: the same fragment read in radians and in degrees."""
    xml = write_mjcf(tmp_path / "box", "box", storage_box())
    xml.write_text(xml.read_text().replace('<compiler angle="radian" />', "<compiler/>").replace('<compiler angle="radian"/>', "<compiler/>"))
    as_radians = formats.read_asset_file(xml, "mjcf", ReadOptions(mjcf_angle="radian"))
    as_degrees = formats.read_asset_file(xml, "mjcf", ReadOptions(mjcf_angle="degree"))
    (jr,), (jd,) = as_radians.model.joints, as_degrees.model.joints
    assert jr.name == jd.name == "lid_hinge"
    assert jr.upper == pytest.approx(1.9) and jd.upper == pytest.approx(math.radians(1.9))


def test_a_format_without_a_reader_is_named(tmp_path):
    with pytest.raises(staging.StagingError, match=r"no reader for the format 'step'.*mjcf, usd"):
        formats.read_asset_file(tmp_path / "part.step", "step")
