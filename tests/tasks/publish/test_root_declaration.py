"""The root declaration of an output folder: initial_state.json "root", the
URDF comment, read back by every check (tasks.assemble.write)."""

from __future__ import annotations

import json

import pytest

from asset2sim.schemas.overlay import RootMount
from asset2sim.tasks.assemble import write
from asset2sim.output_folder import OutputError


def test_record_of_a_mounted_root():
    rec = write.root_record(RootMount(kind="wall-mounted", fixed=True, source="request: 'on the wall'"))
    assert rec == {"fixed": True, "mounting": "wall-mounted", "pose": {"xyz": [0.0, 0.0, 0.0], "quat_xyzw": [0.0, 0.0, 0.0, 1.0]},
                   "source": "request: 'on the wall'"}
    assert "FIXED root" in write.root_sentence(RootMount(kind="wall-mounted", fixed=True))


def test_record_of_a_free_root_and_of_none():
    assert write.root_record(None) == {"fixed": False, "mounting": "free-standing", "pose": None, "source": ""}
    assert write.root_sentence(None).startswith("Free-standing")


def test_read_root_roundtrip_and_defaults(tmp_path):
    assert write.read_root(tmp_path) == RootMount()  # no initial_state.json: free
    (tmp_path / write.STATE_NAME).write_text(json.dumps({"initial_joint_positions": {}}))
    assert not write.read_root(tmp_path).fixed  # earlier outputs without "root"
    m = RootMount(kind="hangs-in-frame", fixed=True, source="category prior (Door)")
    (tmp_path / write.STATE_NAME).write_text(json.dumps({"initial_joint_positions": {}, "root": write.root_record(m)}))
    assert write.read_root(tmp_path) == m


@pytest.mark.parametrize("root", [{"fixed": "yes"}, [], {"fixed": True, "mounting": "glued"}])
def test_malformed_root_is_refused_naming_the_file(tmp_path, root):
    (tmp_path / write.STATE_NAME).write_text(json.dumps({"initial_joint_positions": {}, "root": root}))
    with pytest.raises(OutputError, match="initial_state.json"):
        write.read_root(tmp_path)
