"""Paths of an output folder (:mod:`asset2sim.output_folder`): where it may
lie (:func:`check_location`), its bookkeeping files' names and kind, which
recorded relative paths are safe, and listing and removing entries inside
it without following a symlink out. Errors are :class:`OutputError`.
"""

from __future__ import annotations

import contextlib
import os
import stat
from pathlib import Path, PurePosixPath
from typing import Any, Iterable

from asset2sim import atomic

#: The completion marker and the ownership record of an output folder.
MARKER_NAME = ".asset2sim-complete.json"
RECORD_NAME = ".asset2sim-owned.json"


class OutputError(ValueError):
    """The output folder cannot be used or written as asked.

    ``code``: an ``OUTPUT_*`` code (``docs/guide/outputs.md``, "Exit statuses"; ``OUTPUT_INVALID`` when not
    given);
    ``path``: the file or folder concerned; ``codes``: ``[code]`` (the
    attribute ``refine`` copies into its error)."""

    def __init__(self, message: str, code: str = "OUTPUT_INVALID", path: Path | str | None = None):
        super().__init__(message)
        self.code = code
        self.path = None if path is None else Path(path)
        self.codes = [code]


#: Its public home: error records (``flows.isolation``'s ``error_type``) name it there.
OutputError.__module__ = "asset2sim.output_folder"


def _within(path: Path, root: Path) -> bool:
    """``path`` is ``root`` or lies under it (lexically)."""
    if isinstance(path, PurePosixPath) and isinstance(root, PurePosixPath) and path.is_absolute() == root.is_absolute():
        return path.parts[:len(root.parts)] == root.parts  # as below on POSIX (case-sensitive), without building parents
    return path == root or root in path.parents


def write_inside(path: Path | str, given: Path | str, root: Path | str, *aliases: Path | str) -> str | None:
    """The one output guard: where a destination ``path`` lies relative to an output folder the user named
    ``given`` (absolute, as given) whose real path is ``root`` (resolved); ``aliases``: other names of the folder
    (a staged run's final folder). The path is compared as given and as resolved: it belongs to the folder when it
    lies there by name (under ``given``, ``root`` or an alias) or when its folder resolves inside ``root``.

    Returns:
        Its relative path (POSIX) inside ``root`` (the folder holding it resolved), or None when it lies elsewhere
        both by name and resolved.

    Raises:
        OutputError: ``OUTPUT_SYMLINK_ESCAPES`` when it lies in the folder by name but a symlink on the way (the
            folder given, a subfolder such as ``views/``) leads it out of ``root``; ``OUTPUT_PATH_ESCAPES`` when it
            starts in the folder and leaves it through ``..``.
    """
    given, root = Path(os.path.abspath(given)), Path(root)
    bases = (given, root, *(Path(os.path.abspath(a)) for a in aliases))
    ap = Path(os.path.abspath(path))
    parent = ap.parent.resolve()
    parts = Path(path).parts
    if ".." in parts:
        head = Path(os.path.abspath(Path(*parts[: parts.index("..")])))
        if any(_within(head, base) for base in bases) and not _within(parent, root):
            raise OutputError(f"{path} would be written outside the output folder {given} (through '..')", "OUTPUT_PATH_ESCAPES", path)
    if _within(parent, root):
        return (parent / ap.name).relative_to(root).as_posix()
    if any(_within(ap, base) for base in bases):
        raise OutputError(f"{ap} would be written through a symlink to {parent}, outside the output folder {given}",
                          "OUTPUT_SYMLINK_ESCAPES", ap)
    return None


#: The codes of the output guard's refusals: never turned into a note by a writer that carries on.
ESCAPE_CODES = frozenset({"OUTPUT_SYMLINK_ESCAPES", "OUTPUT_PATH_ESCAPES"})


def raise_refusal(exc: BaseException) -> None:
    """Raise the output guard's refusal (an :class:`OutputError` with a code of :data:`ESCAPE_CODES`) when ``exc`` is
    one or holds one in its chain; return otherwise. A writer that turns its failures into notes calls this first."""
    refusal = next((c for c in exception_chain(exc) if isinstance(c, OutputError) and c.code in ESCAPE_CODES), None)
    if refusal is not None:
        raise refusal


def exception_chain(exc: BaseException) -> list[BaseException]:
    """``exc`` and its causes (else contexts), each once, outermost first (the last: what the libraries wrapped)."""
    out: list[BaseException] = []
    while exc is not None and all(exc is not e for e in out):
        out.append(exc)
        exc = exc.__cause__ or exc.__context__
    return out


