"""The learnability benchmark in ManiSkill 3 (``bench_learnability.py --framework maniskill``).

Per method (``raw``: the unrefined input; ``defaults``, ``human``, ``direct``,
``asset2sim``: :func:`asset2sim.tasks.benchmark.baselines.run_method`) and
seed, one PPO policy (CleanRL's PPO as ManiSkill's ``examples/baselines/ppo``
has it: state observations, ``normalized_dense`` reward, gamma 0.8, GAE 0.9,
4 epochs, clip 0.2, target KL 0.1) trains on the training objects of the
``asset2sim.apps.learn.maniskill`` environment (``Asset2Sim-CloseArticulation-v1`` or
``-OpenArticulation-v1``, one object per sub-scene), then its deterministic
policy runs ``--eval-episodes`` episodes on every object, the held-out ones
(``--held-out``) included. A passive reference (the robot holding still) shows
what gravity does alone. Printed: success per object, method and seed (PPO mean
over seeds / passive), the mean over training and held-out objects, time to the
first successful training episode, and the budget (environments x steps, wall
time, device).

CPU (``--sim-backend cpu``): each training object is an environment of its own
(ManiSkill's CPU backend holds one sub-scene), stepped in turn. GPU
(``--sim-backend gpu``): one environment of ``--n-envs`` sub-scenes holding the
training objects in turn (written for the field's budget, see
:func:`gpu_command`; not run on a machine without a GPU).
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np


def gpu_command(args) -> str:
    """The command that runs this comparison at ManiSkill's tuned budget for OpenCabinetDrawer-v1 (1,024
    environments x 10 M steps, 3 seeds) on a GPU."""
    return ("python benchmarks/bench_learnability.py --framework maniskill --sim-backend gpu --device cuda "
            f"--ids {args.ids or '<train ids>'} --held-out {args.held_out or '<held-out ids>'} --methods {args.methods} "
            f"--action {args.action} --n-envs 1024 --steps 10000000 --num-steps 50 --seeds 0,1,2 --eval-episodes 16 "
            f"--out out/bench_learnability_gpu")


class _Batch:
    """Training environments as one batch: ``obs`` (b, n), ``step(actions)`` -> (obs, reward, done, success),
    each (b,), resetting an environment whose episode ended (CPU: one ManiSkill environment per object)."""

    def __init__(self, env_id: str, folders: list[Path], tasks: dict[str, str], args, seed: int):
        import gymnasium as gym

        kw = dict(task=tasks, obs_mode="state", reward_mode="normalized_dense", control_mode=args.control_mode,
                  render_backend="none")
        self.gpu = args.sim_backend == "gpu"
        if self.gpu:
            from mani_skill.vector.wrappers.gymnasium import ManiSkillVectorEnv

            env = gym.make(env_id, assets=folders, num_envs=args.n_envs, sim_backend="gpu", **kw)
            self.envs = [ManiSkillVectorEnv(env, args.n_envs, auto_reset=True, ignore_terminations=False)]
        else:
            self.envs = [gym.make(env_id, assets=[f], num_envs=1, sim_backend="cpu", **kw) for f in folders]
        self.seed = seed
        self.episodes = 0

    def reset(self):
        import torch

        outs = [e.reset(seed=self.seed + 1000 * i)[0] for i, e in enumerate(self.envs)]
        return torch.cat([o.reshape(-1, o.shape[-1]).float().cpu() for o in outs])

    @property
    def action_dim(self) -> int:
        sp = self.envs[0].single_action_space if self.gpu else self.envs[0].action_space
        return int(np.prod(sp.shape[-1:]))

    def step(self, actions):
        import torch

        if self.gpu:
            obs, rew, term, trunc, info = self.envs[0].step(actions)
            done = term | trunc
            succ = info.get("success", torch.zeros_like(done))
            self.episodes += int(done.sum())
            return obs.float().cpu(), rew.float().cpu(), done.cpu(), succ.cpu()
        obs_l, rew_l, done_l, succ_l = [], [], [], []
        for i, e in enumerate(self.envs):
            o, r, te, tr, info = e.step(actions[i:i + 1].cpu().numpy())
            d = bool(te[0]) or bool(tr[0])
            succ_l.append(bool(info["success"][0]))
            if d:
                self.episodes += 1
                o, _ = e.reset()
            obs_l.append(o.reshape(1, -1).float())
            rew_l.append(float(r[0]))
            done_l.append(d)
        return torch.cat(obs_l), torch.tensor(rew_l), torch.tensor(done_l), torch.tensor(succ_l)

    def close(self):
        for e in self.envs:
            e.close()


def _agent(n_obs: int, n_act: int, hidden: int):
    import torch
    from torch import nn

    def layer(i, o, std=np.sqrt(2)):
        lin = nn.Linear(i, o)
        nn.init.orthogonal_(lin.weight, std)
        nn.init.constant_(lin.bias, 0.0)
        return lin

    class Agent(nn.Module):
        """CleanRL's continuous-action PPO agent (ManiSkill's baseline: tanh MLPs, a learned state-free log std)."""

        def __init__(self):
            super().__init__()
            self.critic = nn.Sequential(layer(n_obs, hidden), nn.Tanh(), layer(hidden, hidden), nn.Tanh(), layer(hidden, 1, 1.0))
            self.actor_mean = nn.Sequential(layer(n_obs, hidden), nn.Tanh(), layer(hidden, hidden), nn.Tanh(),
                                            layer(hidden, n_act, 0.01 * np.sqrt(2)))
            self.actor_logstd = nn.Parameter(torch.ones(1, n_act) * -0.5)

        def value(self, x):
            return self.critic(x)

        def act(self, x, action=None):
            mean = self.actor_mean(x)
            dist = torch.distributions.Normal(mean, torch.exp(self.actor_logstd.expand_as(mean)))
            if action is None:
                action = dist.sample()
            return action, dist.log_prob(action).sum(1), dist.entropy().sum(1), self.critic(x)

    return Agent()


def train_ppo(env_id: str, folders: list[Path], tasks: dict[str, str], args, seed: int) -> tuple[object, dict]:
    """Train one policy on ``folders`` (``tasks``: str(folder) -> task text); returns (agent, record: env steps, episodes, wall time, first success)."""
    import torch

    torch.manual_seed(seed)
    np.random.seed(seed)
    batch = _Batch(env_id, folders, tasks, args, seed)
    t0 = time.perf_counter()
    try:
        dev = torch.device(args.device)
        obs = batch.reset().to(dev)
        b, n_obs = obs.shape
        agent = _agent(n_obs, batch.action_dim, args.hidden).to(dev)
        opt = torch.optim.Adam(agent.parameters(), lr=args.lr, eps=1e-5)
        T = args.num_steps
        steps, first_success = 0, None
        updates = max(1, args.steps // (T * b))
        for _ in range(updates):
            buf_o, buf_a, buf_lp, buf_r, buf_d, buf_v = [], [], [], [], [], []
            for _t in range(T):
                with torch.no_grad():
                    a, lp, _, v = agent.act(obs)
                nxt, r, d, succ = (x.to(dev) for x in batch.step(torch.clamp(a, -1, 1)))
                buf_o.append(obs), buf_a.append(a), buf_lp.append(lp), buf_r.append(r), buf_d.append(d.float()), buf_v.append(v[:, 0])
                steps += b
                if first_success is None and bool(succ.any()):
                    first_success = {"env_steps": steps, "seconds": time.perf_counter() - t0}
                obs = nxt
            with torch.no_grad():
                last_v = agent.value(obs)[:, 0]
            O, A, LP, R, D, V = (torch.stack(x) for x in (buf_o, buf_a, buf_lp, buf_r, buf_d, buf_v))
            adv = torch.zeros_like(R)
            gae = torch.zeros(b, device=dev)
            for t in reversed(range(T)):
                nv = last_v if t == T - 1 else V[t + 1]
                nonterm = 1.0 - D[t]
                delta = R[t] + args.gamma * nv * nonterm - V[t]
                gae = delta + args.gamma * args.gae_lambda * nonterm * gae
                adv[t] = gae
            ret = adv + V
            O, A, LP, adv, ret = O.reshape(T * b, -1), A.reshape(T * b, -1), LP.reshape(-1), adv.reshape(-1), ret.reshape(-1)
            mb = max(1, (T * b) // args.minibatches)
            for _e in range(args.update_epochs):
                perm = torch.randperm(T * b, device=dev)
                stop = False
                for k in range(0, T * b, mb):
                    idx = perm[k:k + mb]
                    _, nlp, ent, nv = agent.act(O[idx], A[idx])
                    ratio = torch.exp(nlp - LP[idx])
                    approx_kl = ((ratio - 1) - torch.log(ratio)).mean()
                    a_n = adv[idx]
                    a_n = (a_n - a_n.mean()) / (a_n.std() + 1e-8) if len(idx) > 1 else a_n
                    pg = torch.max(-a_n * ratio, -a_n * torch.clamp(ratio, 1 - args.clip, 1 + args.clip)).mean()
                    vl = 0.5 * ((nv[:, 0] - ret[idx]) ** 2).mean()
                    loss = pg + 0.5 * vl - 0.0 * ent.mean()
                    opt.zero_grad()
                    loss.backward()
                    torch.nn.utils.clip_grad_norm_(agent.parameters(), 0.5)
                    opt.step()
                    if approx_kl > args.target_kl:
                        stop = True
                        break
                if stop:
                    break
            if args.max_run_seconds and time.perf_counter() - t0 > args.max_run_seconds:
                break
        rec = {"env_steps": steps, "train_seconds": time.perf_counter() - t0, "train_episodes": batch.episodes,
               "first_success": first_success, "n_envs": b}
        return agent, rec
    finally:
        batch.close()


def evaluate(env_id: str, folder: Path, task: str, args, policy) -> dict:
    """``--eval-episodes`` episodes (reset seeds 10000 + i) of ``policy`` (obs -> action, or None: hold still) on
    one object (CPU). Success: the episode ended by the environment's success."""
    import gymnasium as gym
    import torch

    if policy is not None:
        policy.to("cpu")
    env = gym.make(env_id, assets=[folder], task=task, num_envs=1, obs_mode="state", reward_mode="normalized_dense",
                   control_mode=args.control_mode, render_backend="none", sim_backend="cpu")
    try:
        wins, fractions = 0, []
        for i in range(args.eval_episodes):
            obs, _ = env.reset(seed=10000 + i)
            done, success = False, False
            while not done:
                with torch.no_grad():
                    a = np.zeros(env.action_space.shape, np.float32) if policy is None else \
                        torch.clamp(policy.actor_mean(obs.float()), -1, 1).numpy()
                obs, _, te, tr, info = env.step(a)
                success = success or bool(info["success"][0])
                done = bool(te[0]) or bool(tr[0])
            wins += int(success)
            fractions.append(float(info["fraction"][0]))
        u = env.unwrapped
        return {"success_rate": wins / args.eval_episodes, "final_fractions": fractions, "joint": u.objects[0].joint,
                "asset_kind": u.objects[0].kind}
    finally:
        env.close()


