"""The springs and session options an output folder declares, as the measuring and tuning stages import them
(:mod:`asset2sim.engines.loading` holds them; the exports live in :mod:`asset2sim.formats`)."""

from asset2sim.engines.loading import joint_spring, output_session_options, overlay_springs, springs_from_overlay

__all__ = ["joint_spring", "output_session_options", "overlay_springs", "springs_from_overlay"]
