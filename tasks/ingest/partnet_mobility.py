"""PartNet-Mobility: every convention of the dataset's folders, in one adapter.

The rest of the pipeline sees only what this module returns (typed rows and
records); it never opens a dataset side file itself. A PartNet-Mobility object
folder (Xiang et al., "SAPIEN: A SimulAted Part-based Interactive
ENvironment", CVPR 2020) holds:

``mobility.urdf``
    the articulated object (:func:`find_urdf`; a folder without it may hold
    one other ``*.urdf``, files named ``reference_*`` never count).
``semantics.txt``
    one ``link_name joint_kind semantic_label`` line per link
    (:func:`read_semantics`, :func:`iter_semantics`); joint kinds hinge,
    slider, free, heavy, static, junk.
``meta.json``
    annotation metadata; ``model_cat`` is the object category
    (:func:`read_category`).
``reference_gensim2.json`` / ``reference_gensim2.urdf``
    GenSim2's hand-curated copy (Hua et al., "GenSim2", CoRL 2024): the
    ``scale`` it loads the object at, the task joint's
    ``joint_position_range`` and a URDF whose only movable joints are the
    task's (:func:`read_reference`).

A dataset root holds one folder per object id and ``manifest.csv``
(:func:`read_manifest_rows`; :func:`read_manifest` all or nothing): columns
``id``, ``prompt`` (required), ``category``, ``task``, ``gensim2_task``,
``reference_scale``, ``reference_joint_range`` (JSON ``[lo, hi]``),
``time_limit_seconds``. A bad row is reported with its line and a code and
does not hide the others.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, NamedTuple

from asset2sim.tasks.ingest.errors import AssetError
from asset2sim.urdf import MOVABLE, read_urdf

__all__ = [
    "META_NAME",
    "MANIFEST_NAME",
    "REFERENCE_JSON",
    "REFERENCE_URDF",
    "SEMANTICS_NAME",
    "URDF_NAMES",
    "GenSim2Reference",
    "ManifestError",
    "ManifestReading",
    "ManifestRow",
    "ManifestRowError",
    "Semantics",
    "SemanticsLine",
    "find_urdf",
    "format_semantics",
    "has_reference",
    "iter_semantics",
    "meta_category",
    "read_category",
    "is_valid_id",
    "read_manifest",
    "read_manifest_rows",
    "read_reference",
    "read_semantics",
    "urdf_candidates",
]

#: URDF names looked up first in an object folder, in order.
URDF_NAMES = ("mobility.urdf",)
#: Prefix of files that are never the object's URDF (GenSim2's references).
REFERENCE_PREFIX = "reference_"
SEMANTICS_NAME = "semantics.txt"
META_NAME = "meta.json"
REFERENCE_JSON = "reference_gensim2.json"
REFERENCE_URDF = "reference_gensim2.urdf"
MANIFEST_NAME = "manifest.csv"


def _is_regular(path: Path) -> bool:
    try:
        return stat.S_ISREG(os.stat(path).st_mode)
    except OSError:
        return False


# ------------------------------------------------------------------ the URDF


def urdf_candidates(folder: Path) -> list[Path]:
    """The URDF files that may be the object of ``folder``: ``[mobility.urdf]``
    when that name exists (as anything, even a broken link), else every
    ``*.urdf`` not named ``reference_*``, sorted. Nothing is opened.

    Raises:
        OSError: the folder cannot be listed.
    """
    folder = Path(folder)
    for name in URDF_NAMES:
        if os.path.lexists(folder / name):
            return [folder / name]
    return sorted(p for p in folder.glob("*.urdf") if not p.name.startswith(REFERENCE_PREFIX))


def find_urdf(asset: Path | str) -> Path:
    """The URDF of an asset: the path itself if it is a file, else
    ``mobility.urdf`` in the folder, else the only ``*.urdf`` there (files
    named ``reference_*`` excluded). Only regular files qualify (a FIFO named
    ``mobility.urdf`` is never opened).

    Raises:
        AssetError: no (or several candidate) URDF files, or not a regular file.
    """
    asset = Path(asset)
    if asset.is_dir():
        cands = urdf_candidates(asset)
        if len(cands) == 1:
            if not _is_regular(cands[0]):
                raise AssetError(f"{cands[0]}: not a regular file")
            return cands[0]
        if not cands:
            raise AssetError(f"{asset}: no mobility.urdf or other *.urdf file")
        raise AssetError(f"{asset}: several URDF files ({', '.join(p.name for p in cands)}); pass one")
    if not os.path.lexists(asset):
        raise AssetError(f"{asset}: no such file or folder")
    if not _is_regular(asset):
        raise AssetError(f"{asset}: not a regular file")
    return asset


# ------------------------------------------------------------------ semantics.txt


class Semantics(NamedTuple):
    """One link's entry of ``semantics.txt`` (a tuple ``(joint_kind, label)``)."""

    joint_kind: str
    """hinge, slider, free, heavy, static or junk (as written)."""
    label: str
    """Part label, e.g. ``lid``, ``drawer``, ``door`` (may contain spaces)."""


