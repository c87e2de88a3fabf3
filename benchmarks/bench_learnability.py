"""Learnability benchmark: can PPO learn each manifest task on each method's asset?

    python benchmarks/bench_learnability.py [--manifest M] [--ids 103275,100221] \\
        [--methods defaults,human,direct,asset2sim] [--steps 3000] [--seeds 0] \\
        [--eval-episodes 5] [--n-envs 2] [--max-run-seconds 600] [--out DIR] [--reuse] [--no-ppo]
    python benchmarks/bench_learnability.py --table DIR/results.jsonl[,MORE.jsonl]
    python benchmarks/bench_learnability.py ... --catalog catalog.yaml [--dataset NAME]   # flags into the catalog
    python benchmarks/bench_learnability.py --framework maniskill --ids 100221,9912 --held-out 47645 \
        --methods raw,asset2sim --steps 20000 --seeds 0,1,2 [--sim-backend gpu --n-envs 1024 --device cuda]

``--framework maniskill`` runs the comparison in ManiSkill 3 (:mod:`asset2sim.apps.learn.maniskill`, the ``maniskill``
extra): PPO per method and seed on the training objects, evaluated on them and on the held-out ones
(``benchmarks/learnability_maniskill.py``). What follows is the PyBullet benchmark (the default).

The thesis trained PPO with 4096 parallel environments for 3000 iterations
on 9 tasks (SPEC, "Numbers to beat": thesis method 97.5 % mean success,
VLM-IVW 45.7 %, GenSim2 and Direct 11.1 %). This script is the same
experiment at the budget a CPU allows, and scales with ``--steps``,
``--seeds`` and ``--n-envs`` on a bigger machine:

1. For each manifest row (default: the first 9, the thesis set) and method,
   the method's asset is made in-process
   (:func:`asset2sim.apps.benchmark.baselines.run_method`: ``defaults``,
   ``human`` where the row has GenSim2's reference, ``direct``, ``asset2sim``
   = :func:`asset2sim.tasks.refine.refine_asset`) under ``DIR/<method>/<id>/asset``
   (``--reuse`` keeps an asset already there).
2. The row's ``task`` becomes a gymnasium environment
   (:mod:`asset2sim.apps.learn.gym_env`: a force- and speed-limited
   gripper attached at the task link's contact point, PyBullet through the
   engine protocol, staged reward, success = target reached and held 1 s after
   release without the object sliding > 5 mm or tipping > 0.05 rad).
3. Feasibility reference: a scripted policy (along the joint's direction of
   motion at 0.25, 0.5 and 1 times the speed limit,
   :meth:`~asset2sim.apps.learn.gym_env.TaskEnv.scripted_action`)
   runs ``--eval-episodes`` episodes at each speed; its success rate is the
   best speed's: can the task be done at all on this asset with this gripper?
4. PPO (stable-baselines3, ``MlpPolicy``, CPU, ``DummyVecEnv`` of
   ``--n-envs`` environments) trains ``--steps`` environment steps per seed
   (each step ``action_repeat`` = 12 engine steps of 1/240 s), stopped early
   after ``--max-run-seconds`` of wall time (the steps actually trained are
   recorded), then the deterministic policy runs ``--eval-episodes``
   episodes (reset seeds 10000 + i); success rate = successful episodes / episodes.

The passive reference runs the same episodes with the gripper holding still
(a task that gravity does alone, e.g. a lid that falls shut, shows here).

Prints the table (success per task and method: PPO, scripted, passive; mean per
method), the wall time and the budget used (environment and engine steps,
episodes). Each run is appended to ``DIR/results.jsonl`` as it ends, so a run
cut short keeps what it finished; ``--table`` prints the table of such a file. With ``--catalog``, each
asset2sim asset's learnability flag (learned; not learned on any seed while
learned on other assets; undecided: :mod:`asset2sim.flows.learnability`) is
written onto its latest row of the catalog's dataset (columns ``learnable``
and ``learnability``), after a run or from ``--table``.
Needs the ``learn`` extra (``pip install -e ".[learn]"``: stable-baselines3 and torch, about 5 GB from PyPI).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"
DEFAULT_METHODS = "defaults,human,direct,asset2sim"
#: Speeds of the scripted reference, in units of the gripper's speed limit.
SCRIPTED_SPEEDS = (0.25, 0.5, 1.0)


def _pct(x: float | None) -> str:
    return "   -  " if x is None else f"{100 * x:5.1f}%"


def print_table(records: list[dict], out=sys.stdout) -> None:
    """Success per task (rows) and method (columns) as 'PPO / scripted /
    passive' percentages (PPO: mean over seeds; a later record of a reference
    replaces an earlier one), a mean row, and the budget used."""
    methods = list(dict.fromkeys(r["method"] for r in records))
    ids = list(dict.fromkeys(r["id"] for r in records))
    task_of = {r["id"]: r.get("task", "") for r in records}
    cell: dict[tuple[str, str], dict] = {}
    for r in records:
        c = cell.setdefault((r["id"], r["method"]), {"ppo": {}, "scripted": None, "passive": None, "error": None})
        if r.get("error"):
            c["error"] = r["error"]
        if r.get("success_rate") is None:
            continue
        if r.get("kind") == "ppo":
            c["ppo"][r.get("seed")] = r["success_rate"]
        elif r.get("kind") in ("scripted", "passive"):
            c[r["kind"]] = r["success_rate"]

    def fmt(x: float | None) -> str:
        return "-" if x is None else f"{100 * x:.0f}"

    w = 16
    print("success rate (%) per task and method: PPO (mean over seeds) / scripted reference / passive (no action)", file=out)
    print(f"{'id':>7} {'task':<30}" + "".join(f"{m:>{w}}" for m in methods), file=out)
    cols: dict[str, dict[str, list[float]]] = {m: {"ppo": [], "scripted": [], "passive": []} for m in methods}
    for i in ids:
        line = f"{i:>7} {task_of[i][:30]:<30}"
        for m in methods:
            c = cell.get((i, m))
            if c is None:
                line += f"{'':>{w}}"
                continue
            if c["error"] and not c["ppo"] and c["scripted"] is None:
                line += f"{'n/a':>{w}}"
                continue
            p = statistics.fmean(c["ppo"].values()) if c["ppo"] else None
            for k, v in (("ppo", p), ("scripted", c["scripted"]), ("passive", c["passive"])):
                if v is not None:
                    cols[m][k].append(v)
            line += f"{fmt(p) + ' / ' + fmt(c['scripted']) + ' / ' + fmt(c['passive']):>{w}}"
        print(line, file=out)
    line = f"{'mean':>7} {'(tasks with a result)':<30}"
    for m in methods:
        vals = [statistics.fmean(cols[m][k]) if cols[m][k] else None for k in ("ppo", "scripted", "passive")]
        line += f"{' / '.join(fmt(v) for v in vals):>{w}}"
    print(line, file=out)
    ppo = [r for r in records if r.get("kind") == "ppo" and not r.get("error")]
    if ppo:
        steps = sum(r["env_steps"] for r in ppo)
        sim = sum(r["engine_steps"] for r in ppo)
        eps = sum(r["train_episodes"] for r in ppo)
        secs = sum(r["train_seconds"] for r in ppo)
        cut = sum(1 for r in ppo if r.get("stopped_early"))
        print(f"budget used: {len(ppo)} PPO runs, {steps} environment steps ({sim} engine steps of 1/240 s, "
              f"{sim / 240.0 / 3600.0:.2f} h simulated), {eps} training episodes, {secs / 60:.1f} min training wall time; "
              f"per run: median {statistics.median(r['env_steps'] for r in ppo):.0f} environment steps, "
              f"{cut} run(s) stopped by the wall-time limit", file=out)
    ev = sum(r.get("eval_episodes", 0) for r in records if not r.get("error"))
    print(f"evaluation: {ev} episodes (PPO, scripted and passive)", file=out)
    for r in records:
        if r.get("error"):
            print(f"error {r['method']} {r['id']} ({r.get('kind')}): {r['error']}", file=out)


def record_flags(records: list[dict], args) -> None:
    """With ``--catalog``: the per-asset learnability flags of ``--flag-method``'s assets
    (:func:`asset2sim.flows.learnability.learnability_flags`) written onto their latest finished rows of
    ``--dataset`` in the catalog (``learnable``, ``learnability``), each only where the row is of the input the
    trained output was refined from (``DIR/<method>/<id>/asset/report.json``); prints what was written."""
    if args.catalog is None:
        return
    from asset2sim.flows.catalog import ResultCatalog
    from asset2sim.flows.catalog_config import load_catalog
    from asset2sim.flows.learnability import learnability_flags, record_learnability

    flags = learnability_flags(records, args.flag_method)
    cat = load_catalog(args.catalog)
    dataset, _ = cat.dataset(args.dataset)
    hashes = {}
    for rid in flags:
        report = args.out / args.flag_method / rid / "asset" / "report.json"
        if report.is_file():
            hashes[rid] = json.loads(report.read_text()).get("input_hash", "")
    done = record_learnability(ResultCatalog(cat.catalog_root), dataset, flags, hashes)
    for rid, f in flags.items():
        where = (f"written to run {done.written[rid]}" if rid in done.written else
                 "no finished row in the catalog" if rid in done.missing else done.other_input.get(rid, ""))
        print(f"learnability {rid}: {f.verdict} (seeds {f.seeds}; learned on {list(f.learned_on) or '-'}): {where}")


def main(argv: list[str] | None = None) -> int:
    args = _arguments().parse_args(argv)
    if args.framework == "maniskill":
        return _maniskill(args)
    if args.table:
        recs = [json.loads(x) for f in args.table.split(",") for x in Path(f).read_text().splitlines() if x.strip()]
        print_table(recs)
        record_flags(recs, args)
        return 0

    os.environ.setdefault("MPLBACKEND", "Agg")
    # third-party and project imports after argument parsing: --help and --table need none of them
    import torch
    from stable_baselines3 import PPO

    from asset2sim.apps.learn.gym_env import LearnConfig

    torch.set_num_threads(1)
    rows = _manifest_rows(args)
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    args.out.mkdir(parents=True, exist_ok=True)
    results = args.out / "results.jsonl"
    cfg = LearnConfig()
    t_all = time.perf_counter()
    print(f"learnability: {len(rows)} tasks x {methods}, PPO {args.steps} env steps x seeds {seeds}, n_envs {args.n_envs}, "
          f"eval {args.eval_episodes} episodes; control {240 / cfg.action_repeat:.0f} Hz, episode {cfg.episode_time} s; "
          f"start {args.start}; load average {os.getloadavg()[0]:.2f}", flush=True)
    records: list[dict] = []

    def emit(rec: dict) -> None:
        records.append(rec)
        with results.open("a") as f:
            f.write(json.dumps(rec) + "\n")

    # 1. every method's asset first (the pipeline's code is imported once, before any training)
    assets = _make_assets(rows, methods, args)
    # 2-4. per task, per method: scripted reference, then PPO per seed
    for row in rows:
        for m in methods:
            _learn_task(row, m, assets[(row.id, m)], args, cfg, seeds, emit, PPO)
    print(f"wall time {(time.perf_counter() - t_all) / 60:.1f} min; results in {results}", flush=True)
    print_table(records)
    record_flags(records, args)
    return 0


def _arguments() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=DEFAULT_MANIFEST)
    ap.add_argument("--ids", default="", help="comma-separated ids (default: the first 9 rows, the thesis set)")
    ap.add_argument("--methods", default=DEFAULT_METHODS)
    ap.add_argument("--steps", type=int, default=3000, help="environment steps of PPO training per run")
    ap.add_argument("--seeds", default="0", help="comma-separated training seeds")
    ap.add_argument("--eval-episodes", type=int, default=5)
    ap.add_argument("--n-envs", type=int, default=2)
    ap.add_argument("--n-steps", type=int, default=256, help="PPO rollout length per environment")
    ap.add_argument("--max-run-seconds", type=float, default=0.0, help="wall-time cap per PPO run (0: none)")
    ap.add_argument("--start", choices=("task", "asset"), default="task", help="task joint start (learn.task.prepare_task)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_learnability")
    ap.add_argument("--reuse", action="store_true", help="keep assets already made under --out")
    ap.add_argument("--no-ppo", action="store_true", help="only the scripted and passive references")
    ap.add_argument("--table", default="", help="only print the table of results.jsonl file(s), comma-separated")
    ap.add_argument("--catalog", type=Path, default=None,
                    help="write per-asset learnability flags onto the rows of this catalog file's dataset (--dataset)")
    ap.add_argument("--dataset", default=None, help="with --catalog: the dataset (default: the catalog's default_dataset)")
    ap.add_argument("--flag-method", default="asset2sim", help="with --catalog: the method whose assets are flagged")
    ms = ap.add_argument_group("--framework maniskill")
    ms.add_argument("--framework", choices=("pybullet", "maniskill"), default="pybullet")
    ms.add_argument("--held-out", default="", help="comma-separated ids evaluated but not trained on")
    ms.add_argument("--action", choices=("close", "open", "task"), default="close",
                    help="the environment: Close- or OpenArticulation, or task: ManifestTask (each row's own task, its direction)")
    ms.add_argument("--sim-backend", choices=("cpu", "gpu"), default="cpu")
    ms.add_argument("--device", default="cpu", help="where the policy trains (cuda with --sim-backend gpu)")
    ms.add_argument("--control-mode", default="pd_joint_delta_pos")
    ms.add_argument("--num-steps", type=int, default=50, help="PPO rollout length per environment (ManiSkill's baseline: 50)")
    ms.add_argument("--hidden", type=int, default=64, help="units per hidden layer (ManiSkill's baseline: 256)")
    ms.add_argument("--lr", type=float, default=3e-4)
    ms.add_argument("--gamma", type=float, default=0.8)
    ms.add_argument("--gae-lambda", type=float, default=0.9)
    ms.add_argument("--clip", type=float, default=0.2)
    ms.add_argument("--target-kl", type=float, default=0.1)
    ms.add_argument("--update-epochs", type=int, default=4)
    ms.add_argument("--minibatches", type=int, default=4)
    return ap


def _maniskill(args) -> int:
    """``--framework maniskill``: the comparison in ManiSkill 3 (benchmarks/learnability_maniskill.py)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    import learnability_maniskill

    if args.table:
        recs = [json.loads(x) for f in args.table.split(",") for x in Path(f).read_text().splitlines() if x.strip()]
        learnability_maniskill.print_table(recs)
        record_flags(recs, args)
        return 0
    if args.methods == DEFAULT_METHODS:
        args.methods = "raw,asset2sim"
    rows = _manifest_rows(args)
    held = [x.strip() for x in args.held_out.split(",") if x.strip()]
    held_rows = _manifest_rows(argparse.Namespace(manifest=args.manifest, ids=",".join(held))) if held else []
    rows = [r for r in rows if r.id not in held]
    return learnability_maniskill.run(args, rows, held_rows, _make_assets, record_flags)


