"""What the IK is asked to follow: per-frame world targets for named G1 bodies.

The mapping/scaling step (:mod:`retarget.mapping`, :mod:`retarget.scaling`) turns a
:class:`~pipeline.clip.HumanClip` into :class:`IKTargets`; the IK (:mod:`retarget.ik`)
turns :class:`IKTargets` into G1 ``qpos``. Positions are in metres in the robot's world
(already scaled to the robot), quaternions wxyz.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
