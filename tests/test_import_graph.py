"""The package's import graph: no cycles, no guarded imports of its own modules.

Every ``import`` / ``from ... import`` of an ``asset2sim`` module anywhere in a
module (top level or inside a function) is an edge, so a cycle hidden behind a
function-level import is still found. Lazy imports are for optional heavy
third-party packages only.
"""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[1]
#: Installed package name -> source folder (pyproject.toml's package-dir).
PACKAGE_DIRS = {"asset2sim": "asset2sim", "asset2sim.tasks": "tasks", "asset2sim.schemas": "schemas", "asset2sim.flows": "flows"}


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
            if pkg == "asset2sim" and parts and parts[0] in ("tasks", "schemas", "flows"):
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
    guarded_lines: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try):
            catches = [h for h in node.handlers if h.type is not None and "ImportError" in ast.unparse(h.type)]
            if catches:
                for sub in node.body:
                    for n in ast.walk(sub):
                        if isinstance(n, (ast.Import, ast.ImportFrom)):
                            guarded_lines.add(n.lineno)
    out = []
    for node in ast.walk(tree):
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


def test_graph_sees_the_package():
    g, _ = _graph()
    assert "asset2sim.tasks.refine" in g
    assert "asset2sim.cli" in g
    assert g.number_of_edges() > 50


def test_no_import_cycles():
    g, _ = _graph()
    cycles = [sorted(c) for c in nx.strongly_connected_components(g) if len(c) > 1]
    assert not cycles, "import cycles between the project's modules: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_no_guarded_imports_of_own_modules():
    _, guarded = _graph()
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