def _manifest_rows(args) -> list:
    """The manifest rows to learn on: ``--ids``, else the first 9 in file order (the thesis set)."""
    from asset2sim.tasks.ingest.partnet_mobility import read_manifest_rows

    reading = read_manifest_rows(args.manifest)
    rows = sorted(reading.rows, key=lambda r: r.line or 0)
    if args.ids:
        want = [x.strip() for x in args.ids.split(",") if x.strip()]
        return [r for r in rows if r.id in want]
    return rows[:9]


def _make_assets(rows: list, methods: list[str], args) -> dict[tuple[str, str], Path | str]:
    """Each method's asset of each row under ``--out``: (id, method) -> its folder, or the error that left it n/a."""
    from asset2sim.apps.benchmark.baselines import BaselineError, run_method

    assets: dict[tuple[str, str], Path | str] = {}
    for row in rows:
        for m in methods:
            folder = args.out / m / row.id / "asset"
            t0 = time.perf_counter()
            if args.reuse and (folder / "mobility.urdf").is_file():
                assets[(row.id, m)] = folder
                continue
            try:
                run_method(m, row, folder, seed=0)
                assets[(row.id, m)] = folder
                print(f"  asset {m:>9} {row.id}: {time.perf_counter() - t0:.1f} s", flush=True)
            except (BaselineError, KeyError) as exc:
                assets[(row.id, m)] = f"{type(exc).__name__}: {exc}"
                print(f"  asset {m:>9} {row.id}: n/a ({exc})", flush=True)
    return assets


