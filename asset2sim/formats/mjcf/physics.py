"""The one MJCF physics writer: the refined object written back into its own MJCF file, to drop into its host in
place of the original (:func:`write_host_mjcf`), and the audit's patch of an MJCF input (:func:`write_patched_mjcf`),
both through :func:`set_body_inertial` and :func:`set_joint_friction` on MuJoCo's ``MjSpec``.

An MJCF input (a robosuite fragment, a Meta-World scene) is read again with the conventions it was read with
(:func:`asset2sim.formats.mjcf.conventions.mjcf_angle`, the object of
:func:`asset2sim.formats.mjcf.scene.pick_object`), and only its physics is changed to the refined output's:

- each body of the object that carries geometry or declares an ``<inertial>`` gets the refined link's mass, center
  of mass and full inertia tensor (an explicit ``<inertial>``; bodies without either, wrappers, are left as they are);
- each hinge and slide joint gets the refined damping, friction loss, spring (``stiffness``, ``springref``) and
  range, angles in the file's unit, MuJoCo's ``ref`` kept (joint values read the same in the URDF and in MuJoCo);
- the refined initial state is the keyframe ``initial`` (replaced when the file has one; joint values in
  radians, as MJCF writes ``qpos`` whatever the angle unit).

Body, joint, geom and site names, the geometry, the bodies around the object (a table, a wall), the materials
and the file's ``<compiler>`` conventions (its angle unit now stated) stay. MuJoCo writes the result
(``MjSpec.to_xml``, includes inlined, numbers to MuJoCo's 6 significant digits); it is compiled and checked (same names, the refined masses) before it is
written as ``mjcf/host/<input file name>``, with ``mjcf/host/<stem>.diff``, the unified diff of the input file
and the written one. A refine that rescaled the object writes no such file: the host's geometry would no longer
match the physics.

MuJoCo's writer is the MuJoCo installed here, and an older MuJoCo, which a host package may pin (Meta-World
pins 3.3.0), rejects attributes a newer one writes (a texture's ``colorspace``). And a host may build its own scene
around the object's included file (Meta-World's environments include ``objects/assets/drawer.xml``, not the
``objects/drawer.xml`` scene). So each of the input's own files holding bodies of the object (the file given, and
the files it includes) is also written again as ``mjcf/host/files/<its path in the input's tree>``, the package's
XML as it was (XML comments dropped) with only the bodies' ``<inertial>`` those of the host file and their hinge
and slide joints' ``damping``, ``frictionloss`` (with its ``solreffriction`` and ``solimpfriction``, as the MJCF
export holds friction without the no-slip pass, at the host's time step), ``stiffness``, ``springref`` and ``range``
the refined ones in the unit the file is compiled in (bodies matched by name, their joints in order), to copy over the package's file;
``mjcf/host/files.diff`` is their diff against the package's. These files carry no keyframe: the host sets its
state.
"""

from __future__ import annotations

import difflib
import math
import os
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from asset2sim import atomic, file_names, output_folder, safexml
from asset2sim.refined_asset import RefinedAsset
from asset2sim.engines.mjcf.base import FRICTION_SOLIMP, KEYFRAME, friction_solref, load_mujoco, mujoco_messages
from asset2sim.output_folder import MJCF_DIR, URDF_NAME
from asset2sim.schemas.overlay import JointDynamics, LinkPhysics, Overlay
from asset2sim.formats.mjcf import conventions, scene
from asset2sim.formats.mjcf.conventions import ReadOptions
from asset2sim.formats.mjcf.files import MjcfSources, compile_mjcf, gather_mjcf, opened_mjcf, staged_sources
from asset2sim.formats.mjcf.export import MASS_RTOL
from asset2sim.formats.staging import HOST_DIR, host_overlay, MJCF_SUFFIXES, ReadAsset, StagingError, copy_named

