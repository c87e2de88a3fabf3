"""The one reader of an output folder (asset2sim.refined_asset.RefinedAsset): each file read once, on first use,
with the errors of the files a reader asks for only."""

from __future__ import annotations

import json

import pytest

from asset2sim.engines.base import Spring
from asset2sim.output_folder import OVERLAY_NAME, STATE_NAME, OutputError
from asset2sim.refined_asset import RefinedAsset, output_session_options, read_root
from asset2sim.schemas.overlay import RootMount
from tests.contract_asset import write_contract_asset


def _state(folder, q, root=None):
    (folder / STATE_NAME).write_text(json.dumps({"initial_joint_positions": q, **({"root": root} if root else {})}))


def test_an_empty_folder_reads_as_nothing_declared(tmp_path):
    asset = RefinedAsset(tmp_path)
    assert asset.initial_state == {} and asset.root == RootMount() and asset.overlay is None and asset.springs == {}
    assert asset.record("baseline.json") is None
    with pytest.raises(FileNotFoundError, match="not an output folder"):
        RefinedAsset.existing(tmp_path)
    with pytest.raises(FileNotFoundError, match=OVERLAY_NAME):
        asset.required_overlay()


def test_initial_state_json_is_read_once_for_the_joints_and_the_root(tmp_path):
    _state(tmp_path, {"lid": 0.5}, {"fixed": True, "mounting": "wall-mounted"})
    asset = RefinedAsset(tmp_path)
    assert asset.initial_state == {"lid": 0.5}
    (tmp_path / STATE_NAME).write_text("not json")  # already read: the root comes from the same reading
    assert asset.root.fixed and asset.root.kind == "wall-mounted"
    with pytest.raises(OutputError, match=STATE_NAME):
        read_root(tmp_path)  # a fresh reader reads the file again
    assert RefinedAsset.of(asset) is asset


def test_springs_about_the_initial_state_and_the_session_options(tmp_path):
    a = write_contract_asset(tmp_path, lid_angle=0.25, lid_stiffness=2.0)
    asset = RefinedAsset.existing(tmp_path)
    assert asset.urdf_path == a.urdf and set(asset.model.links) >= {"base", "body", "lid", "post"}
    assert asset.springs == {"lid_hinge": Spring(stiffness=2.0, reference=0.25)}
    assert asset.springs_about(None)["lid_hinge"].reference == 0.0
    opts = output_session_options(tmp_path)
    assert opts.initial_state == a.initial_state and opts.springs == asset.springs and not opts.fixed_base
    pieces, notes = asset.collision
    assert len(pieces["body"]) == 5  # one hull per OBJ group


def test_an_invalid_overlay_fails_only_its_readers(tmp_path):
    _state(tmp_path, {"lid": 0.1}, {"fixed": False})
    (tmp_path / OVERLAY_NAME).write_text("{}")
    asset = RefinedAsset(tmp_path)
    assert asset.initial_state == {"lid": 0.1} and not asset.root.fixed
    with pytest.raises(ValueError, match="not a valid overlay"):
        asset.springs
