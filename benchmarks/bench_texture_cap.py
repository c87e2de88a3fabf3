"""PyBullet's load time and peak memory against texture size (the texture caps).

Copies PartNet-Mobility object 103275 (a stapler, 4 JPEG textures of about
1 KB) into a temporary folder and replaces ``images/texture_0.jpg`` by

- ``pixels``: a JPEG of N x N pixels (a smooth gradient, so the file stays
  small: what grows is the decoded image, N * N * 4 bytes as RGBA), and
- ``bytes``: the original 1 KB JPEG followed by zero bytes up to S bytes
  (a sparse file: it costs no disk, but a reader that slurps the file first,
  as PyBullet's importer does, allocates S bytes),

then loads ``mobility.urdf`` with ``pybullet.loadURDF`` in a child process
(``DIRECT``, as refine's engine) and prints, per point, the wall time of the
load (s), the child's peak resident memory (MiB, ``VmHWM``) and its exit
status (a crash such as ``std::bad_alloc`` is reported, not raised). A
least-squares line through the points gives MiB per megapixel and per MiB of
file. The caps in ``tasks/ingest/findings.py`` (``MAX_TEXTURE_PIXELS``,
``MAX_TEXTURE_BYTES``) and ``docs/design/validation.md`` ("Texture caps") come from
this measurement.

    .venv/bin/python benchmarks/bench_texture_cap.py                       # default points
    .venv/bin/python benchmarks/bench_texture_cap.py --pixels 1024 4096 --mib 16 256

Keep N <= 8192 and S <= 1024 MiB on a shared machine (a few seconds and up
to ~1.2 GiB per point); extrapolate beyond.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ASSET = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "103275"
TEXTURE = "images/texture_0.jpg"

#: The child reports VmHWM (peak resident set of its own address space), not
#: ``ru_maxrss``, which Linux carries over from the parent across fork + exec.
_CHILD = r"""
import json, sys, time
import pybullet as p
cid = p.connect(p.DIRECT)
t = time.perf_counter()
body = p.loadURDF(sys.argv[1], useFixedBase=True, physicsClientId=cid)
dt = time.perf_counter() - t
hwm = next(int(ln.split()[1]) for ln in open("/proc/self/status") if ln.startswith("VmHWM:"))
print(json.dumps({"load_s": dt, "body": body, "rss_mib": hwm / 1024.0}))
"""


def gradient_jpeg(path: Path, n: int) -> None:
    """Write an ``n`` x ``n`` RGB JPEG of a smooth gradient (small file)."""
    from PIL import Image

    x = np.linspace(0, 255, n, dtype=np.float32)
    row = np.broadcast_to(x[None, :], (n, n)).astype(np.uint8)
    img = np.stack([row, row.T, np.full((n, n), 128, np.uint8)], axis=-1)
    Image.fromarray(img, "RGB").save(path, quality=50)


def padded_jpeg(path: Path, original: bytes, size: int) -> None:
    """Write ``original`` and extend the file to ``size`` bytes (sparse zeros)."""
    path.write_bytes(original)
    os.truncate(path, size)


def load_in_child(urdf: Path, timeout: float = 300.0) -> dict:
    """Load ``urdf`` in a fresh interpreter; returns load_s, rss_mib, status."""
    t = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-c", _CHILD, str(urdf)], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": "timeout", "wall_s": time.perf_counter() - t}
    wall = time.perf_counter() - t
    at = proc.stdout.rfind('{"load_s"')  # PyBullet's own warnings precede it on the same line
    line = proc.stdout[at:].splitlines()[0] if at >= 0 else None
    if proc.returncode != 0 or line is None:
        tail = (proc.stderr.strip().splitlines() or [""])[-1][:120]
        return {"status": f"exit {proc.returncode}: {tail}", "wall_s": wall}
    return {"status": "ok", "wall_s": wall, **json.loads(line)}


def fit(xs: list[float], ys: list[float]) -> tuple[float, float]:
    """Slope and intercept of the least-squares line (nan when < 2 points)."""
    if len(xs) < 2:
        return float("nan"), float("nan")
    a, b = np.polyfit(np.asarray(xs, float), np.asarray(ys, float), 1)
    return float(a), float(b)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--asset", type=Path, default=ASSET)
    ap.add_argument("--pixels", type=int, nargs="*", default=[256, 1024, 2048, 4096, 8192], help="texture side N (pixels)")
    ap.add_argument("--mib", type=float, nargs="*", default=[1, 16, 64, 256, 1024], help="texture file size (MiB, sparse)")
    args = ap.parse_args(argv)
    if not (args.asset / "mobility.urdf").is_file():
        print(f"no asset at {args.asset}", file=sys.stderr)
        return 2
    original = (args.asset / TEXTURE).read_bytes()
    with tempfile.TemporaryDirectory(prefix="bench-texture-") as tmp:
        asset = Path(tmp) / args.asset.name
        shutil.copytree(args.asset, asset)
        for p in asset.rglob("*"):
            os.chmod(p, 0o755 if p.is_dir() else 0o644)
        tex = asset / TEXTURE
        base = load_in_child(asset / "mobility.urdf")
        print(f"baseline (1 KB textures): load {base.get('load_s', float('nan')):.3f} s, peak {base.get('rss_mib', float('nan')):.0f} MiB, {base['status']}")
        base_rss = base.get("rss_mib", 0.0)

        print("\ntexture_0.jpg of N x N pixels (gradient JPEG)")
        print(f"{'N':>6} {'Mpx':>8} {'file KiB':>9} {'load s':>8} {'peak MiB':>9} {'+MiB':>8}  status")
        mpx, extra = [], []
        for n in args.pixels:
            gradient_jpeg(tex, n)
            r = load_in_child(asset / "mobility.urdf")
            mp = n * n / 1e6
            add = r.get("rss_mib", float("nan")) - base_rss
            print(f"{n:>6} {mp:>8.2f} {tex.stat().st_size / 1024:>9.0f} {r.get('load_s', float('nan')):>8.3f} "
                  f"{r.get('rss_mib', float('nan')):>9.0f} {add:>8.0f}  {r['status']}")
            if r["status"] == "ok":
                mpx.append(mp)
                extra.append(add)
        a, _ = fit(mpx, extra)
        print(f"-> {a:.1f} MiB of peak memory per megapixel")

        print("\ntexture_0.jpg padded with zeros to S MiB (sparse)")
        print(f"{'S MiB':>7} {'load s':>8} {'peak MiB':>9} {'+MiB':>8}  status")
        mib, extra = [], []
        for s in args.mib:
            padded_jpeg(tex, original, int(s * 1024 * 1024))
            r = load_in_child(asset / "mobility.urdf")
            add = r.get("rss_mib", float("nan")) - base_rss
            print(f"{s:>7g} {r.get('load_s', float('nan')):>8.3f} {r.get('rss_mib', float('nan')):>9.0f} {add:>8.0f}  {r['status']}")
            if r["status"] == "ok":
                mib.append(s)
                extra.append(add)
        a, _ = fit(mib, extra)
        print(f"-> {a:.2f} MiB of peak memory per MiB of texture file")
    return 0


if __name__ == "__main__":
    sys.exit(main())
