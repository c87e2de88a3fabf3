"""The user documentation works as written.

- Every ``docs/...md`` and ``benchmarks/...md`` path named in the
  documentation and the source exists.
- Every command and Python snippet of README.md and docs/guide/*.md runs:
  the fenced ``python`` blocks (one namespace per document) and the
  ``asset2sim ...`` lines of ``bash`` / ``console`` blocks, in document
  order, in one temporary folder per document, where ``partnet-mobility/``
  (the folder the guide says PartNet-Mobility is unpacked in) is the dev
  dataset, as written. A command expects exit status 0 unless its line
  says ``# exit status N``. A block that cannot run here carries
  ``<!-- not run in tests: REASON -->`` right above it.
- The command-line help cites no document users do not have.
"""

from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parents[1]
#: The dev dataset, as tests/conftest.py finds it (ASSET2SIM_SHARED, else ../shared beside the repository).
SHARED = Path(os.environ.get("ASSET2SIM_SHARED", ROOT.parent / "shared")) / "datasets" / "partnet_mobility"
#: The folder the guide names PartNet-Mobility's (``partnet-mobility/103275``), relative to where its commands run.
PARTNET = "partnet-mobility"
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]
NOT_RUN = re.compile(r"^<!-- not run in tests: (.*?) -->$")
MAX_NOT_RUN = 7  # the guide's recipe for N machines among them: tests/flows/test_cluster_store.py runs it
RUN_LANGUAGES = {"python": "python", "bash": "shell", "console": "shell", "sh": "shell"}
KNOWN_LANGUAGES = {*RUN_LANGUAGES, "yaml", "text", "json"}
EXIT_STATUS = re.compile(r"#.*\bexit status (\d+)")
LINK = re.compile(r"(?<![\w./-])((?:docs|benchmarks)/[\w./-]*?\.md)(?![\w/-])")
LINK_SOURCES = ["README.md", "DEVELOPERS.md", "docs/**/*.md", "benchmarks/**/*.md",
                "asset2sim/**/*.py", "tasks/**/*.py", "flows/**/*.py", "schemas/**/*.py"]
#: Options of other programs the documents show (pip, dask, mlflow).
FOREIGN_OPTIONS = {"--no-deps", "--backend-store-uri", "--nthreads", "--nworkers", "--exclude-editable"}

#: Files each document's commands and snippets must leave in its folder.
EXPECTED_FILES = {
    "README.md": ["out/assets/laptop/mobility.urdf", "out/laptop/mobility.urdf", "out/laptop/initial_state.json",
                  "out/laptop/overlay.json", "out/laptop/report.json", "out/laptop/report.html", "out/laptop/mjcf/mobility.xml",
                  "out/laptop/usd/mobility.usd", "out/eval/laptop/evaluation.json", "out/eval/laptop/report.html",
                  "out/views/front.png", "out/assets/demo/manifest.csv", "bench/results.csv"],
    "audit.md": ["audit/box_grams/audit.md", "audit/box_grams/patch/storage_box.xml", "audit/audit_assets.parquet",
                 "audit/audit_values.parquet", "audit_api/audit.json", "audit_flow/audit_assets.parquet",
                 "out/kept/report.json"],
    "api.md": ["out/box/mobility.urdf", "out/box/report.json", "out/box/mjcf/mobility.xml", "out/box/usd/mobility.usd"],
    "inputs.md": ["out/from_mjcf/mobility.urdf", "out/from_mjcf/report.json", "out/from_mjcf_api/report.json",
                  "out/robosuite_door/mobility.urdf", "out/robosuite_door/mjcf/host/door.xml",
                  "out/robosuite_door/mjcf/host/files/objects/door.xml",
                  "out/from_usd/usd/host/mobility.usd", "out/from_usd/usd/host/mobility.physics.usda"],
    "outputs.md": ["out/demo/mobility.urdf", "out/demo/initial_state.json", "out/demo/overlay.json", "out/demo/report.json"],
    "requests.md": ["refine.yaml"],
    "pipeline.md": ["project/catalog.yaml"],
    "simulators.md": ["out/box/mjcf/mobility.xml", "out/box/usd/mobility.usd"],
    "validation.md": ["broken/mobility.urdf"],
    "realism.md": ["out/demo/clips/clips.json", "pairs/pairs.json", "pairs/clips/0000/a_front.webm", "pairs/clips/0001/b_perspective.webm"],
}

