"""Files an input names, opened under one policy: a regular file (symlinks resolved), inside the input's
tree when a tree is given, under a size cap, opened without blocking.

Every file the product reads because a user or an input names it (an MJCF or USD file, what it includes,
its meshes, textures, sublayers, references and payloads, a ``--config`` file) goes through
:func:`check_file` (``os.stat`` only: a FIFO, device or socket is refused before anything opens it) and is
read with :func:`read_file` (``O_NONBLOCK``, the descriptor checked again, at most the cap read). A file
that fails raises :class:`InputFileError` with a stable code:

- ``INPUT_NOT_FOUND``: the path does not exist (or a folder on it is a file);
- ``INPUT_NOT_REGULAR_FILE``: a directory, FIFO, character or block device (``/dev/zero``) or socket;
- ``INPUT_TOO_LARGE``: a regular file above the cap (never read);
- ``INPUT_OUTSIDE_TREE``: the path, or a symlink on it, leads outside the tree the input may read;
- ``INPUT_UNREADABLE``: the operating system refuses to open or read it.

Format readers map these to their own codes where the format has them (``MJCF_PATH_ESCAPES``,
``USD_LAYER_OUTSIDE_ASSET``, ...).
"""

from __future__ import annotations

import contextlib
import contextvars
import os
import stat
from pathlib import Path
from typing import Iterator

from asset2sim import atomic

__all__ = ["DEFAULT_MAX_BYTES", "InputFileError", "MAX_CONFIG_BYTES", "MAX_YAML_ALIASES", "MAX_YAML_DEPTH", "MAX_YAML_NODES",
           "allow_outside", "allowed_folders", "allowed_outside", "check_file", "file_kind", "inside", "load_yaml", "read_file",
           "read_head", "set_allowed_outside"]

#: Default cap of one input file, bytes (the largest mesh the validator accepts, ValidationPolicy.max_mesh_bytes).
DEFAULT_MAX_BYTES = 64 * 1024 * 1024

