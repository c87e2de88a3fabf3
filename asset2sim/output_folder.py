"""The output folder owns only what it wrote.

:func:`start` begins a (re)write of an output folder: it checks the location
(:func:`check_location`), removes exactly the files an earlier run recorded,
refuses other files unless ``overwrite``, and records every atomic write in
``.asset2sim-owned.json`` before the file is created. :meth:`OwnedFolder.finish`
writes the completion marker ``.asset2sim-complete.json`` (the files with their
sha256); a rerun over a complete output writes a staging folder and swaps it
in. :func:`adopting` records the files later writers add. Bookkeeping files
are read through :func:`read_record` (regular files only). Errors are
:class:`OutputError` (``code`` ``OUTPUT_*``, ``path``).
"""

from __future__ import annotations

import contextlib
import json
import os
import posixpath
import shutil
import stat
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Iterator

from asset2sim import atomic
from asset2sim.output_paths import (MARKER_NAME, RECORD_NAME, OutputError, _entries, _prune_empty, _remove_with_temps, _safe_rel,
                                    _within, check_location, write_inside)
from asset2sim.output_staging import _BOOKKEEPING, is_staging_folder, remove_stale, staging_folder, try_lock

#: The files and folders of an output folder (the SPEC's contract and the extras).
URDF_NAME = "mobility.urdf"
STATE_NAME = "initial_state.json"
OVERLAY_NAME = "overlay.json"
REPORT_NAME = "report.json"
EVALUATION_NAME = "evaluation.json"
REPORT_HTML_NAME = "report.html"
MJCF_DIR = "mjcf"
USD_DIR = "usd"
VIEWS_DIR = "views"
CLIPS_DIR = "clips"
TIMINGS_NAME = "timings.json"
#: Files an output owns whose bytes differ from run to run (wall times): listed in the completion marker under
#: ``unhashed``, never hashed, so two runs of the same input and code write byte-identical hashed files and markers.
VOLATILE = frozenset({TIMINGS_NAME})
_MAX_LISTED = 5
#: A bookkeeping file larger than this (bytes) is not one asset2sim wrote (a marker lists at most a few thousand files).
MAX_RECORD_BYTES = 64 * 1024 * 1024


def read_record(path: Path | str) -> Any:
    """The JSON of a file of an output folder, read only when it is a regular file of at most
    :data:`MAX_RECORD_BYTES`. Raises OSError (missing, not a regular file, too large) or ValueError (not UTF-8 JSON)."""
    return json.loads(atomic.read_regular(path, MAX_RECORD_BYTES).decode("utf-8"))


def record_or_none(path: Path | str) -> Any:
    """:func:`read_record` of ``path``, or None when it cannot be read (missing, not a regular file, too large, not
    UTF-8 JSON)."""
    try:
        return read_record(path)
    except (OSError, ValueError):
        return None


def merge_timings(out_dir: Path | str, timings: dict[str, Any]) -> Path:
    """Add ``timings`` (JSON values: wall times, s) to ``out_dir/timings.json`` (:data:`VOLATILE`), keeping its other
    entries (an unreadable file is replaced); returns its path."""
    path = Path(out_dir) / TIMINGS_NAME
    old = record_or_none(path)
    return atomic.write_json(path, {**(old if isinstance(old, dict) else {}), **timings})


def _listed(path: Path) -> set[str]:
    """The safe relative paths the ``files`` (and ``unhashed``) of bookkeeping file ``path`` list (none when
    unreadable)."""
    data = record_or_none(path)
    if not isinstance(data, dict):
        return set()
    entries = [*(data.get("files") or []), *(data.get("unhashed") or [])]
    return {r for r in map(_safe_rel, entries) if r is not None}


def recorded_files(out_dir: Path | str) -> set[str]:
    """Relative paths (POSIX) the ownership record and the completion marker of ``out_dir`` list; unreadable
    records count as empty, unsafe entries are ignored."""
    return _listed(Path(out_dir) / RECORD_NAME) | _listed(Path(out_dir) / MARKER_NAME)