#: Python run in a document's folder before its blocks. The pipeline guide
#: queries a catalog: one made of the row the flow writes for a real refine.
SETUP = {
    "pipeline.md": """
import shutil, time
from pathlib import Path
import asset2sim
from asset2sim.demo_assets import build_box_with_lid
from asset2sim.flows.catalog import ResultCatalog, load_catalog
from asset2sim.flows.run_plan import make_run_id
from asset2sim.flows.stages import AssetJob
from asset2sim.flows.job_records import Prepared, RefineOutput, StageRecord, build_row

shutil.copy(CATALOG_YAML, "catalog.yaml")
run = make_run_id()
prompt = "a small box with its lid slightly open"
started = time.time()
result = asset2sim.refine(build_box_with_lid(Path("box")), prompt, "out/box", extras=False)
job = AssetJob(dataset="demo", run_id=run, asset_id="box_lid", prompt=prompt, asset_dir="box",
               out_dir=str(result.out_dir), work_dir="work", metrics_dir="metrics", evaluate=False)
row = build_row(job, Prepared(ok=True, seconds=0.0, category=result.report.category, input_hash=result.report.input_hash),
                StageRecord(status="ok", value=RefineOutput(report=result.report, out_dir=str(result.out_dir)),
                            seconds=time.time() - started), None)
store = ResultCatalog(load_catalog("catalog.yaml").catalog_root)
store.append_row("demo", run, row)
store.compact("demo", run)
del shutil, time, Path, asset2sim, build_box_with_lid, ResultCatalog, load_catalog, AssetJob, make_run_id
""",
}


# ----------------------------------------------------------------------------- reading the documents


def _blocks(path: Path) -> list[dict]:
    """The fenced blocks of a Markdown file, in order: ``language``,
    ``code``, ``line`` (of the opening fence), ``not_run`` (the marker's
    reason, or None)."""
    lines = path.read_text().splitlines()
    blocks, i = [], 0
    while i < len(lines):
        if lines[i].startswith("```"):
            language = lines[i][3:].strip()
            end = next(j for j in range(i + 1, len(lines)) if lines[j].startswith("```"))
            before = next((lines[j].strip() for j in range(i - 1, -1, -1) if lines[j].strip()), "")
            marker = NOT_RUN.match(before)
            blocks.append({"language": language, "code": "\n".join(lines[i + 1:end]), "line": i + 1,
                           "not_run": marker.group(1) if marker else None})
            i = end
        i += 1
    return blocks


def _commands(code: str) -> list[str]:
    """The command lines of a shell block (continuations joined, comments and blank lines dropped)."""
    joined = re.sub(r"\\\n\s*", " ", code)
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.strip().startswith("#")]


def _first_module(code: str) -> str | None:
    for node in ast.walk(ast.parse(code)):
        if isinstance(node, ast.Import):
            return node.names[0].name.split(".")[0]
        if isinstance(node, ast.ImportFrom) and node.module:
            return node.module.split(".")[0]
    return None


def _steps(path: Path) -> tuple[list[dict], list[str]]:
    """The runnable steps of a document and the blocks skipped because their
    simulator is not installed."""
    steps, skipped = [], []
    bin_dir = Path(sys.executable).parent
    continues_skipped = False  # a block without imports of its own goes on from the one before it
    for block in _blocks(path):
        kind = RUN_LANGUAGES.get(block["language"])
        if kind is None or block["not_run"] is not None:
            continue
        where = f"{path.relative_to(ROOT)}:{block['line']}"
        code = block["code"]
        if kind == "python":
            module = _first_module(code)
            if module is not None and importlib.util.find_spec(module) is None:
                skipped.append(f"{where} ({module} not installed)")
                continues_skipped = True
                continue
            if module is None and continues_skipped:
                skipped.append(f"{where} (goes on from a block skipped above)")
                continue
            continues_skipped = False
            steps.append({"kind": "python", "code": code, "where": where})
            continue
        for line in _commands(code):
            argv = shlex.split(line, comments=True)
            assert argv[0] == "asset2sim", f"{where}: {line!r} is not an asset2sim command: mark the block not run"
            status = EXIT_STATUS.search(line)
            steps.append({"kind": "shell", "argv": [str(bin_dir / "asset2sim"), *argv[1:]], "line": line,
                          "status": int(status.group(1)) if status else 0, "where": where})
    return steps, skipped


# ----------------------------------------------------------------------------- the runner (a child process)


def _run_steps(steps_file: str) -> int:
    """Run the steps of ``steps_file`` in the current folder; 1 at the first
    failure (printed), else 0."""
    import traceback

    namespace: dict = {"__name__": "__doc__"}
    for step in json.loads(Path(steps_file).read_text()):
        if step["kind"] == "python":
            try:
                exec(compile(step["code"], step["where"], "exec"), namespace)
            except Exception:
                print(f"FAILED {step['where']}:\n{traceback.format_exc()}", flush=True)
                return 1
            continue
        proc = subprocess.run(step["argv"], capture_output=True, text=True)
        if proc.returncode != step["status"]:
            print(f"FAILED {step['where']}: {step['line']}\nexit status {proc.returncode}, expected {step['status']}\n"
                  f"stdout:\n{proc.stdout[-3000:]}\nstderr:\n{proc.stderr[-3000:]}", flush=True)
            return 1
    return 0


