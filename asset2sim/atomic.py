"""Atomic file output and content hashing.

Every output file of asset2sim is written through :func:`write_bytes` /
:func:`write_text` / :func:`write_json` / :func:`copy_file`: a temporary file
in the same folder, ``fsync``, then ``os.replace`` (atomic on POSIX), then an
``fsync`` of the folder. A run killed at any moment leaves each output file
either absent or complete.

Files are created with mode ``0o666`` minus the process umask (0644 under
umask 022), as ``open()`` would: the temporary file is made with
``os.open(O_CREAT | O_EXCL, 0o666)``, not ``tempfile.mkstemp`` (always 0600).
Temporary files are named ``.<name>.<random>.tmp`` beside their destination.

An observer lets an owner of an output folder (:mod:`asset2sim.output_folder`) hear of every destination before its temporary file is
created (:func:`add_observer`), so a killed run leaves no file its owner
does not know of.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import os
import secrets
import stat
import threading
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterable, Iterator

Observer = Callable[[list[Path]], None]
"""observer(destinations): called before any of ``destinations`` is created;
it may raise to refuse the write (nothing is then created)."""

_OBSERVERS: list[Observer] = []
_OBSERVERS_LOCK = threading.Lock()


def add_observer(observer: Observer) -> None:
    """Call ``observer`` with the destination paths of every atomic write (any
    thread) before anything is created; adding the same observer twice keeps
    one. An exception raised by the observer aborts that write before any
    temporary file exists."""
    with _OBSERVERS_LOCK:
        if observer not in _OBSERVERS:
            _OBSERVERS.append(observer)


def remove_observer(observer: Observer) -> None:
    """Stop calling ``observer`` (no error when it was not added)."""
    with _OBSERVERS_LOCK:
        if observer in _OBSERVERS:
            _OBSERVERS.remove(observer)


@contextlib.contextmanager
def observe(observer: Observer) -> Iterator[None]:
    """:func:`add_observer` for the duration of a ``with`` block."""
    add_observer(observer)
    try:
        yield
    finally:
        remove_observer(observer)


def _announce(paths: list[Path]) -> None:
    with _OBSERVERS_LOCK:
        observers = list(_OBSERVERS)
    for obs in observers:
        obs(paths)


def announce(paths: Iterable[Path | str]) -> None:
    """Tell the observers that ``paths`` belong to the current write although
    they are kept as they are (e.g. a copy whose content is already right)."""
    paths = [Path(p) for p in paths]
    if paths:
        _announce(paths)


def temp_name(path: Path | str) -> str:
    """A fresh temporary file name beside ``path``: ``.<name>.<16 hex>.tmp``."""
    return f".{Path(path).name}.{secrets.token_hex(8)}.tmp"


def is_temp_of(name: str, target: str) -> bool:
    """True when file ``name`` is a temporary file of the destination named
    ``target`` (same folder), as :func:`temp_name` makes them (also the
    ``mkstemp`` names of earlier versions: ``.<target>.<8 chars>.tmp``)."""
    prefix = f".{target}."
    if not (name.startswith(prefix) and name.endswith(".tmp")):
        return False
    mid = name[len(prefix):-4]
    return 1 <= len(mid) <= 32 and all(c.isalnum() or c == "_" for c in mid)


def _create_temp(path: Path) -> tuple[int, str]:
    """Create a new empty temporary file beside ``path`` with mode 0o666 minus
    the umask; returns (fd, name)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOFOLLOW", 0)
    for _ in range(100):
        tmp = str(path.parent / temp_name(path))
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