#: Folder (inside ``mjcf/host/``) of the input's files holding the object, written again.
FILES_DIR = "files"
#: Their unified diff against the package's files (inside ``mjcf/host/``).
FILES_DIFF = "files.diff"
#: Joint attributes a package file takes from the refined joint (in the file's units).
JOINT_PHYSICS = ("damping", "frictionloss", "solreffriction", "solimpfriction", "stiffness", "springref", "range")


class HostExportError(RuntimeError):
    """The host file cannot be written (names the input and why)."""


@dataclass(frozen=True)
class HostExport:
    """What :func:`write_host_mjcf` wrote: ``path`` the MJCF file, ``diff`` the diff against the input, ``bodies``
    and ``joints`` the names whose physics changed, ``files`` the input's files holding the object written again."""

    path: Path
    diff: Path
    bodies: tuple[str, ...]
    joints: tuple[str, ...]
    files: tuple[Path, ...] = ()
    overrides: tuple[str, ...] = ()
    """What the host package's code sets over the written values at run time, with how to keep the refined ones."""


def _names(m, mujoco) -> dict[str, list[str]]:
    """Names of the compiled model's bodies, joints, geoms and sites (sorted; unnamed ones left out)."""
    return {kind: sorted(x for i in range(n) if (x := mujoco.mj_id2name(m, obj, i)))
            for kind, obj, n in (("body", mujoco.mjtObj.mjOBJ_BODY, m.nbody), ("joint", mujoco.mjtObj.mjOBJ_JOINT, m.njnt),
                                 ("geom", mujoco.mjtObj.mjOBJ_GEOM, m.ngeom), ("site", mujoco.mjtObj.mjOBJ_SITE, m.nsite))}


