"""Parts worked at once (tasks/check/joint_batches.py): a keyboard's keys swept and pushed in batches read exactly as
each key alone, a key that fails in its batch is swept alone, and parts that could meet, or a part carried by another
part, are never in one batch."""

from __future__ import annotations

import numpy as np
import pytest

from asset2sim.engines.base import SessionOptions
from asset2sim.engines.registry import available_engines, open_session
from asset2sim.engines.source import SimObject, UrdfFile
from asset2sim.tasks.check import breakaway, joint_batches, sweep
from asset2sim.tasks.check.blockers import fixed_root_options
from asset2sim.tasks.geometry import limits
from asset2sim.urdf import read_urdf, write_urdf
from asset2sim.urdf.model import UrdfDynamics, UrdfLimit
from tests.unseen_assets import build_desk_lamp, build_double_door_cabinet, build_keyboard

def _keyboard(tmp_path, *, deep_key: str | None = None):
    """The generated keyboard's file with friction and damping on every key; ``deep_key`` made to slide 0.04 along
    its row (a key's stroke is 0.009 down), 0.015 into the next key's place."""
    folder = build_keyboard(tmp_path / "kb")
    model = read_urdf(folder / "mobility.urdf")
    for j in model.movable_joints:
        j.dynamics = UrdfDynamics(damping=0.01, friction=0.05)
        if j.name == deep_key:
            j.limit, j.axis_xyz = UrdfLimit(lower=0.0, upper=0.04), np.array([1.0, 0.0, 0.0])
    urdf = folder / "with_friction.urdf"
    urdf.write_bytes(write_urdf(model))
    closed = {j.name: (0.0, 1.0, float(j.limit.upper)) for j in model.movable_joints}
    return urdf, model, closed


def test_keys_swept_together_read_as_each_alone(tmp_path):
    """24 keys in a few batches; every key's sweep (ends, times, deepest contact, trace) equals its sweep alone; the
    key slid into its neighbour (worked in another batch, so held where it stands) is stopped by it in its batch, the
    pair its deepest contact, and only it fails."""
    urdf, model, closed = _keyboard(tmp_path, deep_key="joint_5")
    state = {n: 0.0 for n in closed}
    moved = limits.subtrees(model)
    with open_session("pybullet", urdf, fixed_root_options(state)) as s:
        boxes = {n: joint_batches.swept_box(s, n, moved[n], state, [0.0, closed[n][2]]) for n in closed}
        groups = joint_batches.batches(boxes)
        assert sorted(n for g in groups for n in g) == sorted(closed) and len(groups) <= 4
        saved = s.save_state()
        together = sweep.sweep_together(s, groups[0], closed, moved, state)
        for name in groups[0]:
            s.restore_state(saved)
            alone = sweep.sweep_joint(s, name, closed=0.0, direction=1.0, open_range=closed[name][2], links=moved[name],
                                      initial_state=state)
            assert together[name].summary() == alone.summary() and together[name].trace == alone.trace, name
    assert "joint_5" in groups[0] and "joint_6" not in groups[0]
    stopped = together["joint_5"]
    assert not stopped.passed and stopped.reached_open < 0.95 and set(stopped.worst_pair) == {"link_5", "link_6"}
    assert all(j.passed for n, j in together.items() if n != "joint_5")


def test_run_sweep_equals_every_key_swept_alone(tmp_path, monkeypatch):
    """run_sweep's batches and the sweep of every key alone give the same run, the key slid into its neighbour
    failing in both."""
    urdf, _, closed = _keyboard(tmp_path, deep_key="joint_5")
    obj = SimObject(UrdfFile(urdf), {n: 0.0 for n in closed})
    batched = sweep.run_sweep("pybullet", obj, closed)
    monkeypatch.setattr(sweep, "_passed_together", lambda *a, **k: {})
    alone = sweep.run_sweep("pybullet", obj, closed)
    assert [j.summary() for j in batched.joints] == [j.summary() for j in alone.joints]
    assert sweep.sweep_metric(batched).details["failing"] == ["joint_5"]