def _learn_task(row, m: str, a: Path | str, args, cfg, seeds: list[int], emit, ppo) -> None:
    """The row's task on method ``m``'s asset ``a`` (its folder, or why it is n/a): the scripted and passive
    references, then ``ppo`` (stable-baselines3's ``PPO``) per seed; each record handed to ``emit``."""
    from asset2sim.apps.learn.task import prepare_task

    base = {"id": row.id, "category": row.category, "task": row.task, "method": m}
    if isinstance(a, str):
        emit(dict(base, kind="asset", error=a))
        return
    try:
        task = prepare_task(a, row.task, reference=row.folder, category=row.category or None, start=args.start)
    except Exception as exc:
        emit(dict(base, kind="task", error=f"{type(exc).__name__}: {exc}"))
        print(f"  {m:>9} {row.id}: task n/a ({exc})", flush=True)
        return
    base.update(joint=task.joint, action=task.action, start_fraction=task.start_fraction,
                target_fraction=task.target_fraction)
    _references(task, cfg, args, base, emit)
    for seed in ([] if args.no_ppo else seeds):
        _train_ppo(ppo, task, cfg, args, seed, base, emit)


def _success_rate(outs: list[dict]) -> float:
    """Successful episodes / episodes."""
    return sum(bool(o["success"]) for o in outs) / len(outs)