def write_host_mjcf(out_dir: Path | str, source: Path | str, reading: ReadOptions | None = None, *,
                    sources: MjcfSources | None = None, angle: str | None = None) -> HostExport:
    """Write the refined output in ``out_dir`` back into the MJCF file ``source`` it was refined from.

    Args:
        out_dir: a refined output folder (``mobility.urdf``, ``overlay.json``, ``initial_state.json``).
        source: the MJCF file the refine read (its name; nothing is read from it when ``sources`` is given).
        reading: the options it was read with (the object's body, the angle unit).
        sources: the file and every file it names as the reader policy read them when the refine staged it
            (:func:`~asset2sim.formats.mjcf.files.staged_sources`): MuJoCo compiles from a private copy of these
            bytes, so the write-back never opens the input's paths again; None gathers them once here under the
            reader policy (:func:`~asset2sim.formats.mjcf.files.gather_mjcf`).
        angle: the angle unit the refine read the file in (``radian`` / ``degree``); None works it out from the
            file and its host package as the reader does.

    Returns:
        :class:`HostExport`: ``mjcf/host/<source name>`` and its diff, inside ``out_dir``.

    Raises:
        ImportError: MuJoCo is not installed.
        HostExportError: the output was rescaled; a refined link or joint has no counterpart in the file; the
            written model does not compile or loses a name or a mass.
    """
    source, out_dir = Path(source), Path(out_dir)
    reading = reading or ReadOptions()
    if sources is None:
        sources = gather_mjcf(source)  # once, under the reader policy
    unit = angle or conventions.mjcf_angle(source, reading.mjcf_angle, files=sources.files).unit
    with output_folder.guarding(out_dir), opened_mjcf(sources, degree=unit == "degree") as opened:
        # nothing through a symlinked mjcf/ or mjcf/host/; MuJoCo reads the bytes read before, never the input
        asset = RefinedAsset(out_dir)
        overlay = host_overlay(asset, source, "file", HostExportError)
        model, state = asset.model, asset.initial_state
        spec, original = opened.spec, opened.model
        pick = scene.pick_object(original, source, reading.body)
        per_rad = 180.0 / math.pi if unit == "degree" else 1.0
        explicit = {b.name: bool(b.explicitinertial) for b in spec.bodies if b.name}
        bodies, joints, moving, qpos = [], [], {}, np.array(original.qpos0, float)
        for b in pick.bodies:
            name = scene.label(original, b)
            link = model.links.get(name)
            if link is None:
                raise HostExportError(f"{source}: body {name!r} has no link in the refined {URDF_NAME}")
            jids = scene.body_joints(original, b, (scene.JNT_HINGE, scene.JNT_SLIDE))
            offset = np.asarray(original.jnt_pos[jids[0]], float) if jids else np.zeros(3)  # the link frame sits on the joint
            carries = int(original.body_geomnum[b]) > 0 or explicit.get(original.body(b).name, False)
            if carries and link.inertial is not None and link.inertial.mass:
                inertial = link.inertial
                set_body_inertial(spec.bodies[b], float(inertial.mass), inertial.com(), inertial.inertia_in_link_axes(), offset)
                bodies.append(name)
            for j in jids:
                jname = original.joint(j).name or f"{name}_joint"  # the reader's name for an unnamed joint
                target = next(x for x in spec.joints if x.id == j)
                _set_joint(target, original, j, jname, model, overlay, per_rad)
                joints.append(jname)
                if jname in state:  # the keyframe's: the refined initial state (rad or m, the same values in MuJoCo)
                    qpos[int(original.jnt_qposadr[j])] = float(state[jname])
                moving.setdefault(name, []).append((target, bool(original.jnt_limited[j])))
        key = next((k for k in spec.keys if k.name == KEYFRAME), None)  # the keyframe KEYFRAME: replaced, else added
        if key is not None:
            key.qpos = qpos
        else:
            spec.add_key(name=KEYFRAME, qpos=qpos)
        try:
            written = opened.compile()  # from the private copy of the bytes read
        except Exception as exc:  # StagingError with the compiler's message
            raise HostExportError(f"{source}: the refined host file does not compile: {exc}") from exc
        _check(source, original, written, load_mujoco(), model, bodies)
        xml = spec.to_xml()
        folder, stem = out_dir / MJCF_DIR / HOST_DIR, file_names.file_stem(source.stem)
        path = file_names.join_inside(folder, stem + ".xml")
        atomic.write_bytes(path, xml.encode("utf-8"))
        before = opened.sources.files[opened.sources.main].decode("utf-8", "replace").splitlines(keepends=True)
        diff = "".join(difflib.unified_diff(before, xml.splitlines(keepends=True), fromfile=f"{source.name} (the input)",
                                            tofile=path.name))
        diff_path = file_names.join_inside(folder, stem + ".diff")
        atomic.write_bytes(diff_path, diff.encode("utf-8"))
        files = write_package_files(folder / FILES_DIR, source, xml, set(bodies),
                                    {b: [_joint_physics(*x) for x in v] for b, v in moving.items()}, sources=opened.sources)
        return HostExport(path=path, diff=diff_path, bodies=tuple(bodies), joints=tuple(joints), files=tuple(files),
                          overrides=tuple(override_notes(source, spec, joints)))


def override_notes(source: Path, spec, joints: list[str]) -> list[str]:
    """One sentence per joint of ``joints`` whose physics the host package's code sets at run time
    (:data:`~asset2sim.formats.mjcf.conventions.PHYSICS_OVERRIDES`): what it sets, over which refined values
    (``spec``'s joints, the file's units), and the call that keeps them."""
    out = []
    for override, joint in conventions.physics_overrides(source, joints):
        target = next((x for x in spec.joints if x.name == joint), None)
        if target is None:
            continue
        refined = {"frictionloss": float(target.frictionloss), "damping": float(np.atleast_1d(target.damping)[0])}
        replaced = ", ".join(f"{k} {refined[k]:.6g} with {v:.6g}" for k, v in override.values.items() if k in refined)
        keep = override.keep.format(**{k: f"{v:.6g}" for k, v in refined.items()})
        out.append(f"{override.how}: it replaces the refined {joint!r} {replaced}; build {keep} to keep the refined values")
    return out


