"""The conventions an MJCF file is compiled with by the package it belongs to.

An MJCF object is often a fragment of a larger model: robosuite compiles
``robosuite/models/assets/objects/door.xml`` inside its world file
``robosuite/models/assets/base.xml``, whose ``<compiler angle="radian">``
applies to the object, while MuJoCo compiles the same file alone with its own
default, degrees. Read alone, the door's hinge range ``0 0.4`` (0.4 rad) would
become 0.4 degrees. :func:`mjcf_angle` decides the unit the file's angles are
read in, and says why, in this order:

1. the caller's override (``--mjcf-angle``, config ``mjcf.angle``);
2. the file's own ``<compiler angle>``, in the file or a file it includes
   (the last one MuJoCo reads wins, as in MuJoCo);
3. a known host package, from the folders the file lies in
   (:data:`HOST_LAYOUTS`);
4. a world file beside the file's folders that compiles them
   (``base.xml`` in an ancestor folder, robosuite's layout, stating
   ``<compiler angle>``);
5. MuJoCo's default, degrees.

The hosts' conventions, as their sources state them:

- robosuite: ``robosuite/models/assets/base.xml`` holds
  ``<compiler angle="radian" meshdir="meshes/"/>``; objects, arenas and
  robots are merged into it (``robosuite.models.base.MujocoXML``).
- RoboCasa and LIBERO build their scenes with robosuite's ``MujocoXML``
  classes, so robosuite's ``base.xml`` applies to their fixtures and objects.
- Meta-World: each scene file includes its ``*_dependencies.xml``, which
  states ``<compiler angle="radian">``; the object fragments
  (``assets/*.xml``, ``<mujocoinclude>``) are compiled through those.
- gymnasium-robotics' Franka Kitchen: the items' chains are included by
  ``kitchen_env_model.xml``, which states ``<compiler angle="radian">``.
- dm_control and MuJoCo Menagerie compile each model file as it is: the file's
  own ``<compiler>`` (most Menagerie models state radians), else MuJoCo's
  default, degrees.

Nothing here compiles the model; the files are only read (:mod:`asset2sim.safexml`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, Mapping

from asset2sim import safexml
from asset2sim.package_data import package_yaml

AngleUnit = Literal["radian", "degree"]
#: The angle units MJCF's ``<compiler angle>`` takes.
ANGLE_UNITS: tuple[str, ...] = ("radian", "degree")
#: MuJoCo's default angle unit of a file that does not state one (MuJoCo XML reference, ``compiler/angle``).
MUJOCO_DEFAULT_ANGLE: AngleUnit = "degree"
#: Most ``<include>`` files followed when looking for the file's own ``<compiler angle>``.
MAX_INCLUDES = 64
#: How many folders above the file are searched for a world file (:data:`WORLD_FILES`).
MAX_ANCESTORS = 4
#: World files that hosts compile their fragments inside (robosuite, RoboCasa, LIBERO: ``base.xml``).
WORLD_FILES: tuple[str, ...] = ("base.xml",)


@dataclass(frozen=True)
class HostLayout:
    """A package whose MJCF files are compiled with its conventions: ``folders`` consecutive folder names in the
    file's path (lower case) that mark it; ``angle`` the unit its fragments are compiled with (None: each file's
    own ``<compiler>``, else MuJoCo's default); ``why`` the source of that convention."""

    name: str
    folders: tuple[str, ...]
    angle: AngleUnit | None
    why: str


@dataclass(frozen=True)
class AngleConvention:
    """The angle unit an MJCF file's angles (joint ranges, ``euler``, ``axisangle``, ``springref``, ``ref``) are
    read in: ``unit``; ``source`` one of ``override``, ``file``, ``host``, ``world_file``, ``default``; ``host``
    the package recognised (or None); ``reason`` a sentence saying why."""

    unit: AngleUnit
    source: str
    host: str | None
    reason: str

    @property
    def note(self) -> str:
        """The line the reader's notes carry: ``angles in radians: <reason>``."""
        return f"angles read in {self.unit}s: {self.reason}"


@dataclass(frozen=True)
class ReadOptions:
    """How an input file is read: ``body`` the body (MJCF) whose subtree is the object when a scene holds several
    (``--body``, config ``body``); ``mjcf_angle`` the angle unit of an MJCF file, overriding what its place says
    (``--mjcf-angle``, config ``mjcf.angle``). The defaults read a file as its package compiles it."""

    body: str | None = None
    mjcf_angle: AngleUnit | None = None

    def __post_init__(self) -> None:
        _check_unit(self.mjcf_angle)