def foreign_files(out_dir: Path | str, owned: Iterable[str] | None = None) -> list[str]:
    """Sorted relative paths of ``out_dir`` the product did not write: not in ``owned`` (default
    :func:`recorded_files`), not bookkeeping, not a temporary file of an owned path."""
    root = Path(out_dir)
    owned = set(recorded_files(root) if owned is None else owned)
    tmp_targets: dict[str, set[str]] = {"": set(_BOOKKEEPING)}  # folder -> the names whose temporary files it may hold
    for folder, name in map(posixpath.split, owned):
        tmp_targets.setdefault(folder, set()).add(name)
    return [rel for rel in _entries(root) if rel not in owned and rel not in _BOOKKEEPING
            and not any(atomic.is_temp_of(posixpath.basename(rel), t) for t in tmp_targets.get(posixpath.dirname(rel), ()))]


_ACTIVE: dict[Path, "OwnedFolder"] = {}
_ACTIVE_LOCK = threading.Lock()


_GUARDS: list[tuple[Path, Path]] = []  # (a guarded folder as given, absolute; its real folder)


def _observe(root: Path, owner: "OwnedFolder") -> "OwnedFolder | None":
    """Record the atomic writes into ``root`` in ``owner`` (:func:`_dispatch`); returns the owner it replaces."""
    with _ACTIVE_LOCK:
        previous = _ACTIVE.get(root)
        _ACTIVE[root] = owner
        atomic.add_observer(_dispatch)
    return previous


def _stop_observing_if_idle() -> None:
    """Drop :func:`_dispatch` from the atomic writer's observers when no folder is owned or guarded (under
    ``_ACTIVE_LOCK``)."""
    if not _ACTIVE and not _GUARDS:
        atomic.remove_observer(_dispatch)


def _dispatch(paths: list[Path]) -> None:
    """The atomic writer's observer: hands each destination to the guarded and the owned folders (either may
    refuse it)."""
    with _ACTIVE_LOCK:
        guards, owners = list(_GUARDS), list(_ACTIVE.values())
    for given, root in guards:
        for path in paths:
            write_inside(path, given, root)
    for owner in owners:
        owner._observe(paths)


@contextlib.contextmanager
def guarding(folder: Path | str) -> Iterator[Path]:
    """While the block runs, refuse every atomic write (:mod:`asset2sim.atomic`, any thread of this process) that
    lies in ``folder`` by name (as given or resolved) but leaves it through a symlink (``folder/views`` a symlink
    elsewhere) or ``..``: the one output guard (:func:`~asset2sim.output_paths.write_inside`) for writers that keep
    no ownership record (``audit``, ``judge``, ``rate``, ``pairs``, the host write-backs, a flow's run folder).
    ``folder`` itself may be a symlink (followed: its real folder is the output). Yields the real folder.

    Raises (from the write, which is then not made):
        OutputError: ``OUTPUT_SYMLINK_ESCAPES`` or ``OUTPUT_PATH_ESCAPES``.
    """
    guard = (Path(os.path.abspath(folder)), Path(os.path.realpath(folder)))
    with _ACTIVE_LOCK:
        _GUARDS.append(guard)
        atomic.add_observer(_dispatch)
    try:
        yield guard[1]
    finally:
        with _ACTIVE_LOCK:
            _GUARDS.remove(guard)
            _stop_observing_if_idle()