def write_package_files(folder: Path, source: Path, host_xml: str, inertials: set[str],
                        joints: dict[str, list[dict[str, str]]], *, sources: MjcfSources) -> list[Path]:
    """``source`` and the files it includes that hold a body of ``inertials`` or ``joints`` (names), written again
    under ``folder`` at their path in the input's tree (the host package's asset folder,
    :func:`~asset2sim.formats.mjcf.conventions.package_tree`, else the input's folder; a file from a folder
    ``--allow-outside-paths`` allows is left out): the ``<inertial>`` of the bodies of ``inertials`` as ``host_xml``
    (the host file written) has it, and on the hinge and slide ``<joint>`` elements of the bodies of ``joints``
    (body name -> attributes per joint in order, :func:`_joint_physics`) those attributes; their unified diff against
    the package's files in ``folder``'s parent as :data:`FILES_DIFF`; ``sources``: the files as already read (under
    the reader policy). Returns the files written.

    Raises:
        StagingError: an included file cannot be read again under the input's trust rules.
        UnsafePath: an included file's path would leave ``folder``.
    """
    host = safexml.parse_xml_bytes(host_xml.encode("utf-8"), source="host file")
    keys: dict[tuple, list[str]] = {}  # body key -> labels (scene.label: body ids count from 1 in document order)
    hosted = {}
    for i, b in enumerate(host.iter("body"), start=1):
        label = b.get("name") or f"body_{i}"
        keys.setdefault(_body_key(b), []).append(label)
        if label in inertials:
            hosted[label] = b
    out, diffs = [], []
    for name, data in sorted(sources.files.items()):
        if Path(name).suffix.lower() not in MJCF_SUFFIXES:  # meshes and textures
            continue
        root = safexml.parse_xml_bytes(data, source=name)
        found = [(body, match[0]) for body in root.iter("body")  # one body of the host file is this one
                 if len(match := keys.get(_body_key(body), [])) == 1 and (match[0] in hosted or match[0] in joints)]
        if not found:
            continue
        for body, label in found:
            _copy_physics(hosted.get(label), body, joints.get(label, []))
        if not Path(name).is_relative_to(sources.tree):  # a file --allow-outside-paths let in: no place to mirror it
            continue
        rel = Path(name).relative_to(sources.tree).as_posix()
        path = file_names.join_inside(folder, rel)
        text = ET.tostring(root, encoding="unicode").replace(" />", "/>")  # ET's empty-element style; ">" in values is escaped
        head = data[:data.index(b"<", data.index(b"?>") + 2)] if data.lstrip().startswith(b"<?xml") else b""
        if b"encoding" in head and b"utf-8" not in head.lower():
            head = b""  # written as UTF-8, which needs no declaration
        written = head + text.encode("utf-8") + b"\n"
        atomic.write_bytes(path, written)
        diffs.extend(difflib.unified_diff(data.decode("utf-8", "replace").splitlines(keepends=True),
                                          written.decode("utf-8").splitlines(keepends=True), fromfile=rel, tofile=rel))
        out.append(path)
    if out:
        atomic.write_bytes(folder.parent / FILES_DIFF, "".join(diffs).encode("utf-8"))
    return out


def _body_key(body) -> tuple:
    """What identifies a ``<body>`` element in a package's file and in the host file written from it: its name; an
    unnamed body (Meta-World's window sash) by the names of its own joints and the keys of its child bodies, so the
    same subtree in both files has the same key."""
    if body.get("name"):
        return ("name", body.get("name"))
    return ("subtree", tuple(j.get("name") or "" for j in body.findall("joint")),
            tuple(_body_key(c) for c in body.findall("body")))


def _joint_physics(joint, limited: bool) -> dict[str, str]:
    """The :data:`JOINT_PHYSICS` of ``joint`` (an ``mjsJoint``, in the file's units; ``range`` only when
    ``limited``) as MJCF attribute values, to 12 significant digits."""
    def text(values) -> str:
        return " ".join(f"{float(v):.12g}" for v in values)
    out = {"damping": text(joint.damping[:1]), "frictionloss": text([joint.frictionloss]),
           "solreffriction": text(joint.solref_friction), "solimpfriction": text(joint.solimp_friction),
           "stiffness": text(joint.stiffness[:1]), "springref": text([joint.springref])}
    if limited:
        out["range"] = text(joint.range)
    return out


