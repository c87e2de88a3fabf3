"""Install the asset2sim wheel beside the tools of this field and check that
nothing of theirs moves.

For each host environment (ManiSkill with its SAPIEN; robosuite with MuJoCo;
torch), in a fresh virtual environment: install the host's packages, record
``pip freeze``, install the asset2sim wheel built from this checkout (core
dependencies only) the way the README says to install into an existing
environment (``-c`` a constraints file of what is installed, so pip picks
versions of the new packages that fit it), record ``pip freeze`` again, then run ``asset2sim demo``
(the built-in box, refined and checked) and the Python API (``refine``,
``load_pybullet``) on it. A host package whose version pip changed, or a run
that fails, is a failure. Also printed: what a plain ``pip install`` without
the constraints would have changed (pip prefers the newest versions: pandas
3 wants numpy 2 where robosuite's mink holds numpy 1.26). Prints one table; exit status 1 on any failure.

Needs the network (PyPI) and about 10 GB of disk; takes tens of minutes.
Not part of CI (``make check-install``).

    python benchmarks/check_install.py [--work DIR] [--hosts maniskill,robosuite,torch]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: Host environment -> the packages a user of it has installed first. torch is
#: the CPU build (PyPI's default Linux wheel brings about 5 GB of CUDA runtime).
HOSTS = {
    "maniskill": ["torch==2.13.0", "mani-skill"],
    "robosuite": ["robosuite"],
    "torch": ["torch==2.13.0"],
}
API_CHECK = """
import sys, asset2sim, pybullet as p
from pathlib import Path
from asset2sim import demo_assets
work = Path(sys.argv[1])
box = demo_assets.build_box_with_lid(work / "box")
r = asset2sim.refine(box, "a box with its lid slightly open", work / "api", extras=False)
cid = p.connect(p.DIRECT)
s = asset2sim.load_pybullet(r.out_dir, cid)
s.step(240)
print("api", r.report.failure_mode, len(s.joint_positions()), "joints")
"""

def run(cmd: list[str], log, **kw) -> subprocess.CompletedProcess:
    """Run ``cmd``, appending its output to ``log``."""
    log.write(f"$ {' '.join(cmd)}\n")
    log.flush()
    done = subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, text=True, **kw)
    log.write(f"-> exit {done.returncode}\n")
    return done


def freeze(python: Path) -> dict[str, str]:
    """name (lower case) -> version of what ``pip freeze`` lists."""
    out = subprocess.run([str(python), "-m", "pip", "freeze", "--exclude-editable"], capture_output=True, text=True, check=True).stdout
    pins = {}
    for line in out.splitlines():
        if "==" in line:
            name, version = line.split("==", 1)
            pins[name.lower().replace("_", "-")] = version
    return pins


def would_change(python: Path, wheel: Path, before: dict[str, str]) -> list[str]:
    """The installed packages a plain ``pip install WHEEL`` (no constraints)
    would change, from ``pip install --dry-run --report``."""
    done = subprocess.run([str(python), "-m", "pip", "install", "--dry-run", "--quiet", "--report", "-", str(wheel)],
                          capture_output=True, text=True)
    if done.returncode:
        return [f"dry run failed: {done.stderr.strip().splitlines()[-1:]}"]
    report = json.loads(done.stdout)
    out = []
    for item in report.get("install", []):
        name = item["metadata"]["name"].lower().replace("_", "-")
        if name in before and before[name] != item["metadata"]["version"]:
            out.append(f"{name} {before[name]} -> {item['metadata']['version']}")
    return sorted(out)


def build_wheel(work: Path, log) -> Path:
    """The asset2sim wheel of this checkout (``pip wheel --no-deps``)."""
    dist = work / "dist"
    dist.mkdir(parents=True, exist_ok=True)
    done = run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet", "-w", str(dist), str(ROOT)], log)
    if done.returncode:
        raise SystemExit(f"building the wheel failed; see {log.name}")
    return max(dist.glob("asset2sim-*.whl"), key=lambda p: p.stat().st_mtime)


def check_host(name: str, packages: list[str], wheel: Path, work: Path, log) -> dict:
    """One host environment: what pip changed and whether the runs worked."""
    env = work / f"venv-{name}"
    row = {"host": name, "changed": [], "demo": "not run", "api": "not run", "seconds": 0.0}
    t0 = time.perf_counter()
    python = env / "bin" / "python"
    if run([sys.executable, "-m", "venv", "--clear", str(env)], log).returncode or run(
            [str(python), "-m", "pip", "install", "--quiet", "--upgrade", "pip"], log).returncode:
        row["demo"] = "venv failed"
        return row
    if run([str(python), "-m", "pip", "install", "--quiet", *packages], log).returncode:
        row["demo"] = "host install failed"
        return row
    before = freeze(python)
    row["plain"] = would_change(python, wheel, before)
    keep = work / f"keep-{name}.txt"  # the documented way into an existing environment: keep what is installed
    keep.write_text("".join(f"{k}=={v}\n" for k, v in sorted(before.items())))
    if run([str(python), "-m", "pip", "install", "--quiet", str(wheel), "-c", str(keep)], log).returncode:
        row["demo"] = "asset2sim install failed"
        return row
    after = freeze(python)
    row["changed"] = sorted(f"{k} {v} -> {after.get(k, 'removed')}" for k, v in before.items() if after.get(k) != v)
    out = work / f"out-{name}"
    demo = run([str(env / "bin" / "asset2sim"), "demo", "--out", str(out / "demo")], log, cwd=work)
    row["demo"] = "ok" if demo.returncode in (0, 3) else f"exit {demo.returncode}"
    api = subprocess.run([str(python), "-c", API_CHECK, str(out)], capture_output=True, text=True, cwd=work)
    log.write(api.stdout + api.stderr)
    row["api"] = api.stdout.strip().splitlines()[-1] if api.returncode == 0 and api.stdout.strip() else f"exit {api.returncode}"
    row["seconds"] = time.perf_counter() - t0
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", type=Path, default=None, help="working folder (default: a new temporary one)")
    ap.add_argument("--hosts", default=",".join(HOSTS), help=f"comma-separated, of {', '.join(HOSTS)}")
    args = ap.parse_args()
    work = args.work or Path(tempfile.mkdtemp(prefix="asset2sim-install-"))
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    with open(work / "check_install.log", "a") as log:
        wheel = build_wheel(work, log)
        print(f"wheel {wheel.name} ({wheel.stat().st_size / 1e3:.0f} kB); log {log.name}", flush=True)
        for name in args.hosts.split(","):
            rows.append(check_host(name, HOSTS[name], wheel, work, log))
            r = rows[-1]
            print(f"{r['host']:<10} with -c (installed kept): pip changed {len(r['changed'])} host package(s) {r['changed']}; "
                  f"demo {r['demo']}; {r['api']}; {r['seconds']:.0f} s; a plain install would change {r.get('plain', [])}", flush=True)
    bad = [r for r in rows if r["changed"] or r["demo"] != "ok" or not r["api"].startswith("api ")]
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
