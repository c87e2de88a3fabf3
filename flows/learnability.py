"""Per-asset learnability flags in the result catalog: a quality signal beside the verdict.

A policy that learns a task on some assets and on no seed on another flags that asset: the task is learnable at
the budget, so the asset (a jammed part, a target out of reach, a part that does not stay put) is what keeps the
policy from it. The flags come from the learnability benchmark's records (``benchmarks/bench_learnability.py``, in
the PyBullet harness or ``--framework maniskill``) and are written onto the asset's latest finished row of a
dataset (columns ``learnable`` and ``learnability``, schema version 8), so ``asset2sim failures --by
category,learnable`` breaks them down like the failure modes.

Rule (per method and task action, over the records of one benchmark run):

- ``learned`` (``learnable`` true): some seed's deterministic policy succeeded on the asset (success rate > 0);
- ``not_learned`` (false): no seed succeeded on the asset while the same method's policies succeeded on at least
  one other asset with the same action;
- ``undecided`` (null): nothing was learned on any asset of that action: the budget, not the asset, decides.

Held-out assets (ManiSkill's ``--held-out``) get no flag: the policy did not train on them.
A task the object does by itself (the passive reference, the robot holding still, succeeds) is still ``learned``
where a policy succeeds; the JSON keeps the passive rate to tell them apart.
"""

from __future__ import annotations

import json
import statistics
from dataclasses import asdict, dataclass, field
from typing import Any, Iterable

from asset2sim.flows.catalog import ResultCatalog, plain_value

#: Record kinds holding a trained policy's evaluation: the PyBullet harness's ``ppo``, ManiSkill's ``ppo_eval``.
POLICY_KINDS = ("ppo", "ppo_eval")


@dataclass(frozen=True)
class LearnabilityFlag:
    """One asset's learnability under one method: ``verdict`` learned | not_learned | undecided; ``seeds`` seed ->
    success rate (0-1) of the trained policy's evaluation episodes; ``passive`` the passive reference's success
    rate (None: not run); ``learned_on`` the other assets of the same action a policy succeeded on; ``action``
    (open, close, ...; "" when the records do not say); ``framework`` pybullet | maniskill; ``budget`` what one
    training run had (environment steps, environments, device)."""

    asset_id: str
    method: str
    verdict: str
    seeds: dict[int, float]
    passive: float | None = None
    learned_on: tuple[str, ...] = ()
    action: str = ""
    task: str = ""
    framework: str = ""
    budget: dict[str, Any] = field(default_factory=dict)

    @property
    def learnable(self) -> bool | None:
        """The catalog's ``learnable``: True learned, False not learned where others were, None undecided."""
        return {"learned": True, "not_learned": False}.get(self.verdict)

    def to_json(self) -> str:
        """The catalog's ``learnability`` column: this flag as JSON (success rates 0-1)."""
        data = asdict(self)
        data["seeds"] = {str(k): v for k, v in sorted(self.seeds.items())}
        data["success"] = statistics.fmean(self.seeds.values()) if self.seeds else None
        data["learned_on"] = list(self.learned_on)
        return json.dumps(data, sort_keys=True)


