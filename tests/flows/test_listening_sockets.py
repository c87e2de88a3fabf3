"""Every server a flow run starts listens where its log says: on a loopback
address. While a flow runs on a fresh local Dask cluster, the
listening TCP sockets of this process and all its children (scheduler,
nannies, workers, dashboard, stage servers) are listed; every one opened by
the run must be bound to 127.0.0.0/8 or ::1. With the dashboard on it is one
of them and answers; with ``--no-dashboard`` nothing answers there."""

from __future__ import annotations

import ipaddress
import socket
import threading
import urllib.error
import urllib.request

import psutil
import pytest

pytestmark = pytest.mark.slow  # end to end: the flows (Prefect, Dask, stage processes)

try:
    from .flowproject import make_project
except ImportError:
    from flowproject import make_project

ASSETS = {"box_lid": "box_lid", "laptop": "laptop"}
#: pages of the scheduler's HTTP server: the dashboard (bokeh, or the page
#: saying bokeh is missing), the info pages, the JSON API, health and metrics
DASHBOARD_PATHS = ("/status", "/info/main/workers.html", "/json/index.html", "/health", "/metrics")


def listening_sockets() -> set[tuple[str, int]]:
    """``(ip, port)`` of every listening TCP socket of this process and its
    children (recursively)."""
    me = psutil.Process()
    found = set()
    for proc in [me, *me.children(recursive=True)]:
        try:
            conns = proc.net_connections(kind="inet")
        except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
            continue
        for c in conns:
            if c.status == psutil.CONN_LISTEN and c.type == socket.SOCK_STREAM:
                found.add((c.laddr.ip, c.laddr.port))
    return found


def http_status(host: str, port: int, path: str) -> int | None:
    """HTTP status of ``GET http://<host>:<port><path>`` (None: no answer)."""
    try:
        with urllib.request.urlopen(f"http://{host}:{port}{path}", timeout=3) as resp:
            return resp.status
    except urllib.error.HTTPError as exc:
        return exc.code
    except OSError:
        return None


class SocketWatch:
    """Lists the listening sockets every 0.2 s in a thread while a flow runs
    (those open before it started are left out) and probes the HTTP server of
    each Dask scheduler the run starts in this process."""

    def __init__(self):
        from distributed import Scheduler

        self._schedulers = Scheduler._instances
        self._known = {id(s) for s in self._schedulers}
        self.before = listening_sockets()
        self.seen: set[tuple[str, int]] = set()
        self.http: dict[tuple[str, int], dict[str, int | None]] = {}  # scheduler HTTP (ip, port) -> path -> status
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def _loop(self) -> None:
        while not self._stop.is_set():
            self.seen |= listening_sockets() - self.before
            for sched in list(self._schedulers):
                server = getattr(sched, "http_server", None)
                addr = (getattr(server, "address", None), getattr(server, "port", None))
                if id(sched) in self._known or None in addr or addr in self.http:
                    continue
                self.http[addr] = {p: http_status(addr[0], addr[1], p) for p in DASHBOARD_PATHS}
            self._stop.wait(0.2)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join(timeout=30)


def _assert_loopback(seen: set[tuple[str, int]]) -> None:
    assert seen, "no listening socket seen during the flow"
    wide = sorted((ip, port) for ip, port in seen if not ipaddress.ip_address(ip).is_loopback)
    assert not wide, f"listening beyond loopback: {wide} (all: {sorted(seen)})"


def test_flow_servers_listen_on_loopback_and_the_dashboard_answers_there(tmp_path, prefect_server, monkeypatch):
    monkeypatch.setenv("FLOWFAKES_DELAY_S", "1")  # the cluster stays up while the sockets are listed
    catalog = make_project(tmp_path, ASSETS, catalog_extra={"tracking": {"enabled": False}})
    from asset2sim.flows.refine_flow import run_refine_flow

    with SocketWatch() as watch:
        summary = run_refine_flow(catalog, workers=2)
    assert summary["done"] == 2
    _assert_loopback(watch.seen)
    assert len(watch.http) == 1, watch.http  # one scheduler started by the run
    (addr, pages), = watch.http.items()
    assert addr[0] == "127.0.0.1" and addr in watch.seen  # the dashboard, where the log says it is
    assert pages["/info/main/workers.html"] == 200 and pages["/status"] == 200, pages
    # the scheduler, its nannies and the two worker processes listen as well (all on loopback)
    assert len({p for _, p in watch.seen}) >= 6, sorted(watch.seen)


def test_no_dashboard_and_dask_host_flags(tmp_path, prefect_server, monkeypatch, capsys):
    """``asset2sim flow --no-dashboard --dask-host 127.0.0.2``: every socket
    the run opens is on 127.0.0.2 (the flag reaches the cluster) and the
    scheduler's HTTP port (distributed always opens one) serves nothing."""
    monkeypatch.setenv("FLOWFAKES_DELAY_S", "1")
    catalog = make_project(tmp_path, ASSETS, catalog_extra={"tracking": {"enabled": False}})
    from asset2sim.cli import build_parser

    args = build_parser("flow").parse_args(
        ["flow", "--catalog", str(catalog), "--no-progress", "--no-dashboard", "--dask-host", "127.0.0.2"])
    with SocketWatch() as watch:
        assert args._run(args) == 0
    assert "2 done" in capsys.readouterr().out
    _assert_loopback(watch.seen)
    assert {ip for ip, _ in watch.seen} == {"127.0.0.2"}, sorted(watch.seen)
    assert len(watch.http) == 1, watch.http
    (addr, pages), = watch.http.items()
    assert addr in watch.seen
    assert set(pages.values()) == {404}, pages  # no dashboard, no info pages, no JSON API, no metrics


def test_dask_host_is_configurable_in_the_catalog(tmp_path, prefect_server):
    """``run.dask_host`` and ``run.dashboard`` of ``catalog.yaml`` reach the
    local cluster's arguments (an address no test machine should open to
    its network is not opened here: only the arguments are checked)."""
    pytest.importorskip("prefect_dask")
    from asset2sim.flows.catalog_config import load_catalog
    from asset2sim.flows.flow_runtime import dask_task_runner

    catalog = make_project(tmp_path, ASSETS, catalog_extra={"run": {"dask_host": "10.1.2.3", "dashboard": False}})
    run = load_catalog(catalog).config.run
    assert run.dask_host == "10.1.2.3" and run.dashboard is False
    kw = dask_task_runner(2, None, host=run.dask_host, dashboard=run.dashboard).cluster_kwargs
    assert kw["host"] == "10.1.2.3" and kw["dashboard_address"] is None
    assert kw["scheduler_kwargs"] == {"dashboard_address": ("10.1.2.3", 0)}  # its HTTP port: a free one
    kw = dask_task_runner(2, None).cluster_kwargs  # defaults: loopback, dashboard on a free port there
    assert kw["host"] == "127.0.0.1" and kw["dashboard_address"] == ("127.0.0.1", 0)
    assert dask_task_runner(2, None, host="::1").cluster_kwargs["dashboard_address"] == ("::1", 0)
