"""The mink QP limits the differential IKs add to mink's own (retarget's and physicalize's).

* :class:`FrameVelocityLimit` -- joint and root speed over a whole frame, however many QP steps;
* :class:`SeparationLimit` -- geom pairs kept ``d_min`` apart in displacement units, pushing
  penetrations out, with MuJoCo's own pair filtering;
* :class:`FloorLimit` -- spheres and capsules above the floor plane, in closed form;
* :class:`MinimumJointLimit` -- a lower bound inside the range of a few hinge joints (physicalize's knees);
* :func:`pairs_kept_apart_by_joint_limits` -- the self-collision pairs no joint motion can bring
  into contact (dropped from :class:`SeparationLimit`).
"""

from __future__ import annotations

import hashlib
import itertools

import mink
import mujoco
import numpy as np
from mink.limits.collision_avoidance_limit import compute_contact_normal_jacobian
from mink.limits.limit import Constraint


class FrameVelocityLimit(mink.VelocityLimit):
    r"""Joint and root speed limit over a whole frame, however many QP steps it takes.

    With ``q_0`` the configuration at the frame's start (:meth:`start_frame`) and ``dt`` the
    frame period, each step ``dq`` at ``q`` satisfies, for every limited hinge DoF ``i``,

    ``-v_i dt - (q_i - q_{0,i}) <= dq_i <= v_i dt - (q_i - q_{0,i})``

    so ``|q_t - q_{t-1}| <= v dt``; with ``root_speed`` the same holds per axis for the free
    joint's position (its linear velocity DoFs integrate into its position unrotated), so the
    root cannot jump to satisfy what speed-limited joints could not (unlimited, a retargeted BVH
    walk had 15 cm root jumps in one frame when a foot pin engaged). (mink's
    :class:`~mink.VelocityLimit` bounds each step by ``v dt``, allowing ``n v dt`` in ``n`` steps.)
    Bounds are floored at zero so ``dq = 0`` stays feasible.
    """

    def __init__(self, model: mujoco.MjModel, velocities: dict[str, float], dt: float, root_speed: float | None = None):
        super().__init__(model, velocities=velocities)
        self.dt = float(dt)
        idx, qadr, limit = list(self.indices), list(model.jnt_qposadr[model.dof_jntid[self.indices]]), list(self.limit)
        if root_speed is not None:
            free = [
                j
                for j in range(model.njnt)
                if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE and model.jnt_bodyid[j] == 1
            ]
            if not free:
                raise ValueError("FrameVelocityLimit: root_speed given but the model's first body has no free joint")
            d0, a0 = model.jnt_dofadr[free[0]], model.jnt_qposadr[free[0]]
            idx, qadr, limit = [d0, d0 + 1, d0 + 2, *idx], [a0, a0 + 1, a0 + 2, *qadr], [root_speed] * 3 + limit
        self._qadr, self._limit = np.array(qadr), np.array(limit, dtype=float)
        P = np.zeros((len(idx), model.nv))
        P[np.arange(len(idx)), idx] = 1.0
        self._G = np.vstack([P, -P])
        self._anchor = np.zeros(len(idx))

    def start_frame(self, q: np.ndarray) -> None:
        self._anchor = q[self._qadr].copy()

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> Constraint:
        del dt
        moved = configuration.q[self._qadr] - self._anchor
        budget = self._limit * self.dt
        return Constraint(G=self._G, h=np.maximum(np.concatenate([budget - moved, budget + moved]), 0.0))


def _path_joints(model: mujoco.MjModel, b1: int, b2: int) -> list[int]:
    """Joints between bodies ``b1`` and ``b2`` (below their common ancestor): their relative pose depends on these
    only."""

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


_KEPT_APART: dict[
    str, frozenset[tuple[int, int]]
] = {}  # pairs_kept_apart_by_joint_limits's cache, keyed by the model arrays below
_TREE_FIELDS = (
    "geom_type",
    "geom_size",
    "geom_pos",
    "geom_quat",
    "geom_bodyid",
    "geom_rbound",
    "body_parentid",
    "body_pos",
    "body_quat",
    "body_jntadr",
    "body_jntnum",
    "jnt_type",
    "jnt_range",
    "jnt_limited",
    "jnt_pos",
    "jnt_axis",
    "jnt_qposadr",
    "qpos0",
)


