"""The output folder owns only what it wrote.

An output folder of ``refine`` holds the files of the SPEC's contract, the
copied meshes and the extras, and possibly files of its user. This module
decides which files are the product's and keeps that record on disk:

- **where**: :func:`check_location` refuses an output folder that is the input
  folder, lies inside it, contains it, or resolves into it through symlinks,
  a path that exists but is not a folder (a file, ``/dev/null``), and a
  folder whose bookkeeping file (below) is not a regular file (a FIFO there
  would block the reader forever).
- **reading**: every file this module or the skip rule reads back from an
  output folder (the bookkeeping files, ``report.json``, ``overlay.json``) is
  read through :func:`asset2sim.atomic.read_regular`, which checks on the open
  descriptor that it is a regular file before reading: never a hang.
- **what is ours**: while a run writes, ``.asset2sim-owned.json`` lists every
  file the run is about to write (updated *before* each file's temporary file
  is created, through :func:`asset2sim.atomic.add_observer`), so a run killed
  at any moment leaves no file its successor does not know it owns. When the
  run finishes, the completion marker ``.asset2sim-complete.json`` lists the
  files with their sha256 and the ownership record is removed.
- **rewrite**: :func:`start` removes exactly the files a previous run recorded
  (and the temporary files of those), never anything else; a folder holding
  files the product did not write is refused unless ``overwrite=True`` (those
  files are then left alone unless the run writes the same path).
- **later writers**: ``evaluate``, ``export`` and ``render`` writing into a
  finished output folder record their files too (:func:`adopting`), so a
  later rewrite removes them and does not take them for a user's files.
- **finish**: :meth:`OwnedFolder.finish` writes the completion marker only when
  every file the run wrote exists (a write that failed, e.g. on a full disk,
  leaves no marker, so a rerun redoes the asset).
- **old or new**: a rerun over a *complete* earlier output (its marker is
  there and the folder holds nothing else) writes into a staging folder
  ``.<name>.asset2sim-next`` beside it and, once complete, swaps the two in
  one atomic rename (:func:`asset2sim.atomic.exchange_folders`); a run
  refused, failed or killed before that leaves the earlier output as it was
  (a killed run's staging folder is removed by the next run).

Errors are :class:`OutputError` with a ``code`` (``OUTPUT_*``) and the
``path`` concerned (:mod:`asset2sim.output_paths`, with the location check);
``tasks.assemble.write`` re-exports :class:`OutputError`.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import stat
import threading
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath
from typing import Any, Iterable, Iterator

from asset2sim import atomic
from asset2sim.output_paths import (
    MARKER_NAME,
    RECORD_NAME,
    OutputError,
    _entries,
    _prune_empty,
    _remove_with_temps,
    _safe_rel,
    _within,
    check_location,
)

#: The files and folders of an output folder (the SPEC's contract and the
#: extras), named here once; the writers and readers import them.
URDF_NAME = "mobility.urdf"
STATE_NAME = "initial_state.json"
OVERLAY_NAME = "overlay.json"
REPORT_NAME = "report.json"
EVALUATION_NAME = "evaluation.json"
REPORT_HTML_NAME = "report.html"
MJCF_DIR = "mjcf"
USD_DIR = "usd"
VIEWS_DIR = "views"
_BOOKKEEPING = frozenset({MARKER_NAME, RECORD_NAME})
_MAX_LISTED = 5
#: A bookkeeping file larger than this (bytes) is not one asset2sim wrote (a marker lists at most a few thousand files).
MAX_RECORD_BYTES = 64 * 1024 * 1024


def read_record(path: Path | str) -> Any:
    """The JSON of a bookkeeping file (or of ``report.json`` and the like) of
    an output folder, read only when it is a regular file of at most
    :data:`MAX_RECORD_BYTES` (:func:`asset2sim.atomic.read_regular`: a FIFO
    never blocks).

    Raises:
        OSError: missing, not a regular file, too large, unreadable.
        ValueError: not UTF-8 JSON.
    """
    return json.loads(atomic.read_regular(path, MAX_RECORD_BYTES).decode("utf-8"))


def recorded_files(out_dir: Path | str) -> set[str]:
    """Relative paths (POSIX) the product recorded as its own in ``out_dir``:
    the ownership record of an unfinished run plus the files of the completion
    marker. Unreadable records count as empty; unsafe entries are ignored."""
    out = Path(out_dir)
    owned: set[str] = set()
    for name, key in ((RECORD_NAME, "files"), (MARKER_NAME, "files")):
        try:
            data = read_record(out / name)
        except (OSError, ValueError):
            continue
        entries = data.get(key) if isinstance(data, dict) else None
        for rel in entries or []:
            safe = _safe_rel(rel)
            if safe is not None:
                owned.add(safe)
    return owned


def foreign_files(out_dir: Path | str, owned: Iterable[str] | None = None) -> list[str]:
    """Entries of ``out_dir`` the product did not write: not in ``owned``
    (default :func:`recorded_files`), not the bookkeeping files, not a
    temporary file of an owned path. Sorted relative paths."""
    root = Path(out_dir)
    if not root.is_dir():
        return []
    owned = set(recorded_files(root) if owned is None else owned)
    tmp_targets: dict[str, set[str]] = {}
    for rel in owned:
        p = PurePosixPath(rel)
        tmp_targets.setdefault(p.parent.as_posix(), set()).add(p.name)
    out = []
    for rel in _entries(root):
        if rel in owned or rel in _BOOKKEEPING:
            continue
        p = PurePosixPath(rel)
        names = tmp_targets.get(p.parent.as_posix(), set()) | (_BOOKKEEPING if p.parent.as_posix() == "." else set())
        if any(atomic.is_temp_of(p.name, t) for t in names):
            continue
        out.append(rel)
    return out


_ACTIVE: dict[Path, "OwnedFolder"] = {}
_ACTIVE_LOCK = threading.Lock()


def _dispatch(paths: list[Path]) -> None:
    """The atomic writer's observer: hands each destination to the owned
    folder it lies in."""
    with _ACTIVE_LOCK:
        owners = list(_ACTIVE.values())
    for owner in owners:
        owner._observe(paths)


@dataclass
class OwnedFolder:
    """An output folder during one run: ``root`` (resolved), ``given`` (as
    asked, absolute), ``source`` (the resolved input folder, None when not
    known) and ``files``,
    the relative paths this run has written or is writing."""

    root: Path
    given: Path
    source: Path | None
    files: set[str] = field(default_factory=set)
    created: bool = False
    #: the output folder a staged run replaces when it finishes (None: the run writes ``root`` in place)
    final: Path | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def _rel(self, path: Path) -> str | None:
        """Relative path of a destination inside this folder, or None when it
        lies elsewhere. Raises OutputError when it lies here by name but a
        symlink leads it out."""
        ap = Path(os.path.abspath(path))
        parent = ap.parent.resolve()
        self._refuse_dotdot_escape(Path(path), parent)
        if _within(parent, self.root):
            if self.source is not None and _within(parent, self.source):
                raise OutputError(f"{ap} would be written into the input folder {self.source}", "OUTPUT_SYMLINK_ESCAPES", ap)
            return (parent / ap.name).relative_to(self.root).as_posix()
        if _within(ap, self.given) or _within(ap, self.root):
            raise OutputError(
                f"{ap} would be written through a symlink to {parent}, outside the output folder {self.given}",
                "OUTPUT_SYMLINK_ESCAPES", ap,
            )
        return None

    def _refuse_dotdot_escape(self, path: Path, parent: Path) -> None:
        """Refuse a path that starts in this folder and leaves it through
        ``..`` (``out/collision/../../x.obj``, a name from an input used as a
        path): such a write never happens, whatever wrote it."""
        parts = path.parts
        if ".." not in parts:
            return
        head = Path(os.path.abspath(Path(*parts[: parts.index("..")]) if parts.index("..") else Path(".")))
        starts_here = any(_within(head, base) for base in (self.given, self.root) + ((self.final,) if self.final else ()))
        if starts_here and not _within(parent, self.root):
            raise OutputError(f"{path} would be written outside the output folder {self.given} (through '..')",
                              "OUTPUT_PATH_ESCAPES", path)

    def _observe(self, paths: list[Path]) -> None:
        new = []
        for p in paths:
            rel = self._rel(p)
            if rel is not None and rel not in _BOOKKEEPING and rel not in self.files:
                new.append(rel)
        if new:
            with self._lock:
                self.files.update(new)
                self._save()

    def _save(self) -> None:
        atomic.write_json(self.root / RECORD_NAME, {"version": 1, "files": sorted(self.files)})

    def record(self, paths: Iterable[Path | str]) -> None:
        """Record files of this folder as the run's own (absolute paths or
        paths relative to the folder) without writing them, e.g. copies kept
        because their content is already right."""
        self._observe([p if Path(p).is_absolute() else self.root / p for p in paths])

    def remove_unreferenced(self, folder: str, keep: Iterable[str]) -> list[str]:
        """Remove the files this run wrote under ``folder`` (relative, e.g.
        ``collision``) that are not in ``keep`` (relative paths). Files it did
        not write are never touched. Returns the removed relative paths."""
        prefix = PurePosixPath(folder).as_posix().rstrip("/") + "/"
        keep = {PurePosixPath(k).as_posix() for k in keep}
        gone = [rel for rel in sorted(self.files) if rel.startswith(prefix) and rel not in keep]
        for rel in gone:
            _remove_with_temps(self.root, rel)
        with self._lock:
            self.files.difference_update(gone)
            self._save()
        _prune_empty(self.root, gone)
        return gone

    def finish(self, marker: dict[str, Any]) -> dict[str, str]:
        """Write the completion marker: ``marker`` plus ``files`` (relative
        path -> sha256 of every file this run wrote), then drop the ownership
        record. Stops observing writes.

        Raises:
            OutputError: ``OUTPUT_INCOMPLETE`` when a file the run wrote is
                missing (e.g. its write failed on a full disk); no marker is
                written, the ownership record stays.
        """
        try:
            missing = sorted(rel for rel in self.files if not (self.root / rel).is_file())
            if missing:
                raise OutputError(
                    f"{self.given}: {len(missing)} file(s) the run wrote are missing ({', '.join(missing[:_MAX_LISTED])}); "
                    "the output is incomplete, no completion marker written",
                    "OUTPUT_INCOMPLETE", self.given / missing[0],
                )
            hashes = {rel: atomic.sha256_file(self.root / rel) for rel in sorted(self.files)}
            atomic.write_json(self.root / MARKER_NAME, {**marker, "files": hashes})
            (self.root / RECORD_NAME).unlink(missing_ok=True)
        finally:
            self.close()
        if self.final is not None:
            self._swap_in()
        return hashes

    def _swap_in(self) -> None:
        """A staged run, complete: exchange the staging folder with the earlier
        output, then delete the earlier output (now at the staging path).

        Raises:
            OutputError: ``OUTPUT_WRITE_FAILED`` when the exchange fails (the
                earlier output is then untouched).
        """
        staging, final = self.root, self.final
        try:
            atomic.exchange_folders(staging, final)
        except OSError as exc:
            shutil.rmtree(staging, ignore_errors=True)
            raise _write_failed(self.given, exc) from exc
        shutil.rmtree(staging, ignore_errors=True)
        self.root, self.final = final, None

    def write_path(self, path: Path | str) -> Path:
        """Where this run writes ``path`` (a path in the output folder as the
        user named it): the same path for a run in place, its counterpart in
        the staging folder for a staged run."""
        if self.final is None:
            return Path(path)
        ap = Path(os.path.abspath(path))
        for base in (self.given, self.final):
            if _within(ap, base):
                return self.root / ap.relative_to(base)
        return Path(path)

    def abandon(self) -> None:
        """End a run that failed or was refused: stop observing writes, remove
        the files it wrote (with their temporary files), the ownership record
        and the folder when this run created it and it is left empty, so the
        folder holds what it held before the run (a staged run's earlier
        output was never touched). A file that cannot be removed stays
        recorded for the next run."""
        self.close()
        if self.final is not None:  # staged: the earlier output was never touched
            shutil.rmtree(self.root, ignore_errors=True)
            return
        for rel in sorted(self.files):
            _remove_with_temps(self.root, rel)
        _prune_empty(self.root, self.files)
        self.files = {rel for rel in self.files if os.path.lexists(self.root / rel)}
        if self.files:
            self._save()
        else:
            (self.root / RECORD_NAME).unlink(missing_ok=True)
            if self.created:
                try:
                    self.root.rmdir()
                except OSError:  # not empty: someone else's file appeared
                    pass

    def close(self) -> None:
        """Stop observing writes (the ownership record stays on disk)."""
        with _ACTIVE_LOCK:
            if _ACTIVE.get(self.root) is self:
                del _ACTIVE[self.root]
            if not _ACTIVE:
                atomic.remove_observer(_dispatch)


def start(source_dir: Path | str, out_dir: Path | str, *, overwrite: bool = False) -> OwnedFolder:
    """Begin a (re)write of ``out_dir`` for the asset in ``source_dir``.

    Checks the location (:func:`check_location`), refuses files the product
    did not write unless ``overwrite``, then removes the completion marker and
    every file a previous run recorded (with their temporary files), and from
    here on records every atomic write into the folder (any thread of this
    process) until :meth:`OwnedFolder.finish` or :meth:`OwnedFolder.close`.

    Raises:
        OutputError: a refused location, ``OUTPUT_NOT_EMPTY`` naming the
            first files the product did not write, or ``OUTPUT_WRITE_FAILED``
            when the folder cannot be created or written.
    """
    root = check_location(source_dir, out_dir)
    given = Path(os.path.abspath(out_dir))
    src = Path(source_dir).resolve()
    created = not root.is_dir()
    if not created:
        previous = recorded_files(root)
        foreign = foreign_files(root, previous)
        if foreign and not overwrite:
            raise OutputError(
                f"output folder {given} holds {len(foreign)} file(s) asset2sim did not write "
                f"({', '.join(foreign[:_MAX_LISTED])}{', ...' if len(foreign) > _MAX_LISTED else ''}); "
                "choose an empty or new folder, or allow writing beside them",
                "OUTPUT_NOT_EMPTY", given / foreign[0],
            )
        staged = _start_staged(root, given, src, previous, foreign)
        if staged is not None:
            return staged
    else:
        previous = set()
        try:
            root.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise _write_failed(given, exc) from exc
        root = root.resolve()
    owner = OwnedFolder(root=root, given=given, source=src, created=created)
    try:
        if previous:
            # claim first, so a kill during the removal leaves them recorded
            atomic.write_json(root / RECORD_NAME, {"version": 1, "files": sorted(previous)})
        (root / MARKER_NAME).unlink(missing_ok=True)
        for rel in sorted(previous):
            _remove_with_temps(root, rel)
        _prune_empty(root, previous)
        owner._save()
    except OSError as exc:
        raise _write_failed(given, exc) from exc
    with _ACTIVE_LOCK:
        _ACTIVE[root] = owner
        atomic.add_observer(_dispatch)
    return owner


STAGING_SUFFIX = ".asset2sim-next"


def staging_folder(root: Path) -> Path:
    """The staging folder of output folder ``root``: ``.<name>.asset2sim-next`` beside it."""
    return root.parent / f".{root.name}{STAGING_SUFFIX}"


def _complete(root: Path) -> bool:
    """``root`` holds a readable completion marker listing files."""
    try:
        data = read_record(root / MARKER_NAME)
    except (OSError, ValueError):
        return False
    return isinstance(data, dict) and isinstance(data.get("files"), dict)


def _start_staged(root: Path, given: Path, src: Path, previous: set[str], foreign: list[str]) -> "OwnedFolder | None":
    """A rerun over a complete earlier output that holds only the product's
    files: an :class:`OwnedFolder` writing a fresh staging folder beside it
    (swapped in by :meth:`OwnedFolder.finish`). None when the folder is not
    such an output, or no staging folder can be made beside it (e.g. a
    read-only parent): then the run rewrites the folder in place.

    Raises:
        OutputError: ``OUTPUT_NAME_CONFLICT`` when the staging path is taken
            by something asset2sim did not make (a file, a symlink, a folder
            of other files).
    """
    if foreign or not previous or not _complete(root):
        return None
    staging = staging_folder(root)
    if os.path.lexists(staging):
        ours = staging.is_dir() and not staging.is_symlink() and (
            not any(staging.iterdir()) or any((staging / n).exists() for n in _BOOKKEEPING))
        if not ours:
            raise OutputError(f"{staging} (the staging folder of {given}) exists and is not asset2sim's; remove it",
                              "OUTPUT_NAME_CONFLICT", staging)
        shutil.rmtree(staging)  # a killed run's leftovers
    try:
        staging.mkdir(mode=stat.S_IMODE(root.stat().st_mode))
    except OSError:
        return None
    owner = OwnedFolder(root=staging.resolve(), given=given, source=src, created=True, final=root)
    try:
        owner._save()
    except OSError as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise _write_failed(given, exc) from exc
    with _ACTIVE_LOCK:
        _ACTIVE[owner.root] = owner
        atomic.add_observer(_dispatch)
    return owner


def _write_failed(given: Path, exc: OSError) -> OutputError:
    """``OUTPUT_WRITE_FAILED`` for an OSError met while preparing the folder."""
    where = exc.filename or given
    return OutputError(f"output folder {given} cannot be created or written ({exc.strerror or exc})", "OUTPUT_WRITE_FAILED", where)


def product_folder(path: Path | str) -> Path | None:
    """The output folder of asset2sim that ``path`` is (or lies in): the
    nearest folder, ``path`` included, holding a completion marker or an
    ownership record; None when there is none."""
    p = Path(os.path.abspath(path))
    for folder in (p, *p.parents):
        if (folder / MARKER_NAME).is_file() or (folder / RECORD_NAME).is_file():
            return folder.resolve()
    return None


@contextlib.contextmanager
def adopting(path: Path | str) -> Iterator[OwnedFolder | None]:
    """While the block runs, every atomic write into the asset2sim output
    folder around ``path`` (:func:`product_folder`) is added to its ownership
    record (before the file is created), so a later rewrite removes it
    instead of refusing the folder. Nothing happens when ``path`` is not in
    such a folder. Yields the :class:`OwnedFolder` or None."""
    root = product_folder(path)
    if root is None:
        yield None
        return
    try:
        data = read_record(root / RECORD_NAME)
        files = {r for r in (_safe_rel(x) for x in data.get("files", [])) if r is not None}
    except (OSError, ValueError, AttributeError):
        files = set()
    owner = OwnedFolder(root=root, given=root, source=None, files=files)
    with _ACTIVE_LOCK:
        previous = _ACTIVE.get(root)
        _ACTIVE[root] = owner
        atomic.add_observer(_dispatch)
    try:
        yield owner
    finally:
        with _ACTIVE_LOCK:
            if previous is not None:
                _ACTIVE[root] = previous
            elif _ACTIVE.get(root) is owner:
                del _ACTIVE[root]
            if not _ACTIVE:
                atomic.remove_observer(_dispatch)
