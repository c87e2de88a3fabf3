"""The files an MJCF input names, checked and read before MuJoCo sees any of them, and MuJoCo given only those.

:func:`gather_mjcf` reads the ``<mujoco>`` file and every ``<include>`` (safe XML), takes ``<compiler meshdir
texturedir assetdir>`` and every attribute whose name starts with ``file`` (``<mesh file>``, ``<texture file
fileright ...>``, ``<hfield file>``, ``<skin file>``, ``<model file>``, ``<flexcomp file>`` ...), and resolves
each as MuJoCo does (relative to the model file's folder, through ``meshdir`` for meshes, skins and height
fields and ``texturedir`` for textures). Each must be a relative path that stays inside the input's tree (the
model file's folder), with every symlink resolved, or lie in a folder the user allowed
(:func:`asset2sim.input_files.allow_outside`, ``--allow-outside-paths``), and name a regular file under the size
cap; it is then read without blocking (:mod:`asset2sim.input_files`). A refusal is a
:class:`~asset2sim.formats.staging.StagingError` with a code:

- ``MJCF_PATH_ESCAPES``: an absolute path, a URI, ``../`` leaving the tree or a symlink out of it (in a file
  attribute, an include or ``meshdir`` / ``texturedir`` / ``assetdir``);
- ``INPUT_NOT_FOUND``, ``INPUT_NOT_REGULAR_FILE`` (a FIFO, device, socket or folder), ``INPUT_TOO_LARGE`` (a file
  above its cap, or what MuJoCo would build above :data:`MAX_TOTAL_BYTES` or :data:`MAX_BUILT_FACES`, counting every
  element that names a file: one mesh named 60 times is built 60 times),
  ``INPUT_OUTSIDE_TREE`` (the model file itself a symlink out of its folder), ``INPUT_UNREADABLE``;
- ``MJCF_INCLUDE_INVALID``: an include of itself (a loop), without a file, more than :data:`MAX_INCLUDES`
  includes or a chain deeper than :data:`MAX_INCLUDE_DEPTH`;
- ``XML_*``: the model file or an include is refused by the hardened XML parser.

:func:`compile_mjcf` then writes the bytes read into a private temporary folder, each file at its absolute path
mirrored below it, and lets MuJoCo (``MjSpec.from_file``) read that copy, so MuJoCo opens nothing but what was
checked; its warnings are collected, never written to ``MUJOCO_LOG.TXT``.
"""

from __future__ import annotations

import contextlib
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

from asset2sim import atomic, safexml
from asset2sim.engines.mjcf.base import load_mujoco, mujoco_messages
from asset2sim.extras import import_extra
from asset2sim.input_files import InputFileError, allowed_outside, inside, read_file
from asset2sim.formats.mjcf import conventions
from asset2sim.formats.staging import MAX_BUILT_FACES, SOURCE_DIR, StagingError, input_tree, read_of, read_snapshot, write_snapshot

__all__ = ["MAX_INCLUDES", "MAX_INCLUDE_DEPTH", "MAX_TOTAL_BYTES", "MjcfSources", "OpenedMjcf", "compile_mjcf", "gather_mjcf",
           "opened_mjcf", "staged_sources"]

#: Includes per model (MuJoCo refuses a repeated include; a chain deeper than this is refused too).
MAX_INCLUDES = 256
#: Deepest chain of includes.
MAX_INCLUDE_DEPTH = 16
#: Bytes of every file a model names together (each file: :data:`asset2sim.input_files.DEFAULT_MAX_BYTES`).
MAX_TOTAL_BYTES = 1024 * 1024 * 1024
#: Elements whose file attribute MuJoCo resolves through ``meshdir`` / ``texturedir``.
_MESHDIR_TAGS = frozenset({"mesh", "skin", "hfield"})
_TEXDIR_TAGS = frozenset({"texture"})
_URI = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]+:")
_DRIVE = re.compile(r"^[A-Za-z]:[\\/]")


