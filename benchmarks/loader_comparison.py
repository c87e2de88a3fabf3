"""Run the malformed corpus through our validator, yourdfpy and MuJoCo; print a
Markdown table of what each accepts (the table in ``docs/design/validation.md``).

Usage::

    .venv/bin/python benchmarks/loader_comparison.py [--only NAME ...] [--timeout S]

For every case of ``tests/corpus_builder.CASES`` the asset is generated in a
temporary folder and loaded by:

- **asset2sim**: ``validate_asset`` (in this process); "rejects" when a
  finding of severity error is reported, else "accepts" (warnings shown);
- **yourdfpy load**: ``yourdfpy.URDF.load(path)`` with its defaults (scene
  graph built, visual meshes loaded), in a subprocess;
- **yourdfpy validate**: the same, then ``URDF.validate()`` (strict handler);
- **MuJoCo**: ``mujoco.MjModel.from_xml_path(path)`` (MuJoCo's own URDF
  importer), in a subprocess.

Each subprocess runs with a wall-clock timeout and a 4 GiB address-space
limit; a timeout is reported as "hang", death by a signal as "crash".
Prints the table, then a summary: how many corpus assets each loader accepts
that asset2sim rejects. Nothing outside the temporary folder is written.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests import corpus_builder as cb  # noqa: E402

LOADERS = {
    "yourdfpy_load": (
        "import sys, yourdfpy\n"
        "u = yourdfpy.URDF.load(sys.argv[1])\n"
        "print('OK')\n"
    ),
    "yourdfpy_validate": (
        "import sys, yourdfpy\n"
        "u = yourdfpy.URDF.load(sys.argv[1])\n"
        "ok = u.validate()\n"
        "print('OK' if ok else 'INVALID ' + '; '.join(str(e) for e in u.errors)[:200])\n"
    ),
    "mujoco": (
        "import sys, mujoco\n"
        "m = mujoco.MjModel.from_xml_path(sys.argv[1])\n"
        "print('OK', m.nbody, m.njnt)\n"
    ),
}


def _limit_memory() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))


def run_loader(name: str, urdf: Path, timeout: float) -> tuple[str, str]:
    """(verdict, detail): verdict in accepts / rejects / hang / crash."""
    t = time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, "-c", LOADERS[name], str(urdf)],
            capture_output=True,
            timeout=timeout,
            preexec_fn=_limit_memory,
            cwd=str(urdf.parent),
        )
    except subprocess.TimeoutExpired:
        return "hang", f"no answer in {timeout:.0f} s"
    dt = time.perf_counter() - t
    out = proc.stdout.decode(errors="replace").strip().splitlines()
    err = proc.stderr.decode(errors="replace").strip().splitlines()
    if proc.returncode < 0:
        return "crash", f"signal {-proc.returncode}"
    if proc.returncode == 0 and out and out[-1].startswith("OK"):
        return "accepts", f"{dt:.1f}s"
    if proc.returncode == 0 and out and out[-1].startswith("INVALID"):
        return "rejects", out[-1][8:120]
    last = err[-1] if err else (out[-1] if out else "")
    return "rejects", last[:120]


def urdf_of(folder: Path) -> Path | None:
    if os.path.lexists(folder / "mobility.urdf"):
        return folder / "mobility.urdf"
    cands = sorted(folder.glob("*.urdf"))
    return cands[0] if cands else None


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", default=None, help="case names to run (default: all)")
    ap.add_argument("--timeout", type=float, default=20.0, help="per loader and case, seconds")
    ap.add_argument("--json", type=Path, default=None, help="also write the raw results as JSON here")
    args = ap.parse_args(argv)

    from asset2sim.tasks.ingest import validate_input as vi

    cases = [c for c in cb.CASES if args.only is None or c.name in args.only]
    rows = []
    with tempfile.TemporaryDirectory(prefix="asset2sim-loaders-") as tmp:
        for case in cases:
            folder = case.build(Path(tmp) / case.name / "asset")
            t = time.perf_counter()
            findings = vi.validate_asset(folder, vi.ValidationPolicy(**(case.policy or {})))
            ours_s = time.perf_counter() - t
            hit = [f for f in findings if f.code == case.code]
            ours = "rejects" if vi.has_errors(findings) else "accepts"
            order = {"error": 0, "warning": 1, "info": 2}
            sev = min((f.severity for f in hit), key=order.__getitem__) if hit else "MISSING"
            row = {"case": case.name, "topic": case.topic, "code": case.code, "severity": sev, "ours": ours, "ours_s": ours_s}
            urdf = urdf_of(folder)
            for name in LOADERS:
                if urdf is None:
                    row[name], row[name + "_detail"] = "n/a", "no URDF file"
                else:
                    row[name], row[name + "_detail"] = run_loader(name, urdf, args.timeout)
            rows.append(row)
            print(f"{case.name:<36} ours {ours:<8} " + " ".join(f"{n} {row[n]:<8}" for n in LOADERS), file=sys.stderr, flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))

    def cell(row, name):
        v = row[name]
        if v == "accepts":
            return "**accepts**" if row["ours"] == "rejects" else "accepts"
        if v in ("hang", "crash"):
            return f"**{v}**"
        return v

    print("| case | our code (severity) | asset2sim | yourdfpy load | yourdfpy load+validate | MuJoCo 4.0.0 |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['case']} | `{r['code']}` ({r['severity']}) | {r['ours']} | {cell(r, 'yourdfpy_load')} | "
            f"{cell(r, 'yourdfpy_validate')} | {cell(r, 'mujoco')} |"
        )
    refused = [r for r in rows if r["ours"] == "rejects"]
    print()
    print(f"Corpus: {len(rows)} assets; asset2sim rejects {len(refused)}, accepts {len(rows) - len(refused)} "
          f"(each with a warning or info finding that names the problem). Slowest asset2sim validation: {max(r['ours_s'] for r in rows):.2f} s.")
    print()
    print("| loader | accepts what asset2sim rejects | rejects | hangs | crashes | n/a |")
    print("|---|---|---|---|---|---|")
    for name, label in (("yourdfpy_load", "yourdfpy load"), ("yourdfpy_validate", "yourdfpy load+validate"), ("mujoco", "MuJoCo 4.0.0")):
        acc = sum(1 for r in refused if r[name] == "accepts")
        rej = sum(1 for r in refused if r[name] == "rejects")
        hang = sum(1 for r in refused if r[name] == "hang")
        crash = sum(1 for r in refused if r[name] == "crash")
        na = sum(1 for r in refused if r[name] == "n/a")
        print(f"| {label} | {acc} / {len(refused)} | {rej} | {hang} | {crash} | {na} |")
    missing = [r["case"] for r in rows if r["severity"] == "MISSING"]
    if missing:
        print(f"\nasset2sim did not report the expected code for: {', '.join(missing)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
