"""A small pair set for the realism tests: real WebM (VP9) clips of moving coloured boxes, encoded with PyAV,
their posters and stills (PNG), and a valid ``pairs.json``."""

from __future__ import annotations

import hashlib
import itertools
import json
import random
from pathlib import Path

import numpy as np

from asset2sim.schemas.realism import Clip, ClipPair, PairSet, PairSide

VIEWS = ("front", "side")
WIDTH, HEIGHT, FRAMES, FPS = 64, 48, 8, 8.0


def _frames(color: tuple[int, int, int], speed: int, offset: int) -> list[np.ndarray]:
    """FRAMES RGB images (HEIGHT, WIDTH, 3) of a 16x12 box of ``color`` moving right by ``speed`` px a frame."""
    out = []
    for i in range(FRAMES):
        img = np.full((HEIGHT, WIDTH, 3), 235, np.uint8)
        x = (offset + speed * i) % (WIDTH - 16)
        y = 10 + (3 * i) % (HEIGHT - 24)
        img[y:y + 12, x:x + 16] = color
        out.append(img)
    return out


def _encode_webm(path: Path, frames: list[np.ndarray]) -> None:
    import av

    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), "w", format="webm") as container:
        stream = container.add_stream("libvpx-vp9", rate=int(FPS))
        stream.width, stream.height, stream.pix_fmt = WIDTH, HEIGHT, "yuv420p"
        for img in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)


def _write_png(path: Path, img: np.ndarray) -> None:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(path)


def _method_clips(folder: Path, method: str, rng: random.Random) -> dict[str, Clip]:
    """One clip per view of ``method`` under ``folder/clips/<method>/`` (paths relative to ``folder``)."""
    clips = {}
    base = tuple(rng.randrange(0, 200) for _ in range(3))
    for k, view in enumerate(VIEWS):
        rel = f"clips/{method.replace(':', '_')}/{view}"
        frames = _frames(base, speed=2 + 3 * k + rng.randrange(3), offset=rng.randrange(20))
        _encode_webm(folder / f"{rel}.webm", frames)
        _write_png(folder / f"{rel}.png", frames[FRAMES // 2])
        stills = []
        for i in (0, FRAMES - 1):
            _write_png(folder / f"{rel}_{i}.png", frames[i])
            stills.append(f"{rel}_{i}.png")
        clips[view] = Clip(joint="joint_0", motion="push_release", view=view, video=f"{rel}.webm", poster=f"{rel}.png",
                           frames=stills, fps=FPS, n_frames=FRAMES, duration_s=FRAMES / FPS, width=WIDTH, height=HEIGHT)
    return clips


def write_pair_set(folder: Path, n_pairs: int, methods: tuple[str, ...] = ("asset2sim", "human", "direct", "defaults"),
                   seed: int = 0) -> PairSet:
    """Write ``folder/pairs.json`` with ``n_pairs`` pairs (objects ``obj000``...) cycling over every two of
    ``methods`` (side ``a`` the first of the two), the clips they name (two views each, WebM VP9 64x48, 8 frames,
    different per method) with posters and stills; returns the :class:`PairSet`."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    rng = random.Random(seed)
    clips = {m: _method_clips(folder, m, rng) for m in methods}
    combos = list(itertools.combinations(methods, 2))
    pairs = []
    for k in range(n_pairs):
        ma, mb = combos[k % len(combos)]
        object_id = f"obj{k:03d}"
        pair_id = hashlib.sha256(f"{seed}\0{object_id}\0{ma}\0{mb}".encode()).hexdigest()[:16]
        pairs.append(ClipPair(pair_id=pair_id, object_id=object_id, category="StorageFurniture", joint="joint_0",
                              motion="push_release", a=PairSide(method=ma, clips=[clips[ma][v] for v in VIEWS]),
                              b=PairSide(method=mb, clips=[clips[mb][v] for v in VIEWS])))
    pair_set = PairSet(pairs=pairs)
    (folder / "pairs.json").write_text(json.dumps(pair_set.model_dump(), indent=2))
    return pair_set
