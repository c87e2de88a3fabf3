"""The package's import graph: no cycles, no guarded imports of its own
modules, and the stages as layers in data-flow order.

Every ``import`` / ``from ... import`` of an ``asset2sim`` module anywhere in a
module (top level or inside a function) is an edge, so a cycle hidden behind a
function-level import is still found. A module that imports by name
(``importlib.import_module``, ``flows.isolation.import_target``) has an edge
to every project module a string of it names (``"asset2sim.engines.mujoco_engine"``,
``"asset2sim.tasks.refine:refine_asset"``, an f-string prefix
``f"asset2sim.commands.{name}"``: every module under it). Lazy imports are for
optional heavy third-party packages only.

The layers (:data:`LAYERS`), each importing only its own and earlier ones:
the core (``asset2sim/`` with its format wing ``asset2sim/formats/``, and ``schemas/``), then the stages of ``tasks/`` in
data-flow order (the measuring tiers of ``check/`` below the tuning loop of ``tune/``),
``tasks/refine.py`` that chains them, the applications
(``apps/``: the audit, the realism tools, the benchmark, the learning environments) above it, ``flows/``, the public API
(``asset2sim.api``, whose names the package ``asset2sim`` lends on first use) and the command line. The applications
stand side by side: none imports another (what two of them share lives in a stage or the core).
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Installed package name -> source folder (pyproject.toml's package-dir).
PACKAGE_DIRS = {"asset2sim": "asset2sim", "asset2sim.tasks": "tasks", "asset2sim.schemas": "schemas", "asset2sim.flows": "flows",
                "asset2sim.apps": "apps"}


def _modules() -> dict[str, Path]:
    out: dict[str, Path] = {}
    for pkg, folder in PACKAGE_DIRS.items():
        base = ROOT / folder
        for path in base.rglob("*.py"):
            rel = path.relative_to(base).with_suffix("")
            parts = list(rel.parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            name = ".".join([pkg, *parts])
            # asset2sim/ itself must not claim the other top-level folders' names
            if pkg == "asset2sim" and parts and parts[0] in ("tasks", "schemas", "flows", "apps"):
                continue
            out[name] = path
    return out


def _resolve(name: str, modules: dict[str, Path]) -> str | None:
    """The project module an import of ``name`` loads (longest known prefix)."""
    while name:
        if name in modules:
            return name
        name = name.rpartition(".")[0]
    return None


def _edges(name: str, path: Path, modules: dict[str, Path]) -> list[tuple[str, str, int, bool]]:
    """(target module, imported text, line, guarded by except ImportError) of one module."""
    tree = ast.parse(path.read_text(), filename=str(path))
    nodes = list(ast.walk(tree))  # walked once: the walk, not the parse, was most of the graph's time
    guarded_lines: set[int] = set()
    for node in nodes:
        if isinstance(node, ast.Try):
            catches = [h for h in node.handlers if h.type is not None and "ImportError" in ast.unparse(h.type)]
            if catches:
                for sub in node.body:
                    for n in ast.walk(sub):
                        if isinstance(n, (ast.Import, ast.ImportFrom)):
                            guarded_lines.add(n.lineno)
    out = []
    by_name = any(isinstance(n, ast.Call) and _called_name(n) in _BY_NAME for n in nodes)
    for node in nodes:
        if by_name and isinstance(node, ast.Constant) and isinstance(node.value, str):
            for mod in _named_modules(node.value, modules):
                if mod != name:
                    out.append((mod, node.value, node.lineno, False))
        if by_name and isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant):
            prefix = str(node.values[0].value)
            if prefix.startswith("asset2sim.") and prefix.endswith("."):
                out += [(m, prefix, node.lineno, False) for m in modules if m.startswith(prefix) and m != name]
        targets: list[str] = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            targets = [f"{node.module}.{a.name}" for a in node.names] or [node.module]
        for t in targets:
            if not t.startswith("asset2sim"):
                continue
            mod = _resolve(t, modules)
            if mod and mod != name and not (name.startswith(mod + ".") or mod == name.rsplit(".", 1)[0] and path.name == "__init__.py"):
                out.append((mod, t, node.lineno, node.lineno in guarded_lines))
    return out


#: Functions that import a module named by a string.
_BY_NAME = frozenset({"import_module", "import_target", "__import__"})
_MODULE_TEXT = re.compile(r"asset2sim(\.[A-Za-z_][A-Za-z0-9_]*)+")


def _called_name(call: ast.Call) -> str | None:
    f = call.func
    return f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else None


def _named_modules(text: str, modules: dict[str, Path]) -> list[str]:
    """Project modules a string names as a whole (``pkg.mod`` or ``pkg.mod:attr``)."""
    head = text.split(":", 1)[0]
    if not _MODULE_TEXT.fullmatch(head):
        return []
    mod = _resolve(head, modules)
    return [mod] if mod is not None and (mod == head or head.startswith(mod + ".")) else []


#: The layers in data-flow order (index = rank); a module may import only
#: modules of its own or an earlier layer (:func:`_layer`).
LAYERS = ["core", "ingest", "geometry", "interpret", "synthesize", "assemble", "state", "check", "tune",
          "evaluation", "publish", "refine", "apps", "flows", "api", "cli"]


def _layer(module: str) -> str:
    """The layer of a project module (see :data:`LAYERS`)."""
    parts = module.split(".")
    if module in ("asset2sim.cli", "asset2sim.__main__") or parts[:2] == ["asset2sim", "commands"]:
        return "cli"
    # the public API: the package's names are asset2sim.api's
    if module in ("asset2sim", "asset2sim.api"):
        return "api"
    if parts[:2] == ["asset2sim", "flows"]:
        return "flows"
    if parts[:2] == ["asset2sim", "apps"]:  # the applications (audit, realism, benchmark, learn): above the stages
        return "apps"
    if parts[:2] == ["asset2sim", "tasks"] and len(parts) >= 3:
        return parts[2] if parts[2] in LAYERS else "refine" if parts[2] == "refine" else parts[2]
    return "core"


def _graph() -> tuple[nx.DiGraph, list[str]]:
    modules = _modules()
    g = nx.DiGraph()
    guarded = []
    for name, path in modules.items():
        g.add_node(name)
        for mod, text, line, is_guarded in _edges(name, path, modules):
            # importing a package's __init__ only (a package folder) is not a dependency on its modules
            if modules[mod].name == "__init__.py" and mod != text:
                continue
            g.add_edge(name, mod)
            if is_guarded:
                guarded.append(f"{path.relative_to(ROOT)}:{line} imports {text} under except ImportError")
    return g, guarded


@pytest.fixture(scope="module")
def package_graph() -> tuple[nx.DiGraph, list[str]]:
    """The package's :func:`_graph`, built once for the tests that read it."""
    return _graph()