def _fsync_dir(folder: Path) -> None:
    try:
        fd = os.open(str(folder), os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _replace(tmp: str, path: Path) -> None:
    """``os.replace(tmp, path)``; an error names the destination, not the
    temporary file (e.g. ``IsADirectoryError`` for ``path``)."""
    try:
        os.replace(tmp, path)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


_RENAME_EXCHANGE = 2  # renameat2(2) flag, Linux >= 3.15 (linux/fs.h)
_AT_FDCWD = -100  # fcntl.h


def _renameat2_exchange(a: Path, b: Path) -> bool:
    """Linux's ``renameat2(a, b, RENAME_EXCHANGE)`` through libc; False when
    libc or the filesystem does not offer it (then nothing was changed).

    Raises:
        OSError: the exchange was refused for another reason (names ``b``).
    """
    import ctypes

    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (AttributeError, OSError):
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    if fn(_AT_FDCWD, os.fsencode(str(a)), _AT_FDCWD, os.fsencode(str(b)), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP, errno.ENOTSUP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def exchange_folders(a: Path | str, b: Path | str) -> None:
    """Swap two folders of one filesystem: afterwards ``b`` holds what ``a``
    held and ``a`` what ``b`` held.

    On Linux this is one atomic ``renameat2(RENAME_EXCHANGE)``: at every
    moment ``b`` is either the old or the new folder (how a complete output
    replaces an earlier complete one). Where the kernel, libc or filesystem
    lacks it, three renames through ``.<b>.asset2sim-previous`` beside ``b``
    (then ``b`` is missing for the instant between two renames).

    Raises:
        OSError: either folder is missing, they lie on different
            filesystems, or the parent cannot be written.
    """
    a, b = Path(a), Path(b)
    if not _renameat2_exchange(a, b):
        aside = b.parent / f".{b.name}.asset2sim-previous"
        os.rename(b, aside)
        try:
            os.rename(a, b)
        except OSError:
            os.rename(aside, b)
            raise
        os.rename(aside, a)
    _fsync_dir(b.parent)


def write_bytes(path: Path | str, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (parents created). Returns the path.

    Raises:
        OSError: the folder cannot be written (the error names ``path``).
    """
    path = Path(path)
    _announce([path])
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _create_temp(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        _replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _fsync_dir(path.parent)
    return path


def write_text(path: Path | str, text: str) -> Path:
    """Write UTF-8 ``text`` atomically."""
    return write_bytes(path, text.encode("utf-8"))


def _check_finite(obj: Any, where: str = "$") -> None:
    if isinstance(obj, float) and not math.isfinite(obj):
        raise ValueError(f"non-finite number at {where} cannot be written as JSON")
    if isinstance(obj, dict):
        for k, v in obj.items():
            _check_finite(v, f"{where}.{k}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _check_finite(v, f"{where}[{i}]")


def write_json(path: Path | str, obj: Any, indent: int = 2) -> Path:
    """Write ``obj`` as strict JSON (no NaN/inf; raises ValueError) atomically."""
    _check_finite(obj)
    return write_text(path, json.dumps(obj, indent=indent, sort_keys=False, allow_nan=False) + "\n")


def copy_files(pairs: Iterable[tuple[Path | str, Path | str]]) -> list[Path]:
    """Copy many files atomically each: every destination is first written as a
    temporary file beside it, then one ``os.sync()`` flushes them all, then each
    is renamed into place. A kill at any moment leaves every destination absent
    or complete (one sync instead of one fsync per file: meshes come by the
    hundred)."""
    pairs = [(src, Path(dst)) for src, dst in pairs]
    if pairs:
        _announce([dst for _, dst in pairs])
    staged: list[tuple[str, Path]] = []
    try:
        for src, dst in pairs:
            dst.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = _create_temp(dst)
            staged.append((tmp, dst))
            with os.fdopen(fd, "wb") as fh:
                fh.write(Path(src).read_bytes())
        os.sync()
        for tmp, dst in staged:
            _replace(tmp, dst)
        for folder in {dst.parent for _, dst in staged}:
            _fsync_dir(folder)
    except BaseException:
        for tmp, _ in staged:
            try:
                os.unlink(tmp)
            except OSError:
                pass
        raise
    return [dst for _, dst in staged]


def copy_file(src: Path | str, dst: Path | str) -> Path:
    """Copy ``src`` to ``dst`` atomically (contents only, no metadata)."""
    return write_bytes(dst, Path(src).read_bytes())


class NotRegularFileError(OSError):
    """A path that must be a regular file is a FIFO, device, socket or folder
    (``errno`` EINVAL, or EISDIR for a folder); raised before anything is read,
    so a FIFO never blocks the reader."""


def _open_regular(path: Path | str, follow_symlinks: bool = True) -> int:
    """A read-only descriptor of ``path`` after checking, on the open
    descriptor, that it is a regular file. The open itself cannot block
    (``O_NONBLOCK``: a FIFO opens at once, and is then refused).

    Raises:
        NotRegularFileError: not a regular file.
        OSError: it cannot be opened (``ELOOP`` for a symlink when
            ``follow_symlinks`` is False).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0) | getattr(os, "O_NOCTTY", 0)
    if not follow_symlinks:
        flags |= getattr(os, "O_NOFOLLOW", 0)
    fd = os.open(str(path), flags)
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            code = errno.EISDIR if stat.S_ISDIR(mode) else errno.EINVAL
            raise NotRegularFileError(code, "not a regular file (a folder, FIFO, device or socket)", str(path))
    except BaseException:
        os.close(fd)
        raise
    return fd


def open_regular(path: Path | str) -> BinaryIO:
    """``path`` opened for binary reading once it is known, on the open
    descriptor, to be a regular file (a FIFO never blocks the open); e.g. for
    reading an image header without reading the file.

    Raises:
        NotRegularFileError: not a regular file.
        OSError: it cannot be opened.
    """
    return os.fdopen(_open_regular(path), "rb")


def read_regular(path: Path | str, max_bytes: int | None = None, *, follow_symlinks: bool = True) -> bytes:
    """The bytes of ``path``, which must be a regular file: checked on the open
    descriptor before reading, so a FIFO, a device or a socket put where a file
    was expected is refused at once instead of blocking or streaming without end.

    Args:
        path: the file.
        max_bytes: refuse a larger file (bytes); None: no cap.
        follow_symlinks: False refuses a symlink (``ELOOP``).

    Raises:
        NotRegularFileError: not a regular file.
        OSError: it cannot be opened or read, or it has more than ``max_bytes``
            bytes (``EFBIG``).
    """
    fd = _open_regular(path, follow_symlinks)
    with os.fdopen(fd, "rb") as fh:
        if max_bytes is None:
            return fh.read()
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise OSError(errno.EFBIG, f"more than {max_bytes} bytes", str(path))
    return data


def read_regular_text(path: Path | str, max_bytes: int | None = None) -> str:
    """:func:`read_regular` decoded as UTF-8 (``UnicodeDecodeError``, a
    ``ValueError``, when it is not)."""
    return read_regular(path, max_bytes).decode("utf-8")


def sha256_file(path: Path | str, chunk: int = 1 << 20) -> str:
    """Hex sha256 of a regular file's bytes.

    Raises:
        NotRegularFileError: ``path`` is a FIFO, device, socket or folder
            (never blocks on it).
        OSError: it cannot be read.
    """
    h = hashlib.sha256()
    with os.fdopen(_open_regular(path), "rb") as fh:
        while True:
            block = fh.read(chunk)
            if not block:
                break
            h.update(block)
    return h.hexdigest()


def sha256_files(paths: Iterable[Path | str], root: Path | str | None = None) -> str:
    """Hex sha256 over several files: their names (relative to ``root`` when
    given) and contents, in sorted order, so the hash does not depend on the
    order given."""
    h = hashlib.sha256()
    items = []
    for p in paths:
        p = Path(p)
        name = str(p.relative_to(root)) if root is not None else str(p)
        items.append((name, p))
    for name, p in sorted(set(items)):
        h.update(name.encode())
        h.update(b"\0")
        h.update(sha256_file(p).encode())
        h.update(b"\0")
    return h.hexdigest()


def tree_hashes(root: Path | str) -> dict[str, str]:
    """sha256 of every regular file under ``root`` keyed by relative path
    (used by tests to prove an input tree was not written)."""
    root = Path(root)
    out = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p.relative_to(root))] = sha256_file(p)
    return out