def check_location(source_dir: Path | str, out_dir: Path | str) -> Path:
    """The resolved output folder ``out_dir`` (need not exist), refused where
    it would mix output and the input ``source_dir``.

    Raises:
        OutputError: ``OUTPUT_IS_INPUT``, ``OUTPUT_INSIDE_INPUT`` (also when a
            symlink on the way leads into the input), ``OUTPUT_CONTAINS_INPUT``,
            ``OUTPUT_NOT_A_FOLDER`` or ``OUTPUT_RECORD_NOT_A_FILE``.
    """
    given = Path(os.path.abspath(out_dir))
    out = given.resolve()
    src = Path(source_dir).resolve()
    src_lex = Path(os.path.abspath(source_dir))
    if out == src or given == src_lex:
        raise OutputError(f"output folder {given} is the input folder {src}; choose another", "OUTPUT_IS_INPUT", given)
    if _within(out, src) or _within(given, src_lex):
        via = "" if _within(given, src_lex) else f" (it resolves to {out} through a symlink)"
        raise OutputError(f"output folder {given} is inside the input folder {src}{via}; choose another", "OUTPUT_INSIDE_INPUT", given)
    if _within(src, out) or _within(src_lex, given):
        raise OutputError(f"output folder {given} contains the input folder {src}; choose a folder beside it", "OUTPUT_CONTAINS_INPUT", given)
    if os.path.lexists(given) and not out.is_dir():
        raise OutputError(f"output path {given} exists and is not a folder", "OUTPUT_NOT_A_FOLDER", given)
    if out.is_dir():
        check_bookkeeping(out)
    return out


def check_bookkeeping(out_dir: Path | str) -> None:
    """Refuse an output folder whose completion marker or ownership record
    exists but is not a regular file (``os.lstat``; symlinks refused too).

    Raises:
        OutputError: ``OUTPUT_RECORD_NOT_A_FILE`` naming the file.
    """
    for name in (MARKER_NAME, RECORD_NAME):
        p = Path(out_dir) / name
        try:
            mode = os.lstat(p).st_mode
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise OutputError(f"{p}: cannot be inspected ({exc.strerror})", "OUTPUT_RECORD_NOT_A_FILE", p) from exc
        if not stat.S_ISREG(mode):
            kind = _KINDS.get(stat.S_IFMT(mode), "special file")
            raise OutputError(
                f"{p}: a {kind}, not the regular file asset2sim writes there; remove it or choose another output folder",
                "OUTPUT_RECORD_NOT_A_FILE", p,
            )


_KINDS = {stat.S_IFDIR: "folder", stat.S_IFIFO: "FIFO", stat.S_IFLNK: "symlink", stat.S_IFCHR: "character device",
          stat.S_IFBLK: "block device", stat.S_IFSOCK: "socket"}


def _safe_rel(rel: Any) -> str | None:
    """A recorded relative path, or None when it is not one we could have
    written (absolute, empty, with ``..``): such entries are ignored."""
    if not isinstance(rel, str) or not rel or "\x00" in rel:
        return None
    p = PurePosixPath(rel)
    if p.is_absolute() or ".." in p.parts:
        return None
    return p.as_posix()


def _entries(root: Path) -> list[str]:
    """Relative POSIX paths of every non-folder entry under ``root``, symlinks
    to folders included (not entered)."""
    out: list[str] = []
    for folder, dirs, files in os.walk(root, followlinks=False):
        links = [name for name in dirs if (Path(folder) / name).is_symlink()]
        dirs[:] = [name for name in dirs if name not in links]
        out += [(Path(folder) / name).relative_to(root).as_posix() for name in files + links]
    return sorted(out)


def _unlink_inside(root: Path, rel: str) -> None:
    """Remove ``root/rel`` unless it is a folder or a symlink lies on the way (nothing when it is gone meanwhile or
    cannot be removed)."""
    target = root / rel
    with contextlib.suppress(OSError):
        if target.parent.resolve() == root / PurePosixPath(rel).parent and not (target.is_dir() and not target.is_symlink()):
            target.unlink()


def _remove_with_temps(root: Path, rel: str) -> None:
    _unlink_inside(root, rel)
    p = PurePosixPath(rel)
    folder = root / p.parent
    try:
        if folder.resolve() != folder or not folder.is_dir():
            return
        names = os.listdir(folder)
    except OSError:
        return
    for name in names:
        if atomic.is_temp_of(name, p.name):
            _unlink_inside(root, (p.parent / name).as_posix())


def _prune_empty(root: Path, rels: Iterable[str]) -> None:
    """Remove folders left empty by removing ``rels`` (never ``root``)."""
    # a folder before its parent (its parts start with the parent's)
    for p in sorted({p for rel in rels for p in PurePosixPath(rel).parents if p.parts}, reverse=True):
        d = root / p
        with contextlib.suppress(OSError):
            if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
                d.rmdir()
