"""Settings, model facts and QP limits of the retarget IK (:mod:`retarget.ik`).

* :class:`IKConfig` -- solver, iterations, costs, limits, collision and foot-pinning options;
* :func:`ik_model` -- the scene's model with every free object turned into a mocap body (same
  geoms, so the same collision model as physics, but no object DoFs in the IK);
* :func:`joint_velocity_limits` -- mjlab's G1 motor speed limits per joint;
* :func:`sole_offset` -- height of a foot body's origin above its sole, from its collision geoms;
* :func:`self_collision_groups` -- the robot geoms checked against each other;
* the collision limits the IK adds to mink's: :class:`SeparationLimit` (geom pairs, displacement
  units, pushes penetrations out) and :class:`FloorLimit` (spheres/capsules above the floor
  plane, closed form).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import mink
import mujoco
import numpy as np
from mink.limits.collision_avoidance_limit import compute_contact_normal_jacobian
from mink.limits.limit import Constraint

from pipeline.robot import G1_JOINT_NAMES
from pipeline.scene import Scene

#: Foot bodies (left, right), pinned while ``IKTargets.foot_contact`` is set.
FOOT_BODIES: tuple[str, str] = ("left_ankle_roll_link", "right_ankle_roll_link")

#: Rated motor speeds [rad/s] of mjlab's ``g1_constants.py`` (``velocity_limit`` of the
#: 5020, 7520-14, 7520-22 and 4010 actuators; the ankle and waist roll/pitch 4-bar pairs are
#: 5020s). Matched by joint-name substring, first match wins.
MOTOR_SPEED_RADPS: tuple[tuple[tuple[str, ...], float], ...] = (
    (("elbow", "shoulder", "wrist_roll", "ankle", "waist_roll", "waist_pitch"), 37.0),  # 5020
    (("hip_pitch", "hip_yaw", "waist_yaw"), 32.0),  # 7520-14
    (("hip_roll", "knee"), 20.0),  # 7520-22
    (("wrist_pitch", "wrist_yaw"), 22.0),  # 4010
)


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

    Feet: while ``IKTargets.foot_contact`` is set (and ``pin_feet``), the ``ankle_roll_link``
    target is replaced by the pose at contact onset with the sole ``floor_min_distance`` above
    the floor and level, costs ``foot_pin_position_cost`` / ``foot_pin_orientation_cost``;
    ``pin_anchor`` picks the onset xy and heading: the foot target's (``"target"``) or the
    robot foot's (``"robot"``).

    Object contacts: while ``IKTargets.object_contact`` flags a link, a
    :class:`~retarget.contact.ContactTask` (cost ``contact_cost``, faded in and out over
    ``contact_ramp_s``) drives its distance to the objects to ``contact_gap`` (links farther than
    ``contact_reach`` are left alone). A moving object within ``clearance_margin`` of a planted
    foot is moved away horizontally at up to ``clearance_speed`` [m/s] and stays moved
    (:class:`~retarget.contact.FootClearance`); ``G1Retargeter.objects_pose`` holds the result.
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
    self_collision: bool = True
    self_min_distance: float = 0.005
    object_min_distance: float = 0.005
    floor_min_distance: float = 0.0
    detection_distance: float = 0.05
    collision_gain: float = 0.85
    pin_feet: bool = True
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
            raise ValueError(f"IKConfig: iterations ({self.iterations}) and init_iterations ({self.init_iterations}) must be >= 1")
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


def joint_velocity_limits(factor: float = 1.0) -> dict[str, float]:
    """``{joint: factor * rated motor speed}`` [rad/s] for the 29 G1 joints (:data:`MOTOR_SPEED_RADPS`)."""
    out = {}
    for j in G1_JOINT_NAMES:
        speed = next((v for keys, v in MOTOR_SPEED_RADPS if any(k in j for k in keys)), None)
        if speed is None:
            raise KeyError(f"no motor speed for joint {j}")
        out[j] = factor * speed
    return out


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
    if model.nq != 36:
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


def robot_collision_geoms(model: mujoco.MjModel) -> list[int]:
    """Collision geoms (``contype`` != 0) of the robot tree rooted at ``pelvis``."""
    root = model.body("pelvis").id
    return [g for g in range(model.ngeom) if model.geom_contype[g] and model.body_rootid[model.geom_bodyid[g]] == root]


def object_collision_geoms(model: mujoco.MjModel, scene: Scene) -> list[int]:
    """Collision geoms of every scene object (``<object>_col<k>``, chair parts, ...)."""
    ids = {model.body(o.name).id for o in scene.objects}
    return [g for g in range(model.ngeom) if model.geom_contype[g] and model.geom_bodyid[g] in ids]


def self_collision_groups(model: mujoco.MjModel) -> list[tuple[list[int], list[int]]]:
    """Robot geom groups checked against each other: every robot collision geom against every other.

    :class:`retarget.ik.SeparationLimit` then drops what MuJoCo's physics drops (``<exclude>``
    pairs, geoms of one weld, parent-child bodies), so the IK avoids exactly the self-contacts
    the physics stage would see.
    """
    geoms = robot_collision_geoms(model)
    return [(geoms, geoms)]


def _path_joints(model: mujoco.MjModel, b1: int, b2: int) -> list[int]:
    """Joints between bodies ``b1`` and ``b2`` (below their common ancestor): their relative pose depends on these only."""
    def chain(b):
        out = [b]
        while b:
            b = int(model.body_parentid[b])
            out.append(b)
        return out

    c1, c2 = chain(b1), chain(b2)
    common = next(b for b in c1 if b in c2)
    bodies = c1[: c1.index(common)] + c2[: c2.index(common)]
    return [j for b in bodies for j in range(model.body_jntadr[b], model.body_jntadr[b] + model.body_jntnum[b])]


def pairs_kept_apart_by_joint_limits(model: mujoco.MjModel, pairs: list[tuple[int, int]], samples: int = 41) -> set[tuple[int, int]]:
    """Geom pairs that their joint limits alone keep from touching (e.g. the G1's ankle linkage brace and foot).

    For a pair whose bodies are linked by one or two limited hinges, the distance is sampled on a
    ``samples``-point grid over the joint ranges. Between grid points a joint is at most half a
    step ``s_i / 2`` away, which moves a geom point at most ``r_i s_i / 2`` (``r_i``: the geom's
    distance from the joint anchor plus its bounding radius), so the pair is kept apart if the
    sampled minimum exceeds ``sum_i r_i s_i / 2``.
    """
    data, out = mujoco.MjData(model), set()
    by_path: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for a, b in pairs:
        joints = tuple(_path_joints(model, int(model.geom_bodyid[a]), int(model.geom_bodyid[b])))
        hinges = all(int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) and model.jnt_limited[j] for j in joints)
        if 1 <= len(joints) <= 2 and hinges:
            by_path.setdefault(joints, []).append((a, b))
    for joints, group in by_path.items():
        grids = [np.linspace(*model.jnt_range[j], samples) for j in joints]
        data.qpos[:] = model.qpos0
        mujoco.mj_kinematics(model, data)
        lowest = np.full(len(group), np.inf)
        for values in itertools.product(*grids):
            data.qpos[model.jnt_qposadr[list(joints)]] = values
            mujoco.mj_kinematics(model, data)
            lowest = np.minimum(lowest, [mujoco.mj_geomDistance(model, data, a, b, 1.0, None) for a, b in group])
        for (a, b), low in zip(group, lowest):
            reach = [max(np.linalg.norm(data.geom_xpos[g] - data.xanchor[j]) + model.geom_rbound[g] for g in (a, b)) for j in joints]
            margin = sum(r * (g[1] - g[0]) / 2 for r, g in zip(reach, grids))
            if low > margin:
                out.add((a, b))
    return out


# --- QP limits -----------------------------------------------------------------------------------


class SeparationLimit(mink.CollisionAvoidanceLimit):
    r"""Keep geom pairs at least ``d_min`` apart, in displacement units, pushing penetrations out.

    For each pair with signed distance ``d < d_detect`` (``mj_geomDistance``) and unit normal
    ``n`` (from geom 1 to geom 2), the QP step must satisfy

    ``d + n^T (J_2(p_2) - J_1(p_1)) dq >= d - gain (d - d_min)``, i.e.
    ``-n^T (J_2 - J_1) dq <= gain (d - d_min)``,

    where ``p_i`` are the nearest points. mink 1.3.0's parent class bounds the same row by
    ``gain (d - d_min) / dt``, a velocity compared with a displacement: at 30 fps it lets a pair
    close 25x its gap per step, and once ``d <= d_min`` it only forbids getting worse. Here a
    penetrating pair is pushed out at the rate ``gain``. With ``relaxed`` the bound is floored at
    zero (never requires motion): the fallback when the QP is infeasible.

    Pair filtering is MuJoCo's (the model's ``<exclude>`` pairs, same weld, parent-child,
    contype/conaffinity; mink's parent class ignores ``<exclude>``), except that
    a geom of the world, a static or a mocap body is paired with the robot's root body too
    (mink counts the world as the root's parent and would drop pelvis vs object or floor).
    With ``skip_kept_apart`` the pairs that joint limits alone keep apart are dropped too (the
    G1's shin and ankle brace vs its own foot: 28 pairs always within the detection distance).
    Only active rows enter the QP.
    """

    relaxed: bool = False

    def __init__(self, model: mujoco.MjModel, geom_pairs, *, skip_kept_apart: bool = False, **kwargs):
        """``skip_kept_apart``: drop pairs that joint limits alone keep apart (:func:`pairs_kept_apart_by_joint_limits`)."""
        self.skip_kept_apart = skip_kept_apart
        super().__init__(model, geom_pairs, **kwargs)

    def _construct_geom_id_pairs(self, geom_pairs):
        m = self.model
        excluded = {int(sig) for sig in m.exclude_signature}
        out = set()
        for ids_a, ids_b in self._collision_pairs_to_geom_id_pairs(geom_pairs):
            for a, b in itertools.product(ids_a, ids_b):
                ba, bb = int(m.geom_bodyid[a]), int(m.geom_bodyid[b])
                if (min(ba, bb) << 16) + max(ba, bb) in excluded:
                    continue
                wa, wb = m.body_weldid[ba], m.body_weldid[bb]
                if wa == wb or not (m.geom_contype[a] & m.geom_conaffinity[b] or m.geom_contype[b] & m.geom_conaffinity[a]):
                    continue
                if wa != 0 and wb != 0 and (m.body_weldid[m.body_parentid[wa]] == wb or m.body_weldid[m.body_parentid[wb]] == wa):
                    continue
                out.add((min(a, b), max(a, b)))
        if self.skip_kept_apart:
            out -= pairs_kept_apart_by_joint_limits(m, sorted(out))
        return sorted(out)

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> Constraint:
        del dt  # displacement units
        model, data = self.model, configuration.data
        if self.max_num_contacts == 0:
            return Constraint()
        idx = self._broadphase_survivors(data) if self.max_num_contacts >= self.broadphase_min_pairs else range(self.max_num_contacts)
        rows, bounds = [], []
        dmax, dmin = self.collision_detection_distance, self.minimum_distance_from_collisions
        for i in idx:
            g1, g2 = self.geom_id_pairs[i]
            d = mujoco.mj_geomDistance(model, data, g1, g2, dmax, self._fromto)
            if d >= dmax - 1e-12:
                continue
            row = compute_contact_normal_jacobian(model, data, g1, g2, self._fromto, self._normal, self._jac1, self._jac2)
            # For d >= 0 the normal points from geom 1 to geom 2, so row dq is d's rate; for d < 0 fromto is reversed.
            rows.append(-row if d >= 0 else row)
            h = self.gain * (d - dmin)
            bounds.append(max(h, 0.0) if self.relaxed else h)
        if not rows:
            return Constraint()
        return Constraint(G=np.asarray(rows), h=np.asarray(bounds))


class FloorLimit(mink.Limit):
    r"""Keep sphere and capsule geoms above the floor plane ``z = z_f``, in closed form.

    A capsule (centre ``c``, unit axis ``a``, half-length ``l``, radius ``r``; a sphere has
    ``l = 0``) is at signed distance ``min_{s=+-1} (c + s l a)_z - z_f - r`` from the plane, so
    each segment end ``p`` with ``d_p = p_z - z_f - r < d_detect`` gives the row

    ``-e_z^T J(p) dq <= gain (d_p - d_min)``,  ``J(p) = J_v(b) - [p - x_b]_x J_w(b)``

    with ``J_v, J_w`` the translational/rotational Jacobian of the geom's body ``b`` at its
    origin ``x_b`` (one ``mj_jacBody`` per body with an active end). Same distances as
    ``mj_geomDistance`` against the scene's plane, without a narrow phase per pair.
    ``relaxed`` floors the bound at zero, as in :class:`SeparationLimit`.
    """

    relaxed: bool = False

    def __init__(self, model: mujoco.MjModel, geoms: list[int], floor: int, gain: float = 0.85,
                 minimum_distance: float = 0.0, detection_distance: float = 0.05):  # fmt: skip
        level = np.allclose(model.geom_quat[floor], [1.0, 0.0, 0.0, 0.0])
        if int(model.geom_type[floor]) != int(mujoco.mjtGeom.mjGEOM_PLANE) or model.geom_bodyid[floor] != 0 or not level:
            raise ValueError(f"geom {model.geom(floor).name} is not a horizontal world plane")
        kinds = {int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_CAPSULE)}
        odd = [model.geom(g).name for g in geoms if int(model.geom_type[g]) not in kinds]
        if odd:
            raise ValueError(f"FloorLimit handles spheres and capsules only, not {odd}")
        self.model, self.gain = model, gain
        self.floor_z = float(model.geom_pos[floor, 2])
        self.min_distance, self.detection_distance = minimum_distance, detection_distance
        self.geoms = np.asarray(geoms, dtype=int)
        self.radius = model.geom_size[self.geoms, 0]
        capsule = model.geom_type[self.geoms] == int(mujoco.mjtGeom.mjGEOM_CAPSULE)
        self.half = np.where(capsule, model.geom_size[self.geoms, 1], 0.0)
        self.body = model.geom_bodyid[self.geoms]
        self._jacp, self._jacr = np.empty((3, model.nv)), np.empty((3, model.nv))

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> Constraint:
        del dt
        data = configuration.data
        axis = data.geom_xmat[self.geoms, 2::3]  # geom z-axes in world
        centre = data.geom_xpos[self.geoms]
        lowest = centre[:, 2] - self.half * np.abs(axis[:, 2]) - self.radius - self.floor_z
        near = np.flatnonzero(lowest < self.detection_distance)
        if near.size == 0:
            return Constraint()
        a = axis[near] * self.half[near, None]
        ends = np.concatenate([centre[near] + a, centre[near] - a])
        dist = ends[:, 2] - self.floor_z - np.concatenate([self.radius[near], self.radius[near]])
        keep = dist < self.detection_distance
        ends, dist = ends[keep], dist[keep]
        bodies = np.concatenate([self.body[near], self.body[near]])[keep]
        G = np.empty((len(dist), self.model.nv))
        for b in sorted(set(bodies.tolist())):
            mujoco.mj_jacBody(self.model, data, self._jacp, self._jacr, b)
            rows = bodies == b
            r = ends[rows] - data.xpos[b]
            G[rows] = -(self._jacp[2] + r[:, 1:2] * self._jacr[0] - r[:, 0:1] * self._jacr[1])
        h = self.gain * (dist - self.min_distance)
        return Constraint(G=G, h=np.maximum(h, 0.0) if self.relaxed else h)