# ----------------------------------------------------------------------------- tests


def _documented_paths(text: str) -> set[str]:
    return {m.group(1) for m in LINK.finditer(text)}


def test_every_documented_path_exists():
    missing = []
    for pattern in LINK_SOURCES:
        for source in sorted(ROOT.glob(pattern)):
            for link in _documented_paths(source.read_text(errors="replace")):
                if not (ROOT / link).is_file():
                    missing.append(f"{source.relative_to(ROOT)}: {link}")
    assert missing == []


def test_user_documents_are_short_and_for_users():
    """The README fits in 200 lines; the user documents name no internal
    module, test, dated log or the SPEC."""
    assert len((ROOT / "README.md").read_text().splitlines()) <= 200
    for doc in DOCUMENTS:
        text = doc.read_text()
        found = re.findall(r"SPEC|(?<![\w.])(?:tasks|tests)/|\b20\d\d-\d\d-\d\d\b", text)
        assert found == [], (doc.name, found)


def test_every_block_is_tagged_and_few_are_not_run():
    markers = []
    for doc in DOCUMENTS:
        for block in _blocks(doc):
            assert block["language"] in KNOWN_LANGUAGES, f"{doc.name}:{block['line']}: tag the block's language"
            if block["not_run"] is not None:
                assert block["not_run"].strip(), f"{doc.name}:{block['line']}: say why the block is not run"
                markers.append(f"{doc.name}:{block['line']}")
        text = doc.read_text()
        assert text.count("<!-- not run in tests") == sum(m.startswith(f"{doc.name}:") for m in markers), \
            f"{doc.name}: a not-run marker that is not right above a block"
    assert 0 < len(markers) <= MAX_NOT_RUN, markers


def test_documented_options_exist():
    """Every ``--option`` the user documents name is one of asset2sim's (or of pip, dask, mlflow), or one of a
    benchmark script the documents name (``benchmarks/bench_learnability.py --framework maniskill``)."""
    from asset2sim.cli import build_parser

    parser = build_parser()
    known = set(FOREIGN_OPTIONS)
    texts = " ".join(doc.read_text() for doc in DOCUMENTS)
    for script in sorted(set(re.findall(r"benchmarks/(\w+\.py)", texts))):
        if (ROOT / "benchmarks" / script).is_file():
            known.update(re.findall(r"add_argument\(\s*\"(--[a-z][a-z-]*)\"", (ROOT / "benchmarks" / script).read_text()))
    for action in parser._actions:
        known.update(action.option_strings)
        for sub in getattr(action, "choices", None) or {}:
            known.update(o for a in action.choices[sub]._actions for o in a.option_strings)
    used = {o for doc in DOCUMENTS for o in re.findall(r"(?<![\w-])--[a-z][a-z-]*", doc.read_text())}
    assert sorted(used - known) == []


def test_command_help_cites_no_spec():
    """The help users read points at documents they have, never at the SPEC."""
    from asset2sim.cli import build_parser

    parser = build_parser()
    texts = [parser.format_help()]
    for action in parser._actions:
        for sub in (getattr(action, "choices", None) or {}).values():
            texts.append(sub.format_help())
    assert len(texts) > 10
    for text in texts:
        flat = " ".join(text.split())
        assert "SPEC" not in flat and "shared/" not in flat, flat[:200]
        for link in _documented_paths(flat.replace("- ", "-")):
            assert (ROOT / link).is_file(), link


