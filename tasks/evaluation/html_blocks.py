"""The HTML building blocks of the reports: a whole page with its CSS (:func:`page`), numbers for tables
(:func:`fmt`), images and SVG figures inline as ``data:`` URIs (:func:`img_tag`, :func:`svg_tag`, :func:`figure` of a
render (H, W, 3)) and colour-coded verdict cells; text HTML-escaped.
"""

from __future__ import annotations

import base64
import math
from typing import Any, Iterable

import numpy as np

from asset2sim.inert import CSP_META, html_text
from asset2sim.tasks.evaluation import plots
from asset2sim.package_data import package_text, package_yaml
from asset2sim.tasks.geometry.render_images import png_bytes


#: The reports' style sheet (``report.css`` beside this module), inlined in every page.
CSS = package_text(__package__, "report.css")
#: The fixed paragraphs, captions and column heads of the report and the benchmark pages (``report_texts.yaml`` beside
#: this module): key -> HTML (or a list of column heads).
TEXTS = package_yaml(__package__, "report_texts.yaml")


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
        return f"{float(v):.{digits}g}" if math.isfinite(float(v)) else "-"
    return html_text(v)


def img_tag(png: bytes | None, alt: str, mime: str = "image/png") -> str:
    """An ``<img>`` with the PNG (or other ``mime`` image) inline (empty string for None)."""
    return f'<img alt="{html_text(alt)}" src="data:{mime};base64,{base64.b64encode(png).decode()}"/>' if png else ""


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


def figure(image: np.ndarray, caption: str) -> str:
    """A rendered view (H, W, 3) uint8 with its caption."""
    return f"<figure>{img_tag(png_bytes(image), caption)}<figcaption class='small'>{html_text(caption)}</figcaption></figure>"