@dataclass(frozen=True)
class SemanticsLine:
    """One non-blank line of ``semantics.txt``: ``lineno`` 1-based, ``text``
    as written; ``link`` and ``entry`` are None when the line is malformed
    (fewer than three fields)."""

    lineno: int
    text: str
    link: str | None
    entry: Semantics | None


def iter_semantics(text: str) -> Iterator[SemanticsLine]:
    """The non-blank lines of ``semantics.txt`` text, in order, parsed as
    ``link_name joint_kind semantic_label...`` (the label is the rest of the
    line, whitespace runs joined by one space)."""
    for i, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) < 3:
            yield SemanticsLine(i, line, None, None)
        else:
            yield SemanticsLine(i, line, parts[0], Semantics(parts[1], " ".join(parts[2:])))


def read_semantics(folder: Path) -> dict[str, Semantics]:
    """``semantics.txt`` of ``folder`` as link -> :class:`Semantics`
    ``(joint_kind, label)``; {} when absent. A link named twice keeps its
    last line.

    Raises:
        AssetError: a line that is not ``link joint_kind label``, or
            ``semantics.txt`` is not a regular file.
    """
    path = Path(folder) / SEMANTICS_NAME
    if not os.path.lexists(path):
        return {}
    if not _is_regular(path):
        raise AssetError(f"{path}: not a regular file")
    out: dict[str, Semantics] = {}
    for ln in iter_semantics(path.read_text(encoding="utf-8", errors="replace")):
        if ln.entry is None:
            raise AssetError(f"{path}:{ln.lineno}: expected 'link_name joint_kind semantic_label', got {ln.text!r}")
        out[ln.link] = ln.entry  # type: ignore[index]
    return out


def format_semantics(entries: dict[str, Semantics]) -> str:
    """``semantics.txt`` text for link -> :class:`Semantics`, one
    ``link_name joint_kind semantic_label`` line per link in the given order
    (the writer of :func:`iter_semantics`: ``iter_semantics(format_semantics(e))``
    gives ``e`` back).

    Raises:
        ValueError: a link name or joint kind that is empty or contains
            whitespace, or a label that is empty or spans lines (the format
            cannot express them); the message names the link.
    """
    lines = []
    for link, (kind, label) in entries.items():
        if not link or len(link.split()) != 1 or link.split()[0] != link:
            raise ValueError(f"semantics.txt: link name {link!r} is empty or contains whitespace")
        if not kind or len(kind.split()) != 1 or kind.split()[0] != kind:
            raise ValueError(f"semantics.txt: link {link!r}: joint kind {kind!r} is empty or contains whitespace")
        words = str(label).split()
        if not words or len(str(label).splitlines()) > 1:
            raise ValueError(f"semantics.txt: link {link!r}: label {label!r} is empty or spans lines")
        lines.append(f"{link} {kind} {' '.join(words)}\n")
    return "".join(lines)


