"""People's ratings of one pair set: which pair a rater sees next, on which side each clip is shown, the
answers in ``ratings.sqlite`` beside ``pairs.json`` and their copy ``ratings.parquet`` (rows of
:class:`asset2sim.schemas.realism.Rating`).

The SQLite database (WAL journal, one connection per thread, writes in ``BEGIN IMMEDIATE`` transactions,
10 s busy timeout) is the record: an answer is kept once :meth:`RatingStore.record` returns, whatever
happens next. ``ratings.parquet`` is rewritten from it atomically (:meth:`RatingStore.sync_parquet`),
after every answer by the rating app and whenever a store is opened, so a copy missed by a crash is made
at the next start.

Blinding: which side of a pair (``a`` or ``b``) is shown on the left is the lowest bit of
``sha256("asset2sim-realism-side\\0" + rater + "\\0" + pair_id)`` (:func:`left_slot`): fixed for one rater
and pair (a reload or a restart shows the same layout), independent between raters and pairs, balanced
over many; the rater never sees the pair id, so cannot compute it.

Order: a rater is shown the pair they were shown and have not answered yet, if any; otherwise, of the pairs
they have not answered, the one shown to the fewest raters so far (coverage spreads over raters), ties
broken by ``sha256("asset2sim-realism-order\\0" + rater + "\\0" + pair_id)`` (each rater a different
order; deterministic given the answers stored). A pair counts as seen once answered, and is then never
shown to that rater again.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import secrets
import sqlite3
import stat
import threading
import time
from pathlib import Path
from typing import Iterator, Literal, NamedTuple

from asset2sim import atomic, output_folder
from asset2sim.schemas.catalog import model_arrow_schema, parquet_bytes, parquet_models
from asset2sim.schemas.realism import ClipPair, PairSide, Rating
from asset2sim.apps.realism.pair_set import PAIRS_JSON as PAIRS_FILE, PairSetError, read_pair_set

DATABASE_FILE = "ratings.sqlite"
RATINGS_FILE = "ratings.parquet"
#: A rater id: 1-32 letters, digits, ``.``, ``_`` or ``-``, starting with a letter or digit.
RATER_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,31}")
#: Longest comment kept, characters.
MAX_COMMENT = 2000
#: Seconds a writer waits for another's transaction (SQLite busy timeout).
BUSY_TIMEOUT_S = 10.0

Slot = Literal["a", "b"]

_SCHEMA = """
CREATE TABLE IF NOT EXISTS shown (
    rater TEXT NOT NULL, pair_id TEXT NOT NULL, shown_at REAL NOT NULL, PRIMARY KEY (rater, pair_id));
CREATE TABLE IF NOT EXISTS ratings (
    rater TEXT NOT NULL, pair_id TEXT NOT NULL, object_id TEXT NOT NULL, left TEXT NOT NULL, right TEXT NOT NULL,
    choice TEXT NOT NULL, winner TEXT NOT NULL, loser TEXT NOT NULL, score INTEGER, comment TEXT NOT NULL,
    shown_at REAL NOT NULL, answered_at REAL NOT NULL, seconds REAL NOT NULL, PRIMARY KEY (rater, pair_id));
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value BLOB NOT NULL);
"""
_COLUMNS = tuple(Rating.model_fields)
_INSERT = f"INTO ratings ({', '.join(_COLUMNS)}) VALUES ({', '.join('?' * len(_COLUMNS))})"
_SELECT = f"SELECT {', '.join(_COLUMNS)} FROM ratings"


class RatingsDatabaseError(PairSetError):
    """``ratings.sqlite`` cannot be opened or read as a ratings database (damaged, or not one): the message says
    what to do; the file is left as it is. Code ``RATINGS_DATABASE_DAMAGED``."""

    code = "RATINGS_DATABASE_DAMAGED"


class RatingError(ValueError):
    """An answer or rater id the store refuses (``code``: ``RATER_INVALID``, ``PAIR_UNKNOWN``, ``PAIR_NOT_SHOWN``,
    ``ANSWER_INVALID`` or ``ANSWER_CONFLICT``)."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


class Showing(NamedTuple):
    """A pair as one rater sees it: ``left`` / ``right`` the slots (``a`` / ``b``) shown on each side."""

    pair: ClipPair
    left: Slot
    right: Slot


class Recorded(NamedTuple):
    """The stored answer and whether this call stored it (False: the same answer was already stored)."""

    rating: Rating
    created: bool


