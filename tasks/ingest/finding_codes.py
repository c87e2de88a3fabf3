"""Finding codes: every code the validator can emit (stable identifiers, never renamed), with its
default severity; tabulated in ``docs/guide/validation.md`` by :func:`codes_markdown_table`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Severity = Literal["error", "warning", "info"]

__all__ = ["CODES", "CodeInfo", "MESH_USE_DEPENDENT", "Severity", "codes_markdown_table"]


@dataclass(frozen=True)
class CodeInfo:
    """Default severity, topic and one-line meaning of a finding code."""

    severity: Severity
    topic: str
    summary: str


_c = CodeInfo  # (severity, topic, summary)


#: Every code the validator can emit (stable identifiers; never renamed).
CODES: dict[str, CodeInfo] = {
    # files
    "ASSET_NOT_FOUND": _c("error", "files", "the asset path does not exist"),
    "URDF_NOT_FOUND": _c("error", "files", "no mobility.urdf or other *.urdf in the folder"),
    "URDF_AMBIGUOUS": _c("error", "files", "several *.urdf candidates and no mobility.urdf"),
    "URDF_NOT_REGULAR_FILE": _c("error", "files", "the URDF is a directory, FIFO, device or socket"),
    "URDF_OUTSIDE_ASSET": _c("error", "files", "the URDF is a symlink leaving the asset folder"),
    "URDF_UNREADABLE": _c("error", "files", "the URDF cannot be opened or read"),
    "URDF_ENCODING_UNSUPPORTED": _c("error", "files", "the URDF is not UTF-8 (UTF-16/32, invalid UTF-8, or another declared encoding with non-ASCII bytes)"),
    "ASSET_FILE_NOT_REGULAR": _c("error", "files", "semantics.txt or meta.json is not a regular file inside the folder"),
    "ASSET_FILE_TOO_LARGE": _c("error", "files", "semantics.txt or meta.json is a regular file above the cap (max_extra_bytes, 1 MiB); not read"),
    # files an MJCF or USD input names, and the input file itself (asset2sim.input_files)
    "INPUT_NOT_FOUND": _c("error", "files", "a file the input names (an MJCF include, mesh or texture, a USD layer) does not exist"),
    "INPUT_NOT_REGULAR_FILE": _c("error", "files", "the input file, or a file it names, is a FIFO, device (/dev/zero), socket or folder: refused without reading it"),
    "INPUT_TOO_LARGE": _c("error", "files", "the input file, or a file it names, is above the size cap (64 MiB per file, 1 GiB per MJCF model), or what MuJoCo or the USD reader would build is above its cap (every element naming a file counted: 1 GiB, 1,000,000 triangles): not read"),
    "INPUT_OUTSIDE_TREE": _c("error", "files", "the MJCF or USD file given is a symlink leading out of its folder"),
    "INPUT_UNREADABLE": _c("error", "files", "the operating system refuses to open or read a file the input names (permissions)"),
    "MJCF_PATH_ESCAPES": _c("error", "files", "an MJCF include, mesh, texture, height field, skin or model file, or meshdir / texturedir / assetdir, that is absolute, a URI, leaves the file's folder through ../ or a symlink"),
    "MJCF_INCLUDE_INVALID": _c("error", "files", "an MJCF <include> of itself (a loop) or without a file, more than 256 includes, or a chain deeper than 16"),
    "USD_LAYER_OUTSIDE_ASSET": _c("error", "files", "a USD sublayer, reference or payload outside the file's folder (absolute path, ../, symlink, URI)"),
    "FORMAT_UNREADABLE": _c("error", "files", "MuJoCo or OpenUSD cannot read the MJCF or USD file into an articulated object (the message has the reader's reason)"),
    # xml (safexml)
    "XML_TOO_LARGE": _c("error", "xml", "document above the size cap"),
    "XML_TOKEN_TOO_LARGE": _c("error", "xml", "a text, tag or attribute value above the token cap"),
    "XML_TOO_DEEP": _c("error", "xml", "element nesting above the depth cap"),
    "XML_TOO_MANY_ELEMENTS": _c("error", "xml", "more elements than the cap"),
    "XML_DTD_FORBIDDEN": _c("error", "xml", "a <!DOCTYPE> declaration"),
    "XML_ENTITY_FORBIDDEN": _c("error", "xml", "an entity declaration (billion laughs, quadratic blow-up)"),
    "XML_EXTERNAL_REFERENCE_FORBIDDEN": _c("error", "xml", "an external DTD or external entity (XXE)"),
    "XML_MALFORMED": _c("error", "xml", "not well-formed XML (incl. undefined entities, NUL characters)"),
    "XML_NOT_A_FILE": _c("error", "xml", "the XML source is not a readable regular file"),
    "URDF_ROOT_NOT_ROBOT": _c("error", "structure", "the root element is not <robot>"),
    "URDF_ROBOT_NAME_MISSING": _c("error", "structure", "<robot> has no name attribute (required by URDF; yourdfpy fails on it)"),
    "URDF_NO_LINKS": _c("error", "structure", "the robot has no <link>"),
    "ASSET_NO_GEOMETRY": _c("error", "structure", "no link has a <visual> or <collision>: there is nothing to size, weigh or collide"),
    "URDF_TOO_MANY_LINKS": _c("error", "structure", "more links than the cap (128: PyBullet cannot load more)"),
    "URDF_TOO_MANY_MOVABLE_JOINTS": _c("warning", "structure", "more movable joints than 32: in the worst case (all links touching) refine may not finish within the flow's per-asset time limit, which then ends it"),
    # numbers
    "NUMBER_NAN": _c("error", "numbers", "a NaN where a number is required"),
    "NUMBER_INF": _c("error", "numbers", "an infinity where a number is required"),
    "NUMBER_OVERFLOW": _c("error", "numbers", "a decimal literal that overflows float64 (e.g. 1e400)"),
    "NUMBER_EMPTY": _c("error", "numbers", "an empty numeric attribute"),
    "NUMBER_MALFORMED": _c("error", "numbers", "not a decimal number (hex, 1_0, 1,2, words ...)"),
    "NUMBER_COUNT": _c("error", "numbers", "wrong number of values (e.g. xyz with 2 values)"),
    # structure
    "LINK_NAME_MISSING": _c("error", "structure", "a <link> without name"),
    "LINK_NAME_DUPLICATE": _c("error", "structure", "two links with the same name"),
    "LINK_NAME_NOT_A_FILE_NAME": _c("warning", "structure", "a link name with path separators, '..', control or non-ASCII characters or over 64 characters: files made for it get a safe name (asset2sim.file_names)"),
    "NAME_TOO_LONG": _c("error", "structure", "a link, joint or robot name longer than 256 characters (PyBullet's URDF importer ends the process on a joint name of about 2,000)"),
    "LINK_FILE_NAMES_CLASH": _c("error", "structure", "two link names that give their files one safe name (only a crafted asset can)"),
    "JOINT_NAME_MISSING": _c("error", "structure", "a <joint> without name"),
    "JOINT_NAME_DUPLICATE": _c("error", "structure", "two joints with the same name"),
    "JOINT_TYPE_MISSING": _c("error", "structure", "a joint without type"),
    "JOINT_TYPE_INVALID": _c("error", "structure", "a type other than revolute, continuous, prismatic, fixed, floating, planar"),
    "JOINT_TYPE_UNSUPPORTED": _c("error", "structure", "a floating or planar joint: refine and its simulators model revolute, continuous, prismatic and fixed joints only"),
    "JOINT_PARENT_MISSING": _c("error", "structure", "a joint without <parent link=...>"),
    "JOINT_CHILD_MISSING": _c("error", "structure", "a joint without <child link=...>"),
    "JOINT_PARENT_UNKNOWN": _c("error", "structure", "the parent names no link"),
    "JOINT_CHILD_UNKNOWN": _c("error", "structure", "the child names no link"),
    "JOINT_SELF_LOOP": _c("error", "structure", "parent and child are the same link"),
    "LINK_MULTIPLE_PARENTS": _c("error", "structure", "a link is the child of several joints"),
    "LINK_ORPHAN": _c("error", "structure", "a link connected by no joint (robot with several links)"),
    "TREE_CYCLE": _c("error", "structure", "joints form a cycle"),
    "TREE_NO_ROOT": _c("error", "structure", "every link has a parent: no root"),
    "TREE_MULTIPLE_ROOTS": _c("error", "structure", "several links without parent"),
    "JOINT_MIMIC_UNKNOWN": _c("error", "structure", "<mimic joint=...> names no other joint"),
    "JOINT_MIMIC_UNSUPPORTED": _c("error", "structure", "a <mimic> joint: coupled joints are not modelled by refine (refused, not dropped)"),
    # joint values
    "JOINT_AXIS_ZERO": _c("error", "joints", "zero axis on a movable joint"),
    "JOINT_AXIS_NOT_UNIT": _c("info", "joints", "axis not of unit length (simulators normalize it)"),
    "JOINT_AXIS_IMPLAUSIBLE": _c("error", "joints", "an axis of length outside [1e-3, 1e3] (1e308 overflows, 1e-9 vanishes): an axis is a direction, written as a unit vector"),
    "JOINT_LIMIT_MISSING": _c("error", "joints", "revolute or prismatic joint without <limit>"),
    "JOINT_LIMIT_INCOMPLETE": _c("warning", "joints", "<limit> without lower or upper (URDF default 0)"),
    "JOINT_LIMIT_REVERSED": _c("error", "joints", "lower > upper"),
    "JOINT_LIMIT_EQUAL": _c("warning", "joints", "lower == upper: the joint cannot move"),
    "JOINT_LIMIT_IMPLAUSIBLE": _c("error", "joints", "revolute or continuous limit beyond +-4 pi (two turns), or prismatic travel beyond the object's size"),
    "JOINT_RANGE_WRONG_UNIT": _c("warning", "joints", "a revolute range spanning less than a degree or a prismatic travel under a millimetre: a range that only makes sense in the other unit (radians read as degrees, millimetres as metres); refine refuses it"),
    "JOINT_EFFORT_NEGATIVE": _c("error", "joints", "effort < 0"),
    "JOINT_VELOCITY_NEGATIVE": _c("error", "joints", "velocity < 0"),
    "JOINT_DYNAMICS_NEGATIVE": _c("error", "joints", "damping or friction < 0"),
    # inertials
    "INERTIAL_MASS_MISSING": _c("warning", "inertials", "<inertial> without <mass value=...>; replaced by an estimate"),
    "INERTIA_MISSING": _c("warning", "inertials", "<inertial> without <inertia>; replaced by an estimate"),
    "INERTIAL_MASS_NONPOSITIVE": _c("warning", "inertials", "mass <= 0 on a moving link, or < 0 anywhere; replaced by an estimate"),
    "INERTIAL_MASS_ZERO_STATIC": _c("info", "inertials", "mass 0 on a static link (root or fixed child)"),
    "INERTIA_NOT_POSITIVE_DEFINITE": _c("warning", "inertials", "an eigenvalue <= 0; replaced by an estimate"),
    "INERTIA_TRIANGLE_INEQUALITY": _c("warning", "inertials", "principal moments violate I1 <= I2 + I3; replaced by an estimate"),
    "INERTIAL_IMPLAUSIBLE": _c("error", "inertials", "a mass or inertia entry beyond +-1e9 (kg, kg*m^2): no object's, and 1e308 overflows to infinity"),
    "INERTIAL_ORIGIN_IMPLAUSIBLE": _c("error", "inertials", "a center of mass beyond +-2e5 file units of its link (MAX_COORDINATE, as for mesh vertices)"),
    # geometry and mesh references
    "GEOMETRY_MISSING": _c("error", "geometry", "<visual>/<collision> whose <geometry> is not exactly one <box|cylinder|sphere|mesh>"),
    "GEOMETRY_SIZE_NONPOSITIVE": _c("error", "geometry", "box size, radius or length <= 0"),
    "MESH_SCALE_ZERO": _c("error", "geometry", "a mesh scale component of 0"),
    "MESH_SCALE_NEGATIVE": _c("warning", "geometry", "a negative mesh scale (mirrored mesh)"),
    "MESH_FILENAME_EMPTY": _c("error", "mesh_paths", "<mesh> without filename"),
    "MESH_PATH_NUL": _c("error", "mesh_paths", "a NUL byte in the mesh path"),
    "MESH_PATH_CONTROL_CHAR": _c("error", "mesh_paths", "a control character in the mesh path"),
    "MESH_URI_FORBIDDEN": _c("error", "mesh_paths", "a URI (file://, http://, package:// ...) instead of a relative path"),
    "MESH_PATH_ABSOLUTE": _c("error", "mesh_paths", "an absolute mesh path"),
    "MESH_PATH_ESCAPES": _c("error", "mesh_paths", "a relative path whose ../ leave the asset folder"),
    "MESH_SYMLINK_ESCAPES": _c("error", "mesh_paths", "a symlink on the path leads outside the asset folder"),
    "MESH_NOT_FOUND": _c("error", "mesh_paths", "the mesh file does not exist (all are listed)"),
    "MESH_IS_DIRECTORY": _c("error", "mesh_paths", "the mesh path is a directory"),
    "MESH_NOT_REGULAR_FILE": _c("error", "mesh_paths", "the mesh path is a FIFO, device or socket"),
    "MESH_EXTENSION_UNSUPPORTED": _c("error", "mesh_paths", "not a mesh extension (.obj .stl .ply .off .glb .gltf .dae)"),
    "MESH_FORMAT_UNSUPPORTED": _c("error", "mesh_paths", "a mesh format refine cannot load (OFF and others; PyBullet reads OBJ, STL, DAE; GLB, glTF and PLY are converted to OBJ)"),
    "MESH_UNREADABLE": _c("error", "mesh_paths", "the mesh cannot be opened (permissions)"),
    "MESH_TOO_LARGE": _c("error", "mesh_contents", "mesh file above the byte cap"),
    "MESH_TOO_MANY_FACES": _c("error", "mesh_contents", "mesh above the face-count cap, or the asset's meshes above it together (distinct files: 1,000,000 triangles; every <mesh> reference counted, as the simulators build them: 2,000,000)"),
    "MESH_MALFORMED": _c("error", "mesh_contents", "the mesh cannot be parsed"),
    "MESH_NO_FACES": _c("error", "mesh_contents", "the mesh has no face"),
    "MESH_NONFINITE_VERTEX": _c("error", "mesh_contents", "NaN or infinite vertex coordinates"),
    "MESH_COORDINATE_IMPLAUSIBLE": _c("error", "mesh_contents", "a vertex coordinate beyond +-2e5 file units (MAX_COORDINATE: 20 m even at the smallest overlay scale 1e-4); checked before any arithmetic"),
    "ASSET_SIZE_IMPLAUSIBLE": _c("error", "geometry", "the object's size (bounding box of all geometry at the zero pose) lies outside what any overlay scale in [1e-4, 1e4] can bring to a household size (asset_size_range)"),
    "MESH_BAD_INDEX": _c("error", "mesh_contents", "face indices out of range (or 0 in OBJ), faces with < 3 vertices"),
    "MESH_ZERO_AREA": _c("error", "mesh_contents", "every face is degenerate: the mesh has no surface"),
    "MESH_ZERO_VOLUME": _c("info", "mesh_contents", "all vertices in one plane (a sheet); fine when other pieces give volume"),
    "LINK_ZERO_VOLUME": _c("warning", "mesh_contents", "a link's whole mass geometry is flat: mass must come from area"),
    "MESH_MATERIAL_OUTSIDE": _c("warning", "mesh_paths", "an mtllib/texture path leaving the folder (not used, not copied; the statement is dropped from the output's copy of the OBJ/MTL)"),
    "MESH_MATERIAL_MISSING": _c("info", "mesh_paths", "an mtllib/texture file that does not exist"),
    "MESH_MATERIAL_BESIDE_TARGET": _c("info", "mesh_paths", "an OBJ reached through a symlink names an mtllib that lies beside the real file, not beside the link: loaders of the input miss it; the output copies it beside the mesh"),
    "MATERIAL_NOT_REGULAR_FILE": _c("error", "mesh_paths", "an mtllib/texture path (or its symlink target, anywhere) is a FIFO, device or socket"),
    "TEXTURE_TOO_LARGE": _c("error", "mesh_paths", "a texture above the file-size or pixel cap, per file (256 MiB, 8192 x 8192) or per asset (1 GiB, 4 x 8192 x 8192); read from the image header, nothing decoded"),
    "TEXTURE_UNREADABLE": _c("error", "mesh_paths", "a texture file that is not an image PIL can identify (PyBullet and the renderer would fail on it)"),
    "TEXTURE_PATH_REFUSED": _c("error", "mesh_paths", "a URDF <texture filename> that is absolute, a URI, escapes the folder or is not an image file"),
    "TEXTURE_NOT_FOUND": _c("warning", "mesh_paths", "a URDF <texture filename> that does not exist"),
    # extras
    "SEMANTICS_MALFORMED_LINE": _c("error", "extras", "a semantics.txt line that is not 'link joint_kind label'"),
    "SEMANTICS_UNKNOWN_LINK": _c("info", "extras", "semantics.txt names a link the URDF does not have"),
    "SEMANTICS_UNKNOWN_KIND": _c("info", "extras", "a joint kind other than hinge, slider, free, heavy, static, junk"),
    "META_UNREADABLE": _c("warning", "extras", "meta.json is not a JSON object"),
    "INTERNAL_ERROR": _c("error", "internal", "the validator itself failed on this input (a bug; message has the exception)"),
}

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
