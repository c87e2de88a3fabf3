"""The fast tier refines through the session's shared refines (``refine_once``, ``refine_factory``: DEVELOPERS.md,
"Tests in tiers"): a test module outside the tests of refine's own behaviour calls ``refine_asset`` itself only
where the shared refine cannot stand in (a counterfactual that patches a stage, a fake model server counting its
calls, a rerun), at most :data:`MAX_DIRECT` times in the whole fast tier."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The tests of refine's own behaviour: the refine itself, its output folder (ownership, reruns, kills, staging),
#: what it writes and reads, its step budget and its cache's place; they refine into folders of their own.
REFINE_OWN = ["tests/tasks/test_refine*.py", "tests/asset2sim/test_output_folder.py", "tests/tasks/test_writes_inside_out.py",
              "tests/tasks/test_output_guard.py", "tests/tasks/test_unsafe_names.py", "tests/asset2sim/test_step_budget.py",
              "tests/asset2sim/test_array_cache.py", "tests/tasks/publish/test_output.py",
              "tests/tasks/publish/test_read_once.py"]
MAX_DIRECT = 20


def _slow(decorators: list[ast.expr]) -> bool:
    return any("slow" in ast.unparse(d) for d in decorators)


def direct_refines(path: Path) -> list[int]:
    """Lines of ``path`` that call ``refine_asset(`` outside a test, class or module marked ``slow``."""
    tree = ast.parse(path.read_text())
    module_slow = any(isinstance(n, ast.Assign) and any(getattr(t, "id", "") == "pytestmark" for t in n.targets)
                      and "slow" in ast.unparse(n.value) for n in tree.body)
    lines: list[int] = []

    def walk(node: ast.AST, slow: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = slow
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                inner = slow or _slow(child.decorator_list)
            elif isinstance(child, ast.Call) and not slow:
                f = child.func
                if (f.id if isinstance(f, ast.Name) else getattr(f, "attr", None)) == "refine_asset":
                    lines.append(child.lineno)
            walk(child, inner)

    walk(tree, module_slow)
    return lines


def test_the_fast_tier_refines_through_the_shared_refines():
    own = {p for pattern in REFINE_OWN for p in ROOT.glob(pattern)}
    calls = {str(p.relative_to(ROOT)): n for p in sorted((ROOT / "tests").rglob("*.py"))
             if p not in own and p.name != "helpers.py" and (n := direct_refines(p))}
    total = sum(len(n) for n in calls.values())
    assert total <= MAX_DIRECT, f"{total} direct refine_asset calls in the fast tier (use refine_once): {calls}"