def check_rater(rater: str) -> str:
    """``rater`` if a valid rater id (:data:`RATER_PATTERN`), else RatingError ``RATER_INVALID``."""
    if not isinstance(rater, str) or not RATER_PATTERN.fullmatch(rater):
        raise RatingError("RATER_INVALID", f"rater id {rater!r}: use 1-32 letters, digits, '.', '_' or '-', "
                                           "starting with a letter or digit")
    return rater


def _digest(kind: str, rater: str, pair_id: str) -> bytes:
    return hashlib.sha256(f"asset2sim-realism-{kind}\0{rater}\0{pair_id}".encode()).digest()


def left_slot(rater: str, pair_id: str) -> Slot:
    """The slot shown on the left to ``rater`` for pair ``pair_id``: the lowest bit of a SHA-256 digest of both
    (module docstring, "Blinding")."""
    return "b" if _digest("side", rater, pair_id)[-1] & 1 else "a"


def side(pair: ClipPair, slot: Slot) -> PairSide:
    """The side of ``pair`` in ``slot`` (``a`` or ``b``)."""
    return pair.a if slot == "a" else pair.b


class RatingStore:
    """The ratings of the pair set in ``folder`` (``pairs.json``; ``ratings.sqlite`` created beside it).

    Safe for many threads at once (one SQLite connection per thread) and for several processes (SQLite
    locking). Opening checks the database (SQLite's ``quick_check``), loads the answers of ``ratings.parquet``
    back into a database that has none (a new one, after a damaged one was moved aside: the copy is the
    backup), then syncs ``ratings.parquet`` when the database holds answers it may lack.

    Raises (on opening): FileNotFoundError, PairSetError (:func:`read_pair_set`, or an unreadable
    ``ratings.parquet`` beside an empty database); :class:`RatingsDatabaseError` when ``ratings.sqlite`` is
    damaged or not a ratings database (left as it is; the message says what to do).
    """

    def __init__(self, folder: Path | str):
        self.folder = Path(folder).resolve()
        self.pair_set = read_pair_set(self.folder)
        self.pairs = list(self.pair_set.pairs)
        self.index = {p.pair_id: i for i, p in enumerate(self.pairs)}
        self.database = output_folder.check_destination(self.folder / DATABASE_FILE, self.folder)  # SQLite follows symlinks
        self.parquet = self.folder / RATINGS_FILE
        self._local = threading.local()
        self._connections: list[sqlite3.Connection] = []
        self._lock = threading.Lock()
        self._sync_lock = threading.Lock()
        self.closed = False
        try:
            con = self._con()
            (check,) = con.execute("PRAGMA quick_check").fetchone()
            if check != "ok":
                raise sqlite3.DatabaseError(f"integrity check: {check}")
            con.executescript(_SCHEMA)
            if not self.count() and self.parquet.exists():
                self._load_parquet()
            stored = self.count()
        except sqlite3.DatabaseError as exc:
            self.close()
            raise self._damaged(exc) from None
        except BaseException:  # ratings.parquet unreadable (PairSetError naming it): nothing overwritten
            self.close()
            raise
        if stored or self.parquet.exists():
            self.sync_parquet()

    def _damaged(self, exc: sqlite3.DatabaseError) -> RatingsDatabaseError:
        if isinstance(exc, sqlite3.OperationalError):  # locked, unreadable, read-only folder: not damage
            err = RatingsDatabaseError(self.database, f"cannot be opened ({exc}); check that the folder can be "
                                                      "written and that no other program holds the file")
            err.code = "RATINGS_DATABASE_UNAVAILABLE"
            return err
        backup = f"; {self.parquet.name} beside it holds a copy of the answers, loaded back when the app starts " \
                 "without the damaged file" if self.parquet.exists() else ""
        return RatingsDatabaseError(self.database, (
            f"not a readable ratings database ({exc}); it was left as it is{backup}. Move it aside "
            f"(e.g. mv {self.database} {self.database}.damaged) and start again, or restore it from a backup"))

    def _load_parquet(self) -> None:
        """Copy the answers of ``ratings.parquet`` (and when each pair was shown) into the empty database."""
        rows = read_ratings(self.parquet)
        with self._transaction() as con:
            for r in rows:
                con.execute("INSERT OR IGNORE INTO shown VALUES (?, ?, ?)", (r.rater, r.pair_id, r.shown_at))
                con.execute(f"INSERT OR IGNORE {_INSERT}", tuple(getattr(r, c) for c in _COLUMNS))

    def form_secret(self) -> bytes:
        """The secret of the rating app's form tokens: 32 random bytes made once and kept in the database (so
        a restart keeps open forms valid)."""
        con = self._con()
        con.execute("INSERT OR IGNORE INTO meta VALUES ('form_secret', ?)", (secrets.token_bytes(32),))
        (value,) = con.execute("SELECT value FROM meta WHERE key = 'form_secret'").fetchone()
        return bytes(value)

    # connections -------------------------------------------------------------------------------------
    @contextlib.contextmanager
    def _transaction(self) -> Iterator[sqlite3.Connection]:
        """The thread's connection in a ``BEGIN IMMEDIATE`` transaction: committed when the block ends (a ``return``
        in it included), rolled back when it raises."""
        con = self._con()
        con.execute("BEGIN IMMEDIATE")
        try:
            yield con
            con.execute("COMMIT")
        except BaseException:
            if con.in_transaction:
                con.execute("ROLLBACK")
            raise

    def _con(self) -> sqlite3.Connection:
        if self.closed:
            raise RuntimeError(f"the rating store of {self.folder} is closed")
        con = getattr(self._local, "con", None)
        if con is None:
            con = sqlite3.connect(self.database, timeout=BUSY_TIMEOUT_S, isolation_level=None, check_same_thread=False)
            try:
                con.execute("PRAGMA journal_mode=WAL")
                con.execute("PRAGMA synchronous=FULL")  # an answer survives a power cut once record() returns
            except sqlite3.Error:
                con.close()
                raise
            self._local.con = con
            with self._lock:
                self._connections.append(con)
        return con

    def close(self) -> None:
        """Close every thread's connection (the store cannot be used afterwards)."""
        with self._lock:
            self.closed = True
            for con in self._connections:
                con.close()
            self._connections.clear()

    def __enter__(self) -> RatingStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # showing -----------------------------------------------------------------------------------------
    def showing(self, rater: str, pair_id: str) -> Showing:
        """``pair_id`` as ``rater`` sees it (RatingError ``PAIR_UNKNOWN``, ``RATER_INVALID``)."""
        check_rater(rater)
        if pair_id not in self.index:
            raise RatingError("PAIR_UNKNOWN", f"no pair {pair_id!r} in {self.folder / PAIRS_FILE}")
        left: Slot = left_slot(rater, pair_id)
        return Showing(self.pairs[self.index[pair_id]], left, "b" if left == "a" else "a")

    def next_pair(self, rater: str, now: float | None = None) -> Showing | None:
        """The pair ``rater`` is shown now (module docstring, "Order"), its first showing recorded at ``now``
        (POSIX s, default the clock); None when the rater has answered every pair.

        Raises: RatingError ``RATER_INVALID``.
        """
        check_rater(rater)
        with self._transaction() as con:
            answered = {r for (r,) in con.execute("SELECT pair_id FROM ratings WHERE rater = ?", (rater,))}
            pending = [p for (p,) in con.execute(
                "SELECT pair_id FROM shown WHERE rater = ? ORDER BY shown_at, pair_id", (rater,))
                if p not in answered and p in self.index]
            if pending:
                pair_id = pending[0]
            else:
                todo = [p.pair_id for p in self.pairs if p.pair_id not in answered]
                if not todo:
                    return None
                viewers = dict(con.execute("SELECT pair_id, COUNT(*) FROM shown GROUP BY pair_id").fetchall())
                pair_id = min(todo, key=lambda p: (viewers.get(p, 0), _digest("order", rater, p)))
                con.execute("INSERT INTO shown VALUES (?, ?, ?)", (rater, pair_id, time.time() if now is None else now))
        return self.showing(rater, pair_id)

    def progress(self, rater: str) -> tuple[int, int]:
        """(pairs ``rater`` has answered, pairs in the set)."""
        check_rater(rater)
        (n,) = self._con().execute("SELECT COUNT(*) FROM ratings WHERE rater = ?", (rater,)).fetchone()
        return int(n), len(self.pairs)

    # answers -----------------------------------------------------------------------------------------
    def record(self, rater: str, pair_id: str, choice: str, *, score: int | None = None, comment: str = "",
               now: float | None = None) -> Recorded:
        """Store ``rater``'s answer to pair ``pair_id``: ``choice`` ``left`` or ``right`` (the side of the layout
        :meth:`next_pair` showed), ``score`` an optional 1-5 realism score of the chosen side, ``comment``
        free text (at most :data:`MAX_COMMENT` characters, stripped); ``now`` the answer's POSIX time, s.

        Posting the same answer again returns the stored one (``created`` False): idempotent.

        Raises:
            RatingError: ``RATER_INVALID``; ``PAIR_UNKNOWN``; ``PAIR_NOT_SHOWN`` (the pair was never shown to
                the rater); ``ANSWER_INVALID`` (choice, score or comment out of range); ``ANSWER_CONFLICT`` (the
                rater already gave this pair a different answer; the first is kept).
        """
        shown = self.showing(rater, pair_id)
        if choice not in ("left", "right"):
            raise RatingError("ANSWER_INVALID", f"choice must be 'left' or 'right', got {choice!r}")
        if score is not None and (isinstance(score, bool) or not isinstance(score, int) or not 1 <= score <= 5):
            raise RatingError("ANSWER_INVALID", f"score must be an integer 1-5 or empty, got {score!r}")
        comment = (comment or "").strip()
        if len(comment) > MAX_COMMENT:
            raise RatingError("ANSWER_INVALID", f"comment longer than {MAX_COMMENT} characters")
        left, right = side(shown.pair, shown.left).method, side(shown.pair, shown.right).method
        winner, loser = (left, right) if choice == "left" else (right, left)
        answered_at = time.time() if now is None else float(now)
        with self._transaction() as con:
            old = con.execute(f"{_SELECT} WHERE rater = ? AND pair_id = ?", (rater, pair_id)).fetchone()
            if old is not None:
                stored = Rating(**dict(zip(_COLUMNS, old)))
                if (stored.choice, stored.score, stored.comment) != (choice, score, comment):
                    raise RatingError("ANSWER_CONFLICT", f"rater {rater} already answered this pair "
                                                         f"({stored.choice}); the first answer is kept")
                return Recorded(stored, False)
            row = con.execute("SELECT shown_at FROM shown WHERE rater = ? AND pair_id = ?", (rater, pair_id)).fetchone()
            if row is None:
                raise RatingError("PAIR_NOT_SHOWN", f"pair {self.index[pair_id]} was not shown to rater {rater}")
            rating = Rating(rater=rater, pair_id=pair_id, object_id=shown.pair.object_id, left=left, right=right,
                            choice=choice, winner=winner, loser=loser, score=score, comment=comment, shown_at=row[0],
                            answered_at=answered_at, seconds=max(0.0, answered_at - row[0]))
            con.execute(f"INSERT {_INSERT}", tuple(getattr(rating, c) for c in _COLUMNS))
        return Recorded(rating, True)

    def ratings(self) -> list[Rating]:
        """Every stored answer, in the order answered (ties by rater, pair id)."""
        rows = self._con().execute(f"{_SELECT} ORDER BY answered_at, rater, pair_id")
        return [Rating(**dict(zip(_COLUMNS, r))) for r in rows]

    def count(self) -> int:
        """How many answers are stored."""
        return int(self._con().execute("SELECT COUNT(*) FROM ratings").fetchone()[0])

    def sync_parquet(self) -> Path:
        """Rewrite ``ratings.parquet`` from the database, atomically (:func:`asset2sim.atomic.write_bytes`),
        readable by the file's group; returns its path. Raises OSError when the folder cannot be written."""
        import pyarrow as pa

        with self._sync_lock:
            schema = model_arrow_schema(Rating, score=pa.int8())
            table = pa.Table.from_pylist([r.model_dump() for r in self.ratings()], schema=schema)
            atomic.write_bytes(self.parquet, parquet_bytes(table))
            mode = os.stat(self.parquet).st_mode
            if not mode & stat.S_IRGRP:
                os.chmod(self.parquet, stat.S_IMODE(mode) | stat.S_IRGRP)
        return self.parquet


def read_ratings(path: Path | str) -> list[Rating]:
    """The :class:`Rating` rows of a ``ratings.parquet`` file (PairSetError naming the file when it is not one)."""
    try:
        return parquet_models(path, Rating)
    except (OSError, ValueError) as exc:
        raise PairSetError(path, f"not a ratings table: {exc}") from exc