def _references(task, cfg, args, base: dict, emit) -> None:
    """The scripted reference (success rate: the best of :data:`SCRIPTED_SPEEDS`) and the passive one (the gripper
    holding still), ``--eval-episodes`` episodes each (reset seeds 10000 + i)."""
    import numpy as np

    from asset2sim.apps.learn.gym_env import TaskEnv, run_episode

    m, rid = base["method"], base["id"]
    t0 = time.perf_counter()
    env = TaskEnv(task, cfg)
    try:
        by_speed: dict[str, float] = {}
        fails: list[str] = []
        peak = 0.0
        for sp in SCRIPTED_SPEEDS:
            outs = [run_episode(env, lambda o: env.scripted_action(sp), seed=10000 + i) for i in range(args.eval_episodes)]
            by_speed[str(sp)] = _success_rate(outs)
            fails += [f"{sp}: {o['failure']}" for o in outs if not o["success"]]
            peak = max([peak] + [o["peak_force_n"] for o in outs])
        rate = max(by_speed.values())
        emit(dict(base, kind="scripted", success_rate=rate, by_speed=by_speed,
                  eval_episodes=args.eval_episodes * len(SCRIPTED_SPEEDS), engine_steps=env.sim_steps,
                  failures=fails, peak_force_n=peak, seconds=time.perf_counter() - t0, grasp_rule=env.grasp_rule))
        print(f"  {m:>9} {rid} scripted: {by_speed} ({time.perf_counter() - t0:.1f} s)", flush=True)
        outs = [run_episode(env, lambda o: np.zeros(4), seed=10000 + i) for i in range(args.eval_episodes)]
        emit(dict(base, kind="passive", success_rate=_success_rate(outs),
                  eval_episodes=len(outs), failures=[o["failure"] for o in outs if not o["success"]],
                  final_fractions=[o["fraction"] for o in outs]))
    except Exception as exc:
        emit(dict(base, kind="scripted", error=f"{type(exc).__name__}: {exc}"))
    finally:
        env.close()