# ------------------------------------------------------------------ meta.json


def meta_category(meta: Any) -> str | None:
    """``model_cat`` of a parsed ``meta.json`` (None when ``meta`` is not an
    object or the field is missing or empty)."""
    cat = meta.get("model_cat") if isinstance(meta, dict) else None
    return str(cat) if cat else None


def read_category(folder: Path) -> str | None:
    """``model_cat`` of ``folder/meta.json``; None when absent, unreadable,
    not JSON or not a regular file."""
    path = Path(folder) / META_NAME
    if not _is_regular(path):
        return None
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, OSError):
        return None
    return meta_category(meta)


# ------------------------------------------------------------------ GenSim2 reference


@dataclass(frozen=True)
class GenSim2Reference:
    """GenSim2's reference of one object folder.

    ``scale``: dimensionless load scale (None when ``reference_gensim2.json``
    is missing or has none); ``joint_position_range``: (lo, hi) of the task
    joint in file units (rad or m), or None; ``urdf``: path of
    ``reference_gensim2.urdf`` or None; ``task_joints``: its movable
    (revolute, continuous, prismatic) joints, in file order.
    """

    scale: float | None = None
    joint_position_range: tuple[float, float] | None = None
    urdf: Path | None = None
    task_joints: list[str] = field(default_factory=list)


def has_reference(folder: Path | str) -> bool:
    """Whether ``folder`` holds ``reference_gensim2.json``."""
    return (Path(folder) / REFERENCE_JSON).is_file()


def read_reference(folder: Path | str) -> GenSim2Reference:
    """GenSim2's reference of a PartNet-Mobility folder (all fields empty
    when the folder has none).

    Raises:
        ValueError: ``reference_gensim2.json`` is not JSON, or a range value
            is not a number.
        asset2sim.urdf.UrdfError: ``reference_gensim2.urdf`` cannot be parsed.
    """
    folder = Path(folder)
    scale = rng = None
    js = folder / REFERENCE_JSON
    if js.is_file():
        data = json.loads(js.read_text(encoding="utf-8"))
        if isinstance(data.get("scale"), (int, float)):
            scale = float(data["scale"])
        r = data.get("joint_position_range")
        if isinstance(r, list) and len(r) == 2:
            rng = (float(r[0]), float(r[1]))
    ru = folder / REFERENCE_URDF
    if not ru.is_file():
        return GenSim2Reference(scale=scale, joint_position_range=rng)
    types: dict[str, str] = {}
    for j in read_urdf(ru, mode="lenient").joints:
        types[j.name] = j.type  # a name written twice keeps its first place and last type
    task = [n for n, t in types.items() if t in MOVABLE]
    return GenSim2Reference(scale=scale, joint_position_range=rng, urdf=ru, task_joints=task)


# ------------------------------------------------------------------ manifest.csv

#: Codes of a manifest row that cannot be used (:class:`ManifestRowError`).
ROW_ERROR_CODES = {
    "MANIFEST_ROW_TOO_LARGE": "a field is longer than the CSV field limit (csv.field_size_limit)",
    "MANIFEST_ROW_MALFORMED": "the row is not valid CSV",
    "MANIFEST_MISSING_ID": "the row has no id",
    "MANIFEST_INVALID_ID": "the id is not a safe folder name (letters, digits, '_.-', not starting with '.')",
    "MANIFEST_DUPLICATE_ID": "the id was already used by an earlier row",
    "MANIFEST_MISSING_PROMPT": "the row ends before its prompt column",
    "MANIFEST_EXTRA_FIELDS": "the row has more fields than the header (an unquoted comma?)",
    "MANIFEST_INVALID_REFERENCE_SCALE": "reference_scale is not a positive number",
    "MANIFEST_INVALID_TIME_LIMIT": "time_limit_seconds is not a positive number",
    "MANIFEST_INVALID_JOINT_RANGE": "reference_joint_range is not [lo, hi]",
}
#: Codes of a manifest that cannot be used at all (:class:`ManifestError`).
FILE_ERROR_CODES = {
    "MANIFEST_NOT_TEXT": "the file is not UTF-8 text (not a CSV manifest)",
    "MANIFEST_BAD_HEADER": "the header line is not valid CSV",
    "MANIFEST_MISSING_COLUMNS": "the header lacks the id or prompt column",
}
#: How much of a row's first line is read again to find the id of a row the
#: CSV reader refused (characters; below the CSV field limit).
_ID_PREFIX_CHARS = 4096


