"""The kinematic-tree checks of the validator: structure, inertials, joint travel.

:class:`TreeChecks` works on the link and joint records the URDF checks
(:mod:`asset2sim.tasks.ingest.urdf_checks`) read: unique names, parents and
children, self loops, several parents, cycles, orphans, exactly one root,
the link cap, mimic joints; the given inertials (:func:`check_inertia`); and,
after the meshes were scanned, prismatic travel against the object's size.
"""

from __future__ import annotations

import numpy as np

from asset2sim.frames import rpy_matrix
from asset2sim.tasks.ingest.findings import MOVABLE_TYPES, Recorder
from asset2sim.tasks.ingest.mesh_checks import geometry_corners
from asset2sim.tasks.ingest.urdf_checks import JointRecord, LinkRecord

__all__ = ["TreeChecks", "check_inertia"]


def check_inertia(ixx: float, ixy: float, ixz: float, iyy: float, iyz: float, izz: float) -> tuple[str | None, list[float]]:
    """Check a URDF inertia tensor (kg*m^2, about the COM).

    Returns:
        ``(code, eigenvalues)``: code None when the tensor is symmetric
        positive definite and its principal moments satisfy the triangle
        inequality (each <= the sum of the other two, relative tolerance
        1e-9 of the trace); else ``INERTIA_NOT_POSITIVE_DEFINITE`` (smallest
        eigenvalue <= 1e-12 x largest, or largest <= 0) or
        ``INERTIA_TRIANGLE_INEQUALITY``. Eigenvalues ascending, kg*m^2.
        The tensor is never modified ("balanced").
    """
    m = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], float)
    lam = np.linalg.eigvalsh(m)
    vals = [float(x) for x in lam]
    if lam[2] <= 0 or lam[0] <= 1e-12 * lam[2]:
        return "INERTIA_NOT_POSITIVE_DEFINITE", vals
    tol = 1e-9 * float(lam.sum())
    if lam[2] > lam[0] + lam[1] + tol:
        return "INERTIA_TRIANGLE_INEQUALITY", vals
    return None, vals



