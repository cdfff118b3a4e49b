"""What the IK is asked to follow: per-frame world targets for named G1 bodies.

The mapping/scaling step (:mod:`retarget.mapping`, :mod:`retarget.scaling`) turns a
:class:`~pipeline.clip.HumanClip` into :class:`IKTargets`; the IK (:mod:`retarget.ik`)
turns :class:`IKTargets` into G1 ``qpos``. Positions are in metres in the robot's world
(already scaled to the robot), quaternions wxyz. :func:`targets_from_qpos` builds them from a
known G1 motion by forward kinematics (round-trip checks of the IK).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.robot import NQ_ROBOT


@dataclass(frozen=True)
class IKTargets:
    """Targets for ``K`` robot bodies over ``T`` frames.

    ``pos`` (T,K,3) world positions; ``quat`` (T,K,4) world orientations wxyz (rows of a body
    whose ``rot_weight`` is 0 are ignored); ``pos_weight`` / ``rot_weight`` (K,) task costs;
    ``foot_contact`` (T,2) bool for (left, right): the human foot is on the ground, so the
    robot foot must be pinned flat; ``scale`` the human-to-robot length ratio used;
    ``object_contact`` (T,L) bool over the robot links ``contact_links``: the human touches an
    object with a joint mapped to that link, so the link must be brought to the object surface.
    """

    body_names: tuple[str, ...]
    pos: np.ndarray
    quat: np.ndarray
    pos_weight: np.ndarray
    rot_weight: np.ndarray
    fps: float
    scale: float
    foot_contact: np.ndarray | None = None
    contact_links: tuple[str, ...] = ()
    object_contact: np.ndarray | None = None

    def __post_init__(self):
        T, K = self.pos.shape[:2]
        if self.pos.shape != (T, K, 3) or self.quat.shape != (T, K, 4) or K != len(self.body_names):
            raise ValueError(
                f"IKTargets: pos {self.pos.shape}, quat {self.quat.shape} and {len(self.body_names)} bodies disagree"
            )
        if self.pos_weight.shape != (K,) or self.rot_weight.shape != (K,):
            raise ValueError("IKTargets: pos_weight and rot_weight must have one entry per body")
        if self.foot_contact is not None and self.foot_contact.shape != (T, 2):
            raise ValueError(f"IKTargets: foot_contact shape {self.foot_contact.shape} != ({T}, 2)")
        if self.object_contact is not None and self.object_contact.shape != (T, len(self.contact_links)):
            raise ValueError(
                f"IKTargets: object_contact shape {self.object_contact.shape} != ({T}, {len(self.contact_links)})"
            )

    @property
    def frames(self) -> int:
        return self.pos.shape[0]


def targets_from_qpos(
    model: mujoco.MjModel,
    qpos: np.ndarray,
    body_names: tuple[str, ...],
    fps: float,
    pos_weight: float | np.ndarray = 1.0,
    rot_weight: float | np.ndarray = 0.1,
    foot_contact: np.ndarray | None = None,
) -> IKTargets:
    """:class:`IKTargets` that the G1 trajectory ``qpos`` ``(T, 36)`` reaches exactly (forward kinematics).

    For round-trip checks of the IK: ``model`` is any model whose first 36 ``qpos`` are the G1's.
    """
    qpos = np.asarray(qpos, dtype=np.float64)
    data = mujoco.MjData(model)
    ids = [model.body(b).id for b in body_names]
    T, K = qpos.shape[0], len(ids)
    pos, quat = np.empty((T, K, 3)), np.empty((T, K, 4))
    for t in range(T):
        data.qpos[:NQ_ROBOT] = qpos[t]
        mujoco.mj_kinematics(model, data)
        pos[t], quat[t] = data.xpos[ids], data.xquat[ids]
    return IKTargets(
        body_names=tuple(body_names),
        pos=pos,
        quat=quat,
        pos_weight=np.broadcast_to(np.asarray(pos_weight, float), (K,)).copy(),
        rot_weight=np.broadcast_to(np.asarray(rot_weight, float), (K,)).copy(),
        fps=float(fps),
        scale=1.0,
        foot_contact=foot_contact,
    )