@dataclass(frozen=True)
class MjcfSources:
    """Every file an MJCF model names, checked and read: ``files`` absolute normalized path (as MuJoCo resolves
    it from the model file) -> bytes, the model file's among them as ``main``; ``real`` the same keys -> the real
    path read (for the input hash and the audit's copies); ``tree`` the folder they lie in (or a folder
    :func:`~asset2sim.input_files.allow_outside` allows)."""

    path: Path
    tree: Path
    main: str
    files: dict[str, bytes]
    real: dict[str, Path]

    def snapshot(self, folder: Path | str, **extra: str | None) -> Path:
        """Write these sources into ``folder`` (a staged asset's own ``source/``: :func:`asset2sim.formats.staging.stage`
        calls this; :func:`~asset2sim.formats.staging.write_snapshot`), with the paths, each key's real path and
        ``extra`` (the angle unit it was read with). Returns ``folder``. Raises OSError."""
        return write_snapshot(folder, self.files, kind="mjcf", path=str(self.path), tree=str(self.tree), main=self.main,
                              real={k: str(v) for k, v in self.real.items()}, **extra)

    @classmethod
    def from_snapshot(cls, folder: Path | str) -> tuple["MjcfSources", dict]:
        """(the sources, the snapshot's other fields) written by :meth:`snapshot`, each file checked against its SHA-256.

        Raises:
            OSError: no snapshot there, or a file missing or not a regular file.
            ValueError: not an MJCF snapshot, or a file changed since.
        """
        files, meta = read_snapshot(folder)
        if meta.get("kind") != "mjcf":
            raise ValueError(f"{folder}: not a snapshot of MJCF sources")
        real = {k: Path(meta["real"][k]) for k in files}
        extra = {k: v for k, v in meta.items() if k not in ("kind", "path", "tree", "main", "real")}
        return cls(path=Path(meta["path"]), tree=Path(meta["tree"]), main=meta["main"], files=files, real=real), extra


def _refuse(code: str, message: str) -> StagingError:
    return StagingError(message, code=code)


def _resolve(value: str, base: str, tree: str, source: Path, what: str) -> str:
    """``value`` (as written) joined to the absolute folder ``base`` as MuJoCo joins it (an absolute ``value`` stays
    itself), normalized: an absolute path inside ``tree`` or a folder the user allowed
    (:func:`~asset2sim.input_files.allow_outside`).

    Raises:
        StagingError: ``MJCF_PATH_ESCAPES`` for a control character, a URI, an absolute path (unless allowed) or one
            leaving ``tree`` (lexically or through a symlink, unless into an allowed folder).
    """
    absolute = value.startswith(("/", "\\")) or bool(_DRIVE.match(value))
    joined = os.path.normpath(value if absolute else os.path.join(base, value))
    widen = " (--allow-outside-paths DIR widens this)"
    if any(ord(c) < 32 for c in value):  # NUL among them
        why = ": a control character in the path"
    elif _URI.match(value) and not _DRIVE.match(value):
        why = f": a URI; only relative paths inside {tree} are read"
    elif allowed_outside(joined):
        return joined
    elif absolute:
        why = f": an absolute path; only relative paths inside {tree} are read{widen}"
    elif not inside(joined, tree):
        why = f" resolves to {joined}, outside {tree}{widen}"
    elif not inside(real := os.path.realpath(joined), os.path.realpath(tree)):
        why = f" is a symlink (or under one) to {real}, outside {tree}"
    else:
        return joined
    raise _refuse("MJCF_PATH_ESCAPES", f"{source}: {what} {value!r}{why}")


