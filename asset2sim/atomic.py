"""Atomic file output, reading regular files only, and content hashing.

Every output file is written as a temporary ``.<name>.<random>.tmp`` beside
it, ``fsync``, ``os.replace``, then an ``fsync`` of the folder: a run killed at
any moment leaves each file absent or complete. Inside a scratch folder
(:func:`add_scratch`: a run's working copies, removed when it ends) the two
``fsync`` calls are left out: the write is still atomic for a killed process,
and nothing there has to outlive a crash of the machine. Files get mode ``0o666`` minus
the umask, as ``open()`` gives. Observers (:func:`add_observer`) hear of every
destination before anything is created.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import hashlib
import json
import math
import os
import secrets
import shutil
import stat
import tempfile
import threading
from collections import Counter
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterable

Observer = Callable[[list[Path]], None]
"""observer(destinations): called before any of ``destinations`` is created;
it may raise to refuse the write (nothing is then created)."""

_OBSERVERS: list[Observer] = []
_OBSERVERS_LOCK = threading.Lock()
_SCRATCH: Counter[str] = Counter()  # absolute folder + os.sep -> times added
_SCRATCH_LOCK = threading.Lock()


def add_scratch(folder: Path | str) -> None:
    """Write the files under ``folder`` (absolute, or made so) without ``fsync``: a scratch folder its owner
    removes (every thread; once per :func:`remove_scratch`)."""
    key = os.path.join(os.path.abspath(folder), "")
    with _SCRATCH_LOCK:
        _SCRATCH[key] += 1


def remove_scratch(folder: Path | str) -> None:
    """Undo one :func:`add_scratch` of ``folder`` (no error when it was not added)."""
    key = os.path.join(os.path.abspath(folder), "")
    with _SCRATCH_LOCK:
        _SCRATCH[key] -= 1
        if _SCRATCH[key] <= 0:
            del _SCRATCH[key]


def _durable(path: Path) -> bool:
    """False for a path under a scratch folder (:func:`add_scratch`)."""
    return not _SCRATCH or not any(os.path.abspath(path).startswith(root) for root in list(_SCRATCH))


def add_observer(observer: Observer) -> None:
    """Call ``observer`` with the destinations of every atomic write (any
    thread) before anything is created (once, however often added)."""
    with _OBSERVERS_LOCK:
        if observer not in _OBSERVERS:
            _OBSERVERS.append(observer)


def remove_observer(observer: Observer) -> None:
    """Stop calling ``observer`` (no error when it was not added)."""
    with _OBSERVERS_LOCK:
        if observer in _OBSERVERS:
            _OBSERVERS.remove(observer)


def announce(paths: Iterable[Path | str]) -> None:
    """Tell the observers that ``paths`` belong to the current write although
    they are kept as they are (e.g. a copy whose content is already right)."""
    paths = [Path(p) for p in paths]
    if paths:
        with _OBSERVERS_LOCK:
            observers = list(_OBSERVERS)
        for obs in observers:
            obs(paths)


def temp_name(path: Path | str) -> str:
    """A fresh temporary file name beside ``path``: ``.<name>.<16 hex>.tmp``."""
    return f".{Path(path).name}.{secrets.token_hex(8)}.tmp"


def is_temp_of(name: str, target: str) -> bool:
    """True when file ``name`` is a temporary file of the destination named
    ``target`` (same folder): ``.<target>.<1-32 word characters>.tmp``."""
    prefix = f".{target}."
    if not (name.startswith(prefix) and name.endswith(".tmp")):
        return False
    mid = name[len(prefix):-4]
    return 1 <= len(mid) <= 32 and all(c.isalnum() or c == "_" for c in mid)


def _create_temp(path: Path) -> tuple[int, str]:
    """A new empty temporary file beside ``path``: (fd, name)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC | os.O_NOFOLLOW
    for _ in range(100):
        tmp = str(path.parent / temp_name(path))
        try:
            return os.open(tmp, flags, 0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name beside {path}")


def _unlink_quietly(names: Iterable[str]) -> None:
    for name in names:
        with contextlib.suppress(OSError):
            os.unlink(name)


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(str(folder), os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _replace(tmp: str, path: Path) -> None:
    """``os.replace(tmp, path)``; an error names the destination."""
    try:
        os.replace(tmp, path)
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from exc


_RENAME_EXCHANGE = 2  # renameat2(2) flag, Linux >= 3.15 (linux/fs.h)
_AT_FDCWD = -100  # fcntl.h


def _renameat2_exchange(a: Path, b: Path) -> bool:
    """Linux's ``renameat2(a, b, RENAME_EXCHANGE)`` through libc; False when
    not offered (nothing changed). Raises OSError naming ``b`` otherwise."""
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
    """Swap two folders of one filesystem: one atomic
    ``renameat2(RENAME_EXCHANGE)`` on Linux, else three renames through
    ``.<b>.asset2sim-previous`` beside ``b``.

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


def write_bytes(path: Path | str, data: bytes, *, durable: bool = True, check: Callable[[Path], object] | None = None) -> Path:
    """Write ``data`` to ``path`` atomically (parents created); ``durable=False`` (or a scratch folder): without
    ``fsync``, atomic for a killed process only; ``check``: called with the complete temporary file (beside ``path``,
    so relative references resolve as from ``path``) before it replaces ``path``. Returns the path.

    Raises:
        OSError: the folder cannot be written (the error names ``path``).
        Exception: what ``check`` raised; ``path`` is left as it was.
    """
    path = Path(path)
    announce([path])
    path.parent.mkdir(parents=True, exist_ok=True)
    durable = durable and _durable(path)
    fd, tmp = _create_temp(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            if durable:
                fh.flush()
                os.fsync(fh.fileno())
        if check is not None:
            check(Path(tmp))
        _replace(tmp, path)
    except BaseException:
        _unlink_quietly([tmp])
        raise
    if durable:
        _fsync_dir(path.parent)
    return path


def write_text(path: Path | str, text: str, *, durable: bool = True, check: Callable[[Path], object] | None = None) -> Path:
    """Write UTF-8 ``text`` atomically (``durable`` and ``check`` as in :func:`write_bytes`)."""
    return write_bytes(path, text.encode("utf-8"), durable=durable, check=check)


def non_finite(obj: Any) -> str | None:
    """The JSON path (``$.metrics[3].value``) of the first NaN or infinity in ``obj`` (JSON values; tuples as lists), or None."""
    stack = [(obj, "$")]
    while stack:
        value, at = stack.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return at
        if isinstance(value, dict):
            stack.extend((v, f"{at}.{k}") for k, v in reversed(list(value.items())))
        elif isinstance(value, (list, tuple)):
            stack.extend((v, f"{at}[{i}]") for i, v in reversed(list(enumerate(value))))
    return None


def jsonable(obj: Any) -> Any:
    """``obj`` (dicts, lists, tuples, numbers, numpy scalars) as strict JSON values: non-finite floats as None,
    numpy scalars as Python numbers, tuples as lists, keys as strings."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if hasattr(obj, "item"):  # numpy scalars
        return jsonable(obj.item())
    return obj


def write_json(path: Path | str, obj: Any, *, durable: bool = True) -> Path:
    """Write ``obj`` as strict JSON (no NaN/inf; raises ValueError), indented by 2, atomically (``durable`` as in
    :func:`write_bytes`)."""
    if (where := non_finite(obj)) is not None:
        raise ValueError(f"non-finite number at {where} cannot be written as JSON")
    return write_text(path, json.dumps(obj, indent=2, allow_nan=False) + "\n", durable=durable)


def copy_files(pairs: Iterable[tuple[Path | str, Path | str]]) -> list[Path]:
    """Copy many files, each atomically: all written as temporary files, one
    ``os.sync()`` (none when every destination is in a scratch folder), then each renamed into place.
    Returns the destinations."""
    pairs = [(src, Path(dst)) for src, dst in pairs]
    announce(dst for _, dst in pairs)
    staged: list[tuple[str, Path]] = []
    try:
        for src, dst in pairs:
            dst.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = _create_temp(dst)
            staged.append((tmp, dst))
            with os.fdopen(fd, "wb") as fh:
                fh.write(Path(src).read_bytes())
        durable = any(_durable(dst) for _, dst in staged)
        if durable:
            os.sync()
        for tmp, dst in staged:
            _replace(tmp, dst)
        for folder in {dst.parent for _, dst in staged} if durable else ():
            _fsync_dir(folder)
    except BaseException:
        _unlink_quietly(tmp for tmp, _ in staged)
        raise
    return [dst for _, dst in staged]


def copy_file(src: Path | str, dst: Path | str) -> Path:
    """Copy ``src`` to ``dst`` atomically (contents only, no metadata)."""
    return write_bytes(dst, Path(src).read_bytes())


class NotRegularFileError(OSError):
    """A path that must be a regular file is a FIFO, device, socket or folder
    (``errno`` EINVAL, or EISDIR for a folder)."""


def process_folder(prefix: str) -> Path:
    """A new temporary folder ``<tmp>/<prefix>*`` of this process, removed when it exits (a forked child exiting
    leaves it)."""
    folder = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(_remove_if_owner, folder, os.getpid())
    return folder


def _remove_if_owner(folder: Path, pid: int) -> None:
    if os.getpid() == pid:
        shutil.rmtree(folder, ignore_errors=True)


def open_regular(path: Path | str, follow_links: bool = True) -> BinaryIO:
    """``path`` opened for binary reading, checked on the descriptor to be a regular file
    (``O_NONBLOCK``: a FIFO cannot block the open; ``follow_links=False``: ``O_NOFOLLOW``, a path resolved and
    checked before cannot be swapped for a link). Raises NotRegularFileError, OSError (``ELOOP``: a link)."""
    fd = os.open(str(path), os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC | os.O_NOCTTY | (0 if follow_links else os.O_NOFOLLOW))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            code = errno.EISDIR if stat.S_ISDIR(mode) else errno.EINVAL
            raise NotRegularFileError(code, "not a regular file (a folder, FIFO, device or socket)", str(path))
    except BaseException:
        os.close(fd)
        raise
    return os.fdopen(fd, "rb")


def read_regular(path: Path | str, max_bytes: int | None = None, follow_links: bool = True) -> bytes:
    """The bytes of ``path``, which must be a regular file (checked before reading), at most ``max_bytes``;
    ``follow_links=False`` refuses a link (:func:`open_regular`).

    Raises:
        NotRegularFileError: not a regular file.
        OSError: unreadable or over ``max_bytes`` (``EFBIG``).
    """
    with open_regular(path, follow_links) as fh:
        if max_bytes is None:
            return fh.read()
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise OSError(errno.EFBIG, f"more than {max_bytes} bytes", str(path))
    return data


def sha256_file(path: Path | str) -> str:
    """Hex sha256 of a regular file's bytes (NotRegularFileError, OSError)."""
    h = hashlib.sha256()
    with open_regular(path) as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def sha256_files(paths: Iterable[Path | str], known: dict[str, str] | None = None,
                 named: Callable[[Path], str] | None = None) -> str:
    """Hex sha256 over several files' names and contents, in sorted order; ``known``: path (as ``str``) -> the hex
    sha256 of its bytes as already read (those files are not read again); ``named``: the name a path is hashed
    under (default the path itself; a file in a temporary folder is named relative to it, so the hash is the
    same in every run)."""
    h = hashlib.sha256()
    known = known or {}
    for key, name, p in sorted({(named(p) if named else str(p), str(p), p) for p in map(Path, paths)}):
        h.update(f"{key}\0{known.get(name) or sha256_file(p)}\0".encode())
    return h.hexdigest()