def check_destination(path: Path | str, folder: Path | str) -> Path:
    """``path`` (a file a writer opens itself, not through :mod:`asset2sim.atomic`: a database) checked by the one
    output guard against ``folder`` (:func:`guarding`), and refused when it is a symlink or a hard link (itself, or a
    file a library creates beside it, such as SQLite's ``-wal``): a write in place would change the file it shares
    its bytes with, outside the folder; returns ``path``. (An atomic write replaces a link instead.)

    Raises:
        OutputError: ``OUTPUT_SYMLINK_ESCAPES``, ``OUTPUT_HARD_LINK``.
    """
    path = Path(path)
    if write_inside(path, folder, Path(os.path.realpath(folder))) is None:
        raise OutputError(f"{path} lies outside the folder {folder}", "OUTPUT_SYMLINK_ESCAPES", path)
    for p in (path, *(path.with_name(path.name + suffix) for suffix in ("-wal", "-shm", "-journal"))):
        if p.is_symlink():
            raise OutputError(f"{p} is a symlink (to {os.path.realpath(p)}); asset2sim writes its own file there: remove it",
                              "OUTPUT_SYMLINK_ESCAPES", p)
        if p.is_file() and p.stat().st_nlink > 1:
            raise OutputError(f"{p} is a hard link of another file ({p.stat().st_nlink} names); asset2sim writes its own "
                              "file there: remove it or copy it", "OUTPUT_HARD_LINK", p)
    return path


@dataclass
class OwnedFolder:
    """An output folder during one run: ``root`` (resolved), ``given`` (as asked, absolute), ``source`` (the
    resolved input folder, None when not known) and ``files``, the relative paths this run writes."""

    root: Path
    given: Path
    source: Path | None
    files: set[str] = field(default_factory=set)
    created: bool = False
    #: the output folder a staged run replaces when it finishes (None: the run writes ``root`` in place)
    final: Path | None = None
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    #: a staged run's descriptor of its staging folder, holding the lock that tells a later run it is live
    _held: int | None = field(default=None, repr=False)
    #: the files of an earlier output this run replaces (relative paths; removed now, or when a staged run finishes)
    replaced: tuple[str, ...] = ()

    def _remove_staging(self) -> None:
        """Remove a staged run's staging folder (``root``), then release the lock its descriptor holds."""
        shutil.rmtree(self.root, ignore_errors=True)
        if self._held is not None:
            with contextlib.suppress(OSError):
                os.close(self._held)
            self._held = None

    def _rel(self, path: Path) -> str | None:
        """Relative path of a destination inside this folder, or None when it lies elsewhere
        (:func:`~asset2sim.output_paths.write_inside`, the one output guard). Raises OutputError when it lies here by
        name but a symlink or ``..`` leads it out, or into the input folder."""
        rel = write_inside(path, self.given, self.root, *((self.final,) if self.final else ()))
        if rel is not None and self.source is not None and _within(self.root / rel, self.source):
            ap = Path(os.path.abspath(path))
            raise OutputError(f"{ap} would be written into the input folder {self.source}", "OUTPUT_SYMLINK_ESCAPES", ap)
        return rel

    def _observe(self, paths: list[Path]) -> None:
        new = [rel for p in paths if (rel := self._rel(p)) is not None and rel not in _BOOKKEEPING and rel not in self.files]
        if new:
            with self._lock:
                self.files.update(new)
                self._save()

    def _save(self) -> None:
        # rewritten before each new file, without fsync: it is for a killed run's clean-up; after a crash of the
        # machine a file it missed is foreign to the next run, which then refuses rather than deletes it
        atomic.write_json(self.root / RECORD_NAME, {"version": 1, "files": sorted(self.files)}, durable=False)

    def finish(self, marker: dict[str, Any]) -> dict[str, str]:
        """Write the completion marker: ``marker`` plus ``files`` (relative path -> sha256 of every file this
        run wrote but the :data:`VOLATILE` ones, listed under ``unhashed``), drop the ownership record, stop observing writes, and swap a staged run in.

        Raises:
            OutputError: ``OUTPUT_INCOMPLETE`` when a file the run wrote is missing (no marker is written), or
                ``OUTPUT_WRITE_FAILED`` when a staged run cannot be swapped in.
        """
        try:
            missing = sorted(rel for rel in self.files if not (self.root / rel).is_file())
            if missing:
                raise OutputError(f"{self.given}: {len(missing)} file(s) the run wrote are missing ({', '.join(missing[:_MAX_LISTED])}); "
                                  "the output is incomplete, no completion marker written", "OUTPUT_INCOMPLETE", self.given / missing[0])
            hashes = {rel: atomic.sha256_file(self.root / rel) for rel in sorted(self.files) if rel not in VOLATILE}
            unhashed = sorted(rel for rel in self.files if rel in VOLATILE)
            atomic.write_json(self.root / MARKER_NAME, {**marker, "files": hashes, **({"unhashed": unhashed} if unhashed else {})})
            (self.root / RECORD_NAME).unlink(missing_ok=True)
        finally:
            self.close()
        if self.final is not None:  # exchange the staging folder with the earlier output, then delete that
            try:
                atomic.exchange_folders(self.root, self.final)
            except OSError as exc:
                self._remove_staging()
                raise _write_failed(self.given, exc) from exc
            self._remove_staging()
            self.root, self.final = self.final, None
        return hashes

    def write_path(self, path: Path | str) -> Path:
        """Where this run writes ``path`` (named in the output folder as given): its counterpart in the staging
        folder for a staged run."""
        if self.final is None:
            return Path(path)
        ap = Path(os.path.abspath(path))
        for base in (self.given, self.final):
            if _within(ap, base):
                return self.root / ap.relative_to(base)
        return Path(path)

    def abandon(self) -> None:
        """End a run that failed or was refused: stop observing writes and remove what it wrote (the
        staging folder, or its files, the ownership record and the folder it created); a file that cannot be
        removed stays recorded."""
        self.close()
        if self.final is not None:
            self._remove_staging()
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
                with contextlib.suppress(OSError):  # not empty: someone else's file appeared
                    self.root.rmdir()

    def close(self) -> None:
        """Stop observing writes (the ownership record stays on disk)."""
        with _ACTIVE_LOCK:
            if _ACTIVE.get(self.root) is self:
                del _ACTIVE[self.root]
            _stop_observing_if_idle()


