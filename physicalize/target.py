"""The whole-body controller's interface: what it tracks at one control step (:class:`Target`) and
what one QP solve returns (:class:`Solution`). The reference builder (:mod:`physicalize.reference`),
the grasp planner (:mod:`physicalize.grasp`) and the stepping logic (:mod:`physicalize.stepping`) fill
or adapt a ``Target``; :class:`physicalize.wbc.WholeBodyController` consumes it."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from physicalize.object_loop import HeldObject


@dataclass
class Target:
    """What the controller tracks at one control step (world frame; quaternions wxyz)."""

    qpos: np.ndarray  # (36,) reference configuration (posture, orientations)
    qvel: np.ndarray  # (35,)
    qacc: np.ndarray  # (35,)
    com: np.ndarray  # (3,) planned centre of mass
    com_vel: np.ndarray
    com_acc: np.ndarray
    stance: tuple[bool, bool]  # left, right foot in support
    foot_pos: np.ndarray  # (2, 3) foot body origins
    foot_quat: np.ndarray  # (2, 4)
    foot_vel: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    foot_acc: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    sole_height: np.ndarray | None = None  # (2,) the reference soles' height above the floor (for touchdown)
    hand_pos: np.ndarray | None = None  # (2, 3), None: hands follow the posture only
    torso_quat: np.ndarray | None = None  # (4,), None: the pelvis orientation
    # hand task extras (physicalize.grasp); None: body origins, no feed-forward, weight w_hand
    hand_offset: np.ndarray | None = None  # (2, 3) tracked point in each hand's body frame
    hand_vel: np.ndarray | None = None  # (2, 3) target velocity / acceleration of that point
    hand_acc: np.ndarray | None = None
    hand_weight: np.ndarray | None = None  # (2,) task weight per hand
    hand_rot: np.ndarray | None = None  # (2, 3, 3) hand orientations, tracked with weights hand_rot_weight (2,)
    hand_rot_weight: np.ndarray | None = None
    hand_force: np.ndarray | None = None  # (2, 3) the planned force each hand applies to a held object (the open loop)
    held: HeldObject | None = None  # the object the hands hold, in the QP's loop (physicalize.object_loop)
    seated: bool = False  # a seat carries the body: the QP holds its contacts (physicalize.seat)


@dataclass
class Solution:
    """One control step's QP result."""

    qdd: np.ndarray
    forces: np.ndarray  # (n_corners, 3) world frame
    tau: np.ndarray  # (29,)
    action: np.ndarray  # (29,) joint position targets
    ok: bool
    stance: tuple[bool, bool] | None = None  # the support the QP used (the schedule after the stepping logic)
    landing_shift: np.ndarray | None = None  # (2, 2) each foot's capture-point shift of its last landing [m]
