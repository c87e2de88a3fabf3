"""A pair set with stills for the model-judge tests, and scripted judges for the fake OpenAI server.

:func:`write_judge_pair_set` writes small real PNG stills (64x48, different per pair, side and frame,
so every image has its own digest) and a valid ``pairs.json``: ``n_defect`` calibration pairs (side ``b``
a planted defect, cycling over :data:`DEFECTS`) and ``n_plain`` pairs of asset2sim against other methods.
No video is encoded: the judge reads the stills only.

Scripted judges are fake-server behaviours that read the request's images in order, under the
``Video A`` / ``Video B`` labels of the judge's message, and answer:

- :func:`good_judge`: picks the video without a broken still (from a digest table the test builds with
  :func:`broken_digests`); on plain pairs the side whose first still has the smaller digest (order-free);
- :func:`coin_flip_judge`: a seeded coin per request (the same request always gets the same answer);
- :func:`first_judge`: always ``A`` (position bias: never order-consistent);
- :func:`by_model`: dispatches on the request's model name (two judges behind one server).
"""

from __future__ import annotations

import base64
import hashlib
import json
import random
from pathlib import Path
from typing import Callable

from PIL import Image, ImageDraw

from asset2sim.schemas.realism import Clip, ClipPair, PairSet, PairSide
from tests import fake_openai_server as fake

DEFECTS = ("mass_x100", "door_zero_damping", "drawer_stuck_friction", "penetration_10mm", "scale_x3",
           "lid_slamming_spring")
OTHER_METHODS = ("human", "direct", "defaults")
WIDTH, HEIGHT, N_FRAMES = 64, 48, 3


def _png(path: Path, seed: str, frame: int) -> None:
    """A 64x48 still: a background and a box whose colour and place follow ``seed`` and ``frame``."""
    h = hashlib.sha256(seed.encode()).digest()
    img = Image.new("RGB", (WIDTH, HEIGHT), (h[0], h[1], h[2]))
    x = (h[3] + 9 * frame) % (WIDTH - 16)
    ImageDraw.Draw(img).rectangle([x, 10 + frame * 4, x + 15, 21 + frame * 4], fill=(h[4], h[5], h[6]))
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path, format="PNG")


def _side(folder: Path, name: str, method: str, joint: str) -> PairSide:
    rel = f"clips/{name}"
    frames = []
    for i in range(N_FRAMES):
        _png(folder / f"{rel}/front_{i}.png", f"{name}/{method}", i)
        frames.append(f"{rel}/front_{i}.png")
    clip = Clip(joint=joint, motion="push_release", view="front", video=f"{rel}/front.webm", poster=frames[1],
                frames=frames, fps=10.0, n_frames=20, duration_s=2.0, width=WIDTH, height=HEIGHT)
    return PairSide(method=method, clips=[clip])


def write_judge_pair_set(folder: Path, n_defect: int = 12, n_plain: int = 8) -> PairSet:
    """Write ``folder/pairs.json`` and its stills; returns the :class:`PairSet`. Pair ``i`` shows object
    ``obj{i:03d}``; defect pairs first (``defect`` and side ``b`` method ``defect:<name>``), then plain
    pairs (asset2sim against human / direct / defaults in turn)."""
    folder = Path(folder)
    pairs = []
    for i in range(n_defect + n_plain):
        oid, joint = f"obj{i:03d}", "joint_0"
        defect = DEFECTS[i % len(DEFECTS)] if i < n_defect else None
        other = f"defect:{defect}" if defect else OTHER_METHODS[(i - n_defect) % len(OTHER_METHODS)]
        a = _side(folder, f"{oid}_a", "asset2sim", joint)
        b = _side(folder, f"{oid}_b", other, joint)
        digest = hashlib.sha256()
        for side in (a, b):
            digest.update(side.method.encode())
            for f in side.clips[0].frames:
                digest.update((folder / f).read_bytes())
        pairs.append(ClipPair(pair_id=digest.hexdigest()[:16], object_id=oid, category="StorageFurniture", joint=joint,
                              motion="push_release", a=a, b=b, defect=defect))
    ps = PairSet(pairs=pairs)
    (folder / "pairs.json").write_text(ps.model_dump_json(indent=2))
    return ps


def broken_digests(folder: Path, ps: PairSet) -> set[str]:
    """sha256 (hex) of every still of the broken side (``b``) of the defect pairs."""
    return {hashlib.sha256((Path(folder) / f).read_bytes()).hexdigest()
            for p in ps.pairs if p.defect for c in p.b.clips for f in c.frames}


# ----------------------------------------------------------------------------- reading a request
def videos(req: fake.Request) -> dict[str, list[str]]:
    """sha256 of the images under each ``Video A`` / ``Video B`` label of the request, in order."""
    out: dict[str, list[str]] = {"A": [], "B": []}
    label = None
    for m in req.body.get("messages", []):
        content = m.get("content")
        for part in content if isinstance(content, list) else []:
            if part.get("type") == "text":
                t = part.get("text", "")
                label = "A" if t.startswith("Video A") else "B" if t.startswith("Video B") else label
            elif part.get("type") == "image_url" and label is not None:
                url = part["image_url"]["url"]
                out[label].append(hashlib.sha256(base64.b64decode(url.split(",", 1)[1])).hexdigest())
    return out


def answer(letter: str, reason: str = "scripted") -> fake.Behaviour:
    """Reply with the strict JSON verdict."""
    return fake.reply(json.dumps({"more_realistic": letter, "reason": reason}))


Judge = Callable[[fake.Request], str]


def scripted(judge: Judge) -> fake.Behaviour:
    """A behaviour answering the JSON verdict ``judge(request)`` (``A`` or ``B``)."""

    def b(server: fake.FakeOpenAIServer, req: fake.Request) -> None:
        answer(judge(req))(server, req)

    return b


def good_judge(broken: set[str]) -> fake.Behaviour:
    """Picks the video with no broken still; on plain pairs the one whose first still's digest is smaller."""

    def judge(req: fake.Request) -> str:
        v = videos(req)
        bad = {k for k, digests in v.items() if broken & set(digests)}
        if len(bad) == 1:
            return "B" if "A" in bad else "A"
        return "A" if v["A"][:1] < v["B"][:1] else "B"

    return scripted(judge)


def coin_flip_judge(seed: int = 7) -> fake.Behaviour:
    """A seeded coin per request content: deterministic, blind to what the images show."""

    def judge(req: fake.Request) -> str:
        v = videos(req)
        key = hashlib.sha256(json.dumps([seed, v["A"], v["B"]]).encode()).hexdigest()
        return random.Random(key).choice("AB")

    return scripted(judge)


def first_judge() -> fake.Behaviour:
    """Always ``A``: pure position bias."""
    return scripted(lambda req: "A")


def by_model(judges: dict[str, fake.Behaviour]) -> fake.Behaviour:
    """Dispatch on the request's ``model`` (litellm sends the name without the ``openai/`` provider)."""

    def b(server: fake.FakeOpenAIServer, req: fake.Request) -> None:
        name = str(req.body.get("model", ""))
        beh = judges.get(name) or judges.get(name.rsplit("/", 1)[-1])
        if beh is None:
            fake.status(404, {"error": {"message": f"fake: no judge named {name!r}"}})(server, req)
            return
        beh(server, req)

    return b
