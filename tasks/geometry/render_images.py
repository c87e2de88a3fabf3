"""Rendered images to PNG files (atomic) and contact sheets (a labelled grid of views)."""

from __future__ import annotations

import io
import math
from pathlib import Path
from typing import Mapping

import numpy as np

from asset2sim.atomic import write_bytes

#: RGB of the background behind the object (light blue-grey: white and black objects both stand out).
BACKGROUND: tuple[int, int, int] = (236, 238, 242)


def png_bytes(image: np.ndarray) -> bytes:
    """PNG file bytes of an RGB(A) uint8 image (H, W, 3|4)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", optimize=False)
    return buf.getvalue()


def write_png(path: Path | str, image: np.ndarray) -> Path:
    """Write an RGB(A) uint8 image (H, W, 3|4) as PNG, atomically. Returns the path.

    Raises:
        OSError: the file cannot be written.
    """
    return write_bytes(path, png_bytes(image))


def render_contact_sheet(images: Mapping[str, np.ndarray], *, title: str | None = None) -> np.ndarray:
    """One RGB image (H, W, 3) uint8 with every view in a grid, each labelled with its name (and an
    optional ``title`` line on top), in n columns up to 3 views, else ceil(n / 2). Views of
    different sizes are padded to the largest.

    Raises:
        ValueError: no images, or an image that is not (H, W, 3|4) uint8.
    """
    from PIL import Image, ImageDraw, ImageFont

    if not images:
        raise ValueError("render_contact_sheet needs at least one image")
    arrays = {}
    for name, img in images.items():
        a = np.asarray(img)
        if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] not in (3, 4):
            raise ValueError(f"view {name!r}: expected a (H, W, 3) uint8 image, got {a.dtype} {a.shape}")
        arrays[name] = a[:, :, :3]
    n = len(arrays)
    cols = n if n <= 3 else math.ceil(n / 2)
    rows = math.ceil(n / cols)
    tw = max(a.shape[1] for a in arrays.values())
    th = max(a.shape[0] for a in arrays.values())
    try:
        font = ImageFont.load_default(size=max(11, tw // 16))
    except TypeError:  # Pillow without FreeType sizes
        font = ImageFont.load_default()
    try:
        box = font.getbbox("Ag")
        label_h = int(box[3] - box[1]) + 10  # the text and 10 px around it
    except Exception:  # pragma: no cover
        label_h = 20
    title_h = label_h + 4 if title else 0
    pad = 4
    W = cols * tw + (cols + 1) * pad
    H = title_h + rows * (th + label_h) + (rows + 1) * pad
    sheet = Image.new("RGB", (W, H), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    if title:
        draw.text((pad + 2, pad), title, fill=(20, 20, 20), font=font)
    for k, (name, a) in enumerate(arrays.items()):
        i, j = divmod(k, cols)
        x0 = pad + j * (tw + pad)
        y0 = title_h + pad + i * (th + label_h + pad)
        draw.text((x0 + 2, y0 + 3), name, fill=(30, 30, 30), font=font)
        tile = Image.new("RGB", (tw, th), BACKGROUND)
        tile.paste(Image.fromarray(a), ((tw - a.shape[1]) // 2, (th - a.shape[0]) // 2))
        sheet.paste(tile, (x0, y0 + label_h))
    return np.asarray(sheet, dtype=np.uint8)
