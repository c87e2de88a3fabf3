"""Finding codes: every code the validator can emit (stable identifiers, never renamed), with its
default severity; tabulated in ``docs/guide/validation.md`` by :func:`codes_markdown_table`. The table itself is
data, ``finding_codes.yaml`` beside this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from asset2sim.package_data import package_yaml

Severity = Literal["error", "warning", "info"]

__all__ = ["CODES", "CodeInfo", "MESH_USE_DEPENDENT", "Severity", "codes_markdown_table"]


@dataclass(frozen=True)
class CodeInfo:
    """Default severity, topic and one-line meaning of a finding code."""

    severity: Severity
    topic: str
    summary: str


#: Every code the validator can emit (stable identifiers; never renamed): ``finding_codes.yaml`` beside this module,
#: code -> [severity, topic, summary], in the order of the guide's table.
CODES: dict[str, CodeInfo] = {code: CodeInfo(*entry) for code, entry in package_yaml(__package__, "finding_codes.yaml").items()}

#: Mesh-content codes whose default severity is downgraded where the mesh is only drawn.
MESH_USE_DEPENDENT = frozenset({"MESH_MALFORMED", "MESH_NO_FACES", "MESH_NONFINITE_VERTEX", "MESH_BAD_INDEX",
                                "MESH_ZERO_AREA", "MESH_TOO_MANY_FACES"})


def codes_markdown_table() -> str:
    """The table of codes (code, default severity, topic, meaning) as Markdown."""
    rows = ["| code | default severity | topic | meaning |", "|---|---|---|---|"]
    for code, info in CODES.items():
        sev = info.severity + (" (warning if only drawn)" if code in MESH_USE_DEPENDENT else "")
        rows.append(f"| `{code}` | {sev} | {info.topic} | {info.summary} |")
    return "\n".join(rows)
