"""The kinematic-tree checks of the validator (:class:`TreeChecks`): structure (names, parents,
cycles, orphans, one root, caps, mimic and unsupported joints), the given inertials
(:func:`check_inertia`) and prismatic travel against the object's size.
"""

from __future__ import annotations

import numpy as np

from asset2sim import file_names
from asset2sim.tasks.ingest.findings import MAX_NAME_CHARS, MOVABLE_TYPES, Recorder
from asset2sim.tasks.ingest.urdf_checks import joint_name, link_name
from asset2sim.urdf import UrdfModel
from asset2sim.inert import shorten
from asset2sim.package_data import package_yaml

#: A revolute range spanning less than this (rad, one degree) only makes sense in the other unit.
MIN_REVOLUTE_SPAN = float(np.radians(1.0))
#: A prismatic range spanning less than this (m, one millimetre) only makes sense in the other unit.
MIN_PRISMATIC_SPAN = 1e-3

__all__ = ["TreeChecks", "check_inertia"]


def check_inertia(ixx: float, ixy: float, ixz: float, iyy: float, iyz: float, izz: float) -> tuple[str | None, list[float]]:
    """Check a URDF inertia tensor (kg*m^2, about the COM): ``(code, eigenvalues ascending)``, code None
    when positive definite (smallest eigenvalue > 1e-12 x largest) with the triangle inequality
    (tolerance 1e-9 of the trace), else ``INERTIA_NOT_POSITIVE_DEFINITE`` or
    ``INERTIA_TRIANGLE_INEQUALITY``.
    """
    lam = np.linalg.eigvalsh(np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], float))
    vals = [float(x) for x in lam]
    if lam[2] <= 0 or lam[0] <= 1e-12 * lam[2]:
        return "INERTIA_NOT_POSITIVE_DEFINITE", vals
    tol = 1e-9 * float(lam.sum())
    if lam[2] > lam[0] + lam[1] + tol:
        return "INERTIA_TRIANGLE_INEQUALITY", vals
    return None, vals


_INERTIA_ENTRIES = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))  # ixx ixy ixz iyy iyz izz

#: Joint types refine refuses (``JOINT_TYPE_UNSUPPORTED``), with why and what to write instead (``messages.yaml``;
#: docs/design/validation.md, "Joint types").
_UNSUPPORTED_JOINT_TYPES: dict[str, str] = package_yaml(__package__, "messages.yaml")["unsupported_joint_types"]