def _copy_physics(host, body, joints: list[dict[str, str]]) -> None:
    """``host``'s ``<inertial>`` on ``body`` (replacing its own; ``host`` None: none) and ``joints``' attributes on
    ``body``'s hinge and slide joints, paired in order."""
    inertial = host.find("inertial") if host is not None else None
    if inertial is not None:
        old = body.find("inertial")
        new = ET.Element("inertial", dict(inertial.attrib))
        if old is not None:
            new.tail = old.tail
            body[list(body).index(old)] = new
        else:
            new.tail = body[0].tail if len(body) else None
            body.insert(0, new)
    for target, given in zip([j for j in body.findall("joint") if j.get("type") not in ("free", "ball")], joints):
        for key, value in given.items():
            target.set(key, value)


def set_body_inertial(body, mass: float, com, tensor: np.ndarray, offset: np.ndarray) -> None:
    """An explicit ``<inertial>`` on ``body`` (an ``mjsBody``): ``mass`` kg, the center of mass ``com`` (3,) m in the
    link frame moved by ``offset`` (3,) m to the body frame (the link frame sits on the body's joint), the tensor
    ``tensor`` (3, 3) kg*m^2 about it in the link axes, written as MuJoCo's full inertia."""
    body.explicitinertial = True
    body.mass = mass
    body.ipos = np.asarray(com, float) + offset
    body.iquat = [1.0, 0.0, 0.0, 0.0]
    body.inertia = [0.0, 0.0, 0.0]  # MuJoCo takes either the diagonal or the full tensor
    body.fullinertia = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2], tensor[1, 2]]


def set_joint_friction(joint, damping: float, friction: float) -> None:
    """``joint``'s (an ``mjsJoint``) damping (its first value; N*m*s/rad or N*s/m) and friction loss (N*m or N)."""
    joint.damping = _with_first(joint.damping, damping)
    joint.frictionloss = friction


def _with_first(values, first: float) -> np.ndarray:
    """``values`` (a MuJoCo spec's array attribute) as floats, the first replaced by ``first``."""
    out = np.array(values, float)
    out[0] = first
    return out


def _set_joint(joint, m, j: int, name: str, model, overlay: Overlay, per_rad: float) -> None:
    """The refined damping, friction loss, spring and range of URDF joint ``name`` on ``joint`` (an ``mjsJoint``, id
    ``j`` in ``m``), in
    the file's unit (``per_rad``: file units per radian for a hinge). Joint values read the same in the URDF and
    in MuJoCo (the reader moved the URDF origin by ``ref``), so ranges and references are written as they are."""
    urdf = next((x for x in model.joints if x.name == name), None)
    if urdf is None:
        return
    hinge = int(m.jnt_type[j]) == scene.JNT_HINGE
    unit = per_rad if hinge else 1.0
    if urdf.dynamics is not None:
        set_joint_friction(joint, urdf.damping or 0.0, urdf.friction or 0.0)
        # the friction held without the no-slip pass, as the MJCF export holds it, at the host's time step
        joint.solref_friction = list(friction_solref(float(m.opt.timestep)))
        joint.solimp_friction = list(FRICTION_SOLIMP)
    dyn = overlay.joints.get(name)
    if dyn is not None:
        joint.stiffness = _with_first(joint.stiffness, float(dyn.stiffness))
        if dyn.stiffness > 0 and dyn.spring_reference is not None:
            joint.springref = float(dyn.spring_reference) * unit
    lim = urdf.limit
    if lim is not None and lim.lower is not None and lim.upper is not None and bool(m.jnt_limited[j]):
        joint.range = [float(lim.lower) * unit, float(lim.upper) * unit]