class ManifestError(ValueError):
    """The manifest cannot be used at all (names the file and, for a row of
    the strict :func:`read_manifest`, the line). ``code``: one of
    :data:`FILE_ERROR_CODES` or, from :func:`read_manifest`, of
    :data:`ROW_ERROR_CODES`; ``path``: the manifest."""

    def __init__(self, message: str, code: str = "MANIFEST_INVALID", path: Path | str | None = None):
        super().__init__(message)
        self.code = code
        self.path = None if path is None else Path(path)


@dataclass
class ManifestRow:
    """One row of ``manifest.csv``.

    ``id`` the object folder's name; ``category`` "" when not given;
    ``reference_scale`` dimensionless (> 0) or None; ``reference_joint_range``
    (lo, hi) in file units (rad or m) or None; ``time_limit_seconds`` s (> 0)
    or None; ``folder`` the object folder (``<root>/<id>``); ``line`` the
    1-based line of the file where the row starts (None when not read from a file).
    """

    id: str
    category: str
    prompt: str
    task: str = ""
    gensim2_task: str = ""
    reference_scale: float | None = None
    reference_joint_range: tuple[float, float] | None = None
    time_limit_seconds: float | None = None
    folder: Path = Path(".")
    line: int | None = None


@dataclass(frozen=True)
class ManifestRowError:
    """A manifest row that cannot be used; the other rows are unaffected.

    ``line``: 1-based line of the file where the row starts; ``id``: the
    row's id as written when it could be read (it may itself be the problem:
    check :func:`is_valid_id`), else None; ``code``: one of
    :data:`ROW_ERROR_CODES`; ``message``: names the file, line and id.
    """

    line: int
    id: str | None
    code: str
    message: str


@dataclass
class ManifestReading:
    """What :func:`read_manifest_rows` found: the usable ``rows`` and the
    ``errors`` of the others, each in file order; ``path`` the manifest."""

    path: Path
    rows: list[ManifestRow] = field(default_factory=list)
    errors: list[ManifestRowError] = field(default_factory=list)


#: Asset ids name folders and files: letters, digits, ``_.-``, not starting with a dot.
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


def is_valid_id(text: str | None) -> bool:
    """Whether ``text`` is a usable asset id (letters, digits, ``_.-``, not
    starting with ``.``, ``_`` or ``-``)."""
    return bool(text) and _ID_RE.match(text) is not None


def _short(text: str, n: int = 80) -> str:
    """``repr`` of ``text``, cut to ``n`` characters (messages never echo a huge field)."""
    return repr(text) if len(text) <= n else repr(text[:n]) + f"... ({len(text)} characters)"


class _RowError(Exception):
    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


def _positive(where: str, rec: dict, column: str, code: str) -> float | None:
    text = (rec.get(column) or "").strip()
    if not text:
        return None
    try:
        value = float(text)
    except ValueError as exc:
        raise _RowError(code, f"{where}: {column} {_short(text)} is not a number") from exc
    if not (math.isfinite(value) and value > 0):
        raise _RowError(code, f"{where}: {column} must be a positive number, got {_short(text)}")
    return value