def test_graph_sees_the_package(package_graph):
    g, _ = package_graph
    assert "asset2sim.tasks.refine" in g
    assert "asset2sim.cli" in g
    assert g.number_of_edges() > 50


def test_no_import_cycles(package_graph):
    g, _ = package_graph
    cycles = [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]
    assert not cycles, "import cycles between the project's modules: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_every_module_belongs_to_a_layer():
    unknown = sorted({_layer(m) for m in _modules()} - set(LAYERS))
    assert not unknown, f"packages under tasks/ with no place in LAYERS: {unknown}"


def test_stages_import_only_earlier_layers(package_graph):
    """The stage packages form a chain in data-flow order: no import against it."""
    g, _ = package_graph
    rank = {name: i for i, name in enumerate(LAYERS)}
    against = sorted(f"{a} ({_layer(a)}) imports {b} ({_layer(b)})" for a, b in g.edges
                     if rank.get(_layer(b), 0) > rank.get(_layer(a), 0))
    assert not against, f"{len(against)} imports against the stage order:\n" + "\n".join(against)


def test_no_cycles_between_packages(package_graph):
    """Collapsed to packages (``asset2sim.tasks.state``, ``asset2sim.engines``,
    ``asset2sim.schemas`` ...), the graph has no loop either."""
    g, _ = package_graph
    modules = _modules()
    pkg = {m: m if modules[m].name == "__init__.py" else m.rpartition(".")[0] for m in g.nodes}
    pg = nx.DiGraph()
    pg.add_edges_from((pkg[a], pkg[b]) for a, b in g.edges if pkg[a] != pkg[b] and not pkg[a].startswith(pkg[b] + ".")
                      and not pkg[b].startswith(pkg[a] + "."))
    cycles = [sorted(c) for c in nx.strongly_connected_components(pg) if len(c) > 1]
    assert not cycles, "import loops between packages: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_import_by_name_is_an_edge(tmp_path):
    """A registry that imports its plugins by name (the loop the estimator
    registry once hid) is seen as an import."""
    (tmp_path / "reg.py").write_text("import importlib\nPLUGINS = {'x': 'asset2sim.x.plugin'}\n"
                                     "def get(n):\n    return importlib.import_module(PLUGINS[n])\n")
    (tmp_path / "plugin.py").write_text("from asset2sim.x import reg\n")
    (tmp_path / "cmds.py").write_text("import importlib\ndef run(n):\n    return importlib.import_module(f'asset2sim.x.{n}')\n")
    modules = {"asset2sim.x.reg": tmp_path / "reg.py", "asset2sim.x.plugin": tmp_path / "plugin.py",
               "asset2sim.x.cmds": tmp_path / "cmds.py"}
    edges = {(name, mod) for name, path in modules.items() for mod, _t, _l, _g in _edges(name, path, modules)}
    assert ("asset2sim.x.reg", "asset2sim.x.plugin") in edges and ("asset2sim.x.plugin", "asset2sim.x.reg") in edges
    assert {("asset2sim.x.cmds", "asset2sim.x.reg"), ("asset2sim.x.cmds", "asset2sim.x.plugin")} <= edges