def _check(source: Path, original, written, mujoco, model, bodies: list[str]) -> None:
    """The written model keeps every body, joint, geom and site name and carries the refined masses."""
    before, after = _names(original, mujoco), _names(written, mujoco)
    if before != after:
        lost = {k: sorted(set(before[k]) ^ set(after[k])) for k in before if before[k] != after[k]}
        raise HostExportError(f"{source}: the refined host file changes names: {lost}")
    for name in bodies:
        b = mujoco.mj_name2id(written, mujoco.mjtObj.mjOBJ_BODY, name)
        if b < 0:  # an unnamed body: body_<id>
            b = int(name.removeprefix("body_"))
        want = float(model.links[name].inertial.mass)
        if not math.isclose(float(written.body_mass[b]), want, rel_tol=MASS_RTOL):
            raise HostExportError(f"{source}: body {name!r} weighs {float(written.body_mass[b]):.6g} kg in the host file, "
                                  f"not the refined {want:.6g} kg")


def write_patched_mjcf(source: Path, read: ReadAsset | None, children: dict[str, str], links: dict[str, LinkPhysics],
                       joints: dict[str, JointDynamics], folder: Path, staged_urdf: Path | None = None) -> Path:
    """The audit's patch of the MJCF file ``source``: MuJoCo's own writer (``MjSpec.to_xml``) in ``folder`` with the
    mass, center of mass and inertia tensor of ``links`` and the damping and friction of ``joints`` (SI, the asset
    model's link frames; ``children``: joint -> its child body), compiled from the sources staged when the input
    was read (:func:`~asset2sim.formats.mjcf.files.staged_sources` of ``staged_urdf``; else gathered once here under
    the reader policy), its meshes and textures written from those bytes; the input's paths are not opened again.
    ``read`` is not used (the table's writers share one signature). Returns the patched file.

    Raises:
        ImportError: MuJoCo is not installed.
        StagingError: a file the model names was not checked by the reader policy, or the model does not compile.
    """
    mujoco = load_mujoco()
    staged = staged_sources(staged_urdf) if staged_urdf is not None else None
    sources = staged[0] if staged is not None else gather_mjcf(source)  # only checked files inside the input's tree
    spec, model, _ = compile_mjcf(sources)
    base = source.parent
    meshdir, texdir = Path(spec.meshdir or ""), Path(spec.texturedir or "")
    for items, sub in ((spec.meshes, meshdir), (spec.hfields, meshdir), (spec.skins, meshdir), (spec.textures, texdir)):
        for item in items:
            if getattr(item, "file", ""):
                named = os.path.normpath(os.path.join(os.path.abspath(base), sub, item.file))
                real = sources.real.get(named)
                if real is None:  # gather_mjcf checked every file attribute; nothing else is copied
                    raise StagingError(f"{source}: {item.file!r} was not checked by the reader policy; not copied")
                item.file = copy_named(real, base, folder, data=sources.files[named])
    spec.meshdir = spec.texturedir = ""
    spec.modelfiledir = str(folder)  # MuJoCo resolves the copies' relative paths from the patch's folder
    if spec.compiler.inertiafromgeom == mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_TRUE:  # else explicit inertials would be ignored
        spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    bodies = {scene.label(model, b): b for b in range(1, model.nbody)}
    for name, lp in links.items():
        b = bodies[name]  # the link frame is the body frame moved to its joint's pos, if it has one hinge or slide
        n, adr = int(model.body_jntnum[b]), int(model.body_jntadr[b])
        offset = np.asarray(model.jnt_pos[adr], float) if n == 1 and model.jnt_type[adr] in (2, 3) else np.zeros(3)
        set_body_inertial(spec.bodies[b], lp.mass, lp.com, lp.inertia.matrix(), offset)
    for name, jd in joints.items():
        joint = next(j for j in spec.bodies[bodies[children[name]]].joints if j.type != mujoco.mjtJoint.mjJNT_FREE)
        set_joint_friction(joint, jd.damping, jd.friction)
    with mujoco_messages():
        spec.compile()
        xml = spec.to_xml()
    return atomic.write_text(folder / file_names.file_stem(source.name), xml)