class _Gather:
    def __init__(self, path: Path, tree: Path):
        self.path, self.tree = path, str(tree)
        self.files: dict[str, bytes] = {}
        self.real: dict[str, Path] = {}
        self.total = 0
        self.includes = 0
        self.compiler: dict[str, str] = {}
        self.refs: list[tuple[str, str, str, str]] = []  # (tag, attribute, value, file naming it)
        self.main = os.path.normpath(str(path))
        self.main_dir = os.path.dirname(self.main)

    def read(self, key: str, what: str) -> bytes:
        if key in self.files:
            return self.files[key]
        try:
            data = read_file(key, tree=self.tree, what=f"{self.path.name}: {what}")
        except InputFileError as exc:
            raise _refuse(exc.code, str(exc)) from None
        self.total += len(data)
        if self.total > MAX_TOTAL_BYTES:
            raise _refuse("INPUT_TOO_LARGE", f"{self.path}: the files it names exceed {MAX_TOTAL_BYTES} bytes together; not read")
        self.files[key], self.real[key] = data, Path(os.path.realpath(key))
        return data

    def document(self, key: str, what: str, depth: int, stack: tuple[str, ...] = ()) -> None:
        data = self.read(key, what)
        try:
            root = safexml.parse_xml_bytes(data, source=key)
        except safexml.SafeXMLError as exc:
            raise _refuse(exc.code, str(exc)) from None
        name = os.path.relpath(key, self.main_dir)
        for el in root.iter():
            tag = el.tag if isinstance(el.tag, str) else ""
            if tag == "include":
                self.includes += 1
                if self.includes > MAX_INCLUDES or depth >= MAX_INCLUDE_DEPTH:
                    raise _refuse("MJCF_INCLUDE_INVALID", f"{self.path}: more than {MAX_INCLUDES} includes, or nested deeper "
                                  f"than {MAX_INCLUDE_DEPTH}")
                value = el.get("file", "")
                if not value:
                    raise _refuse("MJCF_INCLUDE_INVALID", f"{self.path}: an <include> in {name} without a file")
                inc = _resolve(value, self.main_dir, self.tree, self.path, "<include file>")
                if inc in stack:
                    chain = " -> ".join(os.path.relpath(k, self.main_dir) for k in (*stack, inc))
                    raise _refuse("MJCF_INCLUDE_INVALID", f"{self.path}: <include file={value!r}> in {name} includes itself ({chain})")
                self.document(inc, f"<include file={value!r}>", depth + 1, (*stack, inc))
                continue
            if tag == "compiler":
                self.compiler.update({a: v for a in ("meshdir", "texturedir", "assetdir") if (v := el.get(a)) is not None})
            for attr, value in el.attrib.items():
                if attr.startswith("file") and value:
                    self.refs.append((tag, attr, value, name))

    def run(self) -> MjcfSources:
        self.document(self.main, "model file", 0, (self.main,))
        dirs = {attr: _resolve(value, self.main_dir, self.tree, self.path, f"<compiler {attr}>") if value else self.main_dir
                for attr in ("meshdir", "texturedir", "assetdir") if (value := self.compiler.get(attr)) is not None}
        meshdir = dirs.get("meshdir", dirs.get("assetdir", self.main_dir))
        texdir = dirs.get("texturedir", dirs.get("assetdir", self.main_dir))
        built_bytes = built_faces = 0
        faces_of: dict[str, int] = {}
        for tag, attr, value, where in self.refs:
            base = meshdir if tag in _MESHDIR_TAGS else texdir if tag in _TEXDIR_TAGS else self.main_dir
            key = _resolve(value, base, self.tree, self.path, f"<{tag} {attr}> in {where}")
            data = self.read(key, f"<{tag} {attr}={value!r}>")
            built_bytes += len(data)  # every element that names the file: MuJoCo builds each
            if tag == "mesh":
                if key not in faces_of:
                    faces_of[key] = mesh_faces(data, key)
                built_faces += faces_of[key]
            if built_bytes > MAX_TOTAL_BYTES:
                raise _refuse("INPUT_TOO_LARGE", f"{self.path}: the files its elements name come to more than {MAX_TOTAL_BYTES} "
                              "bytes as MuJoCo builds them (every element naming a file counts, a file named twice twice); not read")
            if built_faces > MAX_BUILT_FACES:
                raise _refuse("INPUT_TOO_LARGE", f"{self.path}: its <mesh> elements come to {built_faces} triangles or more as "
                              f"MuJoCo builds them (a file named twice counts twice) > cap {MAX_BUILT_FACES}; not compiled")
        return MjcfSources(path=self.path, tree=Path(self.tree), main=self.main, files=self.files, real=self.real)


