"""The URDF model: one set of dataclasses, one reader, one writer.

Every module reads and writes URDF through here: :func:`read_urdf` /
:func:`parse_urdf_bytes` give a :class:`UrdfModel` (XML by
:mod:`asset2sim.safexml`), :func:`write_urdf` gives its bytes (``read -> write
-> read`` gives an equal model), :func:`scale_model` bakes in a uniform scale.
The dataclasses live in :mod:`.model`, the reader in :mod:`.reader` (numbers
in :mod:`.number_lists`), the writer in :mod:`.writer`, in-place edits in
:mod:`.edits`; this package names them all.

Reading modes: ``"strict"`` (default: finite decimal numbers, one tree over
all links, the elements each joint and geometry needs; the first problem
raises :class:`UrdfError` naming file, line and link or joint), ``"lenient"``
(raw third-party files: ``float`` numbers, structure unchecked) and
``"collect"`` (input validation: every problem goes to ``on_problem`` as a
:class:`Problem`, in the validator's order, and reading goes on).

Units: lengths in the file's units, angles rad, mass kg, inertia kg*m^2 about
the COM in the ``<inertial><origin>`` frame, damping N*m*s/rad or N*s/m,
friction N*m or N. Poses are (4, 4) matrices, ``rpy`` as in :mod:`asset2sim.frames`.
"""

from asset2sim.urdf.edits import PASSIVE_EFFORT, PASSIVE_VELOCITY, conform_limits, scale_model
from asset2sim.urdf.model import (
    GEOMETRY_KINDS, JOINT_TYPES, MOVABLE, SIMULATED_JOINT_TYPES, Problem, UrdfDynamics, UrdfError, UrdfGeometry,
    UrdfInertial, UrdfJoint, UrdfLimit, UrdfLink, UrdfMaterial, UrdfMimic, UrdfModel, UrdfSource, clone_model,
)
from asset2sim.urdf.number_lists import NumberError, parse_number_list
from asset2sim.urdf.reader import MAX_NAME_CHARS, Mode, model_of, parse_urdf_bytes, path_of, read_urdf, resolve_mesh_path
from asset2sim.urdf.writer import DEFAULT_STYLE, PARTNET_STYLE, UrdfStyle, write_urdf

__all__ = [
    "DEFAULT_STYLE", "GEOMETRY_KINDS", "JOINT_TYPES", "MAX_NAME_CHARS", "MOVABLE", "Mode",
    "NumberError", "PARTNET_STYLE", "Problem", "SIMULATED_JOINT_TYPES", "UrdfDynamics", "UrdfError", "UrdfGeometry",
    "UrdfInertial", "UrdfJoint", "UrdfLimit", "UrdfLink", "UrdfMaterial", "UrdfMimic", "UrdfModel", "UrdfSource",
    "PASSIVE_EFFORT", "PASSIVE_VELOCITY", "UrdfStyle", "clone_model", "conform_limits", "model_of", "parse_number_list",
    "parse_urdf_bytes", "path_of",
    "read_urdf", "resolve_mesh_path", "scale_model", "write_urdf",
]
