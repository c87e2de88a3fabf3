"""Stage 6 of the refine: the initial-state search on the written candidate, then, each kept only where it
lowers Phi (the SPEC's self-penetration), the parts the request left closed freed to make room and CoACD
decomposition of the colliding pieces (:func:`refine_state_with_decomposition`)."""

from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from asset2sim.engines.base import SessionOptions, SimSession
from asset2sim.schemas.config import RefineConfig
from asset2sim.tasks.assemble import write
from asset2sim.tasks.assemble.candidate import Candidate, Workspace
from asset2sim.tasks.geometry.decomposition import COACD_THRESHOLDS, DecompositionUnavailable
from asset2sim.tasks.state import collision, refine_state
from asset2sim.tasks.synthesize import estimate


def kinematic_session(ws: Workspace, candidate: Candidate, config: RefineConfig,
                      state: dict[str, float] | None = None) -> SimSession:
    """A PyBullet session of ``candidate`` (loaded into ``ws``) with its root pinned, no gravity and no ground, at
    ``state`` (joint -> rad or m; None: 0); the caller closes it."""
    return ws.session(candidate, "pybullet", SessionOptions(fixed_base=True, gravity=False, ground=False,
                                                            initial_state=state or {}, conventions=config.sim))


def phi_at(ws: Workspace, candidate: Candidate, state: dict[str, float], config: RefineConfig) -> float:
    """Phi (m, the SPEC's self-penetration) of ``candidate`` (loaded into ``ws``) at ``state`` (joint -> rad or m)."""
    with kinematic_session(ws, candidate, config, state) as sess:
        return float(sess.self_penetration_fresh()[0])


def refine_state_with_decomposition(candidate: Candidate, closed_out, bands, config, ws: Workspace, say, proposer=None,
                                     intervals=None, addressed: Callable[[], set[str]] | None = None):
    """State refinement of ``candidate`` from its state (the requested one; its pieces are those searched on);
    then, each kept only if it lowers Phi: a search with the parts the request left closed (not in
    ``addressed()``) free where an opened part penetrates them, and CoACD decomposition of the colliding pieces
    with another search (the pieces changed here replace the candidate's collision overrides of the same links).
    Where Phi stays above the tolerance, ``collision_changes`` ends with why: each of the (up to 3) deepest link pairs
    at the state found (``st.result``) with its depth, and the joints on its kinematic path with the interval each was
    searched over (the requested band within the limits); none of those states, nor a collision piece change (where
    the repair is on), cleared it.
    Returns (StateRefinement, the candidate with the collision overrides kept: ``candidate`` itself when nothing
    changed)."""
    st, kept = _refine(candidate, closed_out, bands, config, ws, say, proposer, intervals, addressed)
    if st.phi_result > config.penetration_tolerance:
        allowed = refine_state.allowed_intervals(closed_out, estimate.band_intervals(bands, intervals))
        with kinematic_session(ws, kept, config, st.result) as sess:
            pairs = sess.self_penetration_fresh()[1][:3]
        said = []
        for c in pairs:
            path = [j for j in refine_state.path_joints(kept.asset, c.link_a, c.link_b) if j in allowed]
            where = (", ".join(f"{j} over [{allowed[j].lo:.4g}, {allowed[j].hi:.4g}]" for j in path)
                     or "no movable joint between them")
            said.append(f"'{c.link_a}' and '{c.link_b}' {c.depth * 1000:.3g} mm ({where})")
        st.collision_changes = list(st.collision_changes) + [
            f"self-penetration {st.phi_result * 1000:.3g} mm left at the state found: " + "; ".join(said)
            + f". No state of those intervals (the band asked within the limits; {st.evaluations} states tried) separates "
            + ("them, and no collision piece change lowered it" if config.convex_decomposition
               else "them (collision repair off)")]
    return st, kept