def mesh_faces(data: bytes, name: str) -> int:
    """Triangles MuJoCo builds from the mesh file ``data`` (named ``name``, its suffix telling the format): a binary
    STL's count, an ASCII STL's facets, an OBJ's faces fanned (a face of k corners: k - 2), MuJoCo's ``.msh`` header;
    any other file its bytes over 50 (a binary STL's bytes per face). Reads nothing."""
    suffix = os.path.splitext(name)[1].lower()
    if suffix == ".stl":
        if len(data) >= 84 and 84 + 50 * int.from_bytes(data[80:84], "little") == len(data):
            return int.from_bytes(data[80:84], "little")
        return data.count(b"facet")
    if suffix == ".obj":
        return sum(max(0, len(line.split()) - 3) for line in data.splitlines() if line.startswith((b"f ", b"f\t")))
    if suffix == ".msh" and len(data) >= 16:
        return int.from_bytes(data[12:16], "little", signed=True)
    return len(data) // 50


def gather_mjcf(path: Path | str) -> MjcfSources:
    """Check and read the MJCF file at ``path`` (the ``<mujoco>`` file) and every file it names (module docstring);
    nothing else is opened. The references must stay in its package's asset folder for a file of a known package
    (:func:`~asset2sim.formats.mjcf.conventions.package_tree`, so Meta-World's ``../scene`` includes read), else in
    :func:`~asset2sim.formats.staging.input_tree`, the file's folder. Every reader of the file (extraction, the
    audit's patch, the host write-back) so reads the same files.

    Raises:
        StagingError: with ``code`` (module docstring), naming the file and the reference.
    """
    path = Path(os.path.abspath(str(path)))
    tree = conventions.package_tree(path)
    root = Path(os.path.abspath(str(tree))) if tree is not None else input_tree(path)
    return _Gather(path, root).run()


def _mirrored(tmp: str, path: str) -> str:
    """Where the private copy holds the file at the absolute ``path``: the same path under ``tmp``."""
    return os.path.join(tmp, os.path.splitdrive(path)[1].lstrip("/\\"))


class OpenedMjcf:
    """An MJCF model MuJoCo read from the private copy of its checked sources (:func:`opened_mjcf`): ``spec`` (the
    ``MjSpec``), ``model`` (compiled when opened), ``warnings`` (MuJoCo's, as notes); :meth:`compile` compiles the
    spec again (after edits) from the same copy, while the block that opened it runs."""

    def __init__(self, spec, folder: str, sources: MjcfSources, warnings: list[str]):
        self.spec, self.folder, self.sources, self.warnings = spec, folder, sources, warnings
        self.model = None

    def compile(self):
        """The spec compiled from the private copy (a file attribute or folder written absolute, in a folder the user
        allowed, pointed at its copy while compiling, then given back as written); returns the ``MjModel``.

        Raises:
            StagingError: MuJoCo cannot compile it (its message, naming the file).
        """
        # ImportError without MuJoCo, before anything is pointed at the copy
        load_mujoco()
        spec, tmp = self.spec, self.folder
        try:
            with mujoco_messages() as caught:
                written = []  # (object, attribute, value as written) pointed at the copy while compiling
                for obj, attr in ((spec, "meshdir"), (spec, "texturedir"),
                                  *((item, "file") for items in (spec.meshes, spec.textures, spec.hfields, spec.skins)
                                    for item in items)):
                    value = getattr(obj, attr, "") or ""
                    if os.path.isabs(value):
                        written.append((obj, attr, value))
                        setattr(obj, attr, _mirrored(tmp, os.path.normpath(value)))
                try:
                    model = spec.compile()
                finally:
                    for obj, attr, value in written:
                        setattr(obj, attr, value)
        except Exception as exc:  # mujoco raises ValueError with the compiler's message
            raise StagingError(f"{self.sources.path}: MuJoCo cannot read this MJCF: {_shown(exc, tmp)}") from exc
        self.warnings.extend(f"MuJoCo: {w}" for w in caught)
        return model


