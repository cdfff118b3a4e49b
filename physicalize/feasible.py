"""Layer 1 of the teacher, second half: the whole-body reference re-solved by differential IK (mink)
so that its centre of mass follows the dynamically feasible plan (:mod:`physicalize.plan`) while
feet, hands and posture follow the retargeted motion.

Per frame ``t`` (warm-started from frame ``t-1``'s solution, up to :attr:`FeasibleConfig.iterations`
QP steps, one :func:`mink.solve_ik` each, in displacement units ``dt = 1``)::

    min_dq   ||W_c (J_c dq + c(q) - c*_t)||^2                             (ComTask: the plan)
           + sum_{swing feet, hands} ||W_b (J_b dq + e_b(q, X*_{b,t}))||^2 (FrameTask: reference poses)
           + ||W_o (J_o dq + e_o)||^2   pelvis and torso orientation      (FrameTask, orientation only)
           + ||W_p (dq - (q*_t - q))||^2                                  (PostureTask: reference joints)
           + (lambda + mu) ||dq||^2,   mu = lm * sum_i ||W_i e_i||^2
    s.t.     J_f dq = -e_f(q, F_{f,t})        every planted foot f        (equality: its footstep)
             dq_i = 0                          every dof of a free object  (DofFreezingTask)
             q_min <= q + dq <= q_max                                      (ConfigurationLimit)
             q_knee + dq_knee >= min_knee                                  (MinimumJointLimit)
             |q + dq - q_{t-1}| <= v_max / fps                             (per-frame joint speed)

with ``q*_t`` the reference configuration and ``X*_{b,t}`` its link poses (forward kinematics of the
reference), ``c*_t`` the planned CoM (its height is the reference's: the CoM's z cost is lower, so
the IK may lower the CoM where the legs cannot reach). ``lambda`` is a plain LM damping (a step's
joint motion has a cost: a nearly straight leg does not oscillate) and ``mu`` mink's error-scaled
damping (an unreachable CoM target is approached in small steps, not by chattering between far
configurations that miss the footstep constraint in the true kinematics). If the QP with the
footstep equalities is infeasible at a step, that step is taken with the planted feet as
high-cost tasks instead (counted in ``stats``).

Foot targets (:func:`physicalize.footsteps.foot_targets`): stance feet pinned to footsteps over their
planted frames, the reference with a blended footstep offset elsewhere.

:func:`feasible_reference` chains plan -> IK -> :class:`~physicalize.reference.Reference` of the
re-solved motion (the original stance schedule kept, ``com_plan`` set), optionally re-planning on
the re-solved reference (its support polygons are then the footsteps actually kept).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import mink
import mujoco
import numpy as np

from physicalize.footsteps import FootTargets, foot_targets
from physicalize.plan import plan_com
from physicalize.reference import Reference, build_reference
from physicalize.seat import SEAT_LINKS
from pipeline.ik_limits import FrameVelocityLimit, MinimumJointLimit, SeparationLimit
from pipeline.robot import FOOT_BODIES, HAND_BODIES, NQ_ROBOT, NV_ROBOT, joint_velocity_limits, sole_corners
from pipeline.scene import self_collision_groups
from pipeline.terms.layout import CONTROL_FPS


@dataclass(frozen=True)
class FeasibleConfig:
    """Costs (mink units: weight per metre or radian of error) and solver settings of the re-solve."""

    com_cost: tuple[float, float, float] = (300.0, 300.0, 100.0)  # x, y, z: the plan keeps the reference's height
    stance_position_cost: float = 1000.0  # used only when the exact footstep constraint is infeasible
    stance_orientation_cost: float = 300.0
    swing_position_cost: float = 30.0
    swing_orientation_cost: float = 3.0
    hand_position_cost: float = 10.0
    hand_orientation_cost: float = 0.5
    # sitting links on their reference position while the seat supports them (physicalize.seat)
    seat_position_cost: float = 300.0
    pelvis_orientation_cost: float = 3.0
    torso_orientation_cost: float = 3.0
    posture_cost: float = 0.3
    damping: float = 1.0  # per rad^2 of step: keeps a nearly straight leg from oscillating
    # mink's error-scaled damping (mu = lm ||W e||^2): small steps toward unreachable targets
    task_lm_damping: float = 1.0
    iterations: int = 3  # at most this many QP steps per frame ...
    tolerance: float = 2e-4  # ... stopping once every planted foot and the CoM are this close to their targets [m]
    init_iterations: int = 30  # first frame (no speed limit)
    velocity_limit_factor: float = 1.0  # of the rated motor speeds
    exact_stance: bool = True  # stance feet as equality constraints (else high-cost tasks)
    min_knee: float = 0.1  # rad: the re-solved knees bend at least this much (no straight-leg singularity)
    footstep_tolerance: float = 0.02  # m: a stance frame's reference foot this close to its footstep is planted
    # m: a reference swing whose sole stays lower is lifted to this at mid-swing, level (foot_targets; 0: off). omomo:
    # fell at 3.74 s -> valid; 0.05 also lifts SitStand's turning steps (still valid) and the PyMO walk then fell at
    # 1.44 s instead of 2.50 s
    swing_clearance: float = 0.04
    # robot self-collision avoidance (the retargeter's SeparationLimit): a CoM shift must not put a hand into a thigh
    self_collision: bool = True
    self_min_distance: float = 0.005  # m
    object_collision: bool = True  # robot vs object avoidance, with the objects at their reference poses (when given)
    object_min_distance: float = 0.0  # m: touching is fine, penetrating is not
    # m: pairs closer than this enter the QP (0.05: Carry 6.7 s instead of 1.4 s)
    collision_detection_distance: float = 0.02
    collision_gain: float = 0.85


class ReferenceIK:
    """The differential IK of the module docstring on a compiled scene (robot = the model's first tree,
    ``qpos[:NQ_ROBOT]``; any further dofs, free objects, are frozen). Reusable across clips of one model."""

    def __init__(self, model: mujoco.MjModel, config: FeasibleConfig = FeasibleConfig()):
        if model.body(1).name != "pelvis":
            raise ValueError(
                "ReferenceIK: the robot (pelvis) must be the model's first body (mink's ComTask uses body 1)"
            )
        self.model, self.cfg = model, config
        cfg = config
        self.configuration = mink.Configuration(model)
        self.sole_z = np.array([sole_corners(model, b)[0, 2] for b in FOOT_BODIES])
        lm = cfg.task_lm_damping
        self.feet = [
            mink.FrameTask(b, "body", cfg.swing_position_cost, cfg.swing_orientation_cost, lm_damping=lm)
            for b in FOOT_BODIES
        ]
        self.hands = [
            mink.FrameTask(b, "body", cfg.hand_position_cost, cfg.hand_orientation_cost, lm_damping=lm)
            for b in HAND_BODIES
        ]
        self.pelvis = mink.FrameTask("pelvis", "body", 0.0, cfg.pelvis_orientation_cost, lm_damping=lm)
        self.torso = mink.FrameTask("torso_link", "body", 0.0, cfg.torso_orientation_cost, lm_damping=lm)
        self.com = mink.ComTask(cost=cfg.com_cost, lm_damping=lm)
        self.posture = mink.PostureTask(model, cost=cfg.posture_cost)
        self.seat_ids = [model.body(b).id for b in SEAT_LINKS]
        self.seat = [mink.FrameTask(b, "body", cfg.seat_position_cost, 0.0, lm_damping=lm) for b in SEAT_LINKS]
        self.config_limit = mink.ConfigurationLimit(model)
        self.knee_limit = MinimumJointLimit(model, {"left_knee_joint": cfg.min_knee, "right_knee_joint": cfg.min_knee})
        self.velocity_limit = FrameVelocityLimit(
            model, joint_velocity_limits(cfg.velocity_limit_factor), dt=1.0 / CONTROL_FPS
        )
        self.collision, self.object_limit = _collision_limits(model, cfg)
        self._objects_on = False
        self.freeze = [mink.DofFreezingTask(model, list(range(NV_ROBOT, model.nv)))] if model.nv > NV_ROBOT else []
        self._link_ids = [model.body(b).id for b in (*HAND_BODIES, "pelvis", "torso_link")]
        self.stats: dict[str, float] = {}

    def _reference_poses(self, qpos: np.ndarray, bodies: list[int] | None = None) -> np.ndarray:
        """(T, k, 7) wxyz_xyz poses of the ``bodies`` (default: the hands, pelvis and torso) of the reference ``qpos``
        (T, 36)."""
        ids = self._link_ids if bodies is None else bodies
        d = mujoco.MjData(self.model)
        d.qpos[:] = self.model.qpos0
        out = np.zeros((len(qpos), len(ids), 7))
        for t, q in enumerate(qpos):
            d.qpos[:NQ_ROBOT] = q
            mujoco.mj_kinematics(self.model, d)
            out[t, :, :4] = d.xquat[ids]
            out[t, :, 4:] = d.xpos[ids]
        return out

    def _step(self, tasks: list, stance_tasks: list) -> None:
        """One QP step, in place (none if no QP solves, counted in ``stats['failed_steps']``)."""
        cfg, c = self.cfg, self.configuration
        limits = [
            self.config_limit,
            self.knee_limit,
            self.velocity_limit,
            *self.collision,
            *(self.object_limit if self._objects_on else []),
        ]
        try:
            if not cfg.exact_stance:
                raise mink.NoSolutionFound("daqp")
            dq = mink.solve_ik(
                c,
                tasks,
                1.0,
                "daqp",
                damping=cfg.damping,
                limits=limits,
                constraints=[*stance_tasks, *self.freeze] or None,
            )
        except mink.NoSolutionFound:
            for s in stance_tasks:
                s.set_position_cost(cfg.stance_position_cost)
                s.set_orientation_cost(cfg.stance_orientation_cost)
            try:
                dq = mink.solve_ik(
                    c,
                    [*tasks, *stance_tasks],
                    1.0,
                    "daqp",
                    damping=cfg.damping,
                    limits=limits,
                    constraints=self.freeze or None,
                )
            except mink.NoSolutionFound:
                self._failed += 1
                return
            finally:
                for s in stance_tasks:
                    s.set_position_cost(cfg.swing_position_cost)
                    s.set_orientation_cost(cfg.swing_orientation_cost)
            self._relaxed += cfg.exact_stance
        c.integrate_inplace(dq, 1.0)

    def solve(
        self,
        ref: Reference,
        com_plan: np.ndarray,
        objects: np.ndarray | None = None,
        hand_targets: np.ndarray | None = None,
    ) -> np.ndarray:
        """``(T, 36)`` robot ``qpos``: the reference re-solved so its CoM follows ``com_plan`` (T, 3).
        ``objects`` (T, nq - 36): the objects' qpos per frame (their reference track); the robot then
        keeps out of them (``object_collision``), else they stay at ``qpos0`` and are ignored.
        ``hand_targets`` (T, 2, 3): hand body positions replacing the reference's (e.g. hands held on
        an object, :func:`physicalize.grasp.grasp_schedule`'s ``attached``)."""
        cfg, c = self.cfg, self.configuration
        self._objects_on = objects is not None and bool(self.object_limit)
        T = ref.frames
        t0 = time.perf_counter()
        feet = self.foot_targets = foot_targets(ref, self.sole_z, cfg.footstep_tolerance, cfg.swing_clearance)
        links = self._reference_poses(ref.qpos)
        seat = None if ref.seat is None else self._reference_poses(ref.qpos, self.seat_ids)
        if hand_targets is not None:
            links[:, :2, 4:] = hand_targets[:T]
        q = self._start_configuration(ref, objects)
        c.update(q)
        self.velocity_limit.dt = 1.0 / ref.fps
        self._relaxed = self._failed = 0
        out = np.empty((T, NQ_ROBOT))
        target_q = q.copy()
        for t in range(T):
            if objects is not None and t:
                q = c.q.copy()
                q[NQ_ROBOT:] = objects[t]
                c.update(q)
            target_q[:NQ_ROBOT] = ref.qpos[t]
            tasks, stance = self._frame_tasks(ref, t, target_q, com_plan, links, seat, feet)
            if t == 0:
                for _ in range(cfg.init_iterations):
                    self._step_free(tasks, stance)
            else:
                self.velocity_limit.start_frame(c.q)
                for _ in range(cfg.iterations):
                    self._step(tasks, stance)
                    if self._converged(stance):
                        break
            out[t] = c.q[:NQ_ROBOT]
        dt = time.perf_counter() - t0
        self.stats = {
            "frames": T,
            "seconds": dt,
            "ms_per_frame": 1e3 * dt / max(T, 1),
            "relaxed_steps": self._relaxed,
            "failed_steps": self._failed,
        }
        return out

    def _start_configuration(self, ref: Reference, objects: np.ndarray | None) -> np.ndarray:
        """The first frame's configuration (the objects at their first pose), its hinges clipped into their
        limits (the IK starts inside them)."""
        m = self.model
        lo, hi = m.jnt_range[1:, 0], m.jnt_range[1:, 1]
        hinge = np.array(
            [int(m.jnt_type[j]) == int(mujoco.mjtJoint.mjJNT_HINGE) and m.jnt_limited[j] for j in range(1, m.njnt)]
        )
        q = m.qpos0.copy()
        q[:NQ_ROBOT] = ref.qpos[0]
        if objects is not None:
            q[NQ_ROBOT:] = objects[0]
        adr = m.jnt_qposadr[1:][hinge]
        q[adr] = np.clip(q[adr], lo[hinge], hi[hinge])  # the IK starts inside the limits
        return q

    def _frame_tasks(
        self,
        ref: Reference,
        t: int,
        target_q: np.ndarray,
        com_plan: np.ndarray,
        links: np.ndarray,
        seat: np.ndarray | None,
        feet: FootTargets,
    ) -> tuple[list, list]:
        """``(tasks, stance tasks)`` of frame ``t`` with their targets set: the CoM plan, the hands', pelvis'
        and torso's reference poses ``links``, the posture ``target_q``, the sitting links' reference poses
        ``seat`` where the reference sits, the feet's targets (planted ones as stance tasks)."""
        self.posture.set_target(target_q)
        self.com.set_target(com_plan[t])
        for task, pose in zip((*self.hands, self.pelvis, self.torso), links[t]):
            task.set_target(mink.SE3(wxyz_xyz=pose))
        tasks, stance = [self.com, *self.hands, self.pelvis, self.torso, self.posture], []
        # sitting links stay where the reference sits them (the CoM plan leans the body over them instead)
        if seat is not None:
            for i in np.flatnonzero(np.isfinite(ref.seat[t, :, 0])):
                self.seat[i].set_target(mink.SE3(wxyz_xyz=seat[t, i]))
                tasks.append(self.seat[i])
        for k, task in enumerate(self.feet):
            task.set_target(mink.SE3(wxyz_xyz=np.concatenate([feet.quat[t, k], feet.pos[t, k]])))
            (stance if feet.planted[t, k] else tasks).append(task)
        return tasks, stance

    def _converged(self, stance_tasks: list) -> bool:
        """The CoM and every planted foot within ``tolerance`` of their targets."""
        c, tol = self.configuration, self.cfg.tolerance
        return bool(
            np.linalg.norm(self.com.compute_error(c)) < tol
            and all(np.linalg.norm(s.compute_error(c)[:3]) < tol for s in stance_tasks)
        )

    def _step_free(self, tasks: list, stance_tasks: list) -> None:
        """A first-frame step: no speed limit."""
        saved = self.velocity_limit.dt
        self.velocity_limit.dt = 1e6
        self.velocity_limit.start_frame(self.configuration.q)
        try:
            self._step(tasks, stance_tasks)
        finally:
            self.velocity_limit.dt = saved


