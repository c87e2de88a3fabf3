"""Output collision geometry that every engine takes.

:func:`convex_collisions` replaces the mesh collisions of every link of a URDF
model by a few closed convex pieces (:func:`link_pieces`: the hull of each OBJ
group, or a convex decomposition of a group holding an open cavity such as a
bucket's or a drawer's inside, parents cut around their children, merged,
separated, with running clearance), written as OBJ files in the link frame.
``docs/design/simulators.md`` explains why.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import cachetools
import numpy as np
from scipy.spatial import QhullError

from asset2sim import array_cache, atomic, file_names, mesh_io, urdf
from asset2sim.engines.loading import mesh_hulls
from asset2sim.tasks.assemble import container_pieces
from asset2sim.tasks.assemble.containment_cuts import _resolve_containment, _trim
from asset2sim.tasks.assemble.convex_pieces import (CONTAINMENT_TOLERANCE, MAX_PIECES_HARD, MAX_PIECES_PER_LINK,
                                                    CollisionGeometryError, Piece, cached, depth_inside, drop_slivers,
                                                    merge_pieces, piece_obj, posed, solid_points)
from asset2sim.tasks.assemble.footprint import level_footprint
from asset2sim.tasks.assemble.joint_sweep import reference_state, swept_child_points, swept_other_points
from asset2sim.tasks.assemble.parent_child_separation import separate_parent_child
from asset2sim.tasks.assemble.piece_penetration import parent_child_depths
from asset2sim.tasks.assemble.sliding_clearance import running_clearance, swept_clearance

#: (link -> convex pieces (link frame, m), notes): what :func:`link_pieces` returns.
PiecesNotes = tuple[dict[str, list[Piece]], list[str]]

def _group_hulls(link: urdf.UrdfLink, mesh_path, notes: list[str]) -> list[tuple[int, int, Piece]]:
    """(collision index, group index, hull) of every OBJ group of ``link``'s mesh collisions (link frame, m); a
    group without a hull gets a note and no piece.

    Raises:
        CollisionGeometryError: a collision mesh cannot be read.
    """
    found: list[tuple[int, int, Piece]] = []
    for k, c in enumerate(link.collisions):
        if c.kind != "mesh":
            continue
        try:
            groups = mesh_hulls(mesh_path(c), c.scale)
        except urdf.UrdfError as exc:
            raise CollisionGeometryError(f"link {link.name!r} collision {k} ({c.filename}): {exc}") from exc
        for g, pts in enumerate(groups):
            solid = solid_points(pts)
            if solid is None:
                notes.append(f"link {link.name!r}: group {g} of {c.filename} spans no area; no collision")
                continue
            world = posed(solid, c.origin)
            try:
                found.append((k, g, Piece.of(world, (str(c.filename),))))
            except (QhullError, ValueError):
                notes.append(f"link {link.name!r}: group {g} of {c.filename} has no hull; no collision")
    return found


@dataclass(frozen=True, slots=True)
class _LinkPieces:
    """A link's collision pieces before containment (:func:`_group_pieces`): ``pieces`` (link frame), ``cores``
    (K, 3) m (the open cavities' core points; None: none) and ``decomposed`` (the files of the groups decomposed)."""

    pieces: list[Piece]
    cores: np.ndarray | None
    decomposed: set[str]


def _group_pieces(link: urdf.UrdfLink, mesh_path, notes: list[str], decompose: bool = True,
                  slides_along: set[str] | None = None, up: np.ndarray | None = None,
                  hulls: list[tuple[int, int, Piece]] | None = None) -> _LinkPieces:
    """Pieces of every mesh collision of ``link`` (one per OBJ group, link frame: :func:`_group_hulls`, or
    ``hulls`` when given; with ``decompose``, a group holding an open cavity the link's other groups leave open
    decomposed, :func:`container_pieces.open_pieces`, unless the link slides along the links ``slides_along`` or the cavity opens
    downward against ``up`` (3,), the world's up in the link frame), the cavities' core points (K, 3) m (None:
    none) and the files of the groups decomposed."""
    found = _group_hulls(link, mesh_path, notes) if hulls is None else hulls
    out: list[Piece] = []
    cores: list[np.ndarray] = []
    opened_files: set[str] = set()
    may_hold = [decompose and container_pieces.may_hold_cavity(p) for _, _, p in found]
    surfaces = container_pieces.link_surfaces(link, mesh_path) if any(may_hold) else None
    for (k, g, piece), holds in zip(found, may_hold):
        opened = None
        if surfaces is not None and holds and (k, g) in surfaces[1]:
            opened = container_pieces.open_pieces(link.name, link.collisions[k], g, piece, surfaces[1][(k, g)], surfaces[0],
                                                  notes, slides_along, up)
        if opened is None:
            out.append(piece)
        else:
            out += opened[0]
            cores.append(opened[1])
            opened_files.add(str(link.collisions[k].filename))
    return _LinkPieces(out, np.vstack(cores) if cores else None, opened_files)


def link_pieces(model: urdf.UrdfModel, mesh_path, state: dict[str, float] | None = None, *,
                limit: int = MAX_PIECES_PER_LINK, decompose: bool = True,
                level: bool = False, feet: float | None = None,
                open_containers: bool = False, pushed: Collection[str] = ()) -> PiecesNotes:
    """The convex pieces of every link's mesh collisions (link frame, m), cached in this process and on disk.

    The pieces depend on the joint limits (the ranges swept); only what ``state`` puts a child into its
    parent is cut last, for that state.

    Args:
        model: a URDF model (scale baked in).
        mesh_path: ``UrdfGeometry -> Path`` of a collision mesh's file.
        state: joint -> rad or m, the initial state (None: nothing state-dependent).
        limit: most pieces per link.
        decompose: cut a parent piece that contains its child (else only a note).
        open_containers: with ``decompose``, decompose a part that holds an open cavity (:func:`container_pieces.open_pieces`;
            else its hull, solid inside).
        level: the object is free-standing: its footprint at ``state`` is made planar.
        feet: the height (m) the object's levelling feet take up (:func:`~asset2sim.tasks.assemble.footprint.level_footprint`).
        pushed: joints of parts a press moves into their body (push buttons and keys,
            :func:`~asset2sim.tasks.interpret.part_priors.push_buttons`): with ``state`` and ``decompose``, the parent and
            the part are also cut apart at each end of the joint's range, the recess a real body has for its button.

    Returns:
        (link -> pieces, notes).

    Raises:
        CollisionGeometryError: a collision mesh cannot be read.
    """
    opening = decompose and open_containers
    key, disk_key = _piece_keys(model, mesh_path, limit, decompose, opening)

    def made() -> PiecesNotes:  # the state-independent (pieces, notes), from the disk's cache, else made (and stored)
        hit = _load_pieces(disk_key, model) if disk_key is not None else None
        if hit is None:
            hit = _made_pieces(model, mesh_path, limit, decompose, opening)
            # stored: each piece's arrays, each link's pieces' sources and the notes
            if disk_key is not None:
                arrays: dict[str, np.ndarray] = {}
                for n, p in enumerate(p for plist in hit[0].values() for p in plist):
                    arrays[f"p{n}"], arrays[f"e{n}"], arrays[f"v{n}"] = p.points, p.equations, np.array(p.volume)
                links = {name: [list(p.sources) for p in plist] for name, plist in hit[0].items()}
                arrays["meta"] = array_cache.text_array(json.dumps({"links": links, "notes": hit[1]}))
                array_cache.store("pieces", disk_key, arrays)
        return hit

    def at_state(hit: PiecesNotes) -> PiecesNotes:
        """(link -> pieces, notes) of ``hit`` at the initial ``state``, each ``pushed`` joint's part and parent also cut
        apart at both ends of its range."""
        pieces, notes = {k: list(v) for k, v in hit[0].items()}, list(hit[1])
        if decompose:
            separate_parent_child(model, pieces, notes, state=state)
            joints = {x.name: x for x in model.joints}
            for name in sorted(pushed):
                j = joints.get(name)
                if j is not None and j.type == "prismatic" and np.isfinite(j.lower) and np.isfinite(j.upper):
                    for end in (j.lower, j.upper):
                        separate_parent_child(model, pieces, notes, state={**state, name: float(end)}, joints={name})
            for name in model.links:
                pieces[name] = drop_slivers(pieces[name])
        if level:
            level_footprint(model, pieces, state, notes, feet)
        if state:
            for (parent, child), d in parent_child_depths(model, pieces, state).items():
                if d > CONTAINMENT_TOLERANCE:
                    notes.append(f"link {child!r} penetrates the collision pieces of its parent {parent!r} {d * 1000:.3g} mm at "
                                 "the initial state")
        return pieces, notes

    done = cached(_PIECE_CACHE, key, made)
    if state is not None:
        skey = (key, tuple(sorted((str(k), float(v)) for k, v in state.items())), bool(level), feet, tuple(sorted(pushed)))
        done = cached(_STATE_CACHE, skey, lambda: at_state(done))
    return {k: list(v) for k, v in done[0].items()}, list(done[1])


def _made_pieces(model: urdf.UrdfModel, mesh_path, limit: int, decompose: bool, opening: bool) -> PiecesNotes:
    """(link -> pieces, notes) before any state; ``opening``: containers decomposed (:func:`container_pieces.open_pieces`)."""
    notes: list[str] = []
    pieces: dict[str, list[Piece]] = {}
    cores: dict[str, np.ndarray] = {}
    whole: set[tuple[str, str]] = set()
    # with ``opening`` each link's group hulls are made once: for the sliding contacts and for its pieces
    hull_notes: dict[str, list[str]] = {name: [] for name in model.links}
    hulls = {name: _group_hulls(link, mesh_path, hull_notes[name]) for name, link in model.links.items()} if opening else {}
    # link -> the links it slides along (:func:`running_clearance` on the group hulls: contacts between a moving link
    # and a link its joint does not move, parent and child excepted)
    sliding: dict[str, set[str]] = {}
    trial = {name: [p for _, _, p in found] for name, found in hulls.items()}
    for a, b in running_clearance(model, trial, []) if opening else ():
        sliding.setdefault(a, set()).add(b)
        sliding.setdefault(b, set()).add(a)
    poses = model.link_poses(reference_state(model)) if opening else {}
    holding = container_pieces.holding_children(model, hulls) if opening else set()
    for name, link in model.links.items():
        # the world's up, against which a cavity opens downward; none for a link whose hull a child moves in
        up = poses[name][:3, :3].T @ np.array([0.0, 0.0, 1.0]) if name in poses and name not in holding else None
        notes.extend(hull_notes[name])
        grouped = _group_pieces(link, mesh_path, notes, opening, sliding.get(name), up, hulls.get(name))
        pieces[name] = grouped.pieces
        whole.update((name, source) for source in grouped.decomposed)
        if grouped.cores is not None:
            cores[name] = grouped.cores
    # a container's decomposition is not cut again around a child (a new cut would fill its cavity): only trimmed
    _resolve_containment(model, pieces, mesh_path, notes, decompose, limit, frozenset(whole))
    for name in model.links:
        if len(pieces[name]) > limit:
            _merge_link(model, pieces, name, limit, decompose, notes, cores.get(name))
    if decompose:
        separate_parent_child(model, pieces, notes)
    running_clearance(model, pieces, notes)
    swept_clearance(model, pieces, notes)
    for name in model.links:
        pieces[name] = drop_slivers(pieces[name])
    return pieces, notes


def _merge_link(model: urdf.UrdfModel, pieces: dict[str, list[Piece]], name: str, limit: int, decompose: bool,
                notes: list[str], cavity: np.ndarray | None) -> None:
    """Merge the pieces of link ``name`` (in place) down to ``limit``, guarded against the other links and the
    link's own open cavities (``cavity`` (K, 3) m core points); a merge that holds a child again is trimmed
    (``decompose``)."""
    # the children's swept points, which the merge of this link's pieces does not change
    n, swept = len(pieces[name]), swept_child_points(model, pieces, name)
    guard = [x for x in (swept_other_points(model, pieces, name), *swept.values(), cavity) if x is not None]
    guard = np.vstack(guard) if guard else None
    # merges that hold no other link over the ranges down to the limit; beyond
    # MAX_PIECES_HARD (pieces a parent was cut into around its child) any merge
    pieces[name] = merge_pieces(pieces[name], limit, guard, free_only=True)
    if len(pieces[name]) > max(limit, MAX_PIECES_HARD):
        pieces[name] = merge_pieces(pieces[name], max(limit, MAX_PIECES_HARD), guard)
    notes.append(f"link {name!r}: {n} convex pieces merged into {len(pieces[name])}")
    if decompose and swept:  # a merge the limit forced may hold a child again
        pts = np.vstack(list(swept.values()))
        d = max((depth_inside(pts, p) for p in pieces[name]), default=0.0)
        if d > CONTAINMENT_TOLERANCE:
            _trim(pieces, name, ", ".join(repr(c) for c in swept), pts, d, notes)


#: Pieces made in this process, by :func:`_piece_keys`' first key (the oldest of 16 dropped).
_PIECE_CACHE: cachetools.FIFOCache = cachetools.FIFOCache(maxsize=16)
#: What :func:`link_pieces` returned, by (:func:`_piece_keys`' first key, initial state) (the oldest of 16 dropped).
_STATE_CACHE: cachetools.FIFOCache = cachetools.FIFOCache(maxsize=16)


#: Modules whose source the pieces depend on (part of the on-disk key).
PIECES_CODE = (*(f"asset2sim.tasks.assemble.{m}" for m in ("collision_geometry", "containment_cuts", "convex_pieces", "footprint",
                                                             "joint_sweep", "parent_child_separation", "piece_penetration",
                                                             "sliding_clearance", "container_pieces")),
               *(f"asset2sim.tasks.geometry.{m}" for m in ("limits", "cavities", "decomposition", "voxels")),
               "asset2sim.mesh_io", "asset2sim.engines.loading", "asset2sim.urdf", "asset2sim.frames")


def _piece_keys(model: urdf.UrdfModel, mesh_path, limit: int, decompose: bool, opening: bool = False
                ) -> tuple[str, str | None]:
    """(in-process key, on-disk key) of :func:`link_pieces`' state-independent result: the digest of everything it
    reads, each collision mesh as its file name and bytes, not where the file lies (the final candidate written into
    the output folder finds the pieces made for it in the workspace); the on-disk key also of the source of
    :data:`PIECES_CODE`, None when that or a mesh cannot be read."""
    parts: list[bytes | str] = [repr((limit, decompose, opening))]
    unread = False
    for name, link in model.links.items():
        parts.append(name)
        for c in link.collisions:
            parts.append(repr((c.kind, c.size, c.radius, c.length, c.filename)))
            parts.append(np.asarray(c.origin, float).tobytes() + np.asarray(c.scale, float).tobytes())
            if c.kind == "mesh":
                try:
                    parts.append(hashlib.sha256(mesh_io.file_bytes(mesh_path(c))).digest())
                except OSError:  # made again, with the reader's error, when asked for
                    unread = True
                    parts.append(str(mesh_path(c)))
    for j in model.joints:
        parts.append(repr((j.name, j.type, j.parent, j.child, j.lower, j.upper)))
        parts.append(np.asarray(j.origin, float).tobytes() + j.axis.tobytes())
    key = array_cache.digest(*parts)
    try:
        code = array_cache.source_digest(*PIECES_CODE)
    except (ImportError, OSError, TypeError):
        return key, None
    return key, None if unread else array_cache.digest(code, key)


def _load_pieces(key: str, model: urdf.UrdfModel) -> PiecesNotes | None:
    """What :func:`link_pieces` stored under ``key`` (kind ``pieces``), or None (none, unreadable, or other links)."""
    data = array_cache.load("pieces", key)
    if data is None:
        return None
    try:
        meta = array_cache.array_json(data["meta"])  # NaN or infinity in it: a miss
        if set(meta["links"]) != set(model.links):
            return None
        pieces, n = {}, 0
        for name, sources in meta["links"].items():
            pieces[name] = [Piece(np.asarray(data[f"p{i}"], float), np.asarray(data[f"e{i}"], float), float(data[f"v{i}"]),
                                  tuple(str(x) for x in src)) for i, src in enumerate(sources, n)]
            n += len(sources)
        return pieces, [str(x) for x in meta["notes"]]
    except (KeyError, ValueError, TypeError, UnicodeDecodeError):
        return None


#: Words of the note on a link denser over its pieces than its material allows.
DENSITY_NOTE = "denser than its material"


def convex_collisions(model: urdf.UrdfModel, out_dir: Path, folder: str, state: dict[str, float] | None = None,
                      *, level: bool = False, feet: float | None = None,
                      max_density: dict[str, float] | None = None, open_containers: bool = False,
                      pushed: Collection[str] = ()) -> list[str]:
    """Replace the mesh collisions of every link of ``model`` (in place) by the pieces of :func:`link_pieces`,
    written as ``out_dir/folder/<link>_hull<i>_<digest>.obj`` (link frame, m; an unchanged file is not
    rewritten). Primitive collisions stay.

    Args:
        out_dir: the output folder (relative collision filenames without a ``path`` resolve in it).
        folder: folder (relative to ``out_dir``) of the pieces.
        state: the initial state (joint -> rad or m).
        level: the object is free-standing: its footprint at ``state`` is made planar.
        feet: see :func:`link_pieces`.
        max_density: link -> the densest its material may be (kg/m^3): a link whose inertial mass over its
            pieces' volume exceeds it is noted.
        open_containers, pushed: see :func:`link_pieces`.

    Returns:
        notes (what changed).

    Raises:
        CollisionGeometryError: a collision mesh cannot be read.
    """
    out_dir = Path(out_dir)

    def mesh_path(g: urdf.UrdfGeometry) -> Path:
        return Path(g.path) if g.path is not None else out_dir / str(g.filename)

    pieces, notes = link_pieces(model, mesh_path, state, level=level and state is not None, feet=feet,
                                open_containers=open_containers, pushed=pushed)
    for name, link in model.links.items():
        if not any(c.kind == "mesh" for c in link.collisions):
            continue
        kept = [c for c in link.collisions if c.kind != "mesh"]
        safe = file_names.file_stem(name)
        for i, p in enumerate(pieces[name]):
            data = piece_obj(p)
            rel = f"{folder}/{safe}_hull{i}_{hashlib.sha256(data).hexdigest()[:12]}.obj"
            dst = file_names.join_inside(out_dir, rel)
            if dst.is_file() and not dst.is_symlink() and mesh_io.file_bytes(dst) == data:
                atomic.announce([dst])
            else:
                mesh_io.write_file(dst, data)
            kept.append(urdf.UrdfGeometry(kind="mesh", filename=rel, path=dst))
        link.collisions = kept
        vol, rho = sum(p.volume for p in pieces[name]), (max_density or {}).get(name)
        if rho and link.inertial is not None and vol > 0 and link.inertial.mass > 1.01 * rho * vol:  # 1 %: float and cut slivers
            notes.append(f"link {name!r}: {link.inertial.mass:.3g} kg in its collision pieces' {vol * 1e6:.3g} cm^3 is "
                         f"{link.inertial.mass / vol:.3g} kg/m^3, {DENSITY_NOTE} ({rho:.3g} kg/m^3 at most): the pieces are "
                         "thinner than the part its mass and inertia stand for")
    return notes