def test_a_stage_importing_a_later_one_is_reported():
    assert _layer("asset2sim.tasks.state.clearance") == "state" and _layer("asset2sim.tasks.refine") == "refine"
    assert LAYERS.index(_layer("asset2sim.tasks.assemble.write")) > LAYERS.index(_layer("asset2sim.tasks.synthesize.estimate"))
    # the tuning loop (escalation, the dynamics search, repairs) sits above the measuring tiers:
    # check/ never imports tune/
    assert _layer("asset2sim.tasks.tune.escalation") == "tune"
    assert LAYERS.index("check") < LAYERS.index("tune") < LAYERS.index("evaluation")
    assert _layer("asset2sim.output_folder") == "core" and _layer("asset2sim.flows.catalog") == "flows"
    # the format wing (readers, exports, physics writers) is core: every stage may use it, it imports no stage
    assert _layer("asset2sim.formats.mjcf.physics") == "core" and _layer("asset2sim.formats") == "core"
    # the applications sit above every stage and below the flows and commands
    assert _layer("asset2sim.apps.audit.audit") == "apps" and _layer("asset2sim.apps.realism.judge") == "apps"
    assert LAYERS.index("refine") < LAYERS.index("apps") < LAYERS.index("flows") < LAYERS.index("cli")


def _app(module: str) -> str | None:
    """The application a module belongs to (``asset2sim.apps.<app>...``), else None."""
    parts = module.split(".")
    return parts[2] if parts[:2] == ["asset2sim", "apps"] and len(parts) > 2 else None


def _app_to_app_imports(modules: dict[str, Path]) -> list[str]:
    """Every import (top level or inside a function) by a module of ``apps/<a>/`` of a module of
    ``apps/<b>/``, b != a, as "path:line imports name"."""
    out = []
    for name, path in modules.items():
        a = _app(name)
        if a is None:
            continue
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                targets = [al.name for al in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [node.module] + [f"{node.module}.{al.name}" for al in node.names]
            else:
                continue
            for t in targets:
                b = _app(t)
                if b is not None and b != a:
                    out.append(f"{path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}:{node.lineno} imports {t}")
                    break
    return out


def test_no_application_imports_another():
    """apps/<a>/ never imports apps/<b>/ (b != a), not even inside a function: what two applications share (the
    GenSim2 reference the benchmark's ``human`` method and the ManiSkill environments build) lives below them."""
    found = _app_to_app_imports({n: p for n, p in _modules().items() if _app(n)})
    assert not found, "applications importing another application:\n" + "\n".join(found)


def test_an_application_importing_another_inside_a_function_is_reported(tmp_path):
    (tmp_path / "env.py").write_text("def f():\n    from asset2sim.apps.benchmark.baselines import make_human\n")
    (tmp_path / "own.py").write_text("from asset2sim.apps.learn import task\nimport asset2sim.tasks.refine\n")
    found = _app_to_app_imports({"asset2sim.apps.learn.env": tmp_path / "env.py", "asset2sim.apps.learn.own": tmp_path / "own.py"})
    assert len(found) == 1 and found[0].endswith("env.py:2 imports asset2sim.apps.benchmark.baselines")


def test_no_guarded_imports_of_own_modules(package_graph):
    _, guarded = package_graph
    assert not guarded, "\n".join(guarded)


def test_detects_a_cycle_in_a_generated_package(tmp_path):
    """The cycle finder itself works: two modules importing each other inside functions."""
    (tmp_path / "a.py").write_text("def f():\n    from asset2sim.x import b\n")
    (tmp_path / "b.py").write_text("def g():\n    from asset2sim.x import a\n")
    modules = {"asset2sim.x.a": tmp_path / "a.py", "asset2sim.x.b": tmp_path / "b.py"}
    g = nx.DiGraph()
    for name, path in modules.items():
        for mod, _text, _line, _guard in _edges(name, path, modules):
            g.add_edge(name, mod)
    assert any(len(c) == 2 for c in nx.strongly_connected_components(g))