def pairs_kept_apart_by_joint_limits(
    model: mujoco.MjModel, pairs: list[tuple[int, int]], samples: int = 41
) -> set[tuple[int, int]]:
    """Geom pairs that their joint limits alone keep from touching (e.g. the G1's ankle linkage brace and foot).
    Cached per process by the pairs and the model's kinematic tree and geoms (each clip compiles its own
    scene, with the same robot: the sampling took ~0.25 s of every physicalized clip).

    For a pair whose bodies are linked by one or two limited hinges, the distance is sampled on a
    ``samples``-point grid over the joint ranges. Between grid points a joint is at most half a
    step ``s_i / 2`` away, which moves a geom point at most ``r_i s_i / 2`` (``r_i``: the geom's
    distance from the joint anchor plus its bounding radius), so the pair is kept apart if the
    sampled minimum exceeds ``sum_i r_i s_i / 2``.
    """
    h = hashlib.sha256(repr((sorted(pairs), samples)).encode())
    for field in _TREE_FIELDS:
        h.update(np.ascontiguousarray(getattr(model, field)).tobytes())
    key = h.hexdigest()
    if key not in _KEPT_APART:
        _KEPT_APART[key] = frozenset(_kept_apart(model, pairs, samples))
    return set(_KEPT_APART[key])


def _kept_apart(model: mujoco.MjModel, pairs: list[tuple[int, int]], samples: int) -> set[tuple[int, int]]:
    data, out = mujoco.MjData(model), set()
    by_path: dict[tuple[int, ...], list[tuple[int, int]]] = {}
    for a, b in pairs:
        joints = tuple(_path_joints(model, int(model.geom_bodyid[a]), int(model.geom_bodyid[b])))
        hinges = all(
            int(model.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) and model.jnt_limited[j] for j in joints
        )
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
            reach = [
                max(np.linalg.norm(data.geom_xpos[g] - data.xanchor[j]) + model.geom_rbound[g] for g in (a, b))
                for j in joints
            ]
            margin = sum(r * (g[1] - g[0]) / 2 for r, g in zip(reach, grids))
            if low > margin:
                out.add((a, b))
    return out


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
        """``skip_kept_apart``: drop pairs that joint limits alone keep apart
        (:func:`pairs_kept_apart_by_joint_limits`)."""
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
                if wa == wb or not (
                    m.geom_contype[a] & m.geom_conaffinity[b] or m.geom_contype[b] & m.geom_conaffinity[a]
                ):
                    continue
                if (
                    wa != 0
                    and wb != 0
                    and (m.body_weldid[m.body_parentid[wa]] == wb or m.body_weldid[m.body_parentid[wb]] == wa)
                ):
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
        idx = (
            self._broadphase_survivors(data)
            if self.max_num_contacts >= self.broadphase_min_pairs
            else range(self.max_num_contacts)
        )
        rows, bounds = [], []
        dmax, dmin = self.collision_detection_distance, self.minimum_distance_from_collisions
        for i in idx:
            g1, g2 = self.geom_id_pairs[i]
            d = mujoco.mj_geomDistance(model, data, g1, g2, dmax, self._fromto)
            if d >= dmax - 1e-12:
                continue
            row = compute_contact_normal_jacobian(
                model, data, g1, g2, self._fromto, self._normal, self._jac1, self._jac2
            )
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

    def __init__(
        self,
        model: mujoco.MjModel,
        geoms: list[int],
        floor: int,
        gain: float = 0.85,
        minimum_distance: float = 0.0,
        detection_distance: float = 0.05,
    ):
        level = np.allclose(model.geom_quat[floor], [1.0, 0.0, 0.0, 0.0])
        if (
            int(model.geom_type[floor]) != int(mujoco.mjtGeom.mjGEOM_PLANE)
            or model.geom_bodyid[floor] != 0
            or not level
        ):
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


class MinimumJointLimit(mink.Limit):
    r"""``q_i + dq_i >= q_min,i`` for a few hinge joints (a lower bound inside the joint range), as
    ``-dq_i <= max(q_i - q_min,i, 0)`` so ``dq = 0`` stays feasible from a start below the bound.

    Used on the knees: a straight leg is a kinematic singularity where the linearised footstep
    constraint is met by large, oscillating steps that miss it by centimetres in the true kinematics.
    """

    def __init__(self, model: mujoco.MjModel, minimum: dict[str, float]):
        joints = [model.joint(name).id for name in minimum]
        self._qadr = model.jnt_qposadr[joints]
        self._lower = np.array(list(minimum.values()))
        self._G = np.zeros((len(joints), model.nv))
        self._G[np.arange(len(joints)), model.jnt_dofadr[joints]] = -1.0

    def compute_qp_inequalities(self, configuration: mink.Configuration, dt: float) -> Constraint:
        del dt
        return Constraint(G=self._G, h=np.maximum(configuration.q[self._qadr] - self._lower, 0.0))
