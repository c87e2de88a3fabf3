"""OBJ text as lines, for tools that rewrite an OBJ file (:func:`scan_obj_text`, :func:`parse_vertex_lines`); re-exported
by :mod:`asset2sim.mesh_io`. Format: Wavefront OBJ (Advanced Visualizer manual, B1).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ObjText:
    """An OBJ file as lines: ``vertex_lines`` the ``v`` records, ``data_lines``
    every ``v...`` record, ``faces`` ``usemtl`` material (None before any) ->
    its ``f`` records with absolute indices, ``mtllibs`` the ``mtllib`` names."""

    vertex_lines: list[str] = field(default_factory=list)
    data_lines: list[str] = field(default_factory=list)
    faces: dict[str | None, list[str]] = field(default_factory=dict)
    mtllibs: list[str] = field(default_factory=list)


def _absolute_face(line: str, counts: list[int]) -> str:
    out = ["f"]
    for corner in line.split()[1:]:
        idx = corner.split("/")
        for i, s in enumerate(idx):
            if s.startswith("-") and i < 3:
                idx[i] = str(counts[i] + 1 + int(s))
        out.append("/".join(idx))
    return " ".join(out)


def scan_obj_text(text: str) -> ObjText:
    """Split OBJ ``text`` into :class:`ObjText` (records must start at the
    beginning of their line; other records are ignored)."""
    out = ObjText()
    counts = [0, 0, 0]  # v, vt, vn seen so far (for negative indices)
    current: str | None = None
    for raw in text.splitlines():
        if not raw:
            continue
        c0 = raw[0]
        if c0 == "v":
            if raw.startswith("v "):
                out.vertex_lines.append(raw)
                counts[0] += 1
            elif raw.startswith("vt"):
                counts[1] += 1
            elif raw.startswith("vn"):
                counts[2] += 1
            out.data_lines.append(raw)
        elif c0 == "f" and raw.startswith("f "):
            if "-" in raw:
                raw = _absolute_face(raw, counts)
            out.faces.setdefault(current, []).append(raw)
        elif raw.startswith("usemtl"):
            current = raw[6:].strip() or None
        elif raw.startswith("mtllib"):
            out.mtllibs.append(raw[6:].strip())
    return out


def parse_vertex_lines(lines: list[str]) -> np.ndarray:
    """Coordinates (N, 3) of OBJ ``v x y z ...`` lines (extra values such as
    colours ignored); malformed or short lines are skipped."""
    if not lines:
        return np.zeros((0, 3))
    try:
        return np.array([ln.split()[1:4] for ln in lines], dtype=float).reshape(-1, 3)
    except ValueError:  # ragged or malformed lines: parse one by one
        rows = []
        for ln in lines:
            try:
                row = [float(t) for t in ln.split()[1:4]]
            except ValueError:
                continue
            if len(row) == 3:
                rows.append(row)
        return np.array(rows, dtype=float).reshape(-1, 3)
