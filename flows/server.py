"""A local Prefect server for one flow run or for the nightly deployment, bound to 127.0.0.1, ended with the
process that started it (:mod:`asset2sim.flows.lifeline`)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

from asset2sim.flows import lifeline

__all__ = ["STARTUP_TIMEOUT", "start_local_server", "stop_server"]

#: Seconds a run's own Prefect server may take to answer unless ``PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS`` is
#: set: a first start migrates a fresh SQLite database, slower than Prefect's 20 s default on a busy machine.
STARTUP_TIMEOUT = 180.0


def start_local_server(project_root: Path | str, timeout: float = 120.0, *, ephemeral: bool = False):
    """Start a Prefect server bound to 127.0.0.1 (state under
    ``<project>/.prefect`` unless ``PREFECT_HOME`` is set, log
    ``server.log`` there) and wait until its API answers; it gets SIGKILL
    when this process ends (call from the main thread). ``ephemeral``: the
    API alone (uvicorn, UI off), as one flow run needs; else ``prefect server
    start`` with its services, as ``serve`` needs. Returns ``(process, api_url)``.

    Raises:
        RuntimeError: the server did not answer within ``timeout`` s (its log
            is ``<project>/.prefect/server.log``).
    """
    import urllib.request

    home = Path(project_root) / ".prefect"
    home.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ)
    env.setdefault("PREFECT_HOME", str(home))
    env.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
    env.pop("PREFECT_API_URL", None)
    if ephemeral:
        env.update({"PREFECT_UI_ENABLED": "0", "PREFECT__SERVER_EPHEMERAL": "1", "PREFECT__SERVER_FINAL": "1"})
        # a flow run's API registers no block types: the flows keep no results and read no block (on a new project's
        # database the registration took 6.8 s of the server's 22.4 s start, 4.7 s of its 18.0 s CPU). Not memoized
        # either, so that the project's full server (``serve``) still registers them on its first start.
        env.setdefault("PREFECT_API_BLOCKS_REGISTER_ON_START", "false")
        env.setdefault("PREFECT_MEMOIZE_BLOCK_AUTO_REGISTRATION", "false")
    log_path = home / "server.log"
    for attempt in range(3):  # a free port may be taken before the server binds it
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            port_n = int(s.getsockname()[1])
        if ephemeral:
            import prefect

            argv = [sys.executable, "-m", "uvicorn", "--app-dir", str(Path(prefect.__file__).parent.parent),
                    "--factory", "prefect.server.api.server:create_app", "--host", "127.0.0.1",
                    "--port", str(port_n), "--log-level", "error", "--lifespan", "on"]  # fmt: skip
        else:
            argv = [sys.executable, "-m", "prefect", "server", "start", "--host", "127.0.0.1", "--port", str(port_n)]
        with open(log_path, "ab") as log:
            proc = subprocess.Popen(
                lifeline.command(argv),
                stdout=log,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                env=env,
                start_new_session=True,
            )
        url = f"http://127.0.0.1:{port_n}/api"
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if proc.poll() is not None:
                break
            try:
                with urllib.request.urlopen(url + "/health", timeout=2) as resp:
                    if resp.status == 200:
                        return proc, url
            except OSError:
                time.sleep(0.25)
        else:
            stop_server(proc)
            raise RuntimeError(f"prefect server did not answer at {url} within {timeout:.0f} s; see {log_path}")
        if proc.returncode != 3 or attempt == 2:  # 3: uvicorn could not bind the port
            raise RuntimeError(f"prefect server exited with code {proc.returncode}; see {log_path}")


def stop_server(proc, timeout: float = 20.0) -> None:
    """Stop a server of :func:`start_local_server`: SIGTERM, then SIGKILL
    after ``timeout`` s."""
    if proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(timeout=timeout)
