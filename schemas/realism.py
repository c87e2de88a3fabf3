"""Realism (the research's seventh axis): interaction clips, the pairs a
person or a model judges, their ratings and the scores per method.

Files (``docs/guide/realism.md``):

- an output folder's ``clips/clips.json`` (:class:`ClipSet`): the clips
  ``refine`` and ``evaluate`` write of each task-relevant joint's sweep;
- a pair set's ``pairs.json`` (:class:`PairSet`), beside the ``clips/``
  folders it names: two clips of one object that differ only in physics
  (the same meshes, cameras and scripted motion);
- ``ratings.parquet`` (rows of :class:`Rating`) and ``judgements.parquet``
  (rows of :class:`JudgeVerdict`) beside ``pairs.json``;
- ``realism_scores.parquet`` (rows of :class:`MethodScore`).

Paths inside these files are relative to the file that names them and use
``/``; times are seconds; joint positions rad or m.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from asset2sim.schemas import Frozen

#: Version of the clips.json / pairs.json layout.
REALISM_VERSION = "1"

#: The scripted motions a clip shows: ``sweep`` the joint sweep tier's drive out and back (fixed root, no
#: gravity); ``push_release`` a force-limited push toward open, then the part let go (gravity on, the
#: output's root), what shows damping, friction, springs and mass; ``task`` the gripper task.
Motion = Literal["sweep", "push_release", "task"]


class Clip(Frozen):
    """One rendered clip: ``video`` (WebM, VP9) and ``poster`` (PNG, the frame of the largest opening),
    paths relative to the JSON file naming the clip; ``frames`` a few stills (PNG) spread over the clip,
    for model judges; ``view`` the camera (``asset2sim.tasks.geometry.render_camera.VIEWS``); ``fps`` frames
    per second; ``n_frames`` frames in ``video``; ``duration_s`` simulated time shown, s."""

    joint: str
    motion: Motion
    view: str
    video: str
    poster: str
    frames: list[str] = []
    fps: float
    n_frames: int
    duration_s: float
    width: int
    height: int


class ClipSet(Frozen):
    """``clips/clips.json`` of an output folder: every clip written there (paths relative to ``clips/``)."""

    version: str = REALISM_VERSION
    clips: list[Clip] = []
    skipped: dict[str, str] = {}
    """joint -> why it has no clip"""


class PairSide(Frozen):
    """One side of a pair: the ``method`` whose physics it shows (``asset2sim``, ``human``, ``direct``,
    ``defaults``, or ``defect:<name>`` for a planted defect) and its clips, one per view."""

    method: str
    clips: list[Clip]


class ClipPair(Frozen):
    """Two clips of one object and joint that differ only in physics.

    ``pair_id`` a digest of both sides' clip bytes and methods (stable across runs of the same inputs);
    ``a`` is the side under test (asset2sim's output, or the intact copy in a calibration pair) and ``b``
    the other; which side is shown left is drawn per rater and pair, never stored here.
    ``defect``: the planted defect on side ``b`` (a calibration pair), else None."""

    pair_id: str
    object_id: str
    category: str
    request: str = ""
    joint: str
    motion: Motion
    a: PairSide
    b: PairSide
    defect: str | None = None


class PairSet(Frozen):
    """``pairs.json``: the pairs judges see (paths relative to the folder of ``pairs.json``)."""

    version: str = REALISM_VERSION
    pairs: list[ClipPair] = []
    skipped: dict[str, str] = {}
    """object id / method -> why no pair was made"""


Choice = Literal["left", "right"]


class Rating(Frozen):
    """One person's answer to one pair (a row of ``ratings.parquet``).

    ``left`` / ``right``: the methods shown on each side; ``winner`` / ``loser`` the methods chosen and not
    chosen; ``score`` the optional 1-5 realism score of the chosen side; ``shown_at`` / ``answered_at``
    POSIX times, s; ``seconds`` the time the rater took."""

    rater: str
    pair_id: str
    object_id: str
    left: str
    right: str
    choice: Choice
    winner: str
    loser: str
    score: int | None = Field(None, ge=1, le=5)
    comment: str = ""
    shown_at: float
    answered_at: float
    seconds: float


class JudgeVerdict(Frozen):
    """A model judge's verdict on one pair (a row of ``judgements.parquet``): asked in both orders;
    ``first`` / ``second`` the method each order chose (None: no usable answer); ``kept`` only when both
    orders chose the same method, which is then ``winner``; ``failed_calls`` the questions (of the two) whose
    model call failed (time-out, deadline, reply too large, HTTP error after the retries)."""

    model: str
    family: str
    pair_id: str
    object_id: str
    method_a: str
    method_b: str
    defect: str | None = None
    first: str | None
    second: str | None
    kept: bool
    winner: str | None
    reason: str = ""
    calls: int = 0
    prompt_tokens: int = 0
    completion_tokens: int = 0
    cost_usd: float = 0.0
    failed_calls: int = 0


class MethodScore(Frozen):
    """Bradley-Terry realism of one method (a row of ``realism_scores.parquet``): ``strength`` the log
    strength (the methods' mean is 0) with its 95 % interval; ``elo`` the same on the Elo scale
    (400 / ln 10 per unit, mean 1000); ``source`` ``people`` or a judge model."""

    source: str
    method: str
    strength: float
    ci_low: float
    ci_high: float
    elo: float
    comparisons: int
    wins: int