@pytest.mark.slow  # end to end: every documented command, through the command line
@pytest.mark.parametrize("doc", DOCUMENTS, ids=lambda p: p.name)
def test_document_commands_and_snippets_run(doc, tmp_path):
    text = doc.read_text()
    uses_dataset = f"{PARTNET}/" in text
    if uses_dataset and not SHARED.is_dir():
        pytest.skip(f"dev dataset not found at {SHARED}")
    steps, skipped = _steps(doc)
    setup = SETUP.get(doc.name)
    if setup is not None:
        steps.insert(0, {"kind": "python", "code": f"CATALOG_YAML = {str(ROOT / 'catalog.yaml')!r}\n{setup}",
                         "where": f"tests/test_docs.py SETUP[{doc.name!r}]"})
    if not steps:
        pytest.skip(f"{doc.name} has nothing to run")
    (tmp_path / "steps.json").write_text(json.dumps(steps))
    work = tmp_path / "work"
    work.mkdir()
    if uses_dataset:  # where the guide's reader unpacked PartNet-Mobility: the dev rows
        (work / PARTNET).symlink_to(SHARED, target_is_directory=True)
    proc = subprocess.run([sys.executable, __file__, str(tmp_path / "steps.json")], cwd=work,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-3000:]
    missing = [f for f in EXPECTED_FILES.get(doc.name, []) if not (work / f).is_file()]
    assert missing == [], missing
    for step in steps:  # every refine / demo wrote a complete output folder
        argv = step.get("argv", [])
        if len(argv) > 1 and argv[1] in ("refine", "demo") and step["status"] in (0, 3) and "--out" in argv:
            assert (work / argv[argv.index("--out") + 1] / ".asset2sim-complete.json").is_file(), step["line"]
    print("skipped (not installed):", skipped)


if __name__ == "__main__":
    # run as a script, this file's folder is first on sys.path: its asset2sim/ (tests) would shadow the package
    sys.path = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]
    sys.exit(_run_steps(sys.argv[1]))


def test_the_developers_map_names_every_module():
    """DEVELOPERS.md's map of the code names every module of the package."""
    text = (ROOT / "DEVELOPERS.md").read_text()
    missing = [str(path.relative_to(ROOT)) for folder in ("asset2sim", "tasks", "flows", "schemas")
               for path in sorted((ROOT / folder).rglob("*.py"))
               if path.name != "__init__.py" and not re.search(rf"(?<![\w.]){re.escape(path.stem)}(\.py)?\b", text)]
    assert not missing, f"modules DEVELOPERS.md does not name: {missing}"


def test_the_developers_map_is_the_docstrings_map():
    """DEVELOPERS.md's map of the code is what ``tools/code_map.py`` writes from the module docstrings (so it cannot
    drift from them: ``make map`` rewrites it), one row per module, the same bytes on a second run."""
    spec = importlib.util.spec_from_file_location("code_map", ROOT / "tools" / "code_map.py")
    code_map = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(code_map)
    text = (ROOT / "DEVELOPERS.md").read_text()
    assert code_map.rewritten(text) == text, "DEVELOPERS.md's map differs from the module docstrings: run `make map`"
    assert code_map.code_map() == code_map.code_map()
    rows = [line for line in code_map.code_map().splitlines() if line.startswith("| `")]
    modules = [p for folder in code_map.PACKAGES for p in (ROOT / folder).rglob("*.py") if p.name != "__init__.py"]
    assert len(rows) == len(modules)
    assert code_map.first_sentence("Reads :mod:`a.b`, e.g. ``x | y``. Then more.") == "Reads `a.b`, e.g. `x \\| y`"


def test_every_benchmark_script_feeds_a_result():
    """Every script in benchmarks/ is used: named by benchmarks/RESULTS.md, a test, a document (docs/, README.md,
    DEVELOPERS.md, the Makefile) or another benchmark script; one nothing names goes (git history keeps it)."""
    readers = [ROOT / "benchmarks" / "RESULTS.md", ROOT / "README.md", ROOT / "DEVELOPERS.md", ROOT / "Makefile",
               *sorted((ROOT / "docs").rglob("*.md")), *sorted((ROOT / "tests").rglob("*.py"))]
    scripts = sorted((ROOT / "benchmarks").glob("*.py"))
    text = "\n".join(path.read_text() for path in readers)
    unused = [script.name for script in scripts
              if not re.search(rf"\b{script.stem}\b", text)
              and not any(re.search(rf"\b{script.stem}\b", other.read_text()) for other in scripts if other != script)]
    assert not unused, f"benchmark scripts nothing names: {unused}"


def test_the_readme_needs_no_dev_dataset():
    """Every README command runs in a clone without ``../shared`` (the built-in objects, ``asset2sim demo``), so a
    newcomer's first hour needs no data they do not have; the snippets run in
    :func:`test_document_commands_and_snippets_run`."""
    text = (ROOT / "README.md").read_text()
    assert "../shared" not in text and "shared/datasets" not in text
    assert "asset2sim demo --object" in text and "Bring your own assets" in text


def test_the_guide_names_partnet_mobility_as_its_reader_has_it():
    """The guide's commands on PartNet-Mobility objects name the folder a reader unpacked it in
    (``partnet-mobility/103275``), never this repository's development layout (``../shared/datasets/...``)."""
    for doc in DOCUMENTS:
        assert "../shared" not in doc.read_text() and "shared/datasets" not in doc.read_text(), doc.name
