"""``manifest.csv`` of a PartNet-Mobility dataset root: one row per object folder.

Columns ``id``, ``prompt`` (required), ``category``, ``task``, ``gensim2_task``, ``reference_scale``,
``reference_joint_range`` (JSON ``[lo, hi]``), ``time_limit_seconds``. Re-exported by
:mod:`asset2sim.tasks.ingest.partnet_mobility`.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

from asset2sim.package_data import package_yaml

__all__ = ["FILE_ERROR_CODES", "ROW_ERROR_CODES", "ManifestError", "ManifestReading", "ManifestRow", "ManifestRowError",
           "is_valid_id", "read_manifest", "read_manifest_rows"]

_MESSAGES = package_yaml(__package__, "messages.yaml")
#: Codes of a manifest row that cannot be used (:class:`ManifestRowError`; ``messages.yaml``) -> what each means.
ROW_ERROR_CODES: dict[str, str] = _MESSAGES["manifest_row_codes"]
#: Codes of a manifest that cannot be used at all (:class:`ManifestError`) -> what each means.
FILE_ERROR_CODES: dict[str, str] = _MESSAGES["manifest_file_codes"]
#: Characters of a refused row's first line read again to find its id (below the CSV field limit).
_ID_PREFIX_CHARS = 4096


class ManifestError(ValueError):
    """The manifest cannot be used at all (names the file, and the line for :func:`read_manifest`);
    ``code`` from :data:`FILE_ERROR_CODES` (or :data:`ROW_ERROR_CODES`), ``path`` the manifest."""

    def __init__(self, message: str, code: str = "MANIFEST_INVALID", path: Path | str | None = None):
        super().__init__(message)
        self.code = code
        self.path = None if path is None else Path(path)


@dataclass
class ManifestRow:
    """One row of ``manifest.csv``: ``id`` the object folder's name, ``reference_joint_range`` (lo, hi)
    rad or m, ``time_limit_seconds`` s, ``folder`` ``<root>/<id>``, ``line`` where the row starts."""

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
    """A manifest row that cannot be used: ``line`` where it starts, ``id`` as written (None when
    unreadable; it may itself be the problem), ``code`` from :data:`ROW_ERROR_CODES`, ``message``
    naming the file, line and id."""

    line: int
    id: str | None
    code: str
    message: str


@dataclass
class ManifestReading:
    """What :func:`read_manifest_rows` found: the usable ``rows`` and the ``errors`` of the others."""

    path: Path
    rows: list[ManifestRow] = field(default_factory=list)
    errors: list[ManifestRowError] = field(default_factory=list)


#: Asset ids name folders and files: letters, digits, ``_.-``, not starting with a dot.
_ID_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.\-]*$")


def is_valid_id(text: str | None) -> bool:
    """Whether ``text`` is a usable asset id (letters, digits, ``_.-``, starting with a letter or digit)."""
    return bool(text) and _ID_RE.match(text) is not None


def _short(text: str) -> str:
    """``repr`` of ``text``, cut to 80 characters (messages never echo a huge field)."""
    return repr(text) if len(text) <= 80 else repr(text[:80]) + f"... ({len(text)} characters)"


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


def _id_of_refused(first_line: str, id_col: int) -> str | None:
    """The id field of a record the CSV reader refused, from the start of its first line (None when cut)."""
    try:
        fields = next(csv.reader([first_line[:_ID_PREFIX_CHARS].rstrip("\r\n")]))
    except (csv.Error, StopIteration):
        return None
    complete = len(fields) - (0 if len(first_line) <= _ID_PREFIX_CHARS else 1)
    return (fields[id_col].strip() or None) if id_col < complete else None


def read_manifest_rows(path: Path | str, root: Path | str | None = None) -> ManifestReading:
    """Read a manifest CSV (UTF-8, a byte-order mark allowed) row by row: the usable rows and a
    :class:`ManifestRowError` (:data:`ROW_ERROR_CODES`) for each other, in file order; object folders
    under ``root`` (default: the manifest's folder). A bad row never hides the others; an id used by
    an earlier row (refused or not) is a duplicate; an empty prompt is usable; blank lines are skipped.

    Raises:
        FileNotFoundError / OSError: the manifest cannot be read.
        ManifestError: the whole file is unusable (:data:`FILE_ERROR_CODES`).
    """
    path = Path(path)
    base = path.parent if root is None else Path(root)
    try:
        text = path.read_bytes().decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ManifestError(f"{path}: not a CSV manifest (not UTF-8 text: {exc.reason} at byte {exc.start})",
                            "MANIFEST_NOT_TEXT", path) from exc
    record: list[str] = []  # the lines of the record being parsed

    def lines() -> Iterator[str]:
        for text_line in io.StringIO(text):
            record.append(text_line)
            yield text_line

    reader = csv.reader(lines())
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
    while True:
        line = reader.line_num + 1  # where the next record starts
        record.clear()
        try:
            fields = next(reader)
        except StopIteration:
            break
        except csv.Error as exc:
            rid = _id_of_refused(record[0], id_col) if record else None
            too_large = "field limit" in str(exc)
            code = "MANIFEST_ROW_TOO_LARGE" if too_large else "MANIFEST_ROW_MALFORMED"
            where = f"{path}:{line}" + (f" (id {rid})" if rid else "")
            what = f"a field is longer than the CSV field limit of {csv.field_size_limit()} characters" if too_large else str(exc)
            out.errors.append(ManifestRowError(line, rid, code, f"{where}: {what}"))
        else:
            if not fields or (len(fields) == 1 and not fields[0].strip()):
                continue  # a blank line
            rid = fields[id_col].strip() if id_col < len(fields) else ""
            try:
                out.rows.append(_row(path, base, line, header, fields, rid, prompt_col, seen))
            except _RowError as exc:
                out.errors.append(ManifestRowError(line, rid or None, exc.code, str(exc)))
        if is_valid_id(rid):
            seen.add(rid)  # type: ignore[arg-type]
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
    text = {k: (rec.get(k) or "").strip() for k in ("category", "prompt", "task", "gensim2_task")}
    return ManifestRow(
        id=rid, **text, reference_scale=_positive(where, rec, "reference_scale", "MANIFEST_INVALID_REFERENCE_SCALE"),
        reference_joint_range=_joint_range(where, rec),
        time_limit_seconds=_positive(where, rec, "time_limit_seconds", "MANIFEST_INVALID_TIME_LIMIT"), folder=base / rid,
        line=line)


def read_manifest(path: Path | str, root: Path | str | None = None) -> list[ManifestRow]:
    """Rows of a manifest CSV, in file order, all or nothing (the strict :func:`read_manifest_rows`).

    Raises:
        FileNotFoundError / OSError: the manifest cannot be read.
        ManifestError: the file is unusable, or the first refused row (its code and message).
    """
    reading = read_manifest_rows(path, root)
    if reading.errors:
        err = reading.errors[0]
        more = f" (and {len(reading.errors) - 1} more bad row(s))" if len(reading.errors) > 1 else ""
        raise ManifestError(err.message + more, err.code, reading.path)
    return reading.rows