def start(source_dir: Path | str, out_dir: Path | str, *, overwrite: bool = False) -> OwnedFolder:
    """Begin a (re)write of ``out_dir`` for the asset in ``source_dir`` (module docstring); records every
    atomic write into the folder until :meth:`OwnedFolder.finish` or :meth:`OwnedFolder.close`.

    Raises:
        OutputError: a refused location, ``OUTPUT_NOT_EMPTY`` naming the first files the product did not
            write, ``OUTPUT_NAME_CONFLICT`` (staging path taken) or ``OUTPUT_WRITE_FAILED``.
    """
    root = check_location(source_dir, out_dir)
    given = Path(os.path.abspath(out_dir))
    src = Path(source_dir).resolve()
    created = not root.is_dir()
    if not created:
        previous = recorded_files(root)
        foreign = foreign_files(root, previous)
        if foreign and not overwrite:
            raise OutputError(f"output folder {given} holds {len(foreign)} file(s) asset2sim did not write "
                              f"({', '.join(foreign[:_MAX_LISTED])}{', ...' if len(foreign) > _MAX_LISTED else ''}); "
                              "choose an empty or new folder, or allow writing beside them", "OUTPUT_NOT_EMPTY", given / foreign[0])
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
    owner = OwnedFolder(root=root, given=given, source=src, created=created, replaced=tuple(sorted(previous)))
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
    _observe(root, owner)
    return owner


def _start_staged(root: Path, given: Path, src: Path, previous: set[str], foreign: list[str]) -> "OwnedFolder | None":
    """An :class:`OwnedFolder` writing a fresh staging folder beside a complete output holding only the
    product's files; None (rewrite in place) when it is not one or no staging folder can be made. Raises
    ``OUTPUT_NAME_CONFLICT`` when the staging path is taken by something asset2sim did not make."""
    if foreign or not previous:
        return None
    marker = record_or_none(root / MARKER_NAME)
    if not (isinstance(marker, dict) and isinstance(marker.get("files"), dict)):  # not a complete output
        return None
    staging = staging_folder(root)
    if os.path.lexists(staging):
        if not is_staging_folder(staging):
            raise OutputError(f"{staging} (the staging folder of {given}) exists and is not asset2sim's; remove it",
                              "OUTPUT_NAME_CONFLICT", staging)
        if not remove_stale(staging):
            raise OutputError(f"{staging} (the staging folder of {given}) is being written by another run; wait for it to end",
                              "OUTPUT_NAME_CONFLICT", staging)
    try:
        staging.mkdir(mode=stat.S_IMODE(root.stat().st_mode))
    except OSError:
        return None
    held = try_lock(staging)
    owner = OwnedFolder(root=staging.resolve(), given=given, source=src, created=True, final=root, _held=held,
                        replaced=tuple(sorted(previous)))
    try:
        owner._save()
    except OSError as exc:
        shutil.rmtree(staging, ignore_errors=True)
        raise _write_failed(given, exc) from exc
    _observe(owner.root, owner)
    return owner


