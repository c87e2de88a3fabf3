"""The articulated object inside an MJCF scene.

Many packages ship an object as a scene: Meta-World's ``drawer.xml`` puts a
table (``tablelink``), a retaining wall (``RetainingWall``) and the drawer
under the world body. The object is the subtree under the world body that
carries the hinge and slide joints; the bodies whose subtrees carry no joint at
all are the world it stands on or is mounted on: reported (a note names them)
and not refined. With several jointed subtrees, the caller names one
(``--body NAME``, config ``body``); without a name that is an error listing
them.

Works on a compiled ``mujoco.MjModel`` (bodies numbered depth first, as
MuJoCo numbers them: a body's subtree is the bodies after it up to the next
body outside it).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from asset2sim.formats.staging import StagingError

#: MuJoCo's joint types (``mjtJoint``): free, ball, slide, hinge.
JNT_FREE, JNT_BALL, JNT_SLIDE, JNT_HINGE = 0, 1, 2, 3


@dataclass(frozen=True)
class ScenePick:
    """The object of a scene: ``root`` its body id (a child of the world body), ``bodies`` its subtree (body ids,
    depth first, ``root`` first); ``notes`` what was chosen and why, one line each (the world body's other children
    named: those whose subtrees carry no joint, the world around the object, and those that carry joints, other
    objects or loose bodies)."""

    root: int
    bodies: tuple[int, ...]
    notes: tuple[str, ...] = ()


def label(m, b: int) -> str:
    """Body ``b``'s name, ``body_<b>`` for an unnamed body (the name its link gets)."""
    return m.body(b).name or f"body_{b}"


def subtree(m, b: int) -> list[int]:
    """Body ``b`` and every body below it (ids, depth first)."""
    inside = {b}
    for c in range(b + 1, m.nbody):
        if int(m.body_parentid[c]) in inside:
            inside.add(c)
    # ids ascending: depth first, as MuJoCo numbers bodies
    return sorted(inside)


def body_joints(m, b: int, types: tuple[int, ...] | None = None) -> list[int]:
    """The ids of the joints on body ``b`` (those of ``types``, :data:`JNT_FREE` ..., when given), in order."""
    adr = int(m.body_jntadr[b])
    return [j for j in range(adr, adr + int(m.body_jntnum[b])) if types is None or int(m.jnt_type[j]) in types]


def joint_types(m, bodies: list[int]) -> list[int]:
    """The types (:data:`JNT_FREE` ...) of every joint on ``bodies``."""
    return [int(m.jnt_type[j]) for b in bodies for j in body_joints(m, b)]


def pick_object(m, path: Path | str, body: str | None = None) -> ScenePick:
    """The articulated object of the compiled scene ``m`` (an ``MjModel``) read from ``path``.

    Args:
        m: the compiled model.
        path: the file (for messages).
        body: a body's name (``body_<id>`` or ``#<id>`` for an unnamed one): a child of the world body, or a moving
            part of one (a body with a hinge or slide joint), picks that child; another body deeper in the scene (a
            kitchen's ``microwave`` on its counter) is itself the object's root, mounted on the bodies above it.
            None: the one child whose subtree carries a hinge or slide joint (a file with one child: that child).

    Raises:
        StagingError: no body under the world body; ``body`` names no body (the message lists the candidates);
            several children carry hinge or slide joints and ``body`` is None (listed, with how to pick one); none
            carries one among several children.
    """
    tops = [b for b in range(1, m.nbody) if int(m.body_parentid[b]) == 0]
    if not tops:
        raise StagingError(f"{path}: no body under the world body: nothing to read")
    trees = {b: subtree(m, b) for b in tops}
    moving = {b: [t for t in joint_types(m, trees[b]) if t in (JNT_HINGE, JNT_SLIDE)] for b in tops}
    articulated = [b for b in tops if moving[b]]
    notes: list[str] = []
    if body is not None:
        # by its name; an unnamed body by #<id> or body_<id>
        named = next((b for b in range(1, m.nbody) if body in ((m.body(b).name,) if m.body(b).name else (f"#{b}", f"body_{b}"))),
                     None)
        if named is None:
            names = [label(m, b) for b in (articulated or tops)]
            raise StagingError(f"{path}: no body named {body!r}; the objects under the world body: {names}")
        # an object under the world body, or a moving part of one: that object
        if named in trees or body_joints(m, named, (JNT_HINGE, JNT_SLIDE)):
            root = next(t for t in tops if named in trees[t])
            notes.append(f"object: body {label(m, root)!r} (asked: --body {body})")
        else:  # a body deeper in a scene (a kitchen's microwave on its counter): its own subtree, mounted where it is
            chain, b = [], int(m.body_parentid[named])
            while b != 0:
                chain.append(b)
                b = int(m.body_parentid[b])
            inside = set(subtree(m, named))
            top = chain[-1] if chain else named
            beside = [label(m, b) for b in subtree(m, top) if b not in inside and int(m.body_jntnum[b]) > 0]
            notes.append(f"object: body {label(m, named)!r} (asked: --body {body}), mounted on "
                         f"{[label(m, c) for c in chain]} (left out, not refined)"
                         + (f"; bodies with joints beside it left out: {beside}" if beside else ""))
            root = named
    elif len(tops) == 1:
        root = tops[0]
    elif len(articulated) == 1:
        root = articulated[0]
        notes.append(f"object: body {label(m, root)!r}, the one subtree under the world body with hinge or slide joints "
                     f"({len(moving[root])})")
    elif articulated:
        names = [label(m, b) for b in articulated]
        raise StagingError(f"{path}: {len(articulated)} bodies under the world body carry hinge or slide joints {names}: "
                           "name the object with --body NAME (config body:)")
    else:
        raise StagingError(f"{path}: none of the {len(tops)} bodies under the world body {[label(m, b) for b in tops]} "
                           "carries a hinge or slide joint: name the object with --body NAME (config body:)")
    home = next(t for t in tops if root in trees[t])  # the world body's child holding the object (itself, mostly)
    static = [label(m, b) for b in tops if b != home and not joint_types(m, trees[b])]
    left_out = [label(m, b) for b in tops if b != home and joint_types(m, trees[b])]
    if static:
        where = "stands on" if JNT_FREE in joint_types(m, [root]) else "is mounted on"
        notes.append(f"static bodies {static} (no joints): the world the object {where}; left out, not refined")
    if left_out:
        notes.append(f"other bodies with joints {left_out} left out (one object is read; --body picks another)")
    return ScenePick(root=root, bodies=tuple(subtree(m, root)), notes=tuple(notes))
