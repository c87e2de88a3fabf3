"""Typed overrides (``--mass``, ``--size``, ``--scale``, ``--state``, ``--mount``,
``--material``) checked against the asset and merged into a parsed request:
they replace what the words said about the same quantity (a state after the
words' states) and are recorded in ``spec.overrides`` as given.
"""

from __future__ import annotations

import math

from asset2sim.prior_tables import load_priors
from asset2sim.schemas.asset import AssetDescription
from asset2sim.schemas.request import BAND_TARGET, JointStateRequest, PartProperty, RequestOverrides, RequestSpec, SizeTarget, StateTarget

__all__ = ["OverrideError", "apply_overrides"]


class OverrideError(ValueError):
    """An override that does not fit the asset; ``code``: ``OVERRIDE_UNKNOWN_JOINT``, ``_WRONG_KIND``,
    ``_OUT_OF_LIMITS`` or ``_UNKNOWN_MATERIAL``."""

    def __init__(self, message: str, code: str):
        super().__init__(message)
        self.code = code


def apply_overrides(spec: RequestSpec, overrides: RequestOverrides | None, asset: AssetDescription) -> RequestSpec:
    """``spec`` with ``overrides`` winning over its words.

    Raises:
        OverrideError: a state naming no movable joint or part of ``asset``, an angle for a prismatic joint or
            a distance for a revolute one, an angle beyond the joint's range, or an unknown material.
    """
    if not overrides:
        return spec
    update: dict = {"overrides": overrides.given()}
    props = list(spec.properties)
    if overrides.mass is not None:
        props = [p for p in props if p.label is not None or (p.mass is None and p.mass_range is None)]
        props.append(PartProperty(label=None, mass=overrides.mass, phrase=f"--mass {overrides.mass:g} kg"))
        update["mass_level"] = None
    if overrides.material is not None:
        if overrides.material not in load_priors().materials:
            raise OverrideError(f"--material {overrides.material!r}: not a known material ({', '.join(sorted(load_priors().materials))})",
                                "OVERRIDE_UNKNOWN_MATERIAL")
        props = [p for p in props if p.label is not None or p.material is None]
        props.append(PartProperty(label=None, material=overrides.material, phrase=f"--material {overrides.material}"))
    update["properties"] = props
    if overrides.scale is not None:
        update.update(scale=overrides.scale, sizes=[])
    elif overrides.size is not None:
        update["sizes"] = [SizeTarget(dimension="largest", value=overrides.size, phrase=f"--size {overrides.size:g} m")]
    if overrides.mount is not None:
        update["mount"] = overrides.mount
    if overrides.state:
        update["joint_states"] = list(spec.joint_states) + [_state_request(asset, name, st) for name, st in overrides.state.items()]
    return spec.model_copy(update=update)


def _state_request(asset: AssetDescription, name: str, st) -> JointStateRequest:
    """The joint state request of one ``--state NAME=VALUE`` (a joint name wins over a part label)."""
    movable = {j.name: j for j in asset.movable_joints()}
    labels = {asset.link(j.child).semantic_label for j in movable.values()} - {None, ""}
    phrase = f"--state {name}={st.text or st.value}"
    if name in movable:
        joints, selector = [movable[name]], {"selector": "joint", "joint": name}
    elif name in labels:
        joints = [j for j in movable.values() if asset.link(j.child).semantic_label == name]
        selector = {"selector": "label", "label": name}
    else:
        raise OverrideError(f"{phrase}: the asset has no movable joint or part named {name!r} (joints: "
                            f"{', '.join(movable) or 'none'}; parts: {', '.join(sorted(labels)) or 'none'})", "OVERRIDE_UNKNOWN_JOINT")
    for j in joints:
        _check_fits(phrase, j, st)
    if st.kind == "band":
        return JointStateRequest(band=st.band, phrase=phrase, **selector)
    # the nominal band until the geometry resolves the number: a fraction's nearest
    band = min(BAND_TARGET, key=lambda b: abs(BAND_TARGET[b] - st.value)) if st.kind == "fraction" else "halfway"
    return JointStateRequest(band=band, target=StateTarget(kind=st.kind, value=st.value), phrase=phrase, **selector)


def _check_fits(phrase: str, joint, st) -> None:
    """An angle only for a revolute joint and within its range; a distance only for a prismatic one."""
    angular = joint.type in ("revolute", "continuous")
    if st.kind == "angle" and not angular or st.kind == "distance" and angular:
        need = "an angle (deg, rad)" if angular else "a distance (m, cm, mm)"
        raise OverrideError(f"{phrase}: joint {joint.name!r} is {joint.type}: give {need} or an opening fraction 0-1", "OVERRIDE_WRONG_KIND")
    if st.kind == "angle" and joint.type == "revolute" and joint.lower is not None and joint.upper is not None:
        span = float(joint.upper) - float(joint.lower)
        if st.value > span + 1e-9:
            raise OverrideError(f"{phrase}: beyond joint {joint.name!r}'s range of {span:.4g} rad ({math.degrees(span):.4g} deg) "
                                "from its closed end", "OVERRIDE_OUT_OF_LIMITS")