def _joint_range(where: str, rec: dict) -> tuple[float, float] | None:
    text = (rec.get("reference_joint_range") or "").strip().strip('"')
    if not text:
        return None
    try:
        vals = json.loads(text)
        return (float(vals[0]), float(vals[1]))
    except (ValueError, TypeError, IndexError, KeyError) as exc:
        raise _RowError("MANIFEST_INVALID_JOINT_RANGE",
                        f"{where}: reference_joint_range {_short(text)} is not [lo, hi] ({str(exc)[:80]})") from exc


class _Lines:
    """Iterator over the physical lines of a text that keeps the lines of
    the record being parsed (for the id of a record the CSV reader refuses)."""

    def __init__(self, text: str):
        self._it = iter(io.StringIO(text))
        self.record: list[str] = []

    def __iter__(self) -> "_Lines":
        return self

    def __next__(self) -> str:
        line = next(self._it)
        self.record.append(line)
        return line


def _id_of_refused(first_line: str, id_col: int) -> str | None:
    """The id field of a record the CSV reader refused, read from the start of
    its first line when it ends there (a field cut by the prefix is not used)."""
    try:
        fields = next(csv.reader([first_line[:_ID_PREFIX_CHARS].rstrip("\r\n")]))
    except (csv.Error, StopIteration):
        return None
    complete = len(fields) - (0 if len(first_line) <= _ID_PREFIX_CHARS else 1)
    return (fields[id_col].strip() or None) if id_col < complete else None


def read_manifest_rows(path: Path | str, root: Path | str | None = None) -> ManifestReading:
    """Read a manifest CSV (UTF-8, a byte-order mark allowed) row by row: the
    usable rows and a typed error for each row that is not, in file order;
    object folders under ``root`` (default: the manifest's folder). A bad row
    never hides the others.

    A row is refused (:class:`ManifestRowError`, codes in
    :data:`ROW_ERROR_CODES`) for: a field longer than the CSV field limit
    (``csv.field_size_limit()``, 131072 characters by default) or other CSV
    damage; no id, an unsafe id (letters, digits, ``_.-`` only) or an id an
    earlier row already used (also an earlier refused row); a row that ends
    before the ``prompt`` column; fields beyond the header (non-empty); a
    ``reference_scale`` or ``time_limit_seconds`` that is not a positive
    number; a ``reference_joint_range`` that is not ``[lo, hi]``. An empty
    prompt is a usable row (as for ``asset2sim refine``). Blank lines are skipped.

    Raises:
        FileNotFoundError / OSError: the manifest cannot be read.
        ManifestError: the whole file is unusable: not UTF-8 text
            (``MANIFEST_NOT_TEXT``), a header that is not CSV
            (``MANIFEST_BAD_HEADER``), or no ``id`` / ``prompt`` column
            (``MANIFEST_MISSING_COLUMNS``).
    """
    path = Path(path)
    base = path.parent if root is None else Path(root)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ManifestError(f"{path}: not a CSV manifest (not UTF-8 text: {exc.reason} at byte {exc.start})",
                            "MANIFEST_NOT_TEXT", path) from exc
    lines = _Lines(text)
    reader = csv.reader(lines)
    try:
        header = [h.strip() for h in next(reader, [])]
    except csv.Error as exc:
        raise ManifestError(f"{path}: the header line is not CSV ({exc})", "MANIFEST_BAD_HEADER", path) from exc
    missing = {"id", "prompt"} - set(header)
    if missing:
        raise ManifestError(f"{path}: missing column(s) {sorted(missing)} (header {header[:8]!r})",
                            "MANIFEST_MISSING_COLUMNS", path)
    id_col = header.index("id")
    prompt_col = header.index("prompt")
    out = ManifestReading(path=path)
    seen: set[str] = set()
    consumed = reader.line_num
    while True:
        line = consumed + 1
        lines.record = []
        try:
            fields = next(reader)
        except StopIteration:
            break
        except csv.Error as exc:
            consumed = reader.line_num
            rid = _id_of_refused(lines.record[0], id_col) if lines.record else None
            too_large = "field limit" in str(exc)
            code = "MANIFEST_ROW_TOO_LARGE" if too_large else "MANIFEST_ROW_MALFORMED"
            where = f"{path}:{line}" + (f" (id {rid})" if rid else "")
            what = f"a field is longer than the CSV field limit of {csv.field_size_limit()} characters" if too_large else str(exc)
            out.errors.append(ManifestRowError(line, rid, code, f"{where}: {what}"))
            if is_valid_id(rid):
                seen.add(rid)  # type: ignore[arg-type]
            continue
        consumed = reader.line_num
        if not fields or (len(fields) == 1 and not fields[0].strip()):
            continue  # a blank line
        rid = fields[id_col].strip() if id_col < len(fields) else ""
        try:
            out.rows.append(_row(path, base, line, header, fields, rid, prompt_col, seen))
        except _RowError as exc:
            out.errors.append(ManifestRowError(line, rid or None, exc.code, str(exc)))
        if is_valid_id(rid):
            seen.add(rid)
    return out


