"""The CPU time of every process of a flow run, by role, beside the refine children's: what the orchestration costs.

:class:`FlowCpu` samples, every ``interval`` s, this process and every process below it (psutil: user + system s of
each, and of the children each has reaped). Roles by command line: the driver (this process: the Prefect flow
engine, the catalog rows and, with a local cluster, the Dask scheduler and the nannies), the Prefect server, a Dask
scheduler or ``dask worker`` nanny started as a process of its own, the Dask workers (the processes that run the
tasks: the parents of the stage servers), the stage servers (``asset2sim.flows.forkserver``) and the refine children
they fork (the stages of each asset: counted by what each stage server reaped, plus any child still running), an
S3-compatible server the benchmark started (the store's stand-in, not the flow's) and anything else.

``snapshot(name)`` records every process's figures at that moment (``benchmarks/bench_flow.py`` takes one when the
flow starts, when its first asset's row is written and when its last one is); :meth:`FlowCpu.report` gives the CPU
of each role between two snapshots, the share of the machine (cores x wall s) and of the flow's CPU that refines
nothing (every role but the refine children), and what the rest of the machine did meanwhile.

A process that ends between two samples loses its last interval; the refine children do not, as their stage
server has reaped them (``wait4``) and carries their time. The sampler's own thread time is taken off the driver.
"""

from __future__ import annotations

import os
import re
import threading
import time
from dataclasses import dataclass, field

#: Roles in the order they are printed; "refine children" is the work, every other role of the flow refines nothing.
ROLES = ("driver", "Prefect server", "Dask scheduler", "Dask nannies", "Dask workers", "stage servers",
         "refine children", "other")
#: Roles outside the flow: an S3-compatible server a benchmark starts as the store.
OUTSIDE = ("S3 server",)
WORK_ROLE = "refine children"


def role_of(cmdline: str, is_root: bool, parent_cmdline: str) -> str:
    """The role of a process from its command line (``parent_cmdline``: its parent's)."""
    if is_root or re.search(r"asset2sim\S*\s+flow\b", cmdline):  # this process, or an ``asset2sim flow`` it ran
        return "driver"
    if "asset2sim.flows.forkserver" in cmdline:
        return "refine children" if "asset2sim.flows.forkserver" in parent_cmdline else "stage servers"
    if "moto" in cmdline:
        return "S3 server"
    if "prefect" in cmdline and ("uvicorn" in cmdline or "server start" in cmdline):
        return "Prefect server"
    if "dask scheduler" in cmdline or "dask_scheduler" in cmdline or "dask-scheduler" in cmdline:
        return "Dask scheduler"
    if "spawn_main" in cmdline:
        return "Dask workers"
    if "dask worker" in cmdline or "dask_worker" in cmdline or "dask-worker" in cmdline:
        return "Dask nannies"
    return "other"


@dataclass
class _Proc:
    role: str
    parent: int
    own: float = 0.0  # user + system s
    reaped: float = 0.0  # children's user + system s, those it waited for
    alive: bool = True


@dataclass
class Snapshot:
    """Every process's figures at one moment (``t`` monotonic s, ``machine`` busy CPU s of the whole machine,
    ``sampler`` the sampler thread's CPU s)."""

    t: float
    machine: float
    sampler: float
    procs: dict[tuple[int, float], _Proc] = field(default_factory=dict)