def _collision_limits(model: mujoco.MjModel, cfg: FeasibleConfig) -> tuple[list, list]:
    """``(self-collision limits, robot-object limits)``: :class:`~pipeline.ik_limits.SeparationLimit` s as
    configured (each an empty list when off; the second also without objects)."""
    groups = self_collision_groups(model)
    collision = (
        [
            SeparationLimit(
                model,
                groups,
                skip_kept_apart=True,
                gain=cfg.collision_gain,
                minimum_distance_from_collisions=cfg.self_min_distance,
                collision_detection_distance=cfg.collision_detection_distance,
            )
        ]
        if cfg.self_collision
        else []
    )
    robot_root = model.body("pelvis").id
    object_geoms = [
        g
        for g in range(model.ngeom)
        if model.geom_contype[g] and model.geom_bodyid[g] and model.body_rootid[model.geom_bodyid[g]] != robot_root
    ]
    object_limit = (
        [
            SeparationLimit(
                model,
                [(groups[0][0], object_geoms)],
                gain=cfg.collision_gain,
                minimum_distance_from_collisions=cfg.object_min_distance,
                collision_detection_distance=cfg.collision_detection_distance,
            )
        ]
        if cfg.object_collision and object_geoms
        else []
    )
    return collision, object_limit


def resolve_reference(
    model: mujoco.MjModel, ref: Reference, com_plan: np.ndarray, config: FeasibleConfig = FeasibleConfig()
) -> np.ndarray:
    """``(T, 36)`` qpos: ``ref`` re-solved by :class:`ReferenceIK` so its CoM follows ``com_plan``."""
    return ReferenceIK(model, config).solve(ref, com_plan)


