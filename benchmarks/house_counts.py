"""How the code outside the tests stands against the house rules (DEVELOPERS.md), counted from the source.

    python benchmarks/house_counts.py [--list]

Prints, over ``asset2sim/``, ``tasks/``, ``flows/`` and ``schemas/``: the lines (every line), the modules over 500
lines, the longest function, the functions with 10 or more parameters (``self`` / ``cls`` not counted; ``--list``
names them), the stage functions (``tasks/``) whose signature names ``UrdfSource``, the files of ``tasks/`` that
call ``open_session(``, and the module-level ``OrderedDict`` memos (in-process memos are ``cachetools`` caches).
Reads files only; no import of the project.
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("asset2sim", "tasks", "flows", "schemas")
MANY_PARAMETERS = 10


def _files() -> list[Path]:
    """Every ``.py`` file of :data:`PACKAGES`, sorted."""
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


def _parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """Parameters of ``fn``, ``*args`` and ``**kwargs`` included, a method's first (self / cls) not."""
    a = fn.args
    n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + bool(a.vararg) + bool(a.kwarg)
    first = (a.posonlyargs + a.args)[:1]
    return n - 1 if first and first[0].arg in ("self", "cls") else n


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--list", action="store_true", help="name the functions with many parameters")
    args = ap.parse_args()
    lines, big, many, urdf_source, memos = 0, [], [], [], []
    longest = (0, "")
    for path in _files():
        text = path.read_text(encoding="utf-8")
        rel = path.relative_to(ROOT).as_posix()
        n = len(text.splitlines())
        lines += n
        if n > 500:
            big.append(rel)
        tree = ast.parse(text, filename=rel)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                size = (node.end_lineno or node.lineno) - node.lineno + 1
                longest = max(longest, (size, f"{rel}:{node.lineno} {node.name}"))
                k = _parameters(node)
                if k >= MANY_PARAMETERS:
                    many.append((k, f"{rel}:{node.lineno} {node.name}"))
                if rel.startswith("tasks/") and "UrdfSource" in ast.unparse(node.args):
                    urdf_source.append(f"{rel}:{node.lineno} {node.name}")
        for stmt in tree.body:
            value = stmt.value if isinstance(stmt, (ast.Assign, ast.AnnAssign)) else None
            if isinstance(value, ast.Call) and ast.unparse(value.func).endswith("OrderedDict"):
                memos.append(f"{rel}:{stmt.lineno}")
    sessions = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "tasks").rglob("*.py")
                      if "open_session(" in p.read_text(encoding="utf-8"))
    print(f"lines outside tests: {lines}")
    print(f"modules over 500 lines: {len(big)}")
    print(f"longest function: {longest[0]} lines ({longest[1]})")
    print(f"functions with >= {MANY_PARAMETERS} parameters: {len(many)}")
    if args.list:
        for k, where in sorted(many, reverse=True):
            print(f"  {k:3d}  {where}")
    print(f"stage functions naming UrdfSource: {len(urdf_source)}" + "".join(f"\n  {w}" for w in urdf_source))
    print(f"files of tasks/ calling open_session: {len(sessions)}" + "".join(f"\n  {w}" for w in sessions))
    print(f"module-level OrderedDict memos: {len(memos)}" + "".join(f"\n  {w}" for w in memos))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
