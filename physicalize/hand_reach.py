"""Where the hands are relative to a scene's free objects along a reference (for :mod:`physicalize.grasp`):
each hand's tracked point (:func:`hand_offsets`, a fixed point of the hand body) and, per frame, the
nearest object with the hand surface's signed distance to it and the inward surface normal there
(MuJoCo's ``mj_geomDistance`` between the hand's and the object's collision geoms, the objects at their
reference poses)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.robot import HAND_BODIES, NQ_ROBOT
from pipeline.scene import Scene, hand_geoms, nearest_geom_pair


@dataclass
class ObjectTracks:
    """A scene's free objects: ``names`` (qpos order), their collision ``geoms``, body ids ``bodies`` and
    reference tracks ``poses`` (name -> (T, 7))."""

    names: list[str]
    geoms: list[list[int]]
    bodies: list[int]
    poses: dict[str, np.ndarray]

    @classmethod
    def of(cls, scene: Scene, poses: dict[str, np.ndarray]) -> ObjectTracks:
        m, names = scene.model, list(scene.object_qpos_adr)
        geoms = [
            [g for g in range(m.ngeom) if m.geom_contype[g] and m.geom_bodyid[g] == scene.object_body_id[n]]
            for n in names
        ]
        return cls(names, geoms, [scene.object_body_id[n] for n in names], poses)

    def pose(self, i: int) -> np.ndarray:
        """(T, 7) the reference track of object ``i``."""
        return self.poses[self.names[i]]


@dataclass
class HandReach:
    """Per frame and hand of a reference: the tracked hand ``point`` (T, 2, 3) and the hand's orientation
    ``rot`` (T, 2, 3, 3); the nearest object ``obj`` (T, 2) (-1 none within reach), the hand surface's
    signed distance ``dist`` (T, 2) to it (inf none) and the inward ``normal`` (T, 2, 3)."""

    point: np.ndarray
    rot: np.ndarray
    dist: np.ndarray
    normal: np.ndarray
    obj: np.ndarray


def hand_offsets(model: mujoco.MjModel) -> np.ndarray:
    """(2, 3) each hand's tracked point in its body frame: the mean centre of its own collision geoms."""
    out = np.zeros((2, 3))
    for k, geoms in enumerate(hand_geoms(model)):
        own = [g for g in geoms if model.geom_bodyid[g] == model.body(HAND_BODIES[k]).id]
        if own:
            out[k] = model.geom_pos[own].mean(axis=0)
    return out


def hand_reach(scene: Scene, ref, objs: ObjectTracks, reach: float) -> HandReach:
    """Each hand's tracked point and nearest object within ``reach`` per frame of the reference ``ref``
    (:class:`physicalize.reference.Reference`); a hand touching an object (no distance direction) gets
    the direction towards the object's centre of mass as its normal."""
    m, T = scene.model, ref.frames
    hgeoms, offset = hand_geoms(m), hand_offsets(m)
    hand_ids = [m.body(b).id for b in HAND_BODIES]
    d = mujoco.MjData(m)
    centre, rot = np.zeros((T, 2, 3)), np.zeros((T, 2, 3, 3))
    near_d, near_n, near_o = np.full((T, 2), np.inf), np.zeros((T, 2, 3)), np.full((T, 2), -1)
    fromto = np.zeros(6)
    for t in range(T):
        d.qpos[:NQ_ROBOT] = ref.qpos[t]
        for n in objs.names:
            adr = scene.object_qpos_adr[n]
            d.qpos[adr : adr + 7] = objs.poses[n][t]
        mujoco.mj_kinematics(m, d)
        for k in range(2):
            rot[t, k] = d.xmat[hand_ids[k]].reshape(3, 3)
            centre[t, k] = d.xpos[hand_ids[k]] + rot[t, k] @ offset[k]
            for i, og in enumerate(objs.geoms):
                dist, _, _ = nearest_geom_pair(m, d, hgeoms[k], og, reach, fromto)
                if dist < min(reach, near_d[t, k]):
                    v = (fromto[3:] - fromto[:3]) * (1.0 if dist >= 0 else -1.0)
                    nv = np.linalg.norm(v)
                    near_d[t, k], near_o[t, k] = dist, i
                    to_com = d.xipos[objs.bodies[i]] - centre[t, k]
                    near_n[t, k] = v / nv if nv > 1e-6 else to_com / max(np.linalg.norm(to_com), 1e-9)
    return HandReach(centre, rot, near_d, near_n, near_o)