def _refine(candidate: Candidate, closed_out, bands, config, ws: Workspace, say, proposer, intervals, addressed):
    """:func:`refine_state_with_decomposition` without its closing note."""
    fractions = estimate.band_intervals(bands, intervals)
    asset, requested, tolerance = candidate.asset, dict(candidate.state), config.penetration_tolerance

    def search(on: Candidate, start: dict[str, float]):
        with kinematic_session(ws, on, config) as sess:
            return refine_state.refine_initial_state(sess, asset, closed_out, start, fractions, config, proposer=proposer,
                                                     opened=frozenset(j for j, b in bands.items() if b != "closed"))

    st = search(candidate, requested)
    in_the_way = [] if addressed is None or not st.phi_result > tolerance else \
        refine_state.joints_in_the_way(asset, st.worst_pairs, bands, addressed(), tolerance)
    if in_the_way:
        held = fractions
        fractions = {**fractions, **{j: (0.0, 1.0) for j in in_the_way}}
        room = search(candidate, st.result)
        if room.phi_result < st.phi_result:
            room.requested, room.phi_requested = st.requested, st.phi_requested
            room.evaluations += st.evaluations
            room.model_queries += st.model_queries
            room.method = f"{st.method} | {', '.join(in_the_way)} free to make room -> {room.method}"
            room.room_made = {j: float(abs(closed_out[j].fraction(room.result[j]))) for j in in_the_way if j in closed_out}
            st = room
        else:
            fractions = held
    if not (st.phi_result > tolerance and config.convex_decomposition):
        return st, candidate

    def decomposed_search(threshold: float):
        """The deep pairs' collision pieces of ``candidate`` at ``first.result`` (the search before any decomposition)
        repaired with CoACD at concavity ``threshold`` (:func:`collision.improve_collisions`), then the state searched
        again from ``requested``. Returns (the search, with ``first``'s evaluations added, its notes in
        ``collision_changes``; the candidate with those pieces, or None when no change was kept: then ``first`` itself
        with the notes). Pieces at a finer concavity than the first of :data:`COACD_THRESHOLDS` go to a folder of their
        own, so that the coarser ones stay as they were written."""
        base, folder = candidate.collision_overrides, write.collision_folder(candidate.asset)
        if threshold != COACD_THRESHOLDS[0]:  # beside the coarser pieces, which may be the ones kept
            folder = f"{folder}/concavity_{threshold:g}"
        deep = [(p_["link_a"], p_["link_b"]) for p_ in first.worst_pairs if p_["depth_m"] > tolerance]
        links = sorted({ln for pair in deep for ln in pair})
        sess = kinematic_session(ws, candidate, config, first.result)
        try:
            overrides, dnotes = collision.improve_collisions(sess, candidate.asset, deep, candidate.overlay.scale, ws.root,
                                                             cache=ws.mesh_cache, max_decompositions=config.max_decompositions,
                                                             folder=folder, threshold=threshold)
        except (DecompositionUnavailable, ValueError) as exc:
            say("refine_state", f"collision improvement skipped: {exc}")
            return first.model_copy(update={"collision_changes": [f"collision improvement skipped: {exc}"]}), None
        finally:
            sess.close()
        if not overrides:
            return first.model_copy(update={"collision_changes": dnotes or [
                f"no collision piece change lowered the overlap of {', '.join(links)}"]}), None
        decomposed = replace(candidate, collision_overrides={**base, **overrides})
        st = search(decomposed, requested)
        st.evaluations += first.evaluations
        st.model_queries += first.model_queries
        st.phi_requested = first.phi_requested
        if st.phi_result >= first.phi_result:
            # the decomposition did not help (pieces of neighbours can bulge): keep the original hulls
            return first.model_copy(update={"evaluations": st.evaluations, "model_queries": st.model_queries,
                                            "collision_changes": [
                f"collision pieces changed for {', '.join(links)} but self-penetration went {first.phi_result * 1000:.3g} -> "
                f"{st.phi_result * 1000:.3g} mm; original collision meshes kept"] + dnotes}), None
        st.collision_changes = dnotes
        st.method = first.method + " | collision pieces improved -> " + st.method
        return st, decomposed

    first = st
    st, decomposed = decomposed_search(COACD_THRESHOLDS[0])
    kept = decomposed or candidate
    for threshold in COACD_THRESHOLDS[1:]:  # finer, only where the coarser pieces helped but leave an overlap they explain
        if kept is candidate or not tolerance < st.phi_result <= coarse_bulge(candidate, st.worst_pairs, ws):
            break
        finer, decomposed = decomposed_search(threshold)
        other = finer  # the attempt not kept: its evaluations and model queries are added to the one kept
        if decomposed is not None and finer.phi_result < st.phi_result:
            finer.collision_changes = [f"CoACD at concavity {threshold:g}, where its pieces at the coarser concavity left "
                                       f"{st.phi_result * 1000:.3g} mm:"] + list(finer.collision_changes)
            other, st, kept = st, finer, decomposed
        else:
            st.collision_changes = list(st.collision_changes) + [
                f"CoACD at concavity {threshold:g} left {finer.phi_result * 1000:.3g} mm; not kept"]
        st.evaluations += other.evaluations - first.evaluations
        st.model_queries += other.model_queries - first.model_queries
    return st, kept


def coarse_bulge(candidate: Candidate, pairs: list[dict], ws: Workspace) -> float:
    """The most (m) CoACD's pieces at the first of :data:`COACD_THRESHOLDS` may stand out of the collision meshes of
    the links of ``pairs`` (``StateRefinement.worst_pairs``): that concavity threshold times each mesh's bounding-box
    diagonal at the overlay's scale (CoACD measures concavity on the mesh normalised to its bounding box: Wei et al.,
    "Approximate convex decomposition for 3D meshes with collision-aware concavity and tree search", SIGGRAPH 2022).
    An overlap deeper than this is not the pieces' bulge, and finer pieces would not clear it (a 6 cm stapler's
    parts, 5.5 mm into each other where its meshes' bulge is at most 3.5 mm). 0 without mesh collisions."""
    links = {ln for p_ in pairs for ln in (p_["link_a"], p_["link_b"])}
    diag = 0.0
    for ln in sorted(links):
        for g in candidate.asset.link(ln).collisions:
            if g.kind == "mesh" and g.path is not None:
                v = np.asarray(ws.mesh_cache.get(g.path).vertices, float) * np.asarray(g.scale, float)
                if len(v):
                    diag = max(diag, float(np.linalg.norm(v.max(axis=0) - v.min(axis=0))))
    return COACD_THRESHOLDS[0] * diag * candidate.overlay.scale