def _row(path: Path, base: Path, line: int, header: list[str], fields: list[str], rid: str, prompt_col: int,
         seen: set[str]) -> ManifestRow:
    """One usable row, or :class:`_RowError` naming the file, line and id."""
    if not rid:
        raise _RowError("MANIFEST_MISSING_ID", f"{path}:{line}: row without id")
    if not is_valid_id(rid):
        raise _RowError("MANIFEST_INVALID_ID", f"{path}:{line}: invalid asset id {_short(rid)}")
    if rid in seen:
        raise _RowError("MANIFEST_DUPLICATE_ID", f"{path}:{line}: duplicate asset id {rid!r}")
    where = f"{path}:{line} (id {rid})"
    if prompt_col >= len(fields):
        raise _RowError("MANIFEST_MISSING_PROMPT", f"{where}: the row has {len(fields)} field(s) and ends before the prompt column")
    extra = [f for f in fields[len(header):] if f.strip()]
    if extra:
        raise _RowError("MANIFEST_EXTRA_FIELDS", f"{where}: {len(fields)} fields for {len(header)} columns "
                        "(a comma in an unquoted prompt?)")
    rec = dict(zip(header, fields))
    return ManifestRow(
        id=rid,
        category=(rec.get("category") or "").strip(),
        prompt=(rec.get("prompt") or "").strip(),
        task=(rec.get("task") or "").strip(),
        gensim2_task=(rec.get("gensim2_task") or "").strip(),
        reference_scale=_positive(where, rec, "reference_scale", "MANIFEST_INVALID_REFERENCE_SCALE"),
        reference_joint_range=_joint_range(where, rec),
        time_limit_seconds=_positive(where, rec, "time_limit_seconds", "MANIFEST_INVALID_TIME_LIMIT"),
        folder=base / rid,
        line=line,
    )


def read_manifest(path: Path | str, root: Path | str | None = None) -> list[ManifestRow]:
    """Rows of a manifest CSV, in file order, all or nothing: the strict form
    of :func:`read_manifest_rows` for callers that cannot use part of a
    manifest. The refine flow and the benchmark use :func:`read_manifest_rows`
    (a bad row fails that asset alone).

    Raises:
        FileNotFoundError / OSError: the manifest cannot be read.
        ManifestError: the file is unusable (see :func:`read_manifest_rows`),
            or the first refused row (its ``code`` from
            :data:`ROW_ERROR_CODES`; the message names the file, line and id).
    """
    reading = read_manifest_rows(path, root)
    if reading.errors:
        err = reading.errors[0]
        more = f" (and {len(reading.errors) - 1} more bad row(s))" if len(reading.errors) > 1 else ""
        raise ManifestError(err.message + more, err.code, reading.path)
    return reading.rows
