"""The ingest stage's error: an asset that cannot be read."""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

if TYPE_CHECKING:  # pragma: no cover
    from asset2sim.tasks.ingest.findings import Finding

__all__ = ["AssetError"]


class AssetError(ValueError):
    """The asset cannot be read; the message names the file and the element. ``findings``: every
    validation error (empty when not from validation); ``codes`` their codes."""

    def __init__(self, message: str, findings: Sequence["Finding"] = ()):
        super().__init__(message)
        self.findings = list(findings)

    @property
    def codes(self) -> list[str]:
        return [f.code for f in self.findings]