def print_table(records: list[dict], out=sys.stdout) -> None:
    """Success (%) per object (rows, held-out marked) and method (columns): PPO mean over seeds (each seed in
    brackets) / passive; the means over training and held-out objects; time to first success; the budget."""
    methods = list(dict.fromkeys(r["method"] for r in records))
    ids = list(dict.fromkeys(r["id"] for r in records if r.get("id")))
    split = {r["id"]: r["split"] for r in records if r.get("id")}
    cell: dict[tuple[str, str], dict] = {}
    for r in records:
        if r.get("kind") in ("ppo_eval", "passive") and r.get("success_rate") is not None:
            c = cell.setdefault((r["id"], r["method"]), {"ppo": {}, "passive": None})
            if r["kind"] == "ppo_eval":
                c["ppo"][r["seed"]] = r["success_rate"]
            else:
                c["passive"] = r["success_rate"]

    def fmt(x):
        return "-" if x is None else f"{100 * x:.0f}"

    w = 26
    print("success (%) per object and method: PPO mean over seeds [per seed] / passive (robot holding still)", file=out)
    print(f"{'id':>7} {'split':<9}" + "".join(f"{m:>{w}}" for m in methods), file=out)
    means = {(m, s): [] for m in methods for s in ("train", "held-out")}
    for i in ids:
        line = f"{i:>7} {split[i]:<9}"
        for m in methods:
            c = cell.get((i, m))
            if not c or not c["ppo"]:
                line += f"{'n/a' if not c else '- / ' + fmt(c['passive']):>{w}}"
                continue
            p = statistics.fmean(c["ppo"].values())
            means[(m, split[i])].append(p)
            seeds = ",".join(fmt(v) for _, v in sorted(c["ppo"].items()))
            line += f"{fmt(p) + ' [' + seeds + '] / ' + fmt(c['passive']):>{w}}"
        print(line, file=out)
    for s in ("train", "held-out"):
        print(f"{'mean':>7} {s:<9}" + "".join(f"{fmt(statistics.fmean(means[(m, s)]) if means[(m, s)] else None):>{w}}"
                                              for m in methods), file=out)
    runs = [r for r in records if r.get("kind") == "ppo_train"]
    for r in runs:
        fs = r.get("first_success")
        when = f"after {fs['env_steps']} env steps ({fs['seconds']:.0f} s)" if fs else "never"
        print(f"  {r['method']:>9} seed {r['seed']}: first successful training episode {when}; "
              f"{r['env_steps']} env steps = {r['n_envs']} envs x {r['env_steps'] // max(r['n_envs'], 1)} steps, "
              f"{r['train_episodes']} episodes, {r['train_seconds'] / 60:.1f} min", file=out)
    if runs:
        r0 = runs[0]
        print(f"budget: {len(runs)} PPO runs, {sum(r['env_steps'] for r in runs)} env steps in all "
              f"({sum(r['env_steps'] for r in runs) * 12 / 240 / 3600:.2f} h simulated at 12 PhysX steps of 1/240 s per step), "
              f"{sum(r['train_seconds'] for r in runs) / 60:.1f} min training; device {r0.get('device')}, "
              f"sim backend {r0.get('sim_backend')}; versions {r0.get('versions')}", file=out)
    for r in records:
        if r.get("error"):
            print(f"error {r['method']} {r.get('id', '')} ({r.get('kind')}): {r['error']}", file=out)


