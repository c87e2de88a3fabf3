"""Realism pairs: the scripted push-and-release on two sets of physics, planted defects that change what a
person sees, clips drawn with the same cameras, ``asset2sim pairs``."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("av")

from asset2sim.schemas.realism import PairSet  # noqa: E402
from asset2sim.tasks.evaluation import clips  # noqa: E402
from asset2sim.apps.realism import defects, motion, pairs  # noqa: E402
from asset2sim.apps.realism.pair_set import read_pair_set  # noqa: E402
from asset2sim.urdf import read_urdf  # noqa: E402
from tests.conftest import SHARED, needs_shared  # noqa: E402
from tests.helpers import decode_frames  # noqa: E402


@pytest.fixture(scope="module")
def refined(demo_root, refine_factory):
    """A refined box with a lid (the demo dataset's, extras off; the session's shared refine, read-only): side ``a``
    of every pair here."""
    res = refine_factory(demo_root / "box_lid", "a box with its lid closed", extras=False)
    assert res.report.failure_mode == "none"
    return res.out


@pytest.fixture(scope="module")
def setting(refined):
    a = motion.side_from_folder(refined, "asset2sim")
    [(joint, closed)] = pairs.pushed_joints(refined)
    force = motion.drive_limit(a, joint, closed)
    return a, joint, closed, force


def _run(side, joint, closed, force):
    traj = motion.push_release(side, joint, closed, force)
    return traj, closed.direction * (traj.joints[joint] - closed.q_closed) / closed.open_range  # opening fraction per sample


def test_push_release_is_deterministic_and_opens_then_lets_go(setting):
    a, joint, closed, force = setting
    t1, f1 = _run(a, joint, closed, force)
    t2, f2 = _run(a, joint, closed, force)
    assert np.array_equal(f1, f2) and np.array_equal(t1.root_pos, t2.root_pos)
    cfg = motion.PushReleaseConfig()
    assert t1.t[-1] == pytest.approx(cfg.push_time + cfg.release_time, abs=1e-9)
    push_end = int(np.searchsorted(t1.t, cfg.push_time))
    assert f1[push_end] - f1[0] > 0.2  # the drive opened it
    assert t1.root_rot.shape == (len(t1.t), 3, 3)


@pytest.mark.parametrize("name", sorted(defects.DEFECTS))
def test_each_planted_defect_changes_the_motion_or_the_object(setting, tmp_path, name):
    a, joint, closed, force = setting
    b = defects.plant_defect(a, name, joint, closed, force, tmp_path / "b")
    assert b.method == f"defect:{name}" and b.urdf.parent == tmp_path / "b"
    assert a.urdf.read_bytes() != b.urdf.read_bytes() or b.springs != a.springs
    _, fa = _run(a, joint, closed, force)
    tb, fb = _run(b, joint, closed, force)
    push_end = int(np.searchsorted(tb.t, motion.PushReleaseConfig().push_time))
    if name == "mass_x100":  # the same drive lifts a 100x heavier lid far less
        assert fb[: push_end + 1].max() < 0.5 * fa[: push_end + 1].max()
    elif name == "stuck_friction":  # friction beyond the drive: it never moves
        assert np.abs(fb - fb[0]).max() < 1e-3 and np.abs(fa - fa[0]).max() > 0.2
    elif name == "zero_damping":  # it coasts on after the release (or falls) where the damped part stops
        assert np.abs(np.diff(fb[push_end:])).sum() > 1.5 * np.abs(np.diff(fa[push_end:])).sum()
    elif name == "slamming_spring":  # pulled shut after the release
        assert fb[-1] < fa[-1] - 0.2 and fb[-1] < 0.1
    elif name == "scale_x3":
        la, lb = read_urdf(a.urdf), read_urdf(b.urdf)
        oa = next(j for j in la.joints if j.name == joint).origin[:3, 3]
        ob = next(j for j in lb.joints if j.name == joint).origin[:3, 3]
        assert np.allclose(ob, 3.0 * oa) and b.scale == 3.0
    elif name == "penetration_10mm":
        oa = next(j for j in read_urdf(a.urdf).joints if j.name == joint).origin[:3, 3]
        ob = next(j for j in read_urdf(b.urdf).joints if j.name == joint).origin[:3, 3]
        assert np.linalg.norm(ob - oa) == pytest.approx(defects.PENETRATION_DEPTH, rel=1e-6)
    with pytest.raises(KeyError, match="unknown defect"):
        defects.plant_defect(a, "nonsense", joint, closed, force, tmp_path / "c")


def test_a_pair_holds_the_visuals_fixed_and_only_the_physics_differs(setting, refined, tmp_path):
    a, joint, closed, force = setting
    b = defects.plant_defect(a, "stuck_friction", joint, closed, force, tmp_path / "work")
    spec = pairs.PairSpec(a=a, b=b, joint=joint, object_id="box_lid", category="Box", defect="stuck_friction")
    pair = pairs.make_pair(spec, closed, tmp_path / "set", 0)
    assert [c.view for c in pair.a.clips] == list(clips.CLIP_VIEWS) == [c.view for c in pair.b.clips]
    for ca, cb in zip(pair.a.clips, pair.b.clips):
        va, vb = decode_frames(tmp_path / "set" / ca.video), decode_frames(tmp_path / "set" / cb.video)
        assert len(va) == len(vb) == ca.n_frames
        # the same start pose through the same camera: the first frames are the same picture
        assert np.abs(va[0].astype(int) - vb[0].astype(int)).mean() < 1.0
        # then the intact lid opens and the stuck one does not
        assert np.abs(va[len(va) // 3].astype(int) - vb[len(vb) // 3].astype(int)).mean() > 2.0
    again = pairs.make_pair(spec, closed, tmp_path / "set2", 0)
    assert again.pair_id == pair.pair_id  # a digest of the clips' bytes: same inputs, same pair
    assert "box_lid" not in json.dumps([c.video for c in pair.a.clips + pair.b.clips])  # folders by number only


@pytest.mark.slow  # end to end: the command line
def test_pairs_command_writes_a_pair_set_of_refined_outputs(refined, tmp_path):
    out = tmp_path / "pairs"
    cmd = [sys.executable, "-m", "asset2sim", "pairs", str(refined), "--out", str(out), "--defects", "mass_x100,slamming_spring"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    ps = PairSet.model_validate_json((out / "pairs.json").read_text())
    assert [p.defect for p in ps.pairs] == ["mass_x100", "slamming_spring"]
    assert all(p.a.method == "asset2sim" and p.b.method == f"defect:{p.defect}" for p in ps.pairs)
    for p in ps.pairs:
        for c in p.a.clips + p.b.clips:
            assert (out / c.video).is_file() and all((out / f).is_file() for f in c.frames)
    bad = subprocess.run([*cmd[:-1], "nonsense"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "DEFECT_UNKNOWN" in bad.stderr + bad.stdout
    none = subprocess.run([sys.executable, "-m", "asset2sim", "pairs", str(tmp_path), "--out", str(tmp_path / "x")],
                          capture_output=True, text=True, timeout=120)
    assert none.returncode == 1 and "PAIRS_INPUT_INVALID" in none.stderr + none.stdout


@pytest.mark.slow  # end to end: two refines through the command line
def test_pairs_over_two_refines_of_one_object_get_distinct_ids_that_rate_accepts(refined, tmp_path):
    runs = [tmp_path / run / "box_lid" for run in ("monday", "tuesday")]
    for run in runs:  # two refines of the same object: the same clips for the same planted defect
        shutil.copytree(refined, run)
    out = tmp_path / "pairs"
    cmd = [sys.executable, "-m", "asset2sim", "pairs", *map(str, runs), "--out", str(out), "--defects", "mass_x100"]
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    ps = read_pair_set(out)  # refuses a repeated pair id
    ids = [p.pair_id for p in ps.pairs]
    assert len(ids) == 2 and len(set(ids)) == 2
    assert ps.pairs[0].a.clips[0].video != ps.pairs[1].a.clips[0].video
    rate = subprocess.run([sys.executable, "-m", "asset2sim", "rate", str(out), "--scores"], capture_output=True,
                          text=True, timeout=300)
    assert rate.returncode == 3 and "NOT_RATED" in rate.stderr, rate.stdout + rate.stderr  # a valid set, not rated yet
    again = tmp_path / "again"
    assert subprocess.run([*cmd[:-3], str(again), *cmd[-2:]], capture_output=True, timeout=600).returncode == 0
    assert [p.pair_id for p in read_pair_set(again).pairs] == ids  # deterministic


@pytest.mark.slow  # end to end: dev objects through the benchmark and the pairs
@needs_shared
def test_a_benchmark_folder_gives_asset2sim_against_each_other_method(tmp_path):
    from asset2sim.apps.benchmark.benchmark import run_benchmark

    bench = tmp_path / "bench"
    records = run_benchmark(SHARED / "manifest.csv", ["asset2sim", "defaults", "human"], bench, rows=["100221"], reports=False)
    assert not [r for r in records if r.get("error")]
    specs, skipped = pairs.specs_from_folders([bench], bench / "realism", defects=())
    assert skipped == {} and [(s.a.method, s.b.method) for s, _ in specs] == [("asset2sim", "human"), ("asset2sim", "defaults")]  # in --against order
    assert all(s.object_id == "100221" and s.defect is None and s.request for s, _ in specs)
    ps = pairs.build_pair_set(specs, bench / "realism")
    assert [p.b.method for p in ps.pairs] == ["human", "defaults"] and ps.skipped == {}
    # the human reference's scale differs from asset2sim's: the same cameras show it (the sides' first frames differ)
    a0 = decode_frames(bench / "realism" / ps.pairs[0].a.clips[0].video)[0].astype(int)
    b0 = decode_frames(bench / "realism" / ps.pairs[0].b.clips[0].video)[0].astype(int)
    assert np.abs(a0 - b0).mean() > 1.0
