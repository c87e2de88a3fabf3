"""The estimation context: what stages 1-4 (extract, analyze, request and
category, geometric closed states) hand to overlay synthesis, built by
:func:`build_context` for the refine pipeline, the baselines and benchmarks.
The context holds values only; the input's kinematics session (PyBullet, fixed
base, no gravity) that moves the parts to a state is handed beside it and passed
as ``kin`` to what poses the parts (loads, landings, ordinals, ends, resting pose).
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
from asset2sim.schemas.asset import AssetDescription, LinkGeometry
from asset2sim.schemas.config import RefineConfig
from asset2sim.schemas.overlay import RootMount
from asset2sim.schemas.request import RequestSpec
from asset2sim.tasks.geometry import analyze
from asset2sim.tasks.geometry.closed_state import ClosedState, closed_positions, link_hull_points, links_aabb, object_extents, object_hull_volume, subtree_links
from asset2sim.tasks.ingest import extract
from asset2sim.formats import ReadOptions
from asset2sim.tasks.interpret.mounting import root_mounting
from asset2sim.tasks.interpret.part_labels import labels_from_names
from asset2sim.tasks.interpret.part_priors import push_buttons
from asset2sim.tasks.interpret.reading import interpret

from asset2sim.engines.base import SessionOptions, SimSession
from asset2sim.engines.registry import open_session


@dataclass(frozen=True)
class EstimationContext:
    """Everything an estimator may use (units: input asset at scale 1 unless noted); frozen: a stage that
    changes what it holds (the task, the resting pose) hands on a copy (``dataclasses.replace``)."""

    asset: AssetDescription
    geometry: dict[str, LinkGeometry]
    request: RequestSpec
    category: str
    category_reason: str
    closed: dict[str, ClosedState]
    closed_extents: np.ndarray
    """(3,) extents of the closed object, root frame (closed ends and extents at scale 1, input units)."""
    subtrees: dict[str, list[str]]
    joint_boxes: dict[str, np.ndarray] = field(default_factory=dict)
    """joint -> (2, 3) [lower, upper] corners (scale 1, the input's frame) of its moving subtree's axis-aligned box in the
    closed state; a joint whose subtree has no geometry is left out."""
    hull_points: dict[str, np.ndarray] = field(default_factory=dict)
    """link -> (N, 3) convex-hull vertices of its collision geometry, link frame, scale 1."""
    closed_volume: float | None = None
    """Convex-hull volume of the closed object at scale 1 (the input's units cubed); measured only when the request
    asks a volume ("a 500 ml bottle"), else None."""
    root_rotation: Any = None
    """(3, 3) resting-pose rotation the output will carry (``tasks.state.pose``), or None."""
    task: str | None = None
    """The manipulation task refine was given ("close the microwave door"): the post-check executes it."""
    push_buttons: frozenset[str] = frozenset()
    """Joints of push buttons and keys (:func:`~asset2sim.tasks.interpret.part_priors.push_buttons`): closed where
    they rest out of their body, each returned there by its spring."""
    mounting: RootMount | None = None
    """How the root is held (:func:`asset2sim.tasks.interpret.mounting.root_mounting`, resolved by :func:`build_context`);
    None: free-standing."""

    @property
    def joint_heights(self) -> dict[str, float]:
        """joint -> z (scale 1) of its moving subtree's box center in the closed state (0 without geometry)."""
        return {n: float(0.5 * (self.joint_boxes[n][0][2] + self.joint_boxes[n][1][2])) if n in self.joint_boxes else 0.0
                for n in self.subtrees}

    @property
    def prismatic(self) -> set[str]:
        """The movable joints that slide (positions in the input's units, at the output x its scale)."""
        return {j.name for j in self.asset.movable_joints() if j.type == "prismatic"}

    def joint_label(self, joint: str) -> str | None:
        """The semantic label of ``joint``'s moving (child) link, None when unlabelled."""
        return self.asset.link(self.asset.joint(joint).child).semantic_label

    def closed_state(self) -> dict[str, float]:
        """joint -> closed position (rad, or input units for prismatic joints)."""
        return {n: c.q_closed for n, c in self.closed.items()}


@contextlib.contextmanager
def build_context(source: AssetDescription | Path | str, prompt: str, config: RefineConfig | None = None, *, category: str | None = None,
                  asset_id: str | None = None, geometry: dict[str, LinkGeometry] | None = None,
                  cache: analyze.MeshCache | None = None) -> Iterator[tuple[EstimationContext, SimSession]]:
    """The estimation context of an asset for ``prompt`` and the input's kinematics session, as a context
    manager (``with build_context(...) as (ctx, kin)``): ``kin`` is closed when the ``with`` block ends, also on
    errors.

    Args:
        source: an extracted asset, or its folder / URDF file (extracted with ``asset_id`` and ``category``).
        prompt: the request text.
        config: ``config.sim`` and ``config.overrides`` are used (default :class:`RefineConfig`).
        category: overrides the asset's own category.
        geometry, cache: the analysis result and mesh cache when the caller has them.

    Yields:
        (:class:`EstimationContext` (lengths at scale 1, in the input's units), the fixed-base, gravity-free
        PyBullet session of the input asset: what moves its parts, left at no particular state).

    Raises:
        asset2sim.tasks.ingest.extract.AssetError: ``source`` cannot be read.
        asset2sim.tasks.geometry.analyze.MeshAnalysisError: a link with geometry has no usable geometry.
        OverrideError: an override of ``config.overrides`` does not fit the asset.
    """
    asset = source if isinstance(source, AssetDescription) else extract.extract_asset(source, asset_id=asset_id, category=category)
    asset = labels_from_names(asset)  # an asset without semantics.txt: labels from its link names
    cache = cache if cache is not None else analyze.MeshCache()
    if geometry is None:
        geometry = analyze.analyze_asset(asset, cache=cache)
    cfg = config or RefineConfig()
    meaning = interpret(asset, prompt, category, cfg.overrides, config)
    mount = root_mounting(asset, meaning.request, meaning.category, ReadOptions(body=cfg.body, mjcf_angle=cfg.mjcf.angle))
    with open_session("pybullet", asset.urdf_path,  # the input asset, kinematics only
                      SessionOptions(fixed_base=True, gravity=False, ground=False, conventions=cfg.sim)) as kin:
        hull = link_hull_points(asset, cache=cache)
        buttons = push_buttons(asset, meaning.category)
        closed = closed_positions(kin, asset, hull_points=hull, pushed=buttons)
        closed_q = {n: c.q_closed for n, c in closed.items()}
        extents = object_extents(kin, closed_q, asset, hull)
        subtrees = {j.name: subtree_links(asset, j.child) for j in asset.movable_joints()}
        boxes = {n: np.array(box) for n, box in ((n, links_aabb(kin, links, hull)) for n, links in subtrees.items()) if box is not None}
        volume = (object_hull_volume(kin, closed_q, asset, hull)
                  if any(sz.dimension == "volume" for sz in meaning.request.sizes) else None)
        yield EstimationContext(asset=asset, geometry=geometry, request=meaning.request, category=meaning.category,
                                category_reason=meaning.category_reason, closed=closed, closed_extents=extents,
                                subtrees=subtrees, joint_boxes=boxes, hull_points=hull, closed_volume=volume,
                                push_buttons=buttons, mounting=mount), kin
