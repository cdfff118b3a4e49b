"""Settings and model facts of the retarget IK (:mod:`retarget.ik`).

* :class:`IKConfig` -- solver, iterations, costs, limits, collision and foot-pinning options;
* :func:`ik_model` -- the scene's model with every free object turned into a mocap body (same
  geoms, so the same collision model as physics, but no object DoFs in the IK);
* :func:`sole_offset` -- height of a foot body's origin above its sole, from its collision geoms.

The QP limits the IK adds to mink's live in :mod:`pipeline.ik_limits` (physicalize's IK uses them too);
the G1 motor speed limits in :func:`pipeline.robot.joint_velocity_limits`, the robot geoms checked
against each other in :func:`pipeline.scene.self_collision_groups`.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.robot import NQ_ROBOT
from pipeline.scene import Scene


@dataclass
class IKConfig:
    """Differential-IK settings (lengths in m, angles in rad).

    Each frame takes up to ``iterations`` QP steps from the previous frame's solution and stops
    after a step that moves every DoF less than ``tolerance``: such a step's linearisation error
    is about ``L tolerance^2 / 2`` (0.2 mm for a 1 m lever at 0.02 rad), so another step would
    not change the result. Each step solves

    ``min_dq  sum_i ||W_i (J_i dq + e_i)||^2 + (damping + mu) ||dq||^2``
    ``s.t.    q_min <= q + dq <= q_max  (gain configuration_limit_gain),``
    ``        |q + dq - q_{t-1}| <= velocity_limit_factor * motor speed * dt,``
    ``        |p + dp - p_{t-1}| <= root_speed_limit * dt  (root position, per axis),``
    ``        d_k + n_k^T J_k dq >= d_min,k - (1 - collision_gain) (d_min,k - d_k)``
    ``        for every geom pair k closer than detection_distance,``

    then ``q <- q (+) dq``. Frame 0 starts from the default joint pose with the root at the target
    pelvis position and heading and takes up to ``init_iterations`` steps with no speed limit,
    until a step is below ``init_tolerance``.

    Costs are mink task costs: position in 1/m, orientation in 1/rad; a task contributes
    ``cost^2 error^2``. Body costs come from ``IKTargets``; ``task_lm_damping`` is mink's
    error-scaled damping of those tasks (``mu = task_lm_damping * sum ||W_i e_i||^2``).

    Feet: while ``IKTargets.foot_contact`` is set, the ``ankle_roll_link`` target is replaced by
    the pose at contact onset with the sole ``floor_min_distance`` above the floor and level,
    costs ``foot_pin_position_cost`` / ``foot_pin_orientation_cost``; ``pin_anchor`` picks the
    onset xy and heading: the foot target's (``"target"``) or the robot foot's (``"robot"``).

    Object contacts: while ``IKTargets.object_contact`` flags a link, a
    :class:`~retarget.contact.ContactTask` (cost ``contact_cost``, faded in and out over
    ``contact_ramp_s``) drives its distance to the objects to ``contact_gap`` (links farther than
    ``contact_reach`` are left alone). A moving object within ``clearance_margin`` of a planted
    foot is moved away horizontally at up to ``clearance_speed`` [m/s] and stays moved; an object at
    rest in the input stands still where it ends up (:class:`~retarget.contact.FootClearance`,
    :func:`~retarget.contact.hold_resting`); ``G1Retargeter.objects_pose`` holds the result.
    """

    solver: str = "daqp"
    iterations: int = 2
    init_iterations: int = 60
    tolerance: float = 0.02
    init_tolerance: float = 1e-3
    damping: float = 1e-4
    task_lm_damping: float = 1.0
    posture_cost: float = 0.01
    velocity_limit_factor: float = 0.5
    root_speed_limit: float = 3.0
    configuration_limit_gain: float = 0.95
    self_min_distance: float = 0.005
    object_min_distance: float = 0.005
    floor_min_distance: float = 0.0
    detection_distance: float = 0.05
    collision_gain: float = 0.85
    foot_pin_position_cost: float = 30.0
    foot_pin_orientation_cost: float = 10.0
    pin_anchor: str = "target"
    pin_ramp_s: float = 0.1
    contact_cost: float = 5.0
    contact_gap: float = 0.01
    contact_reach: float = 0.3
    contact_ramp_s: float = 0.1
    clearance_margin: float = 0.02
    clearance_speed: float = 1.0

    def __post_init__(self):
        if self.iterations < 1 or self.init_iterations < 1:
            raise ValueError(
                f"IKConfig: iterations ({self.iterations}) and init_iterations ({self.init_iterations}) must be >= 1"
            )
        if not 0.0 < self.root_speed_limit:
            raise ValueError(f"IKConfig: root_speed_limit must be > 0, got {self.root_speed_limit}")
        if not 0.0 < self.velocity_limit_factor:
            raise ValueError(f"IKConfig: velocity_limit_factor must be > 0, got {self.velocity_limit_factor}")
        if not 0.0 < self.collision_gain <= 1.0:
            raise ValueError(f"IKConfig: collision_gain must be in (0, 1], got {self.collision_gain}")
        if self.detection_distance <= max(self.self_min_distance, self.object_min_distance, self.floor_min_distance):
            raise ValueError("IKConfig: detection_distance must exceed every minimum distance")
        if self.pin_anchor not in ("target", "robot"):
            raise ValueError(f"IKConfig: pin_anchor must be 'target' or 'robot', got {self.pin_anchor!r}")
        if not self.object_min_distance <= self.contact_gap < self.contact_reach:
            raise ValueError("IKConfig: need object_min_distance <= contact_gap < contact_reach")
        if self.clearance_margin <= 0 or self.clearance_speed <= 0:
            raise ValueError("IKConfig: clearance_margin and clearance_speed must be > 0")
        if self.damping < 0 or self.posture_cost < 0:
            raise ValueError("IKConfig: damping and posture_cost must be >= 0")


def ik_model(scene: Scene) -> mujoco.MjModel:
    """The scene's model with each free object made a mocap body (its free joint removed).

    Geoms, sizes, meshes and contact flags are untouched, so distances are those of the
    physics model; the IK has the robot's 35 DoFs only (``qpos`` is the robot's 36), and an
    object is placed per frame through ``data.mocap_pos`` / ``data.mocap_quat``.
    """
    spec = scene.spec.copy()
    for o in scene.objects:
        if o.fixed:
            continue
        body = spec.body(o.name)
        for j in list(body.joints):
            spec.delete(j)
        body.mocap = True
    model = spec.compile()
    if model.nq != NQ_ROBOT:
        raise RuntimeError(f"IK model has nq {model.nq}; expected the G1's 36 after freezing the objects")
    return model


def _lowest_z(model: mujoco.MjModel, g: int) -> float:
    """Lowest point of geom ``g`` along its body's z-axis, in the body frame [m].

    Spheres and capsules exactly (segment end minus radius); other types from the corners of
    MuJoCo's local bounding box (``geom_aabb``), exact for boxes.
    """
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, model.geom_quat[g])
    R = R.reshape(3, 3)
    p, size, typ = model.geom_pos[g], model.geom_size[g], int(model.geom_type[g])
    if typ == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        return float(p[2] - size[0])
    if typ == int(mujoco.mjtGeom.mjGEOM_CAPSULE):
        return float(p[2] - abs(R[2, 2]) * size[1] - size[0])
    c, h = model.geom_aabb[g, :3], model.geom_aabb[g, 3:]
    corners = c + h * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return float((p + corners @ R.T)[:, 2].min())


def sole_offset(model: mujoco.MjModel, body: str) -> float:
    """Height of ``body``'s origin above its sole when the body frame is level [m].

    The sole is the lowest point of the body's collision geoms (``contype`` != 0); for the
    G1 foot it is the bottom of the seven foot capsules (centre 0.025 m below the
    ``ankle_roll_link`` origin, radius 0.01 m: 0.035 m).
    """
    bid = model.body(body).id
    geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == bid and model.geom_contype[g]]
    if not geoms:
        raise ValueError(f"body {body} has no collision geoms to define a sole")
    return -min(_lowest_z(model, g) for g in geoms)