def run(args, rows: list, held_out: list, make_assets, record_flags=None) -> int:
    """The ManiSkill comparison over ``rows`` (training objects) and ``held_out`` (manifest rows); ``make_assets``:
    bench_learnability's (rows, methods, args) -> {(id, method): folder or error}; ``record_flags``: bench_learnability's
    (records, args) -> None, the flags into the catalog (``--catalog``)."""
    import platform

    import mani_skill
    import sapien
    import torch

    import asset2sim.apps.learn.maniskill as ams

    torch.set_num_threads(1)
    env_id = ams.ENV_IDS[args.action]
    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    seeds = [int(s) for s in args.seeds.split(",") if s.strip()]
    args.out.mkdir(parents=True, exist_ok=True)
    results = args.out / "results_maniskill.jsonl"
    device = f"{args.sim_backend} ({platform.processor() or platform.machine()}, torch threads {torch.get_num_threads()})"
    versions = f"mani_skill {mani_skill.__version__}, sapien {sapien.__version__}, torch {torch.__version__}"
    records: list[dict] = []

    def emit(rec: dict) -> None:
        records.append(rec)
        with results.open("a") as f:
            f.write(json.dumps(rec) + "\n")

    t_all = time.perf_counter()
    all_rows = list(rows) + list(held_out)
    made = make_assets(all_rows, [m for m in methods if m != "raw"], args)
    split = {r.id: "train" for r in rows} | {r.id: "held-out" for r in held_out}
    task_of = {r.id: r.task for r in all_rows}
    print(f"ManiSkill learnability: {env_id}, train {[r.id for r in rows]}, held-out {[r.id for r in held_out]}, "
          f"methods {methods}, seeds {seeds}, PPO {args.steps} env steps per run on {args.sim_backend}; "
          f"{args.eval_episodes} eval episodes per object; {versions}", flush=True)
    for m in methods:
        folders = {r.id: (r.folder if m == "raw" else made.get((r.id, m))) for r in all_rows}
        usable = {}
        for rid, f in folders.items():
            if isinstance(f, Path) and (f / "mobility.urdf").is_file():
                try:
                    ams.task_object(f, args.action, task_of[rid])
                    usable[rid] = f
                except ams.ManiSkillAssetError as exc:
                    emit({"method": m, "id": rid, "split": split[rid], "kind": "task", "error": str(exc)})
            else:
                emit({"method": m, "id": rid, "split": split[rid], "kind": "asset", "error": str(f)})
        for rid, f in usable.items():
            res = evaluate(env_id, f, task_of[rid], args, None)
            emit({"method": m, "id": rid, "split": split[rid], "kind": "passive", **res})
        train = [r.id for r in rows if r.id in usable]
        if not train:
            continue
        for seed in seeds:
            agent, rec = train_ppo(env_id, [usable[i] for i in train], {str(usable[i]): task_of[i] for i in train}, args, seed)
            emit({"method": m, "seed": seed, "kind": "ppo_train", "device": device, "sim_backend": args.sim_backend,
                  "versions": versions, "train_ids": train, **rec})
            print(f"  {m:>9} seed {seed}: trained {rec['env_steps']} env steps in {rec['train_seconds']:.0f} s, "
                  f"first success {rec['first_success']}", flush=True)
            for rid, f in usable.items():
                res = evaluate(env_id, f, task_of[rid], args, agent)
                emit({"method": m, "id": rid, "split": split[rid], "seed": seed, "kind": "ppo_eval", **res})
                print(f"    {rid} ({split[rid]}): {res['success_rate']:.2f} {res['final_fractions']}", flush=True)
    print(f"wall time {(time.perf_counter() - t_all) / 60:.1f} min; results in {results}", flush=True)
    print_table(records)
    if record_flags is not None:
        record_flags(records, args)
    print(f"field's budget on a GPU: {gpu_command(args)}")
    return 0
