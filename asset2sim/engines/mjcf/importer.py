"""MuJoCo's own URDF import, the skeleton the converter rewrites: the URDF
handed to it (collisions as convex pieces, inertias in the link axes, the
``<mujoco><compiler .../>`` extension) and ``MjSpec.from_string`` +
``to_xml``.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
from lxml import etree

from asset2sim.engines.loading import BULLET_DEFAULT_INERTIA, BULLET_DEFAULT_MASS, CollisionPiece
from asset2sim.engines.mjcf.base import MjcfError, num_text, safe_name
from asset2sim.engines.mjcf.compiler import load_mujoco, mujoco_messages, mujoco_warnings
from asset2sim.frames import translation_matrix
from asset2sim.urdf import (
    UrdfDynamics,
    UrdfGeometry,
    UrdfInertial,
    UrdfJoint,
    UrdfLimit,
    UrdfLink,
    UrdfModel,
    UrdfStyle,
    write_urdf,
)

#: Numbers of the URDF handed to MuJoCo's importer: :func:`num_text` (shortest round trip, 0 as ``0``).
_IMPORT_STYLE = UrdfStyle(number=num_text)


def urdf_for_import(
    model: UrdfModel,
    pieces: dict[str, list[CollisionPiece]],
    mesh_names: dict[tuple, str],
    mesh_scales: dict[tuple, np.ndarray | None],
    missing_inertial: str,
) -> str:
    """A URDF equivalent to ``model`` whose collisions are the convex pieces
    (mesh files named as in ``mesh_names``), inertias in the link axes, with
    MuJoCo's compiler extension; built as a :class:`~asset2sim.urdf.UrdfModel`
    and written by :func:`asset2sim.urdf.write_urdf`."""
    mujoco_ext = ET.Element("mujoco")
    ET.SubElement(mujoco_ext, "compiler", {
        "angle": "radian", "strippath": "false", "discardvisual": "true", "fusestatic": "false",
        "balanceinertia": "false", "inertiafromgeom": "false", "boundmass": "0", "boundinertia": "0",
    })
    out = UrdfModel(name=safe_name(model.name), extensions=[mujoco_ext])
    for name, link in model.links.items():
        ln = UrdfLink(name=name)
        ine = link.inertial
        if ine is None and missing_inertial == "bullet":
            ln.inertial = UrdfInertial(mass=BULLET_DEFAULT_MASS, inertia=np.diag(np.asarray(BULLET_DEFAULT_INERTIA, float)))
        elif ine is not None:
            ln.inertial = UrdfInertial(mass=ine.mass, origin=translation_matrix(ine.com()), inertia=ine.inertia_in_link_axes())
        for p in pieces[name]:
            if p.kind == "hull":
                key = (name, p.collision, p.group)
                ln.collisions.append(UrdfGeometry(kind="mesh", origin=p.origin, filename=mesh_names[key], mesh_scale=mesh_scales[key]))
            else:
                ln.collisions.append(UrdfGeometry(kind=p.kind, origin=p.origin, size=p.size, radius=p.radius, length=p.length))
        out.links[name] = ln
    for j in model.joints:
        out.joints.append(
            UrdfJoint(
                name=j.name, type=j.type, parent=j.parent, child=j.child, origin=j.origin, axis_xyz=j.axis,
                limit=UrdfLimit(lower=j.lower, upper=j.upper, effort=0.0, velocity=0.0) if j.type in ("revolute", "prismatic") else None,
                dynamics=None if j.type == "fixed" else UrdfDynamics(damping=j.damping, friction=j.friction),
            )
        )
    return write_urdf(out, style=_IMPORT_STYLE).decode("utf-8")


def import_skeleton(urdf_text: str, assets: dict[str, bytes], urdf_path: Path, notes: list[str]):
    """MuJoCo's own URDF import: (``MjSpec``, root element of its MJCF).

    Raises:
        MjcfError: MuJoCo refuses the file.
    """
    mujoco = load_mujoco()
    try:
        with mujoco_messages() as caught:
            spec = mujoco.MjSpec.from_string(urdf_text, assets=assets)
            skeleton = spec.to_xml()
    except Exception as exc:  # mujoco raises ValueError with its message
        raise MjcfError(f"MuJoCo could not import {urdf_path}: {exc}") from exc
    notes.extend(mujoco_warnings(caught))
    return spec, etree.fromstring(skeleton.encode())