def _wall_limit(seconds: float):
    """A stable-baselines3 callback that stops training after ``seconds`` s of wall time (0: never); ``stopped``
    tells whether it did."""
    from stable_baselines3.common.callbacks import BaseCallback

    class _WallLimit(BaseCallback):
        def __init__(self, seconds: float) -> None:
            super().__init__()
            self.seconds, self.t0, self.stopped = seconds, time.perf_counter(), False

        def _on_step(self) -> bool:
            if self.seconds > 0 and time.perf_counter() - self.t0 > self.seconds:
                self.stopped = True
                return False
            return True

    return _WallLimit(seconds)


def _train_ppo(ppo, task, cfg, args, seed: int, base: dict, emit) -> None:
    """PPO trained ``--steps`` environment steps (``--max-run-seconds`` cap) on ``--n-envs`` environments, then its
    deterministic policy run ``--eval-episodes`` episodes (reset seeds 10000 + i)."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from asset2sim.apps.learn.gym_env import TaskEnv, run_episode

    m, rid = base["method"], base["id"]
    t0 = time.perf_counter()
    envs = [TaskEnv(task, cfg) for _ in range(args.n_envs)]
    venv = DummyVecEnv([(lambda e=e: e) for e in envs])
    venv.seed(seed)
    eval_env = TaskEnv(task, cfg)
    try:
        model = ppo("MlpPolicy", venv, n_steps=args.n_steps, batch_size=64, n_epochs=10, learning_rate=3e-4,
                    gamma=0.99, gae_lambda=0.95, ent_coef=0.0, seed=seed, device="cpu", verbose=0,
                    policy_kwargs={"net_arch": [64, 64], "log_std_init": -1.0})
        cap = _wall_limit(args.max_run_seconds)
        model.learn(total_timesteps=args.steps, callback=cap)
        t_train = time.perf_counter() - t0
        outs = [run_episode(eval_env, lambda o: model.predict(o, deterministic=True)[0], seed=10000 + i)
                for i in range(args.eval_episodes)]
        rate = _success_rate(outs)
        emit(dict(base, kind="ppo", seed=seed, success_rate=rate, eval_episodes=len(outs),
                  env_steps=int(model.num_timesteps), engine_steps=int(sum(e.sim_steps for e in envs)),
                  train_episodes=int(sum(e.episodes for e in envs)), train_seconds=t_train,
                  stopped_early=cap.stopped, eval_seconds=time.perf_counter() - t0 - t_train,
                  failures=[o["failure"] for o in outs if not o["success"]],
                  final_fractions=[o["fraction"] for o in outs]))
        print(f"  {m:>9} {rid} PPO seed {seed}: {rate:.2f} after {model.num_timesteps} steps "
              f"({t_train:.0f} s train{', stopped by the wall-time cap' if cap.stopped else ''})", flush=True)
    except Exception as exc:
        emit(dict(base, kind="ppo", seed=seed, error=f"{type(exc).__name__}: {exc}"))
        print(f"  {m:>9} {rid} PPO seed {seed}: error {exc}", flush=True)
    finally:
        venv.close()
        eval_env.close()


if __name__ == "__main__":
    sys.exit(main())