class TreeChecks(Recorder):
    """Structure, inertials and joint travel (mixin of the validator)."""

    # -- structure
    def structure(self, links: list[LinkRecord], joints: list[JointRecord]) -> tuple[set[str], str | None]:
        """Returns (moving links, root)."""
        if not links:
            self.add("URDF_NO_LINKS", "the robot has no <link>")
            return set(), None
        if len(links) > self.policy.max_links:
            self.add("URDF_TOO_MANY_LINKS", f"{len(links)} links > cap {self.policy.max_links}: PyBullet, which refine "
                     f"runs, loads at most {self.policy.max_links} links per body", links=len(links), cap=self.policy.max_links)
        seen: dict[str, LinkRecord] = {}
        for ln in links:
            if ln.name is None:
                continue
            if ln.name in seen:
                self.add("LINK_NAME_DUPLICATE", f"link {ln.name!r} is defined again (first at line {seen[ln.name].line})", line=ln.line, link=ln.name)
            else:
                seen[ln.name] = ln
        jseen: dict[str, JointRecord] = {}
        for j in joints:
            if j.name is None:
                continue
            if j.name in jseen:
                self.add("JOINT_NAME_DUPLICATE", f"joint {j.name!r} is defined again (first at line {jseen[j.name].line})", line=j.line, joint=j.name)
            else:
                jseen[j.name] = j
        names = list(seen)
        has_parent: dict[str, list[str]] = {}
        children: dict[str, list[str]] = {n: [] for n in names}
        first_parent: dict[str, str] = {}
        touched: set[str] = set()
        for j in joints:
            ok = True
            if j.parent is not None and j.parent not in seen:
                self.add("JOINT_PARENT_UNKNOWN", f"parent {j.parent!r} is not a link", line=j.line, joint=j.name)
                ok = False
            if j.child is not None and j.child not in seen:
                self.add("JOINT_CHILD_UNKNOWN", f"child {j.child!r} is not a link", line=j.line, joint=j.name)
                ok = False
            if j.parent is not None and j.parent == j.child:
                self.add("JOINT_SELF_LOOP", f"parent and child are both {j.parent!r}", line=j.line, joint=j.name, link=j.child)
                touched.add(j.parent)
                continue
            for n in (j.parent, j.child):
                if n in seen:
                    touched.add(n)
            if j.child in seen:
                has_parent.setdefault(j.child, []).append(j.name or "?")
            if ok and j.parent and j.child:
                if j.child not in first_parent:
                    first_parent[j.child] = j.parent
                    children[j.parent].append(j.child)
            if j.mimic is not None and (j.mimic not in jseen or j.mimic == j.name):
                self.add("JOINT_MIMIC_UNKNOWN", f"<mimic joint={j.mimic!r}> names no other joint", line=j.line, joint=j.name)
            elif j.mimic is not None:
                self.add("JOINT_MIMIC_UNSUPPORTED", f"<mimic joint={j.mimic!r}>: coupled joints are not modelled (the "
                         "state search, the post-check simulators and the writer treat every joint as free), so the "
                         "coupling would be lost; refused rather than dropped", line=j.line, joint=j.name, leader=j.mimic)
        for child, js in has_parent.items():
            if len(js) > 1:
                self.add("LINK_MULTIPLE_PARENTS", f"link {child!r} is the child of joints {', '.join(map(repr, js))}",
                         line=seen[child].line, link=child, joints=js)
        roots = [n for n in names if n not in has_parent]
        if len(names) > 1:
            for n in roots:
                if n not in touched:
                    self.add("LINK_ORPHAN", f"link {n!r} is connected by no joint", line=seen[n].line, link=n)
        connected_roots = [n for n in roots if n in touched or len(names) == 1]
        # reachability and cycles
        reached: set[str] = set()
        stack = list(roots)
        while stack:
            n = stack.pop()
            if n in reached:
                continue
            reached.add(n)
            stack.extend(children.get(n, []))
        reported: set[str] = set()
        for n in names:
            if n in reached or n in reported or n not in first_parent:
                continue
            path: list[str] = []
            cur = n
            pos: dict[str, int] = {}
            while cur in first_parent and cur not in pos and cur not in reported:
                pos[cur] = len(path)
                path.append(cur)
                cur = first_parent[cur]
            if cur in pos:
                cyc = path[pos[cur]:]
                self.add("TREE_CYCLE", f"joints form a cycle through links {' -> '.join(cyc + [cyc[0]])}",
                         line=seen[cyc[0]].line, link=cyc[0], links=cyc)
            reported.update(path)
        if not roots:
            self.add("TREE_NO_ROOT", "every link has a parent joint: there is no root link")
            root = None
        elif len(connected_roots) > 1:
            self.add("TREE_MULTIPLE_ROOTS", f"several links have no parent: {', '.join(map(repr, connected_roots))}", roots=connected_roots)
            root = None
        elif len(roots) > 1 and not connected_roots:
            self.add("TREE_MULTIPLE_ROOTS", f"no joint connects the links {', '.join(map(repr, roots))}", roots=roots)
            root = None
        else:
            root = connected_roots[0] if connected_roots else roots[0]
        moving = {j.child for j in joints if j.child and j.type in MOVABLE_TYPES}
        return moving, root

    # -- inertials
    def inertials(self, links: list[LinkRecord], moving: set[str]) -> None:
        for ln in links:
            if not ln.has_inertial or ln.name is None:
                continue
            bad = False
            if ln.mass is not None:
                if ln.mass < 0 or (ln.mass == 0 and ln.name in moving):
                    what = "a moving link" if ln.name in moving else "a link"
                    self.add("INERTIAL_MASS_NONPOSITIVE", f"mass {ln.mass!r} kg on {what}; an estimate replaces it",
                             line=ln.inertial_line, link=ln.name, action="replace_with_estimate", mass=ln.mass)
                    bad = True
                elif ln.mass == 0:
                    self.add("INERTIAL_MASS_ZERO_STATIC", "mass 0 on a static link (the simulator may treat it as fixed)",
                             line=ln.inertial_line, link=ln.name, mass=0.0)
            if ln.inertia is not None and not (ln.mass == 0 and ln.name not in moving and not any(ln.inertia)):
                code, lam = check_inertia(*ln.inertia)
                if code is not None:
                    why = ("an eigenvalue <= 0" if code == "INERTIA_NOT_POSITIVE_DEFINITE"
                           else "the largest principal moment exceeds the sum of the other two")
                    self.add(code, f"inertia (ixx ixy ixz iyy iyz izz) = {ln.inertia} kg*m^2 has eigenvalues "
                             f"{', '.join(f'{x:.6g}' for x in lam)}: {why}; an estimate replaces it (never balanced)",
                             line=ln.inertial_line, link=ln.name, action="replace_with_estimate",
                             eigenvalues=lam, inertia=list(ln.inertia))
                    bad = True
            if ln.mass is None or ln.inertia is None:
                bad = True
            if bad:
                self.result.replace_inertials.add(ln.name)

    # -- joint travel against the object's size (after the meshes were scanned)
    def joint_travel(self, links: list[LinkRecord], joints: list[JointRecord], root: str | None) -> None:
        """Prismatic limits beyond ``policy.max_prismatic_travel`` x the
        object's size: the diagonal of the bounding box of every geometry
        placed by forward kinematics at the zero configuration (file units).
        Skipped when the tree is broken or some size is unknown."""
        if root is None:
            return
        by_parent: dict[str, list] = {}
        for j in joints:
            if j.parent and j.child:
                by_parent.setdefault(j.parent, []).append(j)
        geoms = {ln.name: ln.geoms for ln in links if ln.name}
        pts: list[np.ndarray] = []
        stack = [(root, np.eye(4))]
        seen: set[str] = set()
        while stack:
            name, T = stack.pop()
            if name in seen:
                return
            seen.add(name)
            for g in geoms.get(name, []):
                c = geometry_corners(g)
                if c is None:
                    if g.kind is not None:
                        return  # a size is unknown: no claim about the object's size
                    continue
                pts.append(c @ T[:3, :3].T + T[:3, 3])
            for j in by_parent.get(name, []):
                J = np.eye(4)
                J[:3, :3] = rpy_matrix(j.rpy)
                J[:3, 3] = j.xyz
                stack.append((j.child, T @ J))
        if not pts:
            return
        allp = np.vstack(pts)
        size = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0)))
        cap = self.policy.max_prismatic_travel * size
        for j in joints:
            if j.type != "prismatic" or j.lower is None or j.upper is None or size <= 0:
                continue
            travel = max(abs(j.lower), abs(j.upper))
            if travel > cap:
                self.add("JOINT_LIMIT_IMPLAUSIBLE", f"prismatic limits [{j.lower!r}, {j.upper!r}] go beyond the object's "
                         f"size {size:.4g} (diagonal of its bounding box, file units): the part would leave the object; "
                         "check the units of the limits and of the meshes", line=j.limit_line, joint=j.name,
                         lower=j.lower, upper=j.upper, object_size=size)
