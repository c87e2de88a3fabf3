"""No write outside ``--out`` on a fresh machine (``asset2sim.library_dirs``): matplotlib's folders go into asset2sim's
own cache (or a temporary folder of the process when the cache is off), MLflow's telemetry is off; a user's own
matplotlib configuration is left in force. End to end: a refine with its report, through the command line and the
Python API, in a process whose home folder is empty, leaves nothing there but ``.cache/asset2sim`` (nothing at all
with ``ASSET2SIM_CACHE=off``) and nothing in its working directory."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from asset2sim import library_dirs

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture()
def fresh_home(tmp_path, monkeypatch):
    home = tmp_path / "home"
    home.mkdir()
    monkeypatch.setenv("HOME", str(home))
    for name in ("MPLCONFIGDIR", "XDG_CONFIG_HOME", "XDG_CACHE_HOME", "ASSET2SIM_CACHE", "MLFLOW_DISABLE_TELEMETRY"):
        monkeypatch.delenv(name, raising=False)
    return home


def test_matplotlib_goes_into_the_asset2sim_cache_on_a_fresh_home(fresh_home):
    done = library_dirs.configure()
    assert done == {"MPLCONFIGDIR": str(fresh_home / ".cache" / "asset2sim" / "matplotlib"), "MLFLOW_DISABLE_TELEMETRY": "true"}
    assert library_dirs.configure() == {}  # once set, left alone
    assert not (fresh_home / ".config").exists()


def test_a_users_own_matplotlib_configuration_stays_in_force(fresh_home):
    (fresh_home / ".config" / "matplotlib").mkdir(parents=True)
    assert "MPLCONFIGDIR" not in library_dirs.configure()
    assert "MPLCONFIGDIR" not in os.environ


def test_with_the_cache_off_matplotlib_gets_a_temporary_folder(fresh_home, monkeypatch):
    monkeypatch.setenv("ASSET2SIM_CACHE", "off")
    folder = Path(library_dirs.configure()["MPLCONFIGDIR"])
    assert folder.is_dir() and fresh_home not in folder.parents and folder.name.startswith("asset2sim-matplotlib-")


def _listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


@pytest.mark.slow  # end to end: refines with their reports in fresh processes
@pytest.mark.parametrize("cache", ["on", "off"])
def test_a_refine_on_a_fresh_home_writes_nothing_outside_its_output_and_cache(tmp_path, cache):
    home, cwd = tmp_path / "home", tmp_path / "cwd"
    home.mkdir()
    cwd.mkdir()
    env = {k: v for k, v in os.environ.items() if not k.startswith(("XDG_", "MPLCONFIGDIR", "ASSET2SIM_", "MLFLOW_"))}
    env.update(HOME=str(home), TMPDIR=str(tmp_path / "tmp"), PYTHONPATH=str(ROOT))
    if cache == "off":
        env["ASSET2SIM_CACHE"] = "off"
    (tmp_path / "tmp").mkdir()
    cli = subprocess.run([sys.executable, "-m", "asset2sim", "demo", "--out", str(tmp_path / "out_cli")], cwd=cwd, env=env,
                         capture_output=True, text=True, timeout=600)
    assert cli.returncode == 0, cli.stderr[-2000:]
    api = ("import asset2sim, asset2sim.demo_assets as d; from pathlib import Path; "
           f"src = d.build_laptop(Path({str(tmp_path / 'in')!r}) / 'laptop'); "
           f"asset2sim.refine(src, 'a laptop, screen open', Path({str(tmp_path / 'out_api')!r}))")
    run = subprocess.run([sys.executable, "-c", api], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert (tmp_path / "out_cli" / "report.html").is_file() and (tmp_path / "out_api" / "report.html").is_file()
    left = _listing(home)
    if cache == "on":
        assert {p.split("/")[0] for p in left} == {".cache"} and all(p == ".cache" or p.startswith(".cache/asset2sim") for p in left), left
        assert any(p.startswith(".cache/asset2sim/matplotlib") for p in left), left
    else:
        assert left == [], left
    assert _listing(cwd) == [] and _listing(tmp_path / "tmp") == []
