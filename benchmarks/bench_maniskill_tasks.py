"""Is every output a ManiSkill task, or a skip with its MS_* code?

    python benchmarks/bench_maniskill_tasks.py [--root out/bench_refine] [--manifest PATH] [--steps 10]

For every output folder under ROOT and each environment of ``asset2sim.apps.learn.maniskill`` (open, close, the object's own
task with the manifest's task where the output records none): the folder becomes a task object or is skipped with
the code ``load_task_objects`` names. Then each folder alone is built in ``Asset2Sim-ManifestTask-v1`` (in
``Asset2Sim-OpenArticulation-v1`` where no task is recorded, as for third-party objects refined without one) on ManiSkill's
CPU backend (Panda, state observations, no renderer), reset and stepped ``--steps`` control steps of random
actions: "stepped", or the error's MS_* code. Prints one row per folder and the counts.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MANIFEST = ROOT.parent / "shared" / "datasets" / "partnet_mobility" / "manifest.csv"


def code_of(error: str) -> str:
    """The MS_* code an error message starts with (``other`` for an error without one)."""
    head = error.split(":", 1)[0].strip()
    return head if head.startswith("MS_") else "other"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=ROOT / "out" / "bench_refine")
    ap.add_argument("--manifest", type=Path, default=MANIFEST)
    ap.add_argument("--steps", type=int, default=10)
    args = ap.parse_args(argv)
    import gymnasium as gym

    from asset2sim.apps.learn import maniskill as ams

    folders = sorted(p for p in args.root.iterdir() if (p / "mobility.urdf").is_file())
    manifest = args.manifest if args.manifest.is_file() else None
    rows = {f.name: {} for f in folders}
    for action in ("open", "close", "task"):
        try:
            objects, skipped = ams.load_task_objects(folders, action, manifest=manifest if action == "task" else None)
        except ams.ManiSkillAssetError as exc:  # MS_NO_ASSETS: every folder skipped, each with its own code
            objects, skipped = [], exc.skipped
        for obj in objects:
            rows[Path(obj.source or obj.folder).name][action] = f"task ({obj.joint})"
        for folder, error in skipped:
            rows[folder.name][action] = code_of(error)
    print("object | open | close | own task | ManifestTask on the CPU backend | s")
    stepped = 0
    for f in folders:
        t0 = time.perf_counter()
        env_action = "task" if rows[f.name].get("task", "").startswith("task") else "open"
        try:
            env = gym.make(ams.ENV_IDS[env_action], assets=[f], manifest=manifest, num_envs=1, obs_mode="state",
                           render_backend="none", sim_backend="cpu")
            try:
                env.reset(seed=0)
                for _ in range(args.steps):
                    env.step(env.action_space.sample())
            finally:
                env.close()
            built = "stepped" + ("" if env_action == "task" else " (OpenArticulation: no task recorded)")
            stepped += 1
        except Exception as exc:  # recorded with its code; the next folder goes on
            built = code_of(str(exc)) + f" ({type(exc).__name__})"
        r = rows[f.name]
        print(f"{f.name} | {r.get('open', '-')} | {r.get('close', '-')} | {r.get('task', '-')} | {built} | "
              f"{time.perf_counter() - t0:.1f}", flush=True)
    for action in ("open", "close", "task"):
        tasks = sum(v.get(action, "").startswith("task") for v in rows.values())
        codes = sorted({v[action] for v in rows.values() if not v.get(action, "").startswith("task")})
        print(f"{action}: {tasks}/{len(rows)} tasks" + (f", skipped {codes}" if codes else ""))
    print(f"built and stepped: {stepped}/{len(folders)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
