"""One pass over a :class:`~pipeline.clip.RobotClip` in OUR collision model (:mod:`retarget.metrics`).

The collision model is :func:`pipeline.scene.build_scene` with the clip's objects (compiled once per
object set, :func:`scene_for`). Per frame, MuJoCo's ``mj_kinematics`` places the geoms and
``mj_collision`` lists the penetrating pairs with their signed distance ``dist < 0``;
``mj_geomDistance`` gives signed distances for pairs that are apart. :func:`sweep` keeps the robot
geom poses, the foot sites, the deepest robot-object and robot-robot penetrations and, when asked,
object support and contact matches; :func:`lowest_points` gives each geom's lowest point.

Cost: the compiled scene is cached per object set; one pass over a 325-frame clip with a mesh
box takes ~40-60 ms. (The G1 compiles without its visual meshes, :func:`pipeline.robot.g1_spec`.)
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import mujoco
import numpy as np

from pipeline.clip import ObjectTrack, RobotClip
from pipeline.robot import FOOT_BODIES, NQ_ROBOT
from pipeline.scene import Scene, SceneObject, build_scene, link_collision_geoms, nearest_geom_pair

FOOT_SITES = ("left_foot", "right_foot")
_LOWER_BODY_ROOTS = ("pelvis",)


@lru_cache(maxsize=8)
def _scene(objects: tuple[tuple[str, object], ...]) -> Scene:
    """The shared collision scene for these (name, geometry) objects (cached: compiling is slow)."""
    return build_scene([SceneObject(name, geo) for name, geo in objects])


def scene_for(objects: tuple[ObjectTrack, ...]) -> Scene:
    """The collision scene of a clip's objects (their names and geometries; cached)."""
    return _scene(tuple((o.name, o.geometry) for o in objects))


def _subtree(m: mujoco.MjModel, roots: tuple[str, ...], stop: str = "waist_yaw_link") -> set[int]:
    """Ids of the bodies under ``roots`` whose chain up to them does not pass ``stop``."""
    out, stop_id = set(), m.body(stop).id
    ids = [m.body(r).id for r in roots]
    for b in range(m.nbody):
        a = b
        while a > 0 and a not in ids and a != stop_id:
            a = m.body_parentid[a]
        if a in ids:
            out.add(b)
    return out


def lowest_points(
    xpos: np.ndarray, xmat: np.ndarray, gtype: np.ndarray, size: np.ndarray, rbound: np.ndarray
) -> np.ndarray:
    """(..., G) height of each geom's lowest point: sphere ``z - r``, capsule ``z - |a_z| h - r``,
    box ``z - sum_k |R_zk| s_k``, cylinder ``z - |a_z| h - r sqrt(1 - a_z^2)``; others ``z - rbound``."""
    rz = np.abs(xmat[..., 6:9])  # row z of R: world-z component of each local axis
    r, h = size[:, 0], size[:, 1]
    drop = np.select(
        [
            gtype == mujoco.mjtGeom.mjGEOM_SPHERE,
            gtype == mujoco.mjtGeom.mjGEOM_CAPSULE,
            gtype == mujoco.mjtGeom.mjGEOM_BOX,
            gtype == mujoco.mjtGeom.mjGEOM_CYLINDER,
        ],
        [
            np.broadcast_to(r, rz.shape[:-1]),
            rz[..., 2] * h + r,
            (rz * size).sum(-1),
            rz[..., 2] * h + r * np.sqrt(np.clip(1 - rz[..., 2] ** 2, 0, 1)),
        ],
        np.broadcast_to(rbound, rz.shape[:-1]),
    )
    return xpos[..., 2] - drop


