"""Collision repair where the joint sweep is blocked: each collision piece of a
blocked joint's links in sliding contact with a piece it does not move gets
running clearance (:func:`asset2sim.tasks.assemble.sliding_clearance.clear_sliding_contact`),
written as the writer's collision overrides.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial import QhullError

from asset2sim import file_names, mesh_io
from asset2sim.schemas.asset import GeometryRef
from asset2sim.tasks.assemble.sliding_clearance import clear_sliding_contact, joint_velocity, sat_gap
from asset2sim.tasks.state.collision import CollisionPiece
from asset2sim.urdf import UrdfModel

__all__ = ["ClearanceRepair", "clearance_for_blocked", "link_pieces", "sat_gap", "touching_joints",
           "write_piece_overrides"]


@dataclass
class ClearanceRepair:
    """Pieces with clearance for the links that needed it."""

    pieces: dict[str, list[np.ndarray]] = field(default_factory=dict)
    """link -> every convex piece of the link (k, 3) m in the link frame"""
    notes: list[str] = field(default_factory=list)


def link_pieces(model: UrdfModel, root: Path, link: str) -> list[np.ndarray]:
    """Vertices (k, 3) m of each mesh collision of ``link`` (one piece per file),
    link frame, collision origin and mesh scale applied. Raises OSError (a collision
    file cannot be read) or asset2sim.mesh_io.MeshReadError (a malformed record)."""
    out = []
    for c in model.links[link].collisions:
        if c.kind != "mesh" or not c.filename:
            continue
        path = Path(c.path) if c.path is not None else root / c.filename
        v = mesh_io.read_obj(mesh_io.file_bytes(path), str(path)).vertices
        if not len(v):
            continue
        v = np.asarray(v, float) * c.scale
        out.append(v @ c.origin[:3, :3].T + c.origin[:3, 3])
    return out


def clearance_for_blocked(model: UrdfModel, urdf: Path, blocked: dict[str, float], state: dict[str, float],
                          subtrees: dict[str, list[str]], moved: dict[str, dict[str, float]] | None = None) -> ClearanceRepair:
    """Clearance repairs for the joints in ``blocked`` (joint -> rad or m where the sweep stopped) of the written URDF
    ``model`` (file ``urdf``), other joints at ``state``, over which ``moved`` (joint -> {other joint: rad or m}) puts
    the joints its sweep moved (:func:`~asset2sim.tasks.check.sweep_stalls.stall_states`); ``subtrees``: joint -> the
    links it moves. Raises OSError: a collision file cannot be read."""
    root = Path(urdf).parent
    rep = ClearanceRepair()
    # link -> its pieces, read once
    pieces = functools.cache(lambda ln: link_pieces(model, root, ln))
    adjacent = model.adjacent_pairs()
    for name, q in blocked.items():
        joint = model.joint(name)
        poses = model.link_poses({**state, **(moved or {}).get(name, {}), name: q})
        sub = subtrees.get(name, [joint.child])
        others = [ln for ln in model.links if ln not in sub and pieces(ln)]
        for ln in sub:
            inv = np.linalg.inv(poses[ln])
            velocity = joint_velocity(joint, inv @ poses[joint.child])
            own = [P.copy() for P in (rep.pieces.get(ln) or pieces(ln))]
            changed = False
            for other in others:
                if frozenset((ln, other)) in adjacent:
                    continue  # parent-child pairs are not collided (SPEC)
                To = inv @ poses[other]
                for Q in (rep.pieces.get(other) or pieces(other)):  # a piece already given clearance is not squeezed again from the other side
                    Ql = Q @ To[:3, :3].T + To[:3, 3]
                    for i, P in enumerate(own):
                        try:
                            hit = clear_sliding_contact(P, Ql, velocity)
                        except ValueError:
                            continue
                        if hit is None:
                            continue  # apart, or a stop along the motion, not a sliding contact
                        own[i], used, g = hit
                        changed = True
                        rep.notes.append(
                            f"{ln}: collision piece {i} given {used * 1000:.2g} mm running clearance against {other} "
                            f"(gap {g * 1000:.2g} mm, sliding contact blocking {name})")
            if changed:
                rep.pieces[ln] = own
    return rep


def touching_joints(model: UrdfModel, pairs: list[tuple[str, str]], state: dict[str, float],
                    subtrees: dict[str, list[str]]) -> dict[str, float]:
    """joint -> its position in ``state`` (rad or m) for every non-fixed joint of ``state`` that moves exactly one link of a
    touching pair in ``pairs`` ((link_a, link_b)); ``subtrees``: joint -> the links it moves. Input for
    :func:`clearance_for_blocked`. Raises KeyError: a link of ``pairs`` is not in ``model`` (naming it)."""
    out: dict[str, float] = {}
    for a, b in pairs:
        for ln in (a, b):
            if ln not in model.links:
                raise KeyError(f"link {ln!r} of a touching pair is not in the URDF")
        for j in model.joints:
            if j.type == "fixed" or j.name not in state:
                continue
            moved = set(subtrees.get(j.name, [j.child]))
            if (a in moved) != (b in moved):
                out[j.name] = float(state[j.name])
    return out


def write_piece_overrides(pieces: dict[str, list[np.ndarray]], scale: float, out_dir: Path, folder: str,
                          stem: str) -> dict[str, list[CollisionPiece]]:
    """Write convex pieces (link -> (k, 3) m) as hull OBJ files ``out_dir/folder/<link>_<stem><i>.obj`` at the input's units
    (divided by ``scale``); returns the writer's collision overrides (link -> pieces). Raises ValueError (a piece spans no
    volume, naming its link) or OSError (a file cannot be written)."""
    out: dict[str, list[CollisionPiece]] = {}
    for ln, plist in pieces.items():
        safe = file_names.file_stem(ln)
        items = []
        for i, P in enumerate(plist):
            rel = f"{folder}/{safe}_{stem}{i}.obj"
            try:
                data = mesh_io.hull_obj(np.asarray(P, float) / scale)
            except QhullError as exc:
                raise ValueError(f"link {ln!r}: collision piece {i} spans no volume") from exc
            dst = mesh_io.write_file(file_names.join_inside(out_dir, rel), data)
            ref = GeometryRef(role="collision", kind="mesh", filename=rel, path=dst.resolve())
            items.append(CollisionPiece(filename=rel, source=ref))
        out[ln] = items
    return out