class TreeChecks(Recorder):
    """Structure, inertials and joint travel (mixin of the validator)."""

    def structure(self, model: UrdfModel) -> tuple[set[str], str | None]:
        """The structure checks of ``model`` (every ``<link>`` element); returns (moving links, root)."""
        links, joints = model.link_elements, model.joints
        if not links:
            self.add("URDF_NO_LINKS", "the robot has no <link>")
            return set(), None
        links_n, cap = len(links), self.policy.max_links
        if links_n > cap:
            self.add("URDF_TOO_MANY_LINKS", f"{links_n} links > cap {cap}: PyBullet, which refine "
                     f"runs, loads at most {cap} links per body", links=links_n, cap=cap)
        movable, cap = len(model.movable_joints), self.policy.max_movable_joints
        if movable > cap:
            self.add("URDF_TOO_MANY_MOVABLE_JOINTS", f"{movable} movable joints > cap {cap}: "
                     f"refine's closed-state, state search and rest tests grow with the number of joints; with every "
                     f"link touching (worst case, benchmarks/bench_joint_cap.py) it may not finish within the flow's "
                     f"per-asset time limit, which then ends it", joints=movable, cap=cap)
        if model.name and len(model.name) > MAX_NAME_CHARS:
            self.add("NAME_TOO_LONG", f"robot name of {len(model.name)} characters > cap {MAX_NAME_CHARS} "
                     f"({shorten(model.name, 60)!r})", length=len(model.name), cap=MAX_NAME_CHARS)
        seen = self._first_by_name(links, "link")
        jseen = self._first_by_name(joints, "joint")
        for name, ln in seen.items():  # link names that are not clean file names (with the name their files get), and clashes
            if not file_names.is_clean(name):
                self.add("LINK_NAME_NOT_A_FILE_NAME", f"not a safe file name; files made for it are "
                         f"named {file_names.file_stem(name)!r}", line=ln.line, link=name)
        for stem, same in file_names.clashes(seen).items():
            self.add("LINK_FILE_NAMES_CLASH", f"links {', '.join(map(repr, same))} would give their files one name "
                     f"{stem!r}; rename one", line=seen[same[1]].line, link=same[1])
        names = list(seen)
        # the tree as the joints give it: child -> its parent joints' names, the parent of each child's first joint, the
        # links named
        has_parent: dict[str, list[str]] = {}
        first_parent: dict[str, str] = {}
        touched: set[str] = set()
        # unknown links and self loops reported; the joint's support checked when it joins two links
        for j in joints:
            jname, parent, child = joint_name(j.name), link_name(j.parent), link_name(j.child)
            if parent is not None and parent not in seen:
                self.add("JOINT_PARENT_UNKNOWN", f"parent {parent!r} is not a link", line=j.line, joint=jname)
            if child is not None and child not in seen:
                self.add("JOINT_CHILD_UNKNOWN", f"child {child!r} is not a link", line=j.line, joint=jname)
            if parent is not None and parent == child:
                self.add("JOINT_SELF_LOOP", f"parent and child are both {parent!r}", line=j.line, joint=jname, link=child)
                touched.add(parent)
                continue
            touched.update(n for n in (parent, child) if n in seen)
            if child in seen:
                has_parent.setdefault(child, []).append(jname or "?")
            if parent in seen and child in seen and child not in first_parent:
                first_parent[child] = parent
            # mimic joints and joint types refine does not model
            leader = getattr(j.mimic, "joint", None)
            if leader is not None and (leader not in jseen or leader == jname):
                self.add("JOINT_MIMIC_UNKNOWN", f"<mimic joint={leader!r}> names no other joint", line=j.line, joint=jname)
            elif leader is not None:
                self.add("JOINT_MIMIC_UNSUPPORTED", f"<mimic joint={leader!r}>: coupled joints are not modelled (the "
                         "state search, the post-check simulators and the writer treat every joint as free), so the "
                         "coupling would be lost; refused rather than dropped", line=j.line, joint=jname, leader=leader)
            if j.type in _UNSUPPORTED_JOINT_TYPES:
                self.add("JOINT_TYPE_UNSUPPORTED", f"a {j.type} joint between {parent!r} and {child!r}: "
                         f"{_UNSUPPORTED_JOINT_TYPES[j.type]}", line=j.line, joint=jname, type=j.type)
        # links with several parents, orphans, and the links without a parent joint (``roots``, in order)
        for child, js in has_parent.items():
            if len(js) > 1:
                self.add("LINK_MULTIPLE_PARENTS", f"link {child!r} is the child of joints {', '.join(map(repr, js))}",
                         line=seen[child].line, link=child, joints=js)
        roots = [n for n in names if n not in has_parent]
        if len(names) > 1:
            for n in roots:
                if n not in touched:
                    self.add("LINK_ORPHAN", f"link {n!r} is connected by no joint", line=seen[n].line, link=n)
        # ``TREE_CYCLE`` for each cycle of first parents (a walk up from a link a root reaches ends at that root)
        reported: set[str] = set()
        for n in names:
            if n in reported or n not in first_parent:
                continue
            cur = n
            pos: dict[str, int] = {}  # the path: link -> its place
            while cur in first_parent and cur not in pos and cur not in reported:
                pos[cur] = len(pos)
                cur = first_parent[cur]
            if cur in pos:
                cyc = list(pos)[pos[cur]:]
                self.add("TREE_CYCLE", f"joints form a cycle through links {' -> '.join(cyc + [cyc[0]])}",
                         line=seen[cyc[0]].line, link=cyc[0], links=cyc)
            reported.update(pos)
        # the one root link, or None with ``TREE_NO_ROOT`` / ``TREE_MULTIPLE_ROOTS``
        connected_roots, root = [n for n in roots if n in touched or len(names) == 1], None
        if not roots:
            self.add("TREE_NO_ROOT", "every link has a parent joint: there is no root link")
        elif len(connected_roots) > 1:
            self.add("TREE_MULTIPLE_ROOTS", f"several links have no parent: {', '.join(map(repr, connected_roots))}",
                     roots=connected_roots)
        elif len(roots) > 1 and not connected_roots:
            self.add("TREE_MULTIPLE_ROOTS", f"no joint connects the links {', '.join(map(repr, roots))}", roots=roots)
        else:
            root = connected_roots[0] if connected_roots else roots[0]
        return {j.child for j in joints if j.child and j.type in MOVABLE_TYPES}, root

    def _first_by_name(self, items: list, kind: str) -> dict:
        """``kind`` ("link" or "joint") elements by name, the first of each; the others are duplicates. A name longer
        than :data:`MAX_NAME_CHARS` is refused (``NAME_TOO_LONG``), shown shortened."""
        seen: dict = {}
        for it in items:
            if not it.name:
                continue
            if len(it.name) > MAX_NAME_CHARS:
                self.add("NAME_TOO_LONG", f"{kind} name of {len(it.name)} characters > cap {MAX_NAME_CHARS} "
                         f"({shorten(it.name, 60)!r}): PyBullet cannot load it", line=it.line,
                         **{kind: shorten(it.name, 60)}, length=len(it.name), cap=MAX_NAME_CHARS)
            if it.name in seen:
                self.add(f"{kind.upper()}_NAME_DUPLICATE", f"{kind} {it.name!r} is defined again (first at line "
                         f"{seen[it.name].line})", line=it.line, **{kind: it.name})
            else:
                seen[it.name] = it
        return seen

    def inertials(self, model: UrdfModel, moving: set[str]) -> None:
        """The given ``<inertial>`` of every named link (mass > 0 when moving, :func:`check_inertia`);
        invalid or incomplete ones go to ``result.replace_inertials``."""
        for ln in model.link_elements:
            ine = ln.inertial
            if ine is None or not ln.name:
                continue
            mass = ine.mass
            inertia = None if ine.inertia is None else tuple(float(ine.inertia[a, b]) for a, b in _INERTIA_ENTRIES)
            bad = False
            if mass is not None:
                if mass < 0 or (mass == 0 and ln.name in moving):
                    what = "a moving link" if ln.name in moving else "a link"
                    self.add("INERTIAL_MASS_NONPOSITIVE", f"mass {mass!r} kg on {what}; an estimate replaces it",
                             line=ine.line, link=ln.name, action="replace_with_estimate", mass=mass)
                    bad = True
                elif mass == 0:
                    self.add("INERTIAL_MASS_ZERO_STATIC", "mass 0 on a static link (the simulator may treat it as fixed)",
                             line=ine.line, link=ln.name, mass=0.0)
            big = [v for v in (mass, *(inertia or ())) if v is not None and abs(v) > self.policy.max_inertial]
            if big:  # refused: the audit and --keep-declared would compute with it (1e308 squared is inf)
                self.add("INERTIAL_IMPLAUSIBLE", f"<inertial> value {big[0]!r} beyond +-{self.policy.max_inertial:g} "
                         "(kg, kg*m^2): no object asset2sim refines weighs or turns like that", line=ine.line, link=ln.name)
            elif inertia is not None and not (mass == 0 and ln.name not in moving and not any(inertia)):
                code, lam = check_inertia(*inertia)
                if code is not None:
                    why = ("an eigenvalue <= 0" if code == "INERTIA_NOT_POSITIVE_DEFINITE"
                           else "the largest principal moment exceeds the sum of the other two")
                    self.add(code, f"inertia (ixx ixy ixz iyy iyz izz) = {inertia} kg*m^2 has eigenvalues "
                             f"{', '.join(f'{x:.6g}' for x in lam)}: {why}; an estimate replaces it (never balanced)",
                             line=ine.line, link=ln.name, action="replace_with_estimate",
                             eigenvalues=lam, inertia=list(inertia))
                    bad = True
            if bad or mass is None or inertia is None:
                self.result.replace_inertials.add(ln.name)

    def joint_travel(self, model: UrdfModel, box: np.ndarray | None) -> None:
        """Prismatic limits beyond ``policy.max_prismatic_travel`` x the diagonal of ``box`` (:func:`zero_pose_bounds`,
        after the mesh scan); skipped when that is unknown (None)."""
        if box is None or not np.isfinite(box).all():
            return
        size = float(np.linalg.norm(box[1] - box[0]))
        cap = self.policy.max_prismatic_travel * size
        for j in model.joints:
            lim = j.limit
            if j.type != "prismatic" or lim is None or lim.lower is None or lim.upper is None or size <= 0:
                continue
            if max(abs(lim.lower), abs(lim.upper)) > cap:
                self.add("JOINT_LIMIT_IMPLAUSIBLE", f"prismatic limits [{lim.lower!r}, {lim.upper!r}] go beyond the object's "
                         f"size {size:.4g} (diagonal of its bounding box, file units): the part would leave the object; "
                         "check the units of the limits and of the meshes", line=lim.line, joint=joint_name(j.name),
                         lower=lim.lower, upper=lim.upper, object_size=size)

    def joint_range_units(self, model: UrdfModel) -> None:
        """A movable joint whose whole range is below :data:`MIN_REVOLUTE_SPAN` (a degree) or
        :data:`MIN_PRISMATIC_SPAN` (a millimetre) but not zero: a range that only makes sense in the other unit
        (an MJCF fragment's radians read as degrees: robosuite's door ``range="0 0.4"`` becomes 0.4 degrees)."""
        for j in model.joints:
            lim = j.limit
            if j.type not in ("revolute", "prismatic") or lim is None or lim.lower is None or lim.upper is None:
                continue
            span = float(lim.upper) - float(lim.lower)
            if not np.isfinite(span) or span <= 0:
                continue
            if j.type == "revolute" and span < MIN_REVOLUTE_SPAN:
                why = (f"revolute range [{lim.lower:.6g}, {lim.upper:.6g}] rad spans {np.degrees(span):.3g} degrees: "
                       f"a part that turns a fraction of a degree; its numbers read as radians would span {np.degrees(np.degrees(span)):.3g} degrees "
                       "(an MJCF file's radians read as degrees? asset2sim refine --mjcf-angle radian)")
            elif j.type == "prismatic" and span < MIN_PRISMATIC_SPAN:
                why = (f"prismatic range [{lim.lower:.6g}, {lim.upper:.6g}] spans {span * 1000:.3g} mm: a part that slides a "
                       "fraction of a millimetre (millimetres read as metres?)")
            else:
                continue
            self.add("JOINT_RANGE_WRONG_UNIT", why, line=lim.line, joint=joint_name(j.name), lower=lim.lower, upper=lim.upper)
