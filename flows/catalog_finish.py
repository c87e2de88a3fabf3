"""The end of a flow run in the result catalog: compact the run's partition,
compare the run with the previous one and write the comparison's artifacts;
a step that fails is recorded in :attr:`RunFinish.errors` and loses no row.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from asset2sim.flows import queries
from asset2sim.flows.catalog import Compaction, ResultCatalog
from asset2sim.flows.catalog_config import ResultsSettings
from asset2sim.flows.catalog_compare import RunComparison, compare_with_previous, write_comparison_artifacts


@dataclass
class RunFinish:
    """What :func:`finish_run` did: the compaction (None when off or it
    failed), the comparison, the artifact files (name -> path) and the
    errors of steps that failed (text)."""

    compaction: Compaction | None
    comparison: RunComparison
    artifacts: dict[str, Path] = field(default_factory=dict)
    errors: list[str] = field(default_factory=list)


def finish_run(store: ResultCatalog, dataset: str, run: str, out_dir: Path | str,
               settings: ResultsSettings) -> RunFinish:
    """Compact (``settings.compact``), compare with the previous run
    (``settings.regression``) and write the comparison's artifacts into ``out_dir``.

    Raises:
        OSError: the catalog cannot be read at all (the comparison needs it).
    """
    errors: list[str] = []
    compaction = None
    if settings.compact:
        try:
            compaction = store.compact(dataset, run)
        except OSError as exc:  # the row files stay and read as before
            errors.append(f"compaction of {dataset}/{run} failed: {type(exc).__name__}: {exc}")
    finish = RunFinish(compaction=compaction, comparison=compare_with_previous(store, dataset, run, settings.regression),
                       errors=errors)
    try:
        history = queries.pass_rates_over_time(store.read(dataset, columns=list(queries.PASS_RATE_COLUMNS)), dataset)
        finish.artifacts = write_comparison_artifacts(finish.comparison, history, out_dir)
    except OSError as exc:
        errors.append(f"comparison artifacts not written: {type(exc).__name__}: {exc}")
    return finish
