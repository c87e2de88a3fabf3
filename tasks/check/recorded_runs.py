"""The manipulation tiers (joint sweep, robust rest, task execution) measured once per set of
inputs, reused by every check of the same files: the post-check records each
run under a digest of all its inputs (:func:`input_digest`) and refine's
evaluation takes it from there (deterministic simulation: the same inputs
can only repeat the run); any difference in the inputs simulates again.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from asset2sim import file_memo, mesh_io
from asset2sim.tasks.check import operability, robust_rest, sweep, task_execution
from asset2sim.tasks.check.gripper_motion import TaskConfig
from asset2sim.engines.source import SimObject
from asset2sim.urdf import UrdfModel, write_urdf


def _mesh_identities(model: UrdfModel) -> list[tuple[str, str] | str]:
    """(filename as written, sha256 of the bytes) of every mesh file ``model`` references, in file order (the
    filename alone when unreadable): the same for a candidate in the refine's scratch folder and the output it
    publishes."""
    out: list[tuple[str, str] | str] = []
    for link in model.links.values():
        for g in [*link.collisions, *link.visuals]:
            if g.kind != "mesh" or not g.filename:
                continue
            p = Path(g.path) if g.path is not None else Path(model.path or ".").parent / str(g.filename)
            key = str(p.resolve())
            digest = _MESH_DIGESTS.get(key)
            if digest is None:
                files = file_memo.identities([p])  # before reading: a file changed while read is not remembered
                try:
                    digest = hashlib.sha256(mesh_io.file_bytes(p)).hexdigest()
                except OSError:
                    out.append(str(g.filename))
                    continue
                _MESH_DIGESTS.put(key, files, digest)
            out.append((str(g.filename), digest))
    return out


#: sha256 of mesh files by resolved path, while the file is unchanged (:class:`asset2sim.file_memo.FileMemo`).
_MESH_DIGESTS: file_memo.FileMemo[str] = file_memo.FileMemo(lambda d: d, max_entries=4096)


def input_digest(tier: str, engine: str, obj: SimObject, config: Any,
                 closed: dict[str, tuple[float, float, float]] | None = None) -> str:
    """SHA-256 (hex) of everything a manipulation tier (``tier``) reads: the
    engine, the URDF of ``obj.source`` (its model as written) and its meshes' identities, ``obj``'s initial state
    and springs (order-free), its conventions and root, the tier's ``config`` (a dataclass, or a tuple of one and the
    tier's other arguments) and the sweep's ``closed`` ends in order. Floats enter by ``repr`` (exact).

    Raises:
        UrdfError: the source's URDF cannot be read.
    """
    model = obj.source.model(mode="lenient")
    h = hashlib.sha256()
    h.update(repr((tier, engine, bool(obj.fixed_base))).encode())
    h.update(write_urdf(model))
    h.update(repr(_mesh_identities(model)).encode())
    h.update(repr(sorted((str(k), float(v)) for k, v in obj.state.items())).encode())
    h.update(repr(sorted((str(k), float(s.stiffness), float(s.reference)) for k, s in (obj.springs or {}).items())).encode())
    h.update(obj.conventions.model_dump_json().encode())
    h.update(repr(config).encode())
    if closed is not None:
        h.update(repr([(str(n), tuple(float(x) for x in c)) for n, c in closed.items()]).encode())
    return h.hexdigest()


@dataclass
class RecordedRuns:
    """Manipulation-tier runs by :func:`input_digest`; ``hits`` / ``misses`` count the look-ups."""

    runs: dict[str, Any] = field(default_factory=dict)
    hits: int = 0
    misses: int = 0

    def take(self, key: str) -> Any | None:
        """A deep copy of the run recorded under ``key``, None when there is none."""
        run = self.runs.get(key)
        if run is None:
            self.misses += 1
            return None
        self.hits += 1
        return copy.deepcopy(run)

    def put(self, key: str, run: Any) -> None:
        """Record ``run`` (a deep copy) under ``key``."""
        self.runs[key] = copy.deepcopy(run)


def sweep_run(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], *,
              recorded: RecordedRuns | None = None) -> sweep.SweepRun:
    """:func:`asset2sim.tasks.check.sweep.run_sweep`, taken from ``recorded`` when
    a run of exactly these inputs is there, else simulated and recorded into it."""
    cfg = sweep.SweepConfig()
    return _recorded(recorded, lambda: sweep.run_sweep(engine, obj, closed, cfg),
                     "joint_sweep", engine, _swept(obj), cfg, closed)


def _swept(obj: SimObject) -> SimObject:
    """``obj`` with its root fixed, as the sweep and the operability check hold it whatever it declares."""
    return dataclasses.replace(obj, fixed_base=True)


def _recorded(recorded: RecordedRuns | None, simulate, *key_args) -> Any:
    """The run of ``recorded`` under ``input_digest(*key_args)``, else ``simulate()`` recorded there."""
    if recorded is None:
        return simulate()
    key = input_digest(*key_args)
    run = recorded.take(key)
    if run is None:
        run = simulate()
        recorded.put(key, run)
    return run


def robust_rest_run(engine: str, obj: SimObject, config: robust_rest.RobustRestConfig | None = None, *,
                    recorded: RecordedRuns | None = None) -> robust_rest.RobustRestRun:
    """:func:`asset2sim.tasks.check.robust_rest.run_robust_rest`, recorded as :func:`sweep_run`."""
    cfg = config or robust_rest.RobustRestConfig()
    return _recorded(recorded, lambda: robust_rest.run_robust_rest(engine, obj, cfg), "robust_rest", engine, obj, cfg)


def operability_run(engine: str, obj: SimObject, closed: dict[str, tuple[float, float, float]], *,
                    category: str | None = None, labels: dict[str, str | None] | None = None,
                    recorded: RecordedRuns | None = None) -> operability.OperabilityRun:
    """:func:`asset2sim.tasks.check.operability.run_operability` (same arguments), recorded as :func:`sweep_run`."""
    cfg = operability.OperabilityConfig()
    inputs = (cfg, category, tuple(sorted((str(k), str(v)) for k, v in (labels or {}).items() if v)))
    return _recorded(recorded, lambda: operability.run_operability(engine, obj, closed, category=category, labels=labels,
                                                                   config=cfg),
                     "operability", engine, _swept(obj), inputs, closed)


def task_run(engine: str, obj: SimObject, joints: dict[str, tuple[float, float, float]], *,
             actions: tuple[str, ...] = ("close", "open"), targets: dict[str, float] | None = None,
             config: TaskConfig | None = None, hold_required: dict[str, bool] | None = None, task: str | None = None,
             recorded: RecordedRuns | None = None) -> task_execution.TaskRun:
    """:func:`asset2sim.tasks.check.task_execution.run_task` (same arguments), recorded as :func:`sweep_run`: the
    post-check's attempt is the evaluation's when every input is the same (the joints' closed ends to the bit)."""
    cfg = config or TaskConfig()
    inputs = (cfg, tuple((str(n), tuple(float(x) for x in c)) for n, c in joints.items()), tuple(actions),
              tuple(sorted((str(k), float(v)) for k, v in (targets or {}).items())),
              tuple(sorted((str(k), bool(v)) for k, v in (hold_required or {}).items())), task)
    return _recorded(recorded, lambda: task_execution.run_task(
        engine, obj, joints, actions=actions, targets=targets, config=cfg, hold_required=hold_required, task=task),
        "task_execution", engine, obj, inputs)
