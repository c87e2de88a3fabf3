"""Interaction clips: encoded with PyAV, drawn from the joint sweep's trace with fixed cameras, written by
refine (opt-out) and by evaluate, played in report.html, listed in the catalog row."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

pytest.importorskip("av")

from asset2sim import api  # noqa: E402
from asset2sim.schemas.config import RefineConfig  # noqa: E402
from asset2sim.schemas.realism import ClipSet  # noqa: E402
from asset2sim.tasks.evaluation import clips  # noqa: E402
from asset2sim.tasks.refine import refine_asset  # noqa: E402
from tests.conftest import SHARED, needs_shared  # noqa: E402
from tests.helpers import decode_frames  # noqa: E402
from tests.contract_asset import write_contract_asset  # noqa: E402


def _frames(n: int, size=(64, 48)) -> list[np.ndarray]:
    w, h = size
    out = []
    for k in range(n):
        img = np.full((h, w, 3), 230, np.uint8)
        img[10:30, 4 + 3 * k: 20 + 3 * k] = (200, 60, 30)
        out.append(img)
    return out


def test_encode_is_deterministic_and_decodes_to_the_frames():
    frames = _frames(10)
    a, b = clips.encode_webm(frames, 12.0), clips.encode_webm(frames, 12.0)
    assert a == b and a[:4] == b"\x1a\x45\xdf\xa3"  # the same bytes; an EBML (WebM) header
    import io

    import av

    with av.open(io.BytesIO(a)) as f:
        back = [fr.to_ndarray(format="rgb24") for fr in f.decode(video=0)]
    assert len(back) == 10 and back[0].shape == (48, 64, 3)
    # lossy, but the moving box is where it was drawn: mean error small, and frames 0 and 9 differ
    assert np.abs(back[5].astype(int) - frames[5].astype(int)).mean() < 6.0
    assert np.abs(back[0].astype(int) - back[9].astype(int)).mean() > 5.0


def test_encode_refuses_odd_or_mixed_sizes():
    with pytest.raises(ValueError, match="even"):
        clips.encode_webm([np.zeros((47, 64, 3), np.uint8)])
    with pytest.raises(ValueError, match="even"):
        clips.encode_webm([np.zeros((48, 64, 3), np.uint8), np.zeros((48, 62, 3), np.uint8)])
    with pytest.raises(ValueError, match="no frame"):
        clips.encode_webm([])


def test_trajectory_samples_at_the_frame_rate():
    t = np.arange(0, 241) / 240.0  # 1 s at 240 Hz
    traj = clips.Trajectory(t=t, joints={"j": np.linspace(0, 1, 241)})
    idx = traj.sampled(12.0)
    assert len(idx) == 13 and idx[0] == 0 and idx[-1] == 240
    assert np.allclose(t[idx], np.arange(13) / 12.0, atol=1 / 480)
    with pytest.raises(ValueError, match="positions"):
        clips.Trajectory(t=t, joints={"j": np.zeros(3)})


def _check_clip_folder(out, sweeps: int, tasks: int = 0) -> ClipSet:
    """The clips of ``out``: ``sweeps`` joints' sweeps and ``tasks`` task attempts, each from every view, decoding to
    their frames; a sweep's poster (its largest opening) differs from its first frame; a task's first still shows
    the red dot where the gripper holds."""
    from PIL import Image

    clip_set = clips.read_clip_set(out)
    assert clip_set is not None
    by_motion = {m: [c for c in clip_set.clips if c.motion == m] for m in ("sweep", "task")}
    assert len(by_motion["sweep"]) == sweeps * len(clips.CLIP_VIEWS) and len(by_motion["task"]) == tasks * len(clips.CLIP_VIEWS)
    assert len(clip_set.clips) == (sweeps + tasks) * len(clips.CLIP_VIEWS)
    for c in clip_set.clips:
        frames = decode_frames(out / "clips" / c.video)
        assert len(frames) == c.n_frames >= (8 if c.motion == "sweep" else 3)
        assert frames[0].shape == (clips.CLIP_SIZE[1], clips.CLIP_SIZE[0], 3)
        assert len(c.frames) == min(clips.STILLS, c.n_frames) and all((out / "clips" / f).is_file() for f in c.frames)
        first = np.asarray(Image.open(out / "clips" / c.frames[0]).convert("RGB"), int)
        if c.motion == "sweep":  # the part moves: the frame of the largest opening differs from the first
            poster = np.asarray(Image.open(out / "clips" / c.poster).convert("RGB"), int)
            assert np.abs(poster - frames[0].astype(int)).mean() > 1.0
        else:
            red = (first[..., 0] == 220) & (first[..., 1] == 30) & (first[..., 2] == 30)
            assert red.sum() >= 20, "the grasp point is drawn on the first frame"
    return clip_set


@pytest.mark.slow  # end to end: a dev object refined twice with every extra
@needs_shared
def test_refine_writes_clips_that_the_report_plays_and_the_catalog_lists(tmp_path):
    row = next(r for r in csv.DictReader(open(SHARED / "manifest.csv")) if r["id"] == "100221")
    res = refine_asset(SHARED / "100221", row["prompt"], tmp_path / "out", task=row["task"] or None)
    out = tmp_path / "out"
    clip_set = _check_clip_folder(out, 1, tasks=1)  # the manifest's task: one attempt, drawn too
    assert res.extras["clips"] == str(out / "clips")
    html = (out / "report.html").read_text()
    srcs = re.findall(r"<video src='([^']+)' poster='([^']+)'", html)
    assert len(srcs) == len(clip_set.clips)
    for src, poster in srcs:
        assert (out / src).is_file() and (out / poster).is_file()
    assert "How it moves" in html
    # the catalog row's clips column: the videos, relative to the output folder
    assert clips.clip_videos(out) == [f"clips/{c.video}" for c in clip_set.clips]
    # same input, same code: the same clip bytes
    again = refine_asset(SHARED / "100221", row["prompt"], tmp_path / "again", task=row["task"] or None)
    assert again.report.failure_mode == res.report.failure_mode
    for c in clip_set.clips:
        assert (tmp_path / "again" / "clips" / c.video).read_bytes() == (out / "clips" / c.video).read_bytes()


def test_refine_without_clips_writes_none_and_keeps_the_configuration_hash_of_the_default(demo_root, tmp_path, refine_once):
    assert RefineConfig(clips=True).config_hash() == RefineConfig().config_hash()
    assert RefineConfig(clips=False).config_hash() != RefineConfig().config_hash()
    res = refine_once(demo_root / "box_lid", "a box with its lid slightly open", RefineConfig(clips=False))
    assert "clips" not in res.result.extras and not (res.out / "clips").exists()
    assert "<video" not in (res.out / "report.html").read_text()
    assert clips.clip_videos(res.out) == []


@pytest.mark.slow  # end to end: the evaluation with its media (renders and sweep clips)
def test_evaluate_writes_clips_of_any_urdf_and_can_leave_them_out(tmp_path):
    asset = tmp_path / "asset"
    write_contract_asset(asset, lid_angle=0.3)
    ev = api.evaluate(asset, write_to=tmp_path / "ev")
    swept = list(dict.fromkeys([*ev.task_joints, "lid_hinge", "post_slide"]))  # every swept joint, the task-relevant first
    clip_set = _check_clip_folder(tmp_path / "ev", len(swept))  # no task: sweeps only
    assert [c.joint for c in clip_set.clips[::2]] == swept
    assert not any("clips failed" in n for n in ev.notes)
    api.evaluate(asset, write_to=tmp_path / "bare", clips=False)
    assert not (tmp_path / "bare" / "clips").exists()
    assert json.loads((tmp_path / "ev" / "clips" / "clips.json").read_text())["version"] == "1"