def _check_unit(unit: str | None) -> None:
    """ValueError: ``unit`` (an angle unit asked) is neither None, ``radian`` nor ``degree``."""
    if unit is not None and unit not in ANGLE_UNITS:
        raise ValueError(f"mjcf angle {unit!r}: expected one of {list(ANGLE_UNITS)}")


@dataclass(frozen=True)
class PhysicsOverride:
    """A host package whose code sets an object's joint physics when it builds a task, over what its file says:
    ``layout`` the :class:`HostLayout` name, ``files`` the object's file names, ``joints`` the joint names it sets,
    ``values`` attribute -> the value it sets (the file's units), ``how`` the call that sets them and ``keep`` how a
    user keeps the refined values."""

    layout: str
    files: tuple[str, ...]
    joints: tuple[str, ...]
    values: dict[str, float]
    how: str
    keep: str


_HOSTS = package_yaml(__package__, "hosts.yaml")
#: Known host packages, most specific first (``hosts.yaml`` beside this module, with the sources).
HOST_LAYOUTS: tuple[HostLayout, ...] = tuple(HostLayout(h["name"], tuple(h["folders"]), h["angle"], h["why"]) for h in _HOSTS["host_layouts"])
#: Host code that overrides an object's joint physics at run time (``hosts.yaml``, with the sources).
PHYSICS_OVERRIDES: tuple[PhysicsOverride, ...] = tuple(
    PhysicsOverride(**{**o, "files": tuple(o["files"]), "joints": tuple(o["joints"])}) for o in _HOSTS["physics_overrides"])


def physics_overrides(path: Path | str, joints: list[str]) -> list[tuple[PhysicsOverride, str]]:
    """The :data:`PHYSICS_OVERRIDES` that apply to the MJCF file at ``path`` (its host layout and file name), with
    the joint of ``joints`` (names as the file has them) each sets."""
    layout = host_layout(path)
    if layout is None:
        return []
    name = Path(path).name.lower()
    return [(o, j) for o in PHYSICS_OVERRIDES if o.layout == layout.name and name in o.files for j in joints if j in o.joints]


def _host_match(path: Path | str) -> tuple[HostLayout, Path] | None:
    """The first known host package (:data:`HOST_LAYOUTS`) whose folders the file at ``path`` lies in, and its asset
    folder (the innermost match of the layout's folders), or None."""
    parts = Path(os.path.abspath(path)).parent.parts
    lower = [p.lower() for p in parts]
    for layout in HOST_LAYOUTS:
        n = len(layout.folders)
        for i in range(len(lower) - n, -1, -1):  # the innermost match
            if tuple(lower[i:i + n]) == layout.folders:
                return layout, Path(*parts[:i + n])
    return None


def package_tree(path: Path | str) -> Path | None:
    """The asset folder of the known host package (:data:`HOST_LAYOUTS`) the MJCF at ``path`` lies in (the folder
    its layout's last folder name marks: ``.../metaworld/assets``, ``.../robosuite/models/assets``), the tree the
    files it names may come from (its packages' files include shared scenes and textures beside the object's
    folder: ``../scene/basic_scene.xml``, ``../textures``); None outside a known package (the file's own folder is
    the tree). The package's layout bounds it: nothing above that folder is read."""
    match = _host_match(path)
    return None if match is None else match[1]


def host_layout(path: Path | str) -> HostLayout | None:
    """The known host package (:data:`HOST_LAYOUTS`) whose folders the file at ``path`` lies in, or None."""
    match = _host_match(path)
    return None if match is None else match[0]


def _parsed(path: Path, files: Mapping[str, bytes] | None):
    """The XML root of ``path``: from ``files`` (absolute normalized path -> bytes already read under the reader
    policy) when given (None when it is not among them), else read from disk (regular files only)."""
    if files is None:
        return safexml.parse_xml_file(path)
    data = files.get(os.path.normpath(os.path.abspath(path)))
    return None if data is None else safexml.parse_xml_bytes(data, source=str(path))


