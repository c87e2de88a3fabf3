"""Learnability where learners train: brax's PPO on MJX (JAX) environments of each arm's asset, per manifest row.

    python benchmarks/bench_learn_mjx.py --ids 100221,9912 [--dev-ids 7236] [--arms asset2sim,defaults,human] \\
        [--seeds 0,1,2] [--num-envs 32] [--steps 20000] [--max-seconds 0] [--eval-episodes 32] \\
        [--out DIR] [--reuse]
    python benchmarks/bench_learn_mjx.py --table DIR/results.jsonl      # the table of a run

For each row and arm the arm's asset is made as ``benchmarks/bench_learnability.py`` makes it (``asset2sim``: the
refined output, its MJCF exported; ``defaults``: the raw asset at the reference scale with the simulators' defaults;
``human``: GenSim2's reference asset) under ``DIR/<arm>/<id>/asset``; the row's task becomes an MJX environment
(:mod:`asset2sim.apps.learn.mjx_env`: the task joint, target and success rule of
:func:`asset2sim.apps.learn.task.prepare_task`, the environment settings of
:class:`asset2sim.apps.learn.task.LearnConfig`); brax's PPO (``brax.training.agents.ppo.train``) trains ``--steps``
environment steps on ``--num-envs`` environments per seed (stopped after ``--max-seconds`` of wall time when given: the
steps then trained are recorded), then the deterministic policy runs ``--eval-episodes`` episodes in parallel (reset key
10000 + seed); success rate = episodes that reached the target and held it after release without the object sliding or
tipping / episodes. Every arm gets the same budget, seeds, hand and PPO settings. Rows of ``--dev-ids`` are where the
settings were chosen; ``--ids`` are held out; the table gives both, means per arm apart.

Prints and writes ``DIR/table.md``: per row and arm the success over seeds (mean, and min-max), the environment steps
trained, the wall seconds (training, compilation included) and the environment steps a second; each run is appended to
``DIR/results.jsonl`` as it ends. Needs the extra ``learn-mjx`` (``pip install 'asset2sim[learn-mjx]'``: brax, JAX,
MJX). On a GPU install ``jax[cuda12]`` beside it and raise ``--num-envs`` (docs/guide/learnability.md).
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
sys.path.insert(0, str(ROOT / "benchmarks"))

import bench_learnability  # noqa: E402  (the rows and the arms' assets)


def main(argv: list[str] | None = None) -> int:
    args = _arguments().parse_args(argv)
    if args.table:
        print(table([json.loads(x) for x in Path(args.table).read_text().splitlines() if x.strip()]))
        return 0
    import jax

    from asset2sim.formats.mjcf.export import export_mjcf

    # the seeds of one row and arm compile the same programs: kept on disk, compiled once (results unchanged)
    jax.config.update("jax_compilation_cache_dir", str(args.out / "jax_cache"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

    dev = [x for x in args.dev_ids.split(",") if x]
    rows = bench_learnability._manifest_rows(argparse.Namespace(manifest=args.manifest, ids=",".join(dev + args.ids.split(","))))
    arms = [a for a in args.arms.split(",") if a]
    args.out.mkdir(parents=True, exist_ok=True)
    results = args.out / "results.jsonl"
    print(f"learnability in MJX on {jax.devices()[0]}: {len(rows)} rows x {arms}, seeds {args.seeds}, {args.num_envs} "
          f"environments, {args.steps} steps per run; load average {os.getloadavg()[0]:.2f}", flush=True)
    assets = bench_learnability._make_assets(rows, arms, args)
    records = []
    for row in rows:
        for arm in arms:
            base = {"id": row.id, "category": row.category, "task": row.task, "arm": arm, "split": "dev" if row.id in dev else "held-out"}
            a = assets[(row.id, arm)]
            if isinstance(a, str):
                records.append(dict(base, error=a))
                continue
            if arm == "asset2sim":
                export_mjcf(a, visuals=False)  # the environment loads mjcf/mobility.xml, as a user's output has it
            for rec in learn(row, a, args, base):
                records.append(rec)
                with results.open("a") as f:
                    f.write(json.dumps(rec) + "\n")
    text = table(records)
    (args.out / "table.md").write_text(text + "\n")
    print(text)
    return 0


def learn(row, folder: Path, args, base: dict):
    """PPO per seed on the row's task on ``folder``'s asset: yields one record per seed as it ends (or one with the
    error that left the arm n/a)."""
    import functools

    import jax
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo

    from asset2sim.apps.learn.mjx_env import TaskMjxEnv, build_scene, evaluate, wrap_for_training
    from asset2sim.apps.learn.task import LearnConfig, prepare_task

    try:
        task = prepare_task(folder, row.task, reference=row.folder, category=row.category or None)
        cfg = LearnConfig()
        env = TaskMjxEnv(build_scene(folder, task, cfg), task, cfg)
    except Exception as exc:  # noqa: BLE001 - recorded; the next arm goes on
        print(f"  {base['arm']:>9} {row.id}: n/a ({type(exc).__name__}: {exc})", flush=True)
        yield dict(base, error=f"{type(exc).__name__}: {exc}")
        return
    base = dict(base, joint=task.joint, action=task.action, source=env.scene.source, grasp=env.scene.grasp_rule)
    for seed in [int(s) for s in args.seeds.split(",") if s]:
        t0 = time.perf_counter()
        last: dict = {}

        def keep(step, make_policy, params):  # brax calls it after every chunk of training
            last.update(step=step, make_policy=make_policy, params=params)
            if args.max_seconds > 0 and time.perf_counter() - t0 > args.max_seconds:
                raise _WallLimit

        net = functools.partial(ppo_networks.make_ppo_networks, policy_hidden_layer_sizes=(args.hidden,) * 2,
                                value_hidden_layer_sizes=(args.hidden,) * 2)
        try:
            ppo.train(env, num_timesteps=args.steps, num_envs=args.num_envs, episode_length=env.episode_length,
                      wrap_env_fn=wrap_for_training, learning_rate=args.lr, entropy_cost=args.entropy,
                      discounting=args.discounting, unroll_length=args.unroll_length, batch_size=args.batch_size,
                      num_minibatches=args.minibatches, num_updates_per_batch=args.updates, normalize_observations=True,
                      network_factory=net, seed=seed, num_evals=args.chunks, run_evals=False, policy_params_fn=keep)
            capped = False
        except _WallLimit:
            capped = True
        except Exception as exc:  # noqa: BLE001 - recorded; the next seed goes on
            yield dict(base, seed=seed, error=f"{type(exc).__name__}: {exc}")
            print(f"  {base['arm']:>9} {row.id} seed {seed}: error {type(exc).__name__}: {exc}", flush=True)
            continue
        train_s = time.perf_counter() - t0
        ev = evaluate(env, last["make_policy"], last["params"], jax.random.PRNGKey(10000 + seed), args.eval_episodes)
        rec = dict(base, seed=seed, success_rate=float(ev["success"].mean()), reached=float(ev["reached"].mean()),
                   env_steps=int(last["step"]), train_seconds=train_s, eval_seconds=time.perf_counter() - t0 - train_s,
                   stopped_by_wall_time=capped, num_envs=args.num_envs, device=str(jax.devices()[0]))
        print(f"  {base['arm']:>9} {row.id} seed {seed}: success {rec['success_rate']:.2f} (reached {rec['reached']:.2f}) "
              f"after {rec['env_steps']} steps, {train_s:.0f} s", flush=True)
        yield rec


class _WallLimit(Exception):
    """``--max-seconds`` of training passed."""


def table(records: list[dict]) -> str:
    """Markdown: per row and arm the success over seeds in % (mean, min-max), steps, wall s, steps a second; the mean
    of each arm over the held-out rows and over the dev rows."""
    arms = list(dict.fromkeys(r["arm"] for r in records))
    ids = list(dict.fromkeys(r["id"] for r in records))
    lines = ["| id | task | split | " + " | ".join(arms) + " |", "|---|---|---|" + "---|" * len(arms)]
    means: dict[tuple[str, str], list[float]] = {}
    for i in ids:
        rs = [r for r in records if r["id"] == i]
        cells = []
        for a in arms:
            ok = [r for r in rs if r["arm"] == a and "success_rate" in r]
            if not ok:
                cells.append("n/a")
                continue
            s = [100 * r["success_rate"] for r in ok]
            steps = statistics.fmean(r["env_steps"] for r in ok)
            wall = statistics.fmean(r["train_seconds"] for r in ok)
            cells.append(f"{statistics.fmean(s):.0f} ({min(s):.0f}-{max(s):.0f}); {steps:.0f} st, {wall:.0f} s, {steps / wall:.0f} st/s")
            means.setdefault((rs[0]["split"], a), []).append(statistics.fmean(s))
        lines.append(f"| {i} | {rs[0]['task']} | {rs[0]['split']} | " + " | ".join(cells) + " |")
    for split in ("held-out", "dev"):
        if any(k[0] == split for k in means):
            lines.append(f"| mean | {split} rows | {split} | " + " | ".join(
                f"{statistics.fmean(means[(split, a)]):.0f}" if (split, a) in means else "-" for a in arms) + " |")
    return "\n".join(lines)


def _arguments() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--manifest", type=Path, default=bench_learnability.DEFAULT_MANIFEST)
    ap.add_argument("--ids", default="", help="held-out rows, comma-separated")
    ap.add_argument("--dev-ids", default="", help="rows the settings were chosen on, comma-separated")
    ap.add_argument("--arms", default="asset2sim,defaults,human")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--num-envs", type=int, default=32, help="parallel environments (thousands on a GPU)")
    ap.add_argument("--steps", type=int, default=20000, help="environment steps of training per run")
    ap.add_argument("--max-seconds", type=float, default=0.0, help="wall-time limit of one run's training, s (0: none)")
    ap.add_argument("--chunks", type=int, default=4, help="training chunks (brax's num_evals): where --max-seconds is checked")
    ap.add_argument("--eval-episodes", type=int, default=32)
    ap.add_argument("--unroll-length", type=int, default=10)
    ap.add_argument("--batch-size", type=int, default=32)
    ap.add_argument("--minibatches", type=int, default=4)
    ap.add_argument("--updates", type=int, default=4, help="PPO updates per batch")
    ap.add_argument("--lr", type=float, default=3e-4)
    ap.add_argument("--entropy", type=float, default=1e-2)
    ap.add_argument("--discounting", type=float, default=0.97)
    ap.add_argument("--hidden", type=int, default=64, help="units per hidden layer (two layers)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_learn_mjx")
    ap.add_argument("--reuse", action="store_true", help="keep assets already made under --out")
    ap.add_argument("--table", default="", help="only print the table of a results.jsonl")
    return ap


if __name__ == "__main__":
    sys.exit(main())
