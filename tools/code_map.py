"""DEVELOPERS.md's map of the code, written from the modules' docstrings.

The map lies between two marker lines of DEVELOPERS.md (:data:`BEGIN`, :data:`END`): one table per
package folder (``asset2sim/``, ``schemas/``, ``tasks/``, ``apps/``, ``flows/`` and their
sub-folders), one row per module holding the first sentence of its docstring; a folder's
``__init__.py`` docstring, where it has one, opens its table. ``tasks/``' stage folders follow the
data-flow order of ``LAYERS`` in ``tests/test_import_graph.py`` (read as text, never imported);
other folders are in name order. The output depends on the files alone (no imports, no clock),
so two runs on one tree write the same bytes; only each file's first string is tokenized.

Usage: ``python tools/code_map.py`` rewrites the map in place (``make map``);
``python tools/code_map.py --check`` writes nothing and exits 1 when the map differs from the
docstrings (``tests/test_docs.py`` checks it). Errors: ``SystemExit`` naming the file when
DEVELOPERS.md lacks a marker line.
"""

from __future__ import annotations

import ast
import io
import re
import sys
import tokenize
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The package folders the map covers, in the order their tables appear.
PACKAGES = ["asset2sim", "schemas", "tasks", "apps", "flows"]
BEGIN = "<!-- code map: written by tools/code_map.py from the module docstrings (make map) -->"
END = "<!-- end of the code map -->"
#: A sentence ends at ``.``, ``!`` or ``?`` followed by white space, unless the word before is an
#: abbreviation (:data:`ABBREVIATIONS`).
SENTENCE_END = re.compile(r"(\S*)[.!?]\s")
ABBREVIATIONS = {"e.g", "i.e", "incl", "cf", "vs", "approx", "resp", "etc"}
ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")


def docstring(path: Path) -> str:
    """The module docstring of ``path`` ('' when its first statement is not a string), read from
    the file's first tokens only (no parse of the whole module)."""
    skip = {tokenize.ENCODING, tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE}
    with path.open("rb") as f:
        for token in tokenize.tokenize(f.readline):
            if token.type in skip:
                continue
            if token.type != tokenize.STRING:
                return ""
            value = ast.literal_eval(token.string)
            return value if isinstance(value, str) else ""
    return ""


def first_sentence(text: str) -> str:
    """The first sentence of a docstring's first paragraph on one line, as Markdown: reST roles
    (``:mod:`a.b```) and double backquotes become code spans, ``|`` is escaped for a table cell,
    the closing period is dropped."""
    text = " ".join(text.strip().split("\n\n", 1)[0].split()) + " "
    ends = (m.end() - 1 for m in SENTENCE_END.finditer(text) if m.group(1).lower() not in ABBREVIATIONS)
    sentence = text[: next(ends, len(text))].strip()
    sentence = ROLE.sub(lambda m: f"`{m.group(1)}`", sentence).replace("``", "`")
    return sentence.removesuffix(".").replace("|", "\\|")


def stage_order() -> list[str]:
    """The layers of ``tests/test_import_graph.py`` (``LAYERS = [...]``) in data-flow order;
    [] when the file or the assignment is missing."""
    path = ROOT / "tests" / "test_import_graph.py"
    if not path.is_file():
        return []
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "LAYERS" for t in node.targets):
            return [elt.value for elt in node.value.elts if isinstance(elt, ast.Constant)]
    return []


def folders(root: Path = ROOT) -> list[Path]:
    """Every package folder (one holding ``.py`` files) under :data:`PACKAGES`, each package's own
    folder first, then its sub-folders: ``tasks/``' in data-flow order, the others by name."""
    rank = {name: i for i, name in enumerate(stage_order())}
    out: list[Path] = []
    for package in PACKAGES:
        subs = sorted({p.parent for p in (root / package).rglob("*.py")} - {root / package})
        if package == "tasks":
            subs.sort(key=lambda p: (rank.get(p.relative_to(root / package).parts[0], len(rank)), str(p)))
        out += [root / package, *subs]
    return out


def code_map(root: Path = ROOT) -> str:
    """The map's Markdown (the lines between the markers), from the files under ``root``."""
    lines: list[str] = []
    for folder in folders(root):
        modules = sorted(p for p in folder.glob("*.py") if p.name != "__init__.py")
        init = folder / "__init__.py"
        intro = first_sentence(docstring(init)) if init.is_file() else ""
        if not modules and not intro:
            continue
        lines += ["", f"### `{folder.relative_to(root).as_posix()}/`"]
        if intro:
            lines.append(intro.replace("\\|", "|") + ".")
        if modules:
            lines += ["", "| module | holds |", "|---|---|"]
        for path in modules:
            lines.append(f"| `{path.name}` | {first_sentence(docstring(path)) or '(no docstring)'} |")
    return "\n".join(lines) + "\n\n"


def rewritten(text: str, root: Path = ROOT) -> str:
    """``text`` (DEVELOPERS.md) with the lines between :data:`BEGIN` and :data:`END` replaced by
    :func:`code_map`. Raises ``ValueError`` when a marker line is missing or out of order."""
    lines = text.splitlines(keepends=True)
    stripped = [line.rstrip("\n") for line in lines]
    if BEGIN not in stripped or END not in stripped or stripped.index(BEGIN) > stripped.index(END):
        raise ValueError(f"DEVELOPERS.md needs the lines {BEGIN!r} and {END!r}, in that order")
    start, end = stripped.index(BEGIN), stripped.index(END)
    return "".join(lines[: start + 1]) + code_map(root) + "".join(lines[end:])


def main(argv: list[str]) -> int:
    """Rewrite DEVELOPERS.md's map (exit 0), or with ``--check`` compare only (exit 1 when it differs)."""
    path = ROOT / "DEVELOPERS.md"
    text = path.read_text()
    try:
        new = rewritten(text)
    except ValueError as exc:
        raise SystemExit(f"{path}: {exc}") from None
    if "--check" in argv:
        if new != text:
            print(f"{path.name}'s map differs from the module docstrings: run `make map`")
            return 1
        return 0
    if new != text:
        path.write_text(new)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