_KINDS = ((stat.S_ISFIFO, "FIFO"), (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"),
          (stat.S_ISSOCK, "socket"), (stat.S_ISDIR, "directory"), (stat.S_ISREG, "regular file"))


class InputFileError(ValueError):
    """A file an input names that the policy refuses: ``code`` (``INPUT_*``, or a format's own code),
    ``path`` as named."""

    def __init__(self, code: str, path: Path | str, message: str):
        super().__init__(message)
        self.code = code
        self.path = Path(path)


#: Folders outside an input's tree that its files may name, in this context (:func:`allow_outside`): (absolute,
#: real) path pairs.
_OUTSIDE: contextvars.ContextVar[tuple[tuple[str, str], ...]] = contextvars.ContextVar("asset2sim_allowed_outside", default=())


def _refused(code: str, path: Path | str, what: str, text: str) -> InputFileError:
    """The :class:`InputFileError` ``code`` of the file ``path``, its message ``"{what} {path}: {text}"``."""
    return InputFileError(code, path, f"{what} {path}: {text}")


def _pairs(folders) -> tuple[tuple[str, str], ...]:
    pairs = []
    for f in folders:
        absolute = os.path.abspath(str(f))
        if not os.path.isdir(absolute):
            raise InputFileError("INPUT_NOT_FOUND", f, f"--allow-outside-paths {f}: not a folder")
        pairs.append((absolute, os.path.realpath(absolute)))
    return tuple(pairs)


def set_allowed_outside(*folders: Path | str) -> None:
    """:func:`allow_outside` for the rest of the current context (a worker process's initializer)."""
    _OUTSIDE.set(_OUTSIDE.get() + _pairs(folders))


@contextlib.contextmanager
def allow_outside(*folders: Path | str) -> Iterator[None]:
    """Within the block, files an MJCF or USD input names may also lie in ``folders`` (``--allow-outside-paths DIR``:
    a user widening the tree on purpose, e.g. meshes shared by several models); every other rule still holds
    (regular file, size cap, no blocking open). Nested blocks add their folders.

    Raises:
        InputFileError: ``INPUT_NOT_FOUND`` when a folder does not exist or is not a folder.
    """
    token = _OUTSIDE.set(_OUTSIDE.get() + _pairs(folders))
    try:
        yield
    finally:
        _OUTSIDE.reset(token)


def allowed_folders() -> tuple[str, ...]:
    """The real paths of the folders :func:`allow_outside` allows in this context (for cache keys)."""
    return tuple(real for _, real in _OUTSIDE.get())


def allowed_outside(path: Path | str) -> bool:
    """True when ``path`` lies in a folder :func:`allow_outside` allows, as written (normalized) and with every
    symlink resolved."""
    pairs = _OUTSIDE.get()
    if not pairs:
        return False
    lexical = os.path.abspath(str(path))
    real = os.path.realpath(lexical)
    return any(inside(lexical, a) or inside(lexical, r) for a, r in pairs) and any(inside(real, r) for _, r in pairs)


def file_kind(mode: int) -> str:
    """``"FIFO"``, ``"character device"``, ``"regular file"`` ... of an ``st_mode``."""
    return next((name for test, name in _KINDS if test(mode)), "special file")


def inside(path: str, root: str) -> bool:
    """True when ``path`` is ``root`` or lies below it (both absolute and normalized)."""
    return path == root or path.startswith(root.rstrip(os.sep) + os.sep)


def check_file(path: Path | str, *, tree: Path | str | None = None, max_bytes: int | None = DEFAULT_MAX_BYTES,
               what: str = "input file") -> os.stat_result:
    """Check, with ``os.stat`` only (nothing is opened), that ``path`` may be read.

    Args:
        path: the file as named (absolute, or relative to the working directory).
        tree: the folder the file must lie in, lexically and with every symlink resolved (None: anywhere), or
            a folder :func:`allow_outside` allows.
        max_bytes: size cap in bytes (None: none).
        what: how the message names the file ("MJCF include", "--config file" ...).

    Returns:
        The ``os.stat`` result of the real file.

    Raises:
        InputFileError: ``INPUT_OUTSIDE_TREE``, ``INPUT_NOT_FOUND``, ``INPUT_NOT_REGULAR_FILE``,
            ``INPUT_TOO_LARGE`` or ``INPUT_UNREADABLE`` (the message names the file and why).
    """
    name = str(path)
    if "\x00" in name:
        raise InputFileError("INPUT_UNREADABLE", "?", f"{what} {name!r}: the path contains a NUL byte")
    # a folder the user allowed (allow_outside): the tree is wider
    root = os.path.abspath(str(tree)) if tree is not None and not allowed_outside(name) else None
    if root is not None and not inside(os.path.abspath(name), root):
        raise _refused("INPUT_OUTSIDE_TREE", path, what, f"lies outside {root}, the folder the input may read")
    try:
        st = os.stat(name)
    except (FileNotFoundError, NotADirectoryError):
        raise _refused("INPUT_NOT_FOUND", path, what, "no such file") from None
    except OSError as exc:
        raise _refused("INPUT_UNREADABLE", path, what, f"{exc.strerror or exc}") from None
    if not stat.S_ISREG(st.st_mode):
        raise _refused("INPUT_NOT_REGULAR_FILE", path, what, f"a {file_kind(st.st_mode)}, not a regular file "
                             "(FIFOs, devices, sockets and folders are never read)")
    if root is not None:
        real = os.path.realpath(name)
        if not inside(real, os.path.realpath(root)):
            raise _refused("INPUT_OUTSIDE_TREE", path, what, f"a symlink leads to {real}, outside {root}, "
                                 "the folder the input may read")
    if max_bytes is not None and st.st_size > max_bytes:
        raise _refused("INPUT_TOO_LARGE", path, what, f"{st.st_size} bytes, above the cap of {max_bytes} bytes; not read")
    return st


def read_file(path: Path | str, *, tree: Path | str | None = None, max_bytes: int = DEFAULT_MAX_BYTES,
              what: str = "input file") -> bytes:
    """The bytes of ``path`` after :func:`check_file`, opened with ``O_NONBLOCK`` and checked again on the
    open descriptor (a file swapped for a FIFO, or for any other file, between the check and the open is refused,
    not waited on or read); at most ``max_bytes`` are read.

    Raises:
        InputFileError: as :func:`check_file`; ``INPUT_TOO_LARGE`` also when the file grew past the cap.
    """
    checked = check_file(path, tree=tree, max_bytes=max_bytes, what=what)
    try:
        fd = os.open(str(path), os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise _refused("INPUT_UNREADABLE", path, what, f"{exc.strerror or exc}") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise _refused("INPUT_NOT_REGULAR_FILE", path, what, f"a {file_kind(st.st_mode)}, not a regular file")
        if (st.st_dev, st.st_ino) != (checked.st_dev, checked.st_ino):  # swapped between the check and the open
            raise _refused("INPUT_UNREADABLE", path, what, "replaced by another file while it was opened")
        with open(fd, "rb", closefd=False) as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise _refused("INPUT_UNREADABLE", path, what, f"{exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(data) > max_bytes:
        raise _refused("INPUT_TOO_LARGE", path, what, f"grew above the cap of {max_bytes} bytes while read")
    return data


def read_head(path: Path | str, n: int = 4096) -> bytes | None:
    """The first ``n`` bytes of ``path`` when it is a regular file (opened without blocking); None for a
    missing, unreadable or special file (a FIFO, ``/dev/zero``), which is never read
    (:func:`asset2sim.atomic.open_regular`)."""
    try:
        with atomic.open_regular(path) as fh:
            return fh.read(n)
    except (OSError, ValueError):
        return None


#: Cap of a configuration file (``--config``, ``catalog.yaml``), bytes.
MAX_CONFIG_BYTES = 1024 * 1024
#: YAML aliases (``*name``) a configuration file may use: each repeats a whole node, so a few nested anchors
#: make a document of billions of nodes ("billion laughs").
MAX_YAML_ALIASES = 64
#: Deepest nesting of YAML collections in a configuration file.
MAX_YAML_DEPTH = 64
#: Nodes of a configuration file with its aliases expanded.
MAX_YAML_NODES = 100_000


def load_yaml(path: Path | str, *, what: str = "configuration file"):
    """The YAML document at ``path``, read under :func:`read_file`'s policy (at most :data:`MAX_CONFIG_BYTES`) and
    built by PyYAML's safe loader (plain data only: no Python objects) with at most :data:`MAX_YAML_ALIASES` aliases,
    :data:`MAX_YAML_DEPTH` levels of nesting and :data:`MAX_YAML_NODES` nodes once every alias is expanded (counted
    on the parsed graph, before anything is built).

    Raises:
        InputFileError: ``INPUT_NOT_FOUND``, ``INPUT_NOT_REGULAR_FILE`` (a FIFO, ``/dev/zero``),
            ``INPUT_TOO_LARGE``, ``INPUT_UNREADABLE``; ``YAML_ALIAS_LIMIT`` or ``YAML_TOO_DEEP`` (refused while
            parsing, before any node is built); ``YAML_MALFORMED`` (not YAML, not UTF-8).
    """
    import yaml

    data = read_file(path, max_bytes=MAX_CONFIG_BYTES, what=what)

    class _Bounded(yaml.SafeLoader):
        aliases = 0
        depth = 0

        def compose_node(self, parent, index):
            if self.check_event(yaml.AliasEvent):
                self.aliases += 1
                if self.aliases > MAX_YAML_ALIASES:
                    raise _refused("YAML_ALIAS_LIMIT", path, what, f"more than {MAX_YAML_ALIASES} YAML aliases "
                                         "(*name); refused before expanding them")
            self.depth += 1
            try:
                if self.depth > MAX_YAML_DEPTH:
                    raise _refused("YAML_TOO_DEEP", path, what, f"YAML nested deeper than {MAX_YAML_DEPTH} levels")
                return super().compose_node(parent, index)
            finally:
                self.depth -= 1

    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _refused("YAML_MALFORMED", path, what, f"not UTF-8 ({exc})") from None
    loader = _Bounded(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        sizes: dict[int, int] = {}

        def expanded(n) -> int:  # nodes of the document with every alias expanded (each shared node counted once per use)
            if sizes.get(id(n)) == 0:
                raise _refused("YAML_ALIAS_LIMIT", path, what, "a YAML alias inside its own anchor (a recursive document)")
            if id(n) not in sizes:
                sizes[id(n)] = 0  # in progress
                kids = n.value if isinstance(n, yaml.SequenceNode) else []  # a mapping's: its keys and values
                if isinstance(n, yaml.MappingNode):
                    kids = [c for pair in n.value for c in pair]
                sizes[id(n)] = 1 + sum(expanded(c) for c in kids)
            return sizes[id(n)]

        total = expanded(node)
        if total > MAX_YAML_NODES:
            raise _refused("YAML_ALIAS_LIMIT", path, what, f"its aliases expand to {total} YAML nodes, above the "
                                 f"cap of {MAX_YAML_NODES}; refused before expanding them")
        return loader.construct_document(node)
    except yaml.YAMLError as exc:
        raise _refused("YAML_MALFORMED", path, what, f"not YAML: {exc}") from None
    finally:
        loader.dispose()
