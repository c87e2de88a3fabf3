"""The HTML building blocks of the reports: a whole page with its CSS (:func:`page`), numbers for tables
(:func:`fmt`), images and SVG figures inline as ``data:`` URIs (:func:`img_tag`, :func:`svg_tag`, :func:`figure` of a
render (H, W, 3)) and colour-coded verdict cells; text HTML-escaped.
"""

from __future__ import annotations

import base64
import io
import math
from typing import Any, Iterable

import numpy as np

from asset2sim.inert import CSP_META, html_text
from asset2sim.tasks.evaluation import plots


CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px;color:#1d2430;max-width:1200px}
h1{font-size:22px;margin-bottom:4px} h2{font-size:18px;margin-top:28px;border-bottom:1px solid #d0d6de;padding-bottom:4px}
h3{font-size:15px;margin-bottom:6px}
table{border-collapse:collapse;margin:8px 0;font-size:13px;max-width:100%}
th,td{border:1px solid #d0d6de;padding:4px 8px;text-align:left;vertical-align:top;overflow-wrap:anywhere}
th{background:#f1f4f8} td.num{text-align:right;font-variant-numeric:tabular-nums}
.pass{background:#d9f2dd} .fail{background:#f9d6d5} .na{background:#eef0f3;color:#5b6574} .warn{background:#fff1cc}
.badge{display:inline-block;padding:3px 10px;border-radius:12px;font-weight:600}
.meta{color:#4a5565;font-size:13px} img{max-width:100%;border:1px solid #e2e6ec;margin:6px 0}
.small{font-size:12px;color:#5b6574} code{background:#f1f4f8;padding:1px 4px;border-radius:3px}
.views{display:flex;flex-wrap:wrap;gap:8px} .views figure{margin:0} .views img{max-width:280px}
.clips{display:flex;flex-wrap:wrap;gap:8px} .clips figure{margin:0} .clips video{border:1px solid #e2e6ec;background:#eef0f3}
"""


def page(title: str, body: str) -> str:
    """A whole HTML document: ``title`` (HTML text), the CSS, ``body`` (HTML)."""
    return (f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'/>{CSP_META}<title>{title}</title><style>{CSS}</style></head>"
            f"<body>{body}</body></html>\n")


def fmt(v: Any, digits: int = 4) -> str:
    """Number formatting for tables (``-`` for None/NaN)."""
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        if not math.isfinite(float(v)):
            return "-"
        return f"{float(v):.{digits}g}"
    return html_text(v)


def img_tag(png: bytes | None, alt: str, mime: str = "image/png") -> str:
    """An ``<img>`` with the PNG (or other ``mime`` image) inline (empty string for None)."""
    if not png:
        return ""
    return f'<img alt="{html_text(alt)}" src="data:{mime};base64,{base64.b64encode(png).decode()}"/>'


def svg_tag(svg: bytes | None, alt: str) -> str:
    """An ``<img>`` with an SVG figure inline (empty string for None)."""
    return img_tag(svg, alt, plots.SVG_MIME)


def table(head: Iterable[Any], rows: Iterable[str] | str) -> str:
    """A table: one header row of the texts ``head`` (escaped), then ``rows`` (HTML, ``<tr>`` rows as they are)."""
    return "<table><tr>" + "".join(f"<th>{html_text(h)}</th>" for h in head) + "</tr>" + "".join(rows) + "</table>"


def verdict_cell(passed: bool | None) -> str:
    """A colour-coded table cell for a verdict."""
    if passed is None:
        return '<td class="na">reported</td>'
    return '<td class="pass">pass</td>' if passed else '<td class="fail">FAIL</td>'


def array_png(arr: np.ndarray) -> bytes:
    from PIL import Image

    a = np.asarray(arr)
    if a.dtype != np.uint8:
        a = np.clip(a * (255.0 if a.max() <= 1.0 else 1.0), 0, 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG")
    return buf.getvalue()


def figure(image: np.ndarray, caption: str) -> str:
    """A rendered view (H, W, 3) uint8 with its caption."""
    return f"<figure>{img_tag(array_png(image), caption)}<figcaption class='small'>{html_text(caption)}</figcaption></figure>"