def _element_compiler_angle(root, base: Path, top: Path, seen: set[str],
                            files: Mapping[str, bytes] | None = None) -> tuple[str | None, str | None]:
    """(last ``<compiler angle>`` value, the file stating it) in ``root`` and the files it includes, in document
    order; ``base`` the including file's folder, ``top`` the model file's folder (MuJoCo resolves includes against
    it; the including file's folder is tried first); ``files``: the checked files to read includes from (else the
    disk)."""
    found: tuple[str | None, str | None] = (None, None)
    for el in root.iter():
        tag = el.tag if isinstance(el.tag, str) else ""
        if tag == "compiler" and el.get("angle") is not None:
            found = (el.get("angle", "").strip().lower(), None)
        elif tag == "include" and el.get("file") and len(seen) < MAX_INCLUDES:
            name = el.get("file", "")
            for folder in (base, top):
                inc = Path(os.path.abspath(folder / name)) if not os.path.isabs(name) else Path(name)
                if (os.path.normpath(inc) in files) if files is not None else inc.is_file():
                    break
            else:
                continue
            key = os.path.realpath(inc)
            if key in seen:
                continue
            seen.add(key)
            try:
                # among ``files`` when given: found there above
                sub = _parsed(inc, files)
            except (safexml.SafeXMLError, OSError):  # an unreadable include: MuJoCo's compile reports it
                continue
            angle, where = _element_compiler_angle(sub, inc.parent, top, seen, files)
            if angle is not None:
                found = (angle, where or str(inc))
    return found


def file_compiler_angle(path: Path | str, files: Mapping[str, bytes] | None = None) -> tuple[AngleUnit | None, str | None]:
    """(the unit the file's own ``<compiler angle>`` states, the file stating it: ``path`` or an include), or
    (None, None) when neither the file nor its includes state one (or the value is not ``radian`` / ``degree``,
    which MuJoCo refuses when compiling). ``files``: the file and its includes as the reader policy read them
    (absolute normalized path -> bytes, :class:`~asset2sim.formats.mjcf.files.MjcfSources`), so nothing is read
    from disk again; None reads them from disk."""
    path = Path(path)
    try:
        root = _parsed(path, files)
    except (safexml.SafeXMLError, OSError):  # MuJoCo's compile reports an unreadable file with its own message
        return None, None
    if root is None:
        return None, None
    angle, where = _element_compiler_angle(root, path.parent, path.parent, {os.path.realpath(path)}, files)
    if angle not in ANGLE_UNITS:
        return None, None
    return angle, where or str(path)  # type: ignore[return-value]


def _world_file_angle(path: Path) -> tuple[AngleUnit | None, Path | None]:
    """(unit, file) of a world file (:data:`WORLD_FILES`) in one of the :data:`MAX_ANCESTORS` folders above
    ``path``'s folder that states ``<compiler angle>``; (None, None) when none does."""
    folder = Path(os.path.abspath(path)).parent
    for ancestor in list(folder.parents)[:MAX_ANCESTORS]:
        for name in WORLD_FILES:
            cand = ancestor / name
            if cand.is_file() and os.path.realpath(cand) != os.path.realpath(path):
                angle, _ = file_compiler_angle(cand)
                if angle is not None:
                    return angle, cand
    return None, None


def mjcf_angle(path: Path | str, override: AngleUnit | None = None, files: Mapping[str, bytes] | None = None) -> AngleConvention:
    """The angle unit the MJCF file at ``path`` is read in, and why (the order in the module's docstring); ``files``:
    the file and its includes as already read (:func:`file_compiler_angle`).

    Raises:
        ValueError: ``override`` is neither ``radian`` nor ``degree``.
    """
    path = Path(path)
    _check_unit(override)
    if override is not None:
        return AngleConvention(override, "override", None, f"asked (--mjcf-angle {override}, config mjcf.angle)")
    own, where = file_compiler_angle(path, files)
    if own is not None:
        shown = Path(where).name if where else path.name
        return AngleConvention(own, "file", None, f'the file states <compiler angle="{own}"> ({shown})')
    layout = host_layout(path)
    if layout is not None and layout.angle is not None:
        return AngleConvention(layout.angle, "host", layout.name,
                               f"a {layout.name} fragment without its own <compiler angle>: {layout.why}")
    world, world_path = _world_file_angle(path)
    if world is not None and world_path is not None:
        return AngleConvention(world, "world_file", None,
                               f'a fragment without its own <compiler angle>, below {world_path.parent.name}/{world_path.name}, '
                               f'the world file that compiles it, which states <compiler angle="{world}">')
    if layout is not None:
        return AngleConvention(MUJOCO_DEFAULT_ANGLE, "default", layout.name,
                               f"{layout.why}, and this file states no <compiler angle>: MuJoCo's default, degrees")
    return AngleConvention(MUJOCO_DEFAULT_ANGLE, "default", None,
                           "the file states no <compiler angle> and lies in no known host package: MuJoCo's default, degrees")
