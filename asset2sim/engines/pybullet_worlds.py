"""PyBullet worlds beside the simulation session: the free-shape collision world
(:class:`PyBulletShapeWorld`, distances between static convex shapes) and the viewer (:class:`PyBulletViewer`,
images drawn by TinyRenderer on the CPU), each in a private DIRECT client, with what every PyBullet world reads:
the quiet import (:func:`bullet`), joint infos and a link's world frame (position (3,), rotation (3, 3)).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from asset2sim.engines.quiet import quiet_fds, startup_quiet


BULLET_JOINT_TYPES = {0: "revolute", 1: "prismatic", 2: "spherical", 3: "planar", 4: "fixed"}


def bullet():
    with startup_quiet():  # its build-time line
        import pybullet

    return pybullet


def joint_infos(p: "BoundClient", body: int) -> list:
    return [p.getJointInfo(body, j) for j in range(p.getNumJoints(body))]


def body_link_frame(p: "BoundClient", body: int, idx: int) -> tuple[np.ndarray, np.ndarray]:
    """World position (3,) and rotation (3, 3) of link ``idx`` (-1: the base) in client ``p``."""
    if idx < 0:
        pos, orn = p.getBasePositionAndOrientation(body)
    else:
        st = p.getLinkState(body, idx, computeForwardKinematics=True)
        pos, orn = st[4], st[5]
    return np.array(pos, float), np.array(p.getMatrixFromQuaternion(orn), float).reshape(3, 3)


class BoundClient:
    """The ``pybullet`` module with ``physicsClientId`` bound to the client ``cid`` in every function (a call may still
    pass its own), as ``pybullet_utils.bullet_client.BulletClient`` binds it, for a client connected elsewhere."""

    def __init__(self, module, cid: int):
        self._module, self.cid = module, cid

    def __getattr__(self, name: str):
        value = getattr(self._module, name)
        if callable(value):
            value = functools.partial(value, physicsClientId=self.cid)
        setattr(self, name, value)  # looked up once
        return value


class PyBulletShapeWorld:
    """A :class:`~asset2sim.engines.base.ShapeWorld`: static convex mesh bodies in a private DIRECT client."""

    engine = "pybullet"
    #: Bullet's default convex hull collision margin, 1 mm, on each of two touching shapes.
    contact_margin = 0.002

    def __init__(self):
        self._bullet = p = bullet()
        self.cid = p.connect(p.DIRECT)
        self._p = BoundClient(p, self.cid)

    def add_convex(self, vertices, scale, position, orientation) -> int:
        p = self._p
        shape = p.createCollisionShape(p.GEOM_MESH, vertices=np.asarray(vertices, float).tolist(),
                                       meshScale=np.asarray(scale, float).tolist())
        return p.createMultiBody(0, shape, basePosition=np.asarray(position, float).tolist(),
                                 baseOrientation=np.asarray(orientation, float).tolist())

    def set_pose(self, shape: int, position, orientation) -> None:
        self._p.resetBasePositionAndOrientation(shape, np.asarray(position, float).tolist(),
                                                np.asarray(orientation, float).tolist())

    def distances(self, shape_a: int, shape_b: int, max_distance: float = 0.0) -> list[float]:
        return [pt[8] for pt in self._p.getClosestPoints(shape_a, shape_b, max_distance)]

    def close(self) -> None:
        if self.cid is not None:
            self._bullet.disconnect(self.cid)
            self.cid = None


class PyBulletViewer:
    """A :class:`~asset2sim.engines.base.Viewer`: the URDF (fixed base, MTL
    colours) in a private DIRECT client, drawn by TinyRenderer on the CPU
    (RuntimeError: Bullet could not load the file)."""

    engine = "pybullet"

    def __init__(self, urdf_path: Path):
        self.cid = None
        with quiet_fds():  # the import prints PyBullet's build time
            p = bullet()
            self.cid = p.connect(p.DIRECT)
            self._p = p = BoundClient(p, self.cid)
        try:
            with quiet_fds():
                self.body = p.loadURDF(str(urdf_path), basePosition=[0, 0, 0], useFixedBase=True,
                                       flags=p.URDF_USE_MATERIAL_COLORS_FROM_MTL)
        except Exception as exc:
            self.close()
            raise RuntimeError(f"PyBullet could not load {urdf_path}: {exc}") from exc
        infos = joint_infos(p, self.body)
        self._links = {-1: p.getBodyInfo(self.body)[0].decode(), **{j: info[12].decode() for j, info in enumerate(infos)}}
        self._joints = {info[1].decode(): j for j, info in enumerate(infos)}
        self.joint_names = [info[1].decode() for info in infos if info[2] in (p.JOINT_REVOLUTE, p.JOINT_PRISMATIC)]
        self.link_names = list(self._links.values())
        self._index = {name: idx for idx, name in reversed(list(self._links.items()))}

    def visual_colors(self) -> list[tuple[str, int, tuple[float, float, float, float]]]:
        out = []
        counts: dict[int, int] = {}
        for row in self._p.getVisualShapeData(self.body):
            link = row[1]
            k = counts.get(link, 0)
            counts[link] = k + 1
            out.append((self._links[link], k, tuple(row[7])))
        return out

    def set_visual_color(self, link: str, shape: int, rgba) -> None:
        self._p.changeVisualShape(self.body, self._index[link], shapeIndex=shape, rgbaColor=list(rgba))

    def set_joint_positions(self, q: dict[str, float]) -> None:
        for name, value in q.items():
            self._p.resetJointState(self.body, self._joints[name], float(value), 0.0)

    def set_root_pose(self, position, quat_xyzw) -> None:
        self._p.resetBasePositionAndOrientation(self.body, np.asarray(position, float).tolist(),
                                                np.asarray(quat_xyzw, float).tolist())

    def link_frame(self, link: str) -> tuple[np.ndarray, np.ndarray]:
        return body_link_frame(self._p, self.body, self._index[link])

    def draw(self, width: int, height: int, camera: dict, light: dict) -> tuple[np.ndarray, np.ndarray]:
        p = self._p
        view = p.computeViewMatrix(*(np.asarray(camera[k], float).tolist() for k in ("eye", "target", "up")))
        proj = p.computeProjectionMatrixFOV(camera["fov_deg"], width / height, camera["near"], camera["far"])
        res = p.getCameraImage(width, height, view, proj, lightDirection=np.asarray(light["direction"], float).tolist(),
                               lightColor=list(light["color"]), lightDistance=light["distance"], shadow=int(light["shadow"]),
                               lightAmbientCoeff=light["ambient"], lightDiffuseCoeff=light["diffuse"],
                               lightSpecularCoeff=light["specular"], renderer=p.ER_TINY_RENDERER)
        if res is None or len(res) < 5:
            raise RuntimeError("PyBullet returned no image")
        return np.asarray(res[2], dtype=np.uint8).reshape(height, width, 4), np.asarray(res[4]).reshape(height, width)

    def close(self) -> None:
        if self.cid is not None:
            try:
                self._p.disconnect()
            except Exception:
                pass
            self.cid = None

    def __del__(self):  # pragma: no cover - best effort
        try:
            self.close()
        except Exception:
            pass