def feasible_reference(
    model: mujoco.MjModel,
    ref: Reference,
    plan_fn: Callable = plan_com,
    *,
    passes: int = 1,
    replan: bool = False,
    config: FeasibleConfig = FeasibleConfig(),
    stats: dict | None = None,
    objects: np.ndarray | None = None,
    hand_targets: np.ndarray | None = None,
) -> Reference:
    """The reference to track: plan the CoM on ``ref`` (``plan_fn(ref)[0]``), re-solve the whole body
    to it, and build the :class:`Reference` of the re-solved motion with ``ref``'s stance schedule and
    ``com_plan`` set. With ``passes`` > 1, each further pass plans on the previous pass's re-solved
    reference (its support polygons are the footsteps the IK kept) and re-solves ``ref``'s motion to
    that plan; ``replan`` plans once more on the final re-solved reference without re-solving (then
    ``com_plan`` and the re-solved CoM differ). ``stats`` (if given) gets the last IK's figures, the
    IK time of all passes, the CoM error of the last re-solve and ``plan``: the plan tracked
    (``plan_fn``'s whole output, e.g. with the ZMP series for the plots). ``objects`` (T, nq - 36): the
    objects' qpos per frame, which the re-solved body keeps out of (:meth:`ReferenceIK.solve`);
    ``hand_targets`` (T, 2, 3): hand body positions replacing the reference's."""
    if passes < 1:
        raise ValueError("feasible_reference: passes must be >= 1")
    ik = ReferenceIK(model, config)
    planned_on, seconds = ref, 0.0
    for _ in range(passes):
        planned = plan_fn(planned_on)
        com_plan = planned[0]
        out = build_reference(model, ik.solve(ref, com_plan, objects, hand_targets), ref.fps)
        out.stance = ref.stance.copy()
        planned_on, seconds = out, seconds + ik.stats["seconds"]
    com_err = float(np.linalg.norm(out.com - com_plan, axis=1).max())
    if replan:
        planned = plan_fn(out)
    out.com_plan = planned[0]
    if stats is not None:
        stats.update(ik.stats, ik_seconds=seconds, com_err_max_m=com_err, plan=planned)
    return out