def remove_stale_staging(out_dir: Path | str) -> bool:
    """Remove the staging folder ``.<name>.asset2sim-next`` beside ``out_dir`` when a killed or terminated
    ``--force`` run left it (asset2sim's, and no live run holds its lock); True when one was removed. A rerun
    that finds its output complete calls this, so nothing of an interrupted run stays beside ``--out``."""
    try:
        root = Path(out_dir).resolve()
    except (OSError, RuntimeError):
        return False
    staging = staging_folder(root)
    return os.path.lexists(staging) and is_staging_folder(staging) and remove_stale(staging)


def remove_owned(out_dir: Path | str) -> list[str]:
    """Remove what asset2sim wrote in the output folder ``out_dir``: the files its completion marker and ownership
    record list (with their temporary files), then those two, then the folders left empty and ``out_dir`` itself
    when nothing else is in it. A file the product did not write stays (with the folders holding it); nothing is
    followed through a symlink. Returns the relative paths of what stays (sorted)."""
    root = Path(out_dir)
    if not root.is_dir() or root.is_symlink():
        return []
    owned = recorded_files(root)
    for rel in [*sorted(owned), *sorted(_BOOKKEEPING)]:
        _remove_with_temps(root, rel)
    _prune_empty(root, owned)
    left = _entries(root)
    if not left:
        # every folder before its parent, out_dir last
        for folder, _dirs, _files in sorted(os.walk(root), reverse=True):
            with contextlib.suppress(OSError):
                os.rmdir(folder)
    return left


def _write_failed(given: Path, exc: OSError) -> OutputError:
    """``OUTPUT_WRITE_FAILED`` for an OSError."""
    return OutputError(f"output folder {given} cannot be created or written ({exc.strerror or exc})", "OUTPUT_WRITE_FAILED",
                       exc.filename or given)


def product_folder(path: Path | str) -> Path | None:
    """The nearest folder, ``path`` included, holding a completion marker or an ownership record; None when
    there is none. Resolved; :func:`product_folder_as_named` gives it as named."""
    found = product_folder_as_named(path)
    return None if found is None else found.resolve()


def product_folder_as_named(path: Path | str) -> Path | None:
    """:func:`product_folder` as ``path`` names it (absolute, symlinks kept), or None."""
    p = Path(os.path.abspath(path))
    return next((f for f in (p, *p.parents) if (f / MARKER_NAME).is_file() or (f / RECORD_NAME).is_file()), None)


@contextlib.contextmanager
def adopting(path: Path | str) -> Iterator[OwnedFolder | None]:
    """While the block runs, refuse every write that lies in the folder ``path`` by name but leaves it
    (:func:`guarding`) and record every atomic write into the output folder around ``path``
    (:func:`product_folder`) in its ownership record, the folder compared as named and as resolved. Yields the
    :class:`OwnedFolder`, or None when ``path`` is in no such folder (the writes are still guarded)."""
    named = product_folder_as_named(path)
    with guarding(path):
        if named is None:
            yield None
            return
        root = named.resolve()
        owner = OwnedFolder(root=root, given=named, source=None, files=_listed(root / RECORD_NAME))
        previous = _observe(root, owner)
        try:
            yield owner
        finally:
            if previous is None:
                owner.close()
            else:
                with _ACTIVE_LOCK:
                    _ACTIVE[root] = previous