def learnability_flags(records: Iterable[dict], method: str = "asset2sim") -> dict[str, LearnabilityFlag]:
    """The flags of ``method``'s assets (asset id -> :class:`LearnabilityFlag`) from the benchmark's records (dicts
    as ``results.jsonl`` / ``results_maniskill.jsonl`` hold them: ``kind``, ``method``, ``id``, ``seed``,
    ``success_rate``, and where known ``action``, ``task``, ``split``, ``env_steps``, ``n_envs``, ``device``); records
    with an ``error`` are left out, and so are held-out assets (``split`` "held-out": the policy never trained on them,
    so their success measures generalization, not the asset). Rule: the module docstring."""
    records = [r for r in records if r.get("method") == method and not r.get("error") and r.get("split") != "held-out"]
    framework = "maniskill" if any(r.get("kind") == "ppo_eval" for r in records) else "pybullet"
    seeds: dict[str, dict[int, float]] = {}
    passive: dict[str, float] = {}
    action: dict[str, str] = {}
    task: dict[str, str] = {}
    budget: dict[str, Any] = {}
    for r in records:
        rid = str(r.get("id") or "")
        rated = rid and r.get("success_rate") is not None
        if r.get("kind") in POLICY_KINDS and rated:
            seeds.setdefault(rid, {})[int(r.get("seed") or 0)] = float(r["success_rate"])
        elif r.get("kind") == "passive" and rated:
            passive[rid] = float(r["success_rate"])
        if r.get("kind") in ("ppo", "ppo_train") and r.get("env_steps") is not None:
            budget = {"env_steps": int(r["env_steps"]), "n_envs": r.get("n_envs"), "device": r.get("device"),
                      "sim_backend": r.get("sim_backend")}
        if rid and r.get("action"):
            action[rid] = str(r["action"])
        if rid and r.get("task"):
            task[rid] = str(r["task"])
    learned = {rid for rid, s in seeds.items() if any(v > 0 for v in s.values())}
    out = {}
    for rid, s in sorted(seeds.items()):
        same = sorted(o for o in learned if o != rid and action.get(o, "") == action.get(rid, ""))
        verdict = "learned" if rid in learned else ("not_learned" if same else "undecided")
        out[rid] = LearnabilityFlag(asset_id=rid, method=method, verdict=verdict, seeds=dict(s), passive=passive.get(rid),
                                    learned_on=tuple(same), action=action.get(rid, ""), task=task.get(rid, ""),
                                    framework=framework, budget={k: v for k, v in budget.items() if v is not None})
    return out


@dataclass
class Recorded:
    """What :func:`record_learnability` did: ``written`` (asset id -> the run its row is in), ``missing`` (asset ids
    with no finished row in the dataset), ``other_input`` (asset id -> why the row was left: its input differs)."""

    written: dict[str, str] = field(default_factory=dict)
    missing: list[str] = field(default_factory=list)
    other_input: dict[str, str] = field(default_factory=dict)


def record_learnability(store: ResultCatalog, dataset: str, flags: dict[str, LearnabilityFlag],
                        input_hashes: dict[str, str] | None = None) -> Recorded:
    """Write each flag onto its asset's latest finished (done or skipped) row of ``dataset`` in ``store``: the row
    again with ``learnable`` and ``learnability`` set (:meth:`ResultCatalog.append_row`, atomic, replacing it in its
    run). ``input_hashes`` (asset id -> the trained output's input hash, from its ``report.json``): a row of another
    input is left as it is and named in :attr:`Recorded.other_input`.

    Raises:
        OSError: the catalog's filesystem refused a write.
    """
    import pyarrow.dataset as pads

    done = Recorded()
    if not flags:
        return done
    expr = pads.field("status").isin(["done", "skipped"]) & pads.field("asset_id").isin(sorted(flags))
    # the rows come sorted by run (ResultCatalog.read): an asset's last row is its latest
    latest = {rec["asset_id"]: rec for rec in store.read(dataset, filter=expr).to_dict("records")}
    for aid, flag in sorted(flags.items()):
        row = latest.get(aid)
        if row is None:
            done.missing.append(aid)
            continue
        want = (input_hashes or {}).get(aid)
        if want and row.get("input_hash") and want != row["input_hash"]:
            done.other_input[aid] = f"the catalog's row (run {row['run']}) is of input {row['input_hash'][:12]}, the trained output of {want[:12]}"
            continue
        run = row.pop("run")
        row.pop("dataset", None)
        values = {k: plain_value(v) for k, v in row.items()}
        values.update(learnable=flag.learnable, learnability=flag.to_json())
        store.append_row(dataset, run, values)
        done.written[aid] = run
    return done