@pytest.mark.parametrize("engine", ["pybullet", pytest.param("physx", marks=pytest.mark.physx)])
def test_keys_pushed_together_break_away_as_each_alone(tmp_path, engine):
    """Each key's breakaway push (N) pushed with the others equals its push alone, within 1e-9 N."""
    if engine not in available_engines():
        pytest.skip(f"{engine} not installed")
    urdf, model, closed = _keyboard(tmp_path)
    frictions = {n: 0.05 for n in closed}
    dampings = {n: 0.01 for n in closed}
    opts = SessionOptions(initial_state={n: 0.004 for n in closed}, fixed_base=True, gravity=False, ground=False)
    with open_session(engine, urdf, opts) as s:
        together = breakaway.measure_breakaway(s, frictions, dampings, model)
        for name, got in together.items():
            alone = breakaway.joint_breakaway(s, name, 0.05, 0.01)
            assert got.passed and alone.passed
            assert got.breakaway == pytest.approx(alone.breakaway, abs=1e-9) and got.direction == alone.direction, name
        assert s.joint_positions() == pytest.approx(opts.initial_state, abs=1e-6)  # the state restored


def test_parts_that_could_meet_or_ride_on_another_part_are_worked_apart(tmp_path):
    """Two doors meeting at the middle sweep through one another's boxes: one door to a batch. A lamp's upper arm and
    shade ride on the lower arm: only the lower arm is a branch of the root."""
    folder = build_double_door_cabinet(tmp_path / "cab")
    model = read_urdf(folder / "mobility.urdf")
    doors = [j.name for j in model.movable_joints]
    assert joint_batches.root_branches(model, doors) == doors
    state = {n: 0.0 for n in doors}
    with open_session("pybullet", folder / "mobility.urdf", fixed_root_options(state)) as s:
        boxes = {n: joint_batches.swept_box(s, n, limits.subtrees(model)[n], state, [0.0, 1.57]) for n in doors}
    assert joint_batches.batches(boxes) == [[doors[0]], [doors[1]]]
    lamp = read_urdf(build_desk_lamp(tmp_path / "lamp") / "mobility.urdf")
    arms = [j.name for j in lamp.movable_joints]
    assert joint_batches.root_branches(lamp, arms) == [j.name for j in lamp.movable_joints if j.parent == "link_3"] == ["joint_0"]


def test_boxes_apart_by_less_than_the_margin_are_not_batched():
    """Boxes 0.5 mm apart (under the 1 mm margin on each side) are worked apart; 3 mm apart, together."""
    a = ([0.0, 0.0, 0.0], [1.0, 1.0, 1.0])
    near = ([1.0005, 0.0, 0.0], [2.0, 1.0, 1.0])
    far = ([1.003, 0.0, 0.0], [2.0, 1.0, 1.0])
    assert joint_batches.batches({"a": a, "b": near}) == [["a"], ["b"]]
    assert joint_batches.batches({"a": a, "b": far}) == [["a", "b"]]


def test_a_batch_reads_each_parts_links_in_their_subtree_order(tmp_path, monkeypatch):
    """A part of several links (the desk lamp's lower arm carries the upper arm and the shade) has its mass summed and
    its lever measured over its links in the order the tree gives them, as when it is swept alone: not in the order
    of a set of names, which Python's string hashing changes from one process to the next (a sum of three masses can
    differ in its last bit)."""
    model = read_urdf(build_desk_lamp(tmp_path / "lamp") / "mobility.urdf")
    moved = limits.subtrees(model)
    closed = {j.name: (float(j.limit.lower), 1.0, float(j.limit.upper - j.limit.lower)) for j in model.movable_joints}
    state = {n: 0.0 for n in closed}
    seen: dict[str, list[list[str]]] = {}
    for name in ("effort_limit", "traverse_speed"):
        real = getattr(sweep, name)
        monkeypatch.setattr(sweep, name, lambda s, j, links, *a, _real=real, _name=name, **k:
                            seen.setdefault(_name, []).append(list(links)) or _real(s, j, links, *a, **k))
    lower = next(n for n, links in moved.items() if len(links) == 3)
    with open_session("pybullet", model.path, fixed_root_options(state)) as s:
        sweep.sweep_together(s, [lower], closed, moved, state)
    assert seen == {"effort_limit": [moved[lower]], "traverse_speed": [moved[lower]]}
