"""Realism scores per method from people's ratings of one pair set: Bradley-Terry
(:mod:`asset2sim.apps.realism.bradley_terry`) over the answers of ``ratings.sqlite`` (else
``ratings.parquet``), written to ``realism_scores.parquet`` beside ``pairs.json`` (rows of
:class:`asset2sim.schemas.realism.MethodScore`).

``realism_scores.parquet`` may also hold the scores of model judges: writing the scores of one source
replaces that source's rows only and keeps the others.
"""

from __future__ import annotations

from pathlib import Path

from asset2sim import atomic
from asset2sim.schemas.catalog import model_arrow_schema, parquet_bytes, parquet_models
from asset2sim.schemas.realism import MethodScore
from asset2sim.apps.realism.bradley_terry import ELO_PER_UNIT, fit_bradley_terry
from asset2sim.apps.realism.ratings import DATABASE_FILE, RATINGS_FILE, PairSetError, RatingStore, read_ratings

SCORES_FILE = "realism_scores.parquet"
#: The source of scores from people's ratings.
PEOPLE = "people"


class NotRated(ValueError):
    """No answer to score (realism is then "not rated", never invented)."""


def read_scores(path: Path | str) -> list[MethodScore]:
    """The :class:`MethodScore` rows of a ``realism_scores.parquet`` (PairSetError naming the file when it is
    not one)."""
    try:
        return parquet_models(path, MethodScore)
    except (OSError, ValueError) as exc:
        raise PairSetError(path, f"not a realism scores table: {exc}") from exc


def write_scores(path: Path | str, scores: list[MethodScore]) -> Path:
    """Write ``scores`` into the Parquet file ``path`` atomically, keeping the rows already there whose
    ``source`` none of ``scores`` has; returns the path. Raises PairSetError (an unreadable existing file),
    OSError."""
    import pyarrow as pa

    path = Path(path)
    sources = {s.source for s in scores}
    kept = [s for s in read_scores(path) if s.source not in sources] if path.exists() else []
    return atomic.write_bytes(path, parquet_bytes(pa.Table.from_pylist([s.model_dump() for s in [*kept, *scores]],
                                                                        schema=model_arrow_schema(MethodScore))))


def realism_scores(folder: Path | str, *, write: bool = True) -> list[MethodScore]:
    """Bradley-Terry scores (source ``people``) from the ratings of the pair set in ``folder``: the answers of
    ``ratings.sqlite`` (``ratings.parquet`` is synced from it first), else those of ``ratings.parquet``;
    written to ``folder/realism_scores.parquet`` unless ``write`` is False (:func:`write_scores`).

    Returns the scores, strongest first (:func:`fit_bradley_terry`).

    Raises:
        FileNotFoundError: ``folder`` holds no ``pairs.json``.
        PairSetError: ``pairs.json`` or ``ratings.parquet`` unreadable.
        NotRated: no answers yet, or answers comparing fewer than two methods.
        OSError: the folder cannot be written.
    """
    folder = Path(folder)
    if (folder / DATABASE_FILE).exists() or not (folder / RATINGS_FILE).exists():
        with RatingStore(folder) as store:
            ratings = store.ratings()
            if ratings:
                store.sync_parquet()
    else:
        ratings = read_ratings(folder / RATINGS_FILE)
    if not ratings:
        raise NotRated(f"{folder}: no ratings yet: realism is not rated")
    try:  # a pair showing one method on both sides tells nothing about methods
        scores = fit_bradley_terry([(r.winner, r.loser) for r in ratings if r.winner != r.loser], source=PEOPLE)
    except ValueError as exc:
        raise NotRated(f"{folder}: {exc}") from exc
    if write:
        write_scores(folder / SCORES_FILE, scores)
    return scores


#: What the benchmark's realism column says of a method nobody and no calibrated model rated.
NOT_RATED = "not rated"


def realism_column(pair_set: Path | str | None, methods: list[str]) -> dict[str, str]:
    """The ``realism`` column of ``asset2sim benchmark``: per method, its Bradley-Terry Elo with the 95 % interval
    and the comparisons behind it (``1043 Elo [1010, 1076], people, 40``) from ``pair_set/realism_scores.parquet``,
    people's scores first, else the first judge model's (only calibrated models' scores are written there);
    :data:`NOT_RATED` for every method without a score, and for all when there is no scores file. Raises
    PairSetError: the scores file is unreadable."""
    path = None if pair_set is None else Path(pair_set) / SCORES_FILE
    if path is None or not path.is_file():
        return {m: NOT_RATED for m in methods}
    by_source: dict[str, dict[str, MethodScore]] = {}
    for s in read_scores(path):
        by_source.setdefault(s.source, {})[s.method] = s
    source = PEOPLE if PEOPLE in by_source else min(by_source, default=None)
    got = by_source.get(source, {})  # no source (None): no score
    return {m: f"{s.elo:.0f} Elo [{1000.0 + ELO_PER_UNIT * s.ci_low:.0f}, {1000.0 + ELO_PER_UNIT * s.ci_high:.0f}], {source}, "
               f"{s.comparisons}" if (s := got.get(m)) is not None else NOT_RATED for m in methods}


def judge_scores(folder: Path | str, verdicts, calibration, *, write: bool = True) -> list[MethodScore]:
    """Bradley-Terry scores (source: the model) of every calibrated judge
    (:func:`asset2sim.apps.realism.calibration.judge_calibration`) from its kept verdicts on the pairs without a planted
    defect (:func:`~asset2sim.apps.realism.calibration.kept_comparisons`), written to ``folder/realism_scores.parquet``
    beside people's (:func:`write_scores`). An uncalibrated model's verdicts are noise: it gets no score. Returns the
    scores written; models whose kept verdicts compare fewer than two methods are left out."""
    from asset2sim.apps.realism.calibration import kept_comparisons

    out: list[MethodScore] = []
    for m in calibration.models:
        if not m.calibrated:
            continue
        try:
            out += fit_bradley_terry(kept_comparisons(verdicts, m.model), source=m.model)
        except ValueError:  # no plain pair kept, or one method only
            continue
    if write and out:
        write_scores(Path(folder) / SCORES_FILE, out)
    return out
