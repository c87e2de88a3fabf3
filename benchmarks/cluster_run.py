"""The guide's recipe for N machines run on 127.0.0.1, and a flow run on it compared with the local flow's.

``docs/guide/pipeline.md`` ("On N machines") holds the recipe as one fenced block after the line that starts with
:data:`RECIPE_MARK` (the documents' own test does not run it): a Prefect server and a Dask scheduler on one machine, the environment every machine exports
(the Prefect API, the object store's endpoint and credentials), one ``dask worker`` line run on each worker machine
and the driver's ``asset2sim flow --scheduler ...``. :func:`recipe` reads those commands; :class:`RecipeCluster` runs
them here, each as a process of its own, after substituting what the recipe writes in capitals (``HOST`` ->
127.0.0.1, ``0.0.0.0`` -> 127.0.0.1, the ports -> free ports, ``CORES`` -> 1, ``ENDPOINT`` / ``KEY`` / ``SECRET`` /
``REGION`` -> the local S3-compatible server's), the worker line once per machine asked for. Nothing else is
added: a change of the recipe changes what the test (``tests/flows/test_cluster_store.py``) and the benchmark
(``benchmarks/bench_cluster.py``) run.

:func:`compare_runs` compares a cluster run's catalog rows and output folders (in the store) with a local run's:
every column but the timings and the run's own names, and every file's bytes but ``timings.json``.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "guide" / "pipeline.md"
#: The line before the recipe's fenced block in the guide.
RECIPE_MARK = "<!-- not run in tests: the recipe for N machines"
BIN = Path(sys.executable).parent

#: Catalog columns that differ between two runs of the same work: times, the run's names, where the output lies, and
#: the checkout's label (``code_version``: the commit when each run started, a commit of documents in between changes
#: it; ``code_hash``, the source, is compared).
RUN_COLUMNS = ("run", "wall_seconds", "stage_seconds", "started_at", "finished_at", "flow_run_id", "worker", "out_dir",
               "source_run", "dataset", "code_version")


@dataclass
class Recipe:
    """The recipe's commands: ``servers`` (started in the background on the coordinating machine), ``env`` (what
    every machine exports), ``worker`` (run on each worker machine) and ``driver`` (the flow), each an argv."""

    servers: list[list[str]]
    env: dict[str, str]
    worker: list[str]
    driver: list[str]


def recipe(guide: Path = GUIDE) -> Recipe:
    """The commands of the fenced block after :data:`RECIPE_MARK` in ``guide`` (comments and ``&`` dropped).
    ValueError: no such block, or it lacks a server, the worker line or the flow line."""
    text = guide.read_text()
    at = text.find(RECIPE_MARK)
    if at < 0:
        raise ValueError(f"{guide}: no recipe after {RECIPE_MARK!r}")
    block = re.search(r"```bash\n(.*?)```", text[at:], re.S)
    if block is None:
        raise ValueError(f"{guide}: the recipe's fenced block is missing")
    servers, env, worker, driver = [], {}, None, None
    for line in block.group(1).splitlines():
        line = line.split("#", 1)[0].strip().rstrip("&").strip()
        if not line:
            continue
        argv = shlex.split(line)
        if argv[0] == "export":
            env.update(kv.split("=", 1) for kv in argv[1:])
        elif argv[:2] == ["dask", "worker"]:
            worker = argv
        elif argv[:2] == ["asset2sim", "flow"]:
            driver = argv
        else:
            servers.append(argv)
    if not servers or worker is None or driver is None:
        raise ValueError(f"{guide}: the recipe needs its servers, a 'dask worker' line and an 'asset2sim flow' line")
    return Recipe(servers, env, worker, driver)


def free_port() -> int:
    """A free TCP port on 127.0.0.1."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_port(port: int, proc: subprocess.Popen, timeout: float, what: str, log: Path) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"{what} exited with {proc.returncode} (log {log})")
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.25)
    raise RuntimeError(f"{what} did not listen on 127.0.0.1:{port} within {timeout:.0f} s (log {log})")