def _shown(exc: BaseException, tmp: str) -> str:
    return str(exc).replace(tmp + os.sep, "/").replace(tmp, ".")


@contextlib.contextmanager
def opened_mjcf(sources: MjcfSources, degree: bool | None = None) -> Iterator[OpenedMjcf]:
    """The model of checked ``sources`` read by MuJoCo from a private temporary copy holding only those files (each at
    its absolute path mirrored under the copy's folder), its angles read in degrees (``degree`` True) or radians
    (False) whatever its ``<compiler angle>`` says (None: as it says), compiled once; the copy lives while the block
    runs (edits to the spec compile again from it, :meth:`OpenedMjcf.compile`) and is removed after. Nothing is read
    from the input's own paths.

    Raises:
        MissingExtra (an ImportError): MuJoCo is not installed (the message names the extra, ``[mujoco]``).
        StagingError: MuJoCo cannot read or compile the model (its message, naming the file).
    """
    import_extra("mujoco", "reading MJCF")  # MissingExtra naming the extra when MuJoCo is not installed
    mujoco = load_mujoco()
    with tempfile.TemporaryDirectory(prefix="asset2sim-mjcf-") as tmp:
        for key, data in sources.files.items():
            atomic.write_bytes(_mirrored(tmp, key), data, durable=False)
        try:
            with mujoco_messages() as caught:
                spec = mujoco.MjSpec.from_file(_mirrored(tmp, sources.main))
        except Exception as exc:  # mujoco raises ValueError with the parser's message
            raise StagingError(f"{sources.path}: MuJoCo cannot read this MJCF: {_shown(exc, tmp)}") from exc
        if degree is not None:  # MuJoCo converts angles when compiling (range, euler, axisangle, ref, springref)
            spec.compiler.degree = degree
        opened = OpenedMjcf(spec, tmp, sources, [f"MuJoCo: {w}" for w in caught])
        opened.model = opened.compile()
        yield opened


def compile_mjcf(sources: MjcfSources, degree: bool | None = None):
    """(spec, compiled ``MjModel``, MuJoCo's warnings) of checked ``sources`` (:func:`opened_mjcf`); the private copy
    is removed before returning (the model holds what it needs; compile the spec again inside :func:`opened_mjcf`).

    Raises:
        MissingExtra (an ImportError): MuJoCo is not installed (the message names the extra, ``[mujoco]``).
        StagingError: MuJoCo cannot read or compile the model (its message, naming the file).
    """
    with opened_mjcf(sources, degree) as opened:
        return opened.spec, opened.model, list(opened.warnings)


def staged_sources(urdf_path: Path | str) -> tuple[MjcfSources, dict] | None:
    """The checked sources an MJCF input was staged from (the staged URDF ``urdf_path``: this process's read when it
    is still held, :func:`asset2sim.formats.staging.read_of`, else the snapshot in the staged folder), and what
    was recorded with them (``angle``: the unit its angles were read in); None when neither is at hand (not an
    MJCF input, or its staged folder is gone). Every later stage (the host write-back, the audit's patch) compiles
    from these, never from the input's paths."""
    read = read_of(urdf_path)
    if read is not None and isinstance(read.sources, MjcfSources):
        return read.sources, {"angle": read.angle_unit}
    try:
        return MjcfSources.from_snapshot(Path(urdf_path).parent / SOURCE_DIR)
    except (OSError, ValueError, KeyError, TypeError):
        return None
