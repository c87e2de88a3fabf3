"""What the engines' session classes share, mixed into each beside
:class:`~asset2sim.engines.base.NoRootHold` where it applies."""

from __future__ import annotations


class SessionDefaults:
    """The session is a context manager that closes it, and
    ``step_ground_penetration`` is ``ground_penetration`` (of
    :class:`~asset2sim.engines.base.SimSession`; engines that measure the
    ground from the geometry, without a contact cache, keep this one)."""

    def step_ground_penetration(self) -> float:
        """:meth:`ground_penetration` (from the geometry, no contact cache)."""
        return self.ground_penetration()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
