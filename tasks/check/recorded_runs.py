"""The manipulation tiers measured once per set of inputs, reused by every
check of the same files.

The refine post-check (:mod:`asset2sim.tasks.check.postcheck`) runs the joint
sweep (:mod:`asset2sim.tasks.check.sweep`) and robust rest
(:mod:`asset2sim.tasks.check.robust_rest`) on the written asset; refine's
evaluation (:mod:`asset2sim.tasks.evaluation.evaluate`, "no method grades
itself") measures them again with its own closed ends. Both simulations are
deterministic (fixed step, PyBullet DIRECT mode, a fresh session each), so
when every input is the same the second run can only repeat the first.

:class:`RecordedRuns` keeps each run under a digest of all its inputs
(:func:`input_digest`): the engine, the URDF's bytes, the identity (resolved
path, size, modification time) of every mesh file it references, the initial
state, springs, SPEC conventions, the root (fixed or free), the tier's
configuration and, for the sweep, the closed ends in sweep order. A check
that finds its digest takes the recorded run (a deep copy); any difference
(other closed ends, an escalated friction in the URDF, a rewritten collision
piece, other conventions) gives another digest, and the tier is simulated
again. This is the same contract as the rest test's
:class:`~asset2sim.tasks.check.postcheck.RestRecording`, keyed by content
instead of compared field by field.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from asset2sim.engines.base import Spring
from asset2sim.schemas.config import SimConventions
from asset2sim.tasks.check import robust_rest, sweep
from asset2sim.urdf import UrdfError, read_urdf


def _mesh_identities(urdf: Path) -> list[tuple[str, int, int] | str]:
    """(resolved path, size B, mtime ns) of every mesh file ``urdf``
    references (collisions and visuals, in file order); the path alone when
    the file cannot be read (the engine will fail on it the same way)."""
    try:
        model = read_urdf(urdf, mode="lenient")
    except (UrdfError, OSError, ValueError) as exc:
        return [f"unreadable: {type(exc).__name__}: {exc}"]
    out: list[tuple[str, int, int] | str] = []
    for link in model.links.values():
        for g in [*link.collisions, *link.visuals]:
            if g.kind != "mesh" or not g.filename:
                continue
            p = Path(g.path) if g.path is not None else urdf.parent / str(g.filename)
            try:
                st = p.stat()
                out.append((str(p.resolve()), st.st_size, st.st_mtime_ns))
            except OSError:
                out.append(str(p))
    return out


def input_digest(tier: str, engine: str, urdf: Path | str, initial_state: dict[str, float],
                 springs: dict[str, Spring] | None, conventions: SimConventions, fixed_base: bool,
                 config: Any, closed: dict[str, tuple[float, float, float]] | None = None) -> str:
    """SHA-256 (hex) of everything a manipulation tier's simulation reads.

    Args:
        tier: "joint_sweep" or "robust_rest".
        engine: engine name.
        urdf: the URDF file (its bytes are hashed, and the identity of every
            mesh it references: :func:`_mesh_identities`).
        initial_state: joint -> rad or m (order-free).
        springs: joint -> :class:`~asset2sim.engines.base.Spring` (order-free).
        conventions: the SPEC conventions.
        fixed_base: the root is fixed as the asset declares.
        config: the tier's dataclass configuration
            (:class:`~asset2sim.tasks.check.sweep.SweepConfig`,
            :class:`~asset2sim.tasks.check.robust_rest.RobustRestConfig`).
        closed: the sweep's joint -> (q_closed, direction, open range), in
            sweep order (the order of the recorded results).

    Floats enter by ``repr`` (exact). Raises OSError when ``urdf`` cannot be read.
    """
    urdf = Path(urdf).resolve()
    h = hashlib.sha256()
    h.update(repr((tier, engine, bool(fixed_base))).encode())
    h.update(urdf.read_bytes())
    h.update(repr(_mesh_identities(urdf)).encode())
    h.update(repr(sorted((str(k), float(v)) for k, v in initial_state.items())).encode())
    h.update(repr(sorted((str(k), float(s.stiffness), float(s.reference)) for k, s in (springs or {}).items())).encode())
    h.update(conventions.model_dump_json().encode())
    h.update(repr(dataclasses.asdict(config)).encode())
    if closed is not None:
        h.update(repr([(str(n), tuple(float(x) for x in c)) for n, c in closed.items()]).encode())
    return h.hexdigest()


@dataclass
class RecordedRuns:
    """Manipulation-tier runs by :func:`input_digest` (the post-check's, handed
    to the evaluation of the same files). ``hits`` / ``misses`` count the
    look-ups (a run taken from the record / simulated)."""

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


def sweep_run(engine: str, urdf: Path | str, closed: dict[str, tuple[float, float, float]],
              initial_state: dict[str, float], springs: dict[str, Spring] | None = None,
              conventions: SimConventions | None = None, config: sweep.SweepConfig | None = None, *,
              recorded: RecordedRuns | None = None) -> sweep.SweepRun:
    """:func:`asset2sim.tasks.check.sweep.run_sweep`, taken from ``recorded``
    when a run of exactly these inputs is there (:func:`input_digest`), else
    simulated and recorded into it (when given).

    Raises:
        EngineUnavailable, and whatever :func:`~asset2sim.tasks.check.sweep.run_sweep` raises.
    """
    cfg = config or sweep.SweepConfig()
    conv = conventions or SimConventions()
    key = input_digest("joint_sweep", engine, urdf, initial_state, springs, conv, True, cfg, closed) if recorded is not None else ""
    run = recorded.take(key) if recorded is not None else None
    if run is None:
        run = sweep.run_sweep(engine, urdf, closed, initial_state, springs, conv, cfg)
        if recorded is not None:
            recorded.put(key, run)
    return run


def robust_rest_run(engine: str, urdf: Path | str, initial_state: dict[str, float],
                    springs: dict[str, Spring] | None = None, conventions: SimConventions | None = None,
                    config: robust_rest.RobustRestConfig | None = None, fixed_base: bool = False, *,
                    recorded: RecordedRuns | None = None) -> robust_rest.RobustRestRun:
    """:func:`asset2sim.tasks.check.robust_rest.run_robust_rest`, taken from
    ``recorded`` when a run of exactly these inputs is there
    (:func:`input_digest`), else simulated and recorded into it (when given).

    Raises:
        EngineUnavailable, and whatever :func:`~asset2sim.tasks.check.robust_rest.run_robust_rest` raises.
    """
    cfg = config or robust_rest.RobustRestConfig()
    conv = conventions or SimConventions()
    key = input_digest("robust_rest", engine, urdf, initial_state, springs, conv, fixed_base, cfg) if recorded is not None else ""
    run = recorded.take(key) if recorded is not None else None
    if run is None:
        run = robust_rest.run_robust_rest(engine, urdf, initial_state, springs, conv, cfg, fixed_base=fixed_base)
        if recorded is not None:
            recorded.put(key, run)
    return run