class FlowCpu:
    """Samples the CPU time of this process and its descendants by role (a context manager; ``snapshot(name)``
    while it runs)."""

    def __init__(self, interval: float = 0.5):
        import psutil

        self._psutil, self.interval = psutil, float(interval)
        self._me = psutil.Process()
        self._procs: dict[tuple[int, float], _Proc] = {}
        self._handles: dict[tuple[int, float], object] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="flow-cpu-sampler", daemon=True)
        self._sampler_cpu = 0.0
        self.snapshots: dict[str, Snapshot] = {}

    def _machine_busy(self) -> float:
        t = self._psutil.cpu_times()
        return sum(getattr(t, f) for f in t._fields if f not in ("idle", "iowait", "steal", "guest", "guest_nice"))

    def _sample(self) -> None:
        ps = self._psutil
        try:
            procs = [self._me, *self._me.children(recursive=True)]
        except ps.Error:
            return
        seen = set()
        for p in procs:
            try:
                key = (p.pid, p.create_time())
                if key not in self._handles:
                    try:
                        parent = p.parent()
                        pcmd = " ".join(parent.cmdline()) if parent is not None else ""
                        ppid = parent.pid if parent is not None else 0
                    except ps.Error:
                        pcmd, ppid = "", 0
                    self._handles[key] = p
                    self._procs[key] = _Proc(role_of(" ".join(p.cmdline()), p.pid == self._me.pid, pcmd), ppid)
                t = p.cpu_times()
            except (ps.NoSuchProcess, ps.ZombieProcess, ps.AccessDenied):
                continue
            rec = self._procs[key]
            rec.own = t.user + t.system
            rec.reaped = t.children_user + t.children_system
            rec.alive = True
            seen.add(key)
        for key, rec in self._procs.items():
            if key not in seen:
                rec.alive = False

    def _loop(self) -> None:
        while not self._stop.wait(self.interval):
            with self._lock:
                c0 = time.thread_time()
                self._sample()
                self._sampler_cpu += time.thread_time() - c0

    def snapshot(self, name: str) -> Snapshot:
        """Sample now and keep every process's figures under ``name``."""
        with self._lock:
            c0 = time.thread_time()
            self._sample()
            self._sampler_cpu += time.thread_time() - c0
            snap = Snapshot(time.monotonic(), self._machine_busy(), self._sampler_cpu,
                            {k: _Proc(v.role, v.parent, v.own, v.reaped, v.alive) for k, v in self._procs.items()})
        self.snapshots[name] = snap
        return snap

    def __enter__(self) -> "FlowCpu":
        self.snapshot("start")
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()
        self.snapshot("end")

    def report(self, since: str, until: str, cores: int | None = None) -> dict:
        """CPU s by role between snapshots ``since`` and ``until``, and the shares that refine nothing.

        Returns:
            ``{"wall_s", "cores", "roles": {role: s}, "outside": {role: s}, "flow_s", "work_s", "orchestration_s",
            "orchestration_share_of_machine", "orchestration_share_of_flow", "rest_of_machine_s"}``; the refine
            children's s is what the stage servers reaped in between plus what children alive at ``until`` used.
        """
        a, b = self.snapshots[since], self.snapshots[until]
        cores = int(cores or os.cpu_count() or 1)
        roles = dict.fromkeys(ROLES, 0.0)
        outside = dict.fromkeys(OUTSIDE, 0.0)
        ended_children_of_driver = 0.0
        root_key = next((k for k in b.procs if k[0] == os.getpid()), None)  # this process (the sampler's)
        for key, p in b.procs.items():
            before = a.procs.get(key)
            own = p.own - (before.own if before else 0.0)
            bucket = outside if p.role in outside else roles
            if p.role == "refine children":
                if p.alive:  # still running at ``until``: its own time (a reaped one is in its stage server's)
                    roles[WORK_ROLE] += own
                continue
            bucket[p.role] += own
            if p.role == "stage servers":
                roles[WORK_ROLE] += p.reaped - (before.reaped if before else 0.0)
            if not p.alive and root_key is not None and p.parent == root_key[0]:  # reaped by this process: its own
                ended_children_of_driver += own + p.reaped - (before.reaped if before else 0.0)  # and what it reaped
        if root_key is not None:  # processes this process ran and reaped unseen between two samples (git, ...)
            d_b, d_a = b.procs[root_key], a.procs.get(root_key)
            reaped = d_b.reaped - (d_a.reaped if d_a else 0.0)
            roles["other"] += max(0.0, reaped - ended_children_of_driver)
            roles["driver"] -= b.sampler - a.sampler  # the sampler is the benchmark's, not the flow's
        wall = b.t - a.t
        flow = sum(roles.values())
        orch = flow - roles[WORK_ROLE]
        machine = b.machine - a.machine
        return {"wall_s": wall, "cores": cores, "roles": roles, "outside": outside, "flow_s": flow,
                "work_s": roles[WORK_ROLE], "orchestration_s": orch,
                "orchestration_share_of_machine": orch / (cores * wall) if wall > 0 else None,
                "orchestration_share_of_flow": orch / flow if flow > 0 else None,
                "rest_of_machine_s": max(0.0, machine - flow - sum(outside.values()))}


def print_report(r: dict, title: str, prepare_s: float | None = None) -> None:
    """Print :meth:`FlowCpu.report`'s figures (``prepare_s``: the prepare stage's summed CPU s, the catalog's
    ``cpu.prepare``: reading, checking and hashing the inputs in the Dask workers, counted in their CPU)."""
    roles = ", ".join(f"{k} {v:.1f}" for k, v in r["roles"].items() if v >= 0.05 and k != WORK_ROLE)
    print(f"  CPU of the flow's processes, {title} ({r['wall_s']:.1f} s wall on {r['cores']} cores): "
          f"refine children {r['work_s']:.1f} s; refining nothing {r['orchestration_s']:.1f} s ({roles})")
    line = (f"    refining nothing: {100 * (r['orchestration_share_of_machine'] or 0):.1f} % of the machine (goal < 8 %), "
            f"{100 * (r['orchestration_share_of_flow'] or 0):.1f} % of the flow's CPU")
    if prepare_s:
        line += (f"; of it the inputs read in the Dask workers (prepare) {prepare_s:.1f} s, without them "
                 f"{100 * (r['orchestration_s'] - prepare_s) / (r['cores'] * r['wall_s']):.1f} % of the machine")
    outside = ", ".join(f"{k} {v:.1f} s" for k, v in r["outside"].items() if v >= 0.05)
    print(line + (f"; outside the flow: {outside}" if outside else "")
          + f"; other processes on the machine {r['rest_of_machine_s']:.1f} s")
