"""One row of the Parquet result catalog (:class:`CatalogRow`), the contract
between the flow and :class:`asset2sim.flows.catalog.ResultCatalog`; the
Parquet schema is derived from its fields (:func:`arrow_schema`). Units are in
the column names (``_mm``, ``_m``, ``_rad``, ``_kg``, ``_seconds``, ``_pct``).
"""

from __future__ import annotations

import math
import types
import typing
from datetime import datetime
from typing import Literal

from pydantic import BaseModel, ConfigDict, field_validator

from asset2sim.schemas import Strict

#: Version of the row schema in every Parquet file's metadata; columns are only
#: ever added (nullable), so a reader of version N reads every older file
#: (version 2 added ``code_hash``, version 3 ``request_warnings``, version 4 ``clips``, version 5 ``operable`` and
#: ``operating_efforts``, version 6 ``request_met`` and ``request_unmet``, version 7 ``media``, version 8 ``learnable`` and
#: ``learnability``, version 9 ``postcheck_rounds`` and ``extra_rounds``).
SCHEMA_VERSION = 9
SCHEMA_VERSION_KEY = b"asset2sim.catalog_schema_version"

RowStatus = Literal["done", "skipped", "failed"]
ROW_STATUSES: tuple[str, ...] = RowStatus.__args__  # type: ignore[attr-defined]


class CatalogRow(Strict):
    """One asset's result in one flow run (``dataset`` and ``run`` are the
    partition folders): ``status`` done, skipped (``source_run`` reused) or
    failed; ``initial_state`` JSON {joint: rad or m}; ``stage_seconds`` JSON
    {stage: s}; ``request_warnings`` JSON [text]: what of the request was not
    understood or not applied; ``request_met``: the as-asked verdict (every part and state the request names
    applied, every number within its tolerance; null without a request), ``request_unmet`` JSON [{phrase, kind,
    target, achieved, gap, unit, text, ...}]: what was not; ``operable``: every handled part moved by a hand inside its real operating range;
    ``operating_efforts`` JSON {joint: {peak_force_n, peak_torque_nm, force_range_n, ...}}; ``clips`` JSON [path]: the output's interaction clips (WebM), relative to
    ``out_dir``; ``media``: the output's media phase (renders, clips, ``report.html``) when the row was written:
    ``done``, ``deferred`` (``asset2sim report OUT`` makes it) or ``off``; ``learnable``: a trained policy learned the
    asset's task (false: on no seed while it learned it on other assets; null: not measured or undecided),
    ``learnability`` JSON {verdict, seeds, success, passive, learned_on, action, framework, budget}, written by the
    learnability benchmark (:mod:`asset2sim.flows.learnability`); ``postcheck_rounds``: the post-check rounds the refine
    ran (1: its first post-check decided), ``extra_rounds`` JSON [{round, after, reason}]: what started each round after
    the first (``after``: the checks that failed the round before, a robust-rest check with its failing trials;
    ``reason``: the round's own account); ``code_hash`` what the skip rule compares.
    Non-finite floats are null."""

    model_config = ConfigDict(validate_assignment=True)

    asset_id: str
    category: str | None = None
    prompt: str | None = None
    status: RowStatus
    failure_mode: str | None = None
    error: str | None = None
    estimator: str | None = None
    model: str | None = None
    scale: float | None = None
    reference_scale: float | None = None
    scale_deviation_pct: float | None = None
    total_mass_kg: float | None = None
    initial_state: str | None = None
    penetration_mm: float | None = None
    rest_stable: bool | None = None
    d_pos_m: float | None = None
    d_ori_rad: float | None = None
    oscillation_pass: bool | None = None
    prompt_alignment: float | None = None
    operable: bool | None = None
    operating_efforts: str | None = None
    request_warnings: str | None = None
    request_met: bool | None = None
    request_unmet: str | None = None
    clips: str | None = None
    media: str | None = None
    learnable: bool | None = None
    learnability: str | None = None
    postcheck_rounds: int | None = None
    extra_rounds: str | None = None
    model_queries: int | None = None
    tokens: int | None = None
    wall_seconds: float | None = None
    stage_seconds: str | None = None
    input_hash: str | None = None
    config_hash: str | None = None
    refine_config_hash: str | None = None
    code_version: str | None = None
    code_hash: str | None = None
    out_dir: str | None = None
    source_run: str | None = None
    flow_run_id: str | None = None
    worker: str | None = None
    started_at: datetime | None = None
    finished_at: datetime | None = None

    @field_validator("*", mode="before")
    @classmethod
    def _finite(cls, v):
        """NaN / inf floats (and NaN-like missing values) become null."""
        if isinstance(v, float) and not math.isfinite(v):
            return None
        return v


#: Column names of a catalog row, in order.
ROW_COLUMNS: tuple[str, ...] = tuple(CatalogRow.model_fields)


def arrow_type(annotation):
    """The Arrow type of a pydantic field's annotation (str, a Literal, bool, int, float, datetime, each optionally
    None). Raises TypeError: any other annotation."""
    import pyarrow as pa

    args = [a for a in typing.get_args(annotation) if a is not type(None)]
    base = args[0] if typing.get_origin(annotation) in (typing.Union, types.UnionType) else annotation
    if typing.get_origin(base) is Literal:
        return pa.string()
    by_type = {str: pa.string(), bool: pa.bool_(), int: pa.int64(), float: pa.float64(), datetime: pa.timestamp("us", tz="UTC")}
    if base not in by_type:
        raise TypeError(f"no Parquet type for {annotation!r}")
    return by_type[base]


def model_arrow_schema(model: type[BaseModel], **own_types):
    """The Arrow schema of a pydantic model's rows: one nullable column per field, in order, of its
    :func:`arrow_type` (``own_types``: a field's Arrow type when it is not that)."""
    import pyarrow as pa

    return pa.schema([(name, own_types.get(name) or arrow_type(f.annotation)) for name, f in model.model_fields.items()])


def parquet_models(path, model: type[BaseModel]) -> list:
    """The rows of the Parquet file ``path`` as ``model`` instances. Raises OSError (unreadable), ValueError (not
    a Parquet file, or rows that are not ``model``'s)."""
    import pyarrow.parquet as pq

    return [model.model_validate(row) for row in pq.read_table(path).to_pylist()]


def parquet_bytes(table, **write_options) -> bytes:
    """An Arrow table as the bytes of a Parquet file (``write_options``: :func:`pyarrow.parquet.write_table`'s)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    sink = pa.BufferOutputStream()
    pq.write_table(table, sink, **write_options)
    return sink.getvalue().to_pybytes()


def arrow_schema(with_version: bool = False):
    """The Parquet (pyarrow) schema of :class:`CatalogRow`, every column
    nullable; ``with_version``: :data:`SCHEMA_VERSION` in its metadata."""
    schema = model_arrow_schema(CatalogRow)
    if with_version:
        schema = schema.with_metadata({SCHEMA_VERSION_KEY: str(SCHEMA_VERSION).encode()})
    return schema