@dataclass
class RecipeCluster:
    """The recipe running on 127.0.0.1 (a context manager): its servers, ``machines`` worker lines, every process in
    its own process group with its log in ``workdir``. ``store``: the S3-compatible endpoint and credentials
    (``ENDPOINT``, ``KEY``, ``SECRET``, ``REGION``) the recipe's placeholders stand for."""

    workdir: Path
    store: dict[str, str]
    machines: int = 2
    timeout: float = 240.0
    procs: list[subprocess.Popen] = field(default_factory=list)
    subs: dict[str, str] = field(default_factory=dict)
    env: dict[str, str] = field(default_factory=dict)
    recipe: Recipe | None = None

    def _sub(self, arg: str) -> str:
        for k, v in self.subs.items():
            arg = re.sub(rf"\b{re.escape(k)}\b", v, arg)
        return arg

    def _argv(self, argv: list[str]) -> list[str]:
        argv = [self._sub(a) for a in argv]
        exe = BIN / argv[0]
        return [str(exe) if exe.is_file() else argv[0], *argv[1:]]

    def _start(self, argv: list[str], name: str) -> subprocess.Popen:
        log = open(self.workdir / f"{name}.log", "wb")
        proc = subprocess.Popen(self._argv(argv), env=self.env, stdout=log, stderr=subprocess.STDOUT, cwd=self.workdir,
                                start_new_session=True)
        self.procs.append(proc)
        return proc

    def __enter__(self) -> "RecipeCluster":
        self.workdir.mkdir(parents=True, exist_ok=True)
        self.recipe = recipe()
        ports = {p: str(free_port()) for p in {m for argv in [*self.recipe.servers, self.recipe.worker, self.recipe.driver,
                                                              list(self.recipe.env.values())]
                                                 for a in argv for m in re.findall(r"\b(\d{4,5})\b", a)}}
        self.subs = {"HOST": "127.0.0.1", "0.0.0.0": "127.0.0.1", "CORES": "1", **ports, **self.store}
        self.env = {**os.environ, **{k: self._sub(v) for k, v in self.recipe.env.items()}}
        self.env["PATH"] = f"{BIN}{os.pathsep}{self.env.get('PATH', '')}"
        try:
            for i, argv in enumerate(self.recipe.servers):
                proc = self._start(argv, f"server{i}")
                port = next(int(self._sub(a)) for a in argv if re.fullmatch(r"\d{4,5}", a))
                _wait_port(port, proc, self.timeout, " ".join(argv[:3]), self.workdir / f"server{i}.log")
            self._wait_prefect()
            for i in range(self.machines):
                self._start(self.recipe.worker, f"worker{i}")
            self._wait_workers()
        except BaseException:
            self.close()
            raise
        return self

    def _wait_prefect(self) -> None:
        import urllib.request

        url = self.env["PREFECT_API_URL"]
        deadline = time.monotonic() + self.timeout
        while time.monotonic() < deadline:
            try:
                with urllib.request.urlopen(url + "/health", timeout=2) as resp:
                    if resp.status == 200:
                        return
            except OSError:
                time.sleep(0.5)
        raise RuntimeError(f"the Prefect server did not answer at {url} (logs in {self.workdir})")

    @property
    def scheduler(self) -> str:
        """The scheduler's address as the recipe's driver line names it."""
        i = self.recipe.driver.index("--scheduler")
        return self._sub(self.recipe.driver[i + 1])

    def _wait_workers(self) -> None:
        from distributed import Client

        n = self.machines * int(self._sub(self.recipe.worker[self.recipe.worker.index("--nworkers") + 1]))
        with Client(self.scheduler, timeout=self.timeout) as client:
            client.wait_for_workers(n, timeout=self.timeout)

    def flow(self, catalog: Path, *extra: str, timeout: float = 1800.0) -> subprocess.CompletedProcess:
        """The recipe's driver line with ``--catalog catalog`` (and ``extra`` arguments), run to its end."""
        argv = self._argv(self.recipe.driver)
        argv[argv.index("--catalog") + 1] = str(catalog)
        return subprocess.run([*argv, *extra, "--no-progress"], env=self.env, cwd=catalog.parent, capture_output=True, text=True,
                              timeout=timeout)

    def local_flow(self, catalog: Path, workers: int = 2, timeout: float = 1800.0) -> subprocess.CompletedProcess:
        """:func:`local_flow` with the recipe's environment (its Prefect server)."""
        return local_flow(catalog, workers, self.env, timeout)

    def close(self) -> None:
        for p in reversed(self.procs):
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except (ProcessLookupError, PermissionError):
                continue
        for p in reversed(self.procs):
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(p.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
                p.wait(timeout=20)
        self.procs.clear()

    def __exit__(self, *exc) -> None:
        self.close()


def local_flow(catalog: Path, workers: int = 2, env: dict[str, str] | None = None,
               timeout: float = 1800.0) -> subprocess.CompletedProcess:
    """``asset2sim flow --catalog catalog --workers N`` on this machine alone (the flow's own Dask cluster; without
    ``PREFECT_API_URL`` in ``env``, its own temporary Prefect server), run to its end."""
    argv = [str(BIN / "asset2sim"), "flow", "--catalog", str(catalog), "--workers", str(workers), "--no-progress"]
    return subprocess.run(argv, env=env if env is not None else dict(os.environ), cwd=catalog.parent,
                          capture_output=True, text=True, timeout=timeout)


def run_rows(catalog: Path, run: str | None = None):
    """The catalog rows of ``catalog``'s default dataset, of ``run`` (None: the latest run), sorted by asset id."""
    from asset2sim.flows.catalog import ResultCatalog
    from asset2sim.flows.catalog_config import load_catalog

    cat = load_catalog(catalog)
    name, _ = cat.dataset(None)
    store = ResultCatalog(cat.catalog_root)
    run = run or sorted(r for _, r in store.runs(name))[-1]
    return store.read(name, run).sort_values("asset_id").reset_index(drop=True)


def folder_files(uri: str) -> dict[str, str]:
    """Relative path -> SHA-256 of every file of the output folder at ``uri`` (a path or a store URI) but
    ``timings.json`` (the output's wall times)."""
    import hashlib

    import pyarrow.fs as pafs

    from asset2sim.flows import store
    from asset2sim.output_folder import VOLATILE

    loc = store.open_location(uri)
    out = {}
    for info in loc.fs.get_file_info(pafs.FileSelector(loc.base, recursive=True)):
        if info.type != pafs.FileType.File:
            continue
        rel = info.path[len(loc.base.rstrip("/")) + 1:]
        if rel in VOLATILE:
            continue
        with loc.fs.open_input_stream(info.path) as fh:
            out[rel] = hashlib.sha256(fh.read()).hexdigest()
    return out


def compare_runs(local_rows, cluster_rows) -> list[str]:
    """What differs between two runs of the same assets (empty: nothing but the timings and the run's names): a
    catalog column (all but :data:`RUN_COLUMNS`) of an asset, and a file of its output folder (``out_dir``: a local
    folder or a store URI), its bytes (SHA-256) or its presence, ``timings.json`` aside."""
    import pandas as pd

    problems = []
    a, b = local_rows.set_index("asset_id"), cluster_rows.set_index("asset_id")
    if set(a.index) != set(b.index):
        problems.append(f"assets differ: local only {sorted(set(a.index) - set(b.index))}, "
                        f"cluster only {sorted(set(b.index) - set(a.index))}")
    cols = [c for c in a.columns if c in b.columns and c not in RUN_COLUMNS]
    for aid in sorted(set(a.index) & set(b.index)):
        for c in cols:
            x, y = a.at[aid, c], b.at[aid, c]
            if not ((pd.isna(x) and pd.isna(y)) if not isinstance(x, (list, dict)) else False) and x != y:
                problems.append(f"{aid}: {c} {x!r} (local) != {y!r} (cluster)")
        if isinstance(a.at[aid, "out_dir"], str) and isinstance(b.at[aid, "out_dir"], str):
            fa, fb = folder_files(a.at[aid, "out_dir"]), folder_files(b.at[aid, "out_dir"])
            for rel in sorted(set(fa) | set(fb)):
                if fa.get(rel) != fb.get(rel):
                    problems.append(f"{aid}: {rel} " + ("differs" if rel in fa and rel in fb
                                                        else "only local" if rel in fa else "only in the cluster's"))
    return problems


def write_catalogs(work: Path, dataset_root: Path, manifest: Path, bucket: str, run: dict) -> tuple[Path, Path]:
    """``work/local/catalog.yaml`` (catalog and outputs in local folders) and ``work/cluster/catalog.yaml`` (catalog
    and outputs in ``s3://bucket``) over the same dataset (``run``: the ``run`` section of both; tracking off, code
    changes kept: another edit of the package source meanwhile redoes nothing). Returns both paths."""
    paths = []
    for name, where in (("local", {"catalog_root": "catalog", "output_root": "refined"}),
                        ("cluster", {"catalog_root": f"s3://{bucket}/catalog", "output_root": "refined",
                                     "output_store": f"s3://{bucket}/refined"})):
        (work / name).mkdir(parents=True, exist_ok=True)
        config = {"version": 1, "default_dataset": "dev", **where,
                  "datasets": {"dev": {"root": str(dataset_root), "manifest": str(manifest)}},
                  "run": run, "tracking": {"enabled": False}, "results": {"code_change": "keep"}}
        path = work / name / "catalog.yaml"
        path.write_text(json.dumps(config))  # JSON is YAML
        paths.append(path)
    return paths[0], paths[1]


class S3Server:
    """moto's S3-compatible server as a process of its own on 127.0.0.1 (a context manager) with one ``bucket``;
    :attr:`store` the recipe's store placeholders."""

    def __init__(self, workdir: Path, bucket: str):
        self.workdir, self.bucket, self.proc = workdir, bucket, None
        self.port = free_port()
        self.endpoint = f"http://127.0.0.1:{self.port}"
        self.store = {"ENDPOINT": self.endpoint, "KEY": "testing", "SECRET": "testing", "REGION": "us-east-1"}

    def __enter__(self) -> "S3Server":
        import boto3

        self.workdir.mkdir(parents=True, exist_ok=True)
        log = open(self.workdir / "s3.log", "wb")
        self.proc = subprocess.Popen([str(BIN / "moto_server"), "-H", "127.0.0.1", "-p", str(self.port)], stdout=log,
                                     stderr=subprocess.STDOUT, start_new_session=True)
        _wait_port(self.port, self.proc, 60.0, "moto_server", self.workdir / "s3.log")
        boto3.client("s3", endpoint_url=self.endpoint, region_name="us-east-1", aws_access_key_id="testing",
                     aws_secret_access_key="testing").create_bucket(Bucket=self.bucket)
        return self

    def environ(self) -> dict[str, str]:
        """The environment that points S3 clients of this process at the server."""
        return {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1",
                "AWS_ENDPOINT_URL": self.endpoint, "AWS_EC2_METADATA_DISABLED": "true"}

    def __exit__(self, *exc) -> None:
        if self.proc is not None:
            try:
                os.killpg(self.proc.pid, signal.SIGKILL)
            except (ProcessLookupError, PermissionError):
                pass
            self.proc.wait(timeout=20)