@dataclass
class Sweep:
    """Per-frame results of one pass over the clip (robot collision geoms ``G``)."""

    model: mujoco.MjModel
    robot_geoms: np.ndarray
    xpos: np.ndarray  # (T, G, 3)
    xmat: np.ndarray  # (T, G, 9)
    sites: np.ndarray  # (T, 2, 3) left/right foot sites
    obj_depth: np.ndarray  # (T,) deepest robot-object penetration (>= 0)
    self_depth: np.ndarray  # (T,) deepest robot-robot penetration (>= 0)
    supported: np.ndarray  # (T,) a pelvis/leg/foot geom within support_tol of an object
    preserved: np.ndarray  # (T,) every reference contact within contact_tol of an object
    measurable: bool  # contact preservation can be measured

    def lowest(self) -> np.ndarray:
        """(T, G) height of each robot collision geom's lowest point."""
        m, rg = self.model, self.robot_geoms
        return lowest_points(self.xpos, self.xmat, m.geom_type[rg], m.geom_size[rg], m.geom_rbound[rg])

    def foot_heights(self, low: np.ndarray) -> np.ndarray:
        """(T, 2) lowest point of each foot's collision geoms."""
        body = self.model.geom_bodyid[self.robot_geoms]
        return np.column_stack([low[:, body == self.model.body(b).id].min(axis=1) for b in FOOT_BODIES])


def _depths(d: mujoco.MjData, kind: np.ndarray) -> tuple[float, float]:
    """(robot-object, robot-robot) deepest penetration among ``d``'s contacts (0 when none)."""
    n = d.ncon
    if not n:
        return 0.0, 0.0
    geom, dist = d.contact.geom[:n], d.contact.dist[:n]
    k1, k2 = kind[geom[:, 0]], kind[geom[:, 1]]
    pairs = (((k1 == 1) & (k2 == 2)) | ((k1 == 2) & (k2 == 1)), (k1 == 1) & (k2 == 1))
    return tuple(max(0.0, -float(dist[p].min())) if p.any() else 0.0 for p in pairs)  # type: ignore[return-value]


def sweep(
    robot: RobotClip,
    refs: tuple[np.ndarray, list[str]] | None,
    *,
    contact_tol: float,
    support_tol: float | None = None,
) -> Sweep:
    """Place robot and objects at every frame; collect geom poses, contacts and the distances asked for.

    ``refs``: ``(T, K)`` contact flags over ``K`` robot links; a frame is ``preserved`` when every
    flagged link's collision geoms are within ``contact_tol`` of an object's. ``supported`` is
    measured only with a ``support_tol`` (a pelvis/leg/foot geom within it of an object).
    """
    sc = scene_for(robot.objects)
    m, d, T = sc.model, mujoco.MjData(sc.model), robot.frames
    rg = sc.robot_geom_ids
    obj_bodies = set(sc.object_body_id.values())
    og = [g for g in range(m.ngeom) if m.geom_contype[g] and m.geom_bodyid[g] in obj_bodies]
    kind = np.zeros(m.ngeom, np.int8)
    kind[rg], kind[og] = 1, 2
    lower = _subtree(m, _LOWER_BODY_ROOTS)
    lower_geoms = [g for g in rg if m.geom_bodyid[g] in lower]
    flags, links = refs if refs is not None else (np.zeros((T, 0), bool), [])
    link_geoms = [link_collision_geoms(m, b) for b in links]
    site_ids = [m.site(s).id for s in FOOT_SITES]
    adr = [(sc.object_qpos_adr[o.name], o.pose) for o in robot.objects]
    out = Sweep(
        m,
        rg,
        np.empty((T, len(rg), 3)),
        np.empty((T, len(rg), 9)),
        np.empty((T, 2, 3)),
        np.zeros(T),
        np.zeros(T),
        np.zeros(T, bool),
        np.ones(T, bool),
        refs is not None and (bool(og) or not flags.any()),
    )
    for t in range(T):
        d.qpos[:NQ_ROBOT] = robot.qpos[t]
        for a, pose in adr:
            d.qpos[a : a + 7] = pose[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_collision(m, d)
        out.xpos[t], out.xmat[t], out.sites[t] = d.geom_xpos[rg], d.geom_xmat[rg], d.site_xpos[site_ids]
        out.obj_depth[t], out.self_depth[t] = _depths(d, kind)
        if support_tol is not None and og:
            out.supported[t] = nearest_geom_pair(m, d, lower_geoms, og, 2 * support_tol)[0] <= support_tol
        out.preserved[t] = all(
            bool(og) and nearest_geom_pair(m, d, link_geoms[k], og, 2 * contact_tol)[0] <= contact_tol
            for k in np.flatnonzero(flags[t])
        )
    return out
