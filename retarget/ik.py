"""Differential IK (mink + daqp) from :class:`~retarget.targets.IKTargets` to G1 ``qpos``.

Per frame ``t`` the retargeter sets the targets and, warm-started from frame ``t-1``'s
solution, takes up to ``IKConfig.iterations`` QP steps (one :func:`mink.solve_ik` each, in
displacement units: ``dt = 1``), stopping after a step below ``IKConfig.tolerance``:

``min_dq  sum_b ||W_b (J_b dq + e_b)||^2 + ||W_p (dq - (q* - q))||^2 + (lambda + mu) ||dq||^2``

over the frame tasks ``b`` (one per target body, costs from the target weights), a posture task
``p`` (default pose, low cost), LM damping ``lambda`` and mink's error-scaled task damping
``mu = task_lm_damping * sum_b ||W_b e_b||^2`` (it stops the chatter of a limb pressed against
an object by an unreachable target), subject to

* joint limits (:class:`mink.ConfigurationLimit`);
* a per-frame joint and root speed limit (:class:`~pipeline.ik_limits.FrameVelocityLimit`):
  ``|q_t - q_{t-1}| <= v_max dt`` (root position: ``IKConfig.root_speed_limit`` per axis);
* collision avoidance with the scene's own geoms: robot vs the floor plane
  (:class:`~pipeline.ik_limits.FloorLimit`), robot vs every object geom and robot self-collision
  (:class:`~pipeline.ik_limits.SeparationLimit`, the pairs MuJoCo's physics checks).

Objects are not optimised: :func:`~retarget.ik_config.ik_model` turns each free object into a
mocap body (same geoms), moved every frame to its pose in ``objects_pose`` (an object missing
there stays at its scene pose). The QP has the robot's 35 DoFs only.

Feet: while ``IKTargets.foot_contact`` is set, the foot's ``ankle_roll_link`` is pinned by a
high-cost frame task (replacing its target) to ``(x0, y0, h_sole)`` with zero roll and pitch and
heading ``yaw0``, where ``(x0, y0, yaw0)`` are the foot target's at contact onset and ``h_sole``
is derived from the foot collision capsules (:func:`~retarget.ik_config.sole_offset`); the pin's
orientation turns there from the foot's at onset over ``IKConfig.pin_ramp_s``.

Objects: while ``IKTargets.object_contact`` flags a link (the human touches an object with a
joint mapped to it), a :class:`~retarget.contact.ContactTask` drives the link's distance to the
objects to ``IKConfig.contact_gap``, faded in and out over ``contact_ramp_s``.

Start-up: frame 0 starts from the default joint pose with the root at the target pelvis
position and heading (lifted until no geom is below the floor), and runs up to
``init_iterations`` QP steps with no speed limit.
"""

from __future__ import annotations

import math
import time

import mink
import mujoco
import numpy as np

from pipeline.errors import InputError, first_bad_frame
from pipeline.ik_limits import FloorLimit, FrameVelocityLimit, SeparationLimit
from pipeline.robot import FOOT_BODIES, default_qpos, joint_velocity_limits
from pipeline.rotations import yaw_quat
from pipeline.scene import Scene, object_collision_geoms, robot_collision_geoms, self_collision_groups
from retarget.contact import ContactTask, FootClearance, contact_ramp, hold_resting
from retarget.ik_config import IKConfig, ik_model, sole_offset
from retarget.targets import IKTargets


def _yaw_of(quat_wxyz: np.ndarray) -> float:
    """Heading of a frame's x-axis: ``atan2(R[1,0], R[0,0])``."""
    w, x, y, z = quat_wxyz
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


class G1Retargeter:
    """Differential IK of the G1 in a :class:`~pipeline.scene.Scene` (robot + objects + floor)."""

    def __init__(self, scene: Scene, config: IKConfig | None = None):
        self.scene = scene
        self.config = cfg = config or IKConfig()
        self.model = m = ik_model(scene)
        self.q_default = default_qpos(scene.profile)
        self.configuration = mink.Configuration(m, self.q_default)
        self.sole = {b: sole_offset(m, b) for b in FOOT_BODIES}
        self.posture = mink.PostureTask(m, cost=cfg.posture_cost)
        self.posture.set_target(self.q_default)
        self.pin_tasks = {
            b: mink.FrameTask(b, "body", cfg.foot_pin_position_cost, cfg.foot_pin_orientation_cost) for b in FOOT_BODIES
        }
        self.config_limit = mink.ConfigurationLimit(m, gain=cfg.configuration_limit_gain)
        self.velocity_limit = FrameVelocityLimit(
            m, joint_velocity_limits(cfg.velocity_limit_factor), dt=1.0 / 30.0, root_speed=cfg.root_speed_limit
        )
        self._robot_geoms = robot_collision_geoms(m)
        self._object_geoms = object_collision_geoms(m, scene)
        self.collision_limits = self._collision_limits()
        self._mocap = {o.name: int(m.body_mocapid[m.body(o.name).id]) for o in scene.objects if not o.fixed}
        self.stats: dict[str, float] = {}
        self._relaxed_steps = self._failed_steps = 0

    # --- public API -------------------------------------------------------------------------------

    def retarget(
        self, targets: IKTargets, objects_pose: dict[str, np.ndarray] | None = None, source: str = "<memory>"
    ) -> np.ndarray:
        """``(T, 36)`` G1 ``qpos`` following ``targets``; objects at ``objects_pose[name]`` ``(T, 7)``.

        Raises :class:`~pipeline.errors.InputError` (naming ``source`` and the frame) on non-finite
        targets or object poses, or if the IK diverges.
        """
        T, cfg = targets.frames, self.config
        objects_pose = self._check_inputs(targets, objects_pose or {}, source)
        tasks = self._body_tasks(targets)
        contact_task, contact_w = self._contact_task(targets)
        contact = targets.foot_contact if targets.foot_contact is not None else np.zeros((T, 2), bool)
        clearance = (
            FootClearance(
                self.model,
                FOOT_BODIES,
                tuple(objects_pose),
                margin=cfg.clearance_margin,
                step=cfg.clearance_speed / targets.fps,
            )
            if objects_pose
            else None
        )
        self._objects_in, self.objects_pose = objects_pose, {name: pose.copy() for name, pose in objects_pose.items()}
        feet_idx = [targets.body_names.index(b) if b in targets.body_names else None for b in FOOT_BODIES]
        self.velocity_limit.dt = 1.0 / targets.fps
        pins: list[np.ndarray | None] = [None, None]
        norm = np.linalg.norm(targets.quat, axis=-1, keepdims=True)
        unit = np.where(
            norm > 1e-9, targets.quat / np.maximum(norm, 1e-9), np.array([1.0, 0.0, 0.0, 0.0])
        )  # zero rows: rot_weight 0
        poses = np.concatenate([unit, targets.pos], axis=-1)
        out = np.empty((T, self.model.nq))
        solves, t0 = 0, time.perf_counter()
        self._relaxed_steps = self._failed_steps = 0
        for t in range(T):
            self._place_objects(t, clearance)
            if t == 0:
                self.configuration.update(self._initial_qpos(targets))
            else:
                self.configuration.update()
                if clearance is not None and contact[t].any() and clearance.update(self.configuration.data, contact[t]):
                    self._place_objects(t, clearance)
                    self.configuration.update()
            active = self._frame_tasks(targets, t, tasks, poses[t], contact[t], pins, feet_idx)
            if contact_task is not None and contact_w[t].any():
                contact_task.set_weights(contact_w[t])
                active.append(contact_task)
            if t == 0:
                limits = [self.config_limit, *self.collision_limits]
                solves += self._solve_frame(active, limits, cfg.init_iterations, cfg.init_tolerance)
            else:
                self.velocity_limit.start_frame(self.configuration.q)
                limits = [self.config_limit, self.velocity_limit, *self.collision_limits]
                solves += self._solve_frame(active, limits, cfg.iterations, cfg.tolerance)
            q = self.configuration.q
            if not np.isfinite(q).all():
                raise InputError(source, "qpos", "IK diverged (non-finite joint positions)", frame=t)
            out[t] = q
        if clearance is not None:  # a resting object does not slide: each rest takes its final offset
            for name in self.objects_pose:
                self.objects_pose[name] = hold_resting(objects_pose[name], self.objects_pose[name], targets.fps)
        dt = time.perf_counter() - t0
        self.stats = {
            "frames": T,
            "qp_solves": solves,
            "relaxed_steps": self._relaxed_steps,
            "failed_steps": self._failed_steps,
            "seconds": dt,
            "frames_per_s": T / dt if dt > 0 else float("inf"),
        }
        return out

    # --- internals ----------------------------------------------------------------------------------

    def _place_objects(self, t: int, clearance: FootClearance | None) -> None:
        """Move the mocap objects to frame ``t``'s pose (plus the clearance offset) and record it in
        ``objects_pose``."""
        for name, pose in self.objects_pose.items():  # every name is a free (mocap) object: _check_inputs
            if clearance is not None:
                pose[t, :3] = self._objects_in[name][t, :3] + clearance.offset[name]
            self.configuration.data.mocap_pos[self._mocap[name]] = pose[t, :3]
            self.configuration.data.mocap_quat[self._mocap[name]] = pose[t, 3:]

    def _frame_tasks(
        self,
        targets: IKTargets,
        t: int,
        tasks: list,
        poses: np.ndarray,
        contact: np.ndarray,
        pins: list,
        feet_idx: list,
    ) -> list:
        """Frame ``t``'s tasks: body targets, a pin replacing the target of each foot in contact, the posture.

        ``pins`` (per foot, updated in place) holds the contact's onset frame, the pinned position with
        the foot's orientation there, and the pinned pose; the pin's orientation turns from the first
        to the second over ``pin_ramp_s`` (a heel strike's pitched foot levelled in one frame made
        the root jump 15 cm).
        """
        for k, task in enumerate(tasks):
            task.set_target(mink.SE3(wxyz_xyz=poses[k]))
        active = list(tasks)
        for s, body in enumerate(FOOT_BODIES):
            if not contact[s]:
                pins[s] = None
                continue
            if pins[s] is None:
                pin = self._pin_pose(targets, t, body, feet_idx[s])
                onset = self.configuration.get_transform_frame_to_world(body, "body").wxyz_xyz
                pins[s] = (t, mink.SE3(wxyz_xyz=np.concatenate([onset[:4], pin[4:]])), mink.SE3(wxyz_xyz=pin))
            t0, onset, pin = pins[s]
            ramp = max(int(round(self.config.pin_ramp_s * targets.fps)), 1)
            self.pin_tasks[body].set_target(onset.interpolate(pin, min((t - t0 + 1) / ramp, 1.0)))
            if feet_idx[s] is not None:
                active.remove(tasks[feet_idx[s]])
            active.append(self.pin_tasks[body])
        active.append(self.posture)
        return active

    def _contact_task(self, targets: IKTargets) -> tuple[ContactTask | None, np.ndarray | None]:
        """The object-contact task and its ``(T, L)`` weights (None when nothing is flagged or no object has geoms)."""
        flags = targets.object_contact
        if flags is None or not flags.any() or not self._object_geoms:
            return None, None
        cfg = self.config
        task = ContactTask(
            self.model,
            targets.contact_links,
            self._object_geoms,
            cost=cfg.contact_cost,
            gap=cfg.contact_gap,
            reach=cfg.contact_reach,
        )
        return task, contact_ramp(flags, int(round(cfg.contact_ramp_s * targets.fps)))

    def _collision_limits(self) -> list[FloorLimit | SeparationLimit]:
        """Robot vs floor (closed form for spheres/capsules), robot vs objects, robot vs robot."""
        m, cfg, robot = self.model, self.config, self._robot_geoms
        kw = dict(gain=cfg.collision_gain, collision_detection_distance=cfg.detection_distance)
        floor = m.geom("floor").id
        round_kinds = (int(mujoco.mjtGeom.mjGEOM_SPHERE), int(mujoco.mjtGeom.mjGEOM_CAPSULE))
        round_ = [g for g in robot if int(m.geom_type[g]) in round_kinds]
        limits: list[FloorLimit | SeparationLimit] = [
            FloorLimit(m, round_, floor, cfg.collision_gain, cfg.floor_min_distance, cfg.detection_distance)
        ]
        others = [g for g in robot if g not in round_]
        if others:
            limits.append(
                SeparationLimit(m, [(others, [floor])], minimum_distance_from_collisions=cfg.floor_min_distance, **kw)
            )
        objects = self._object_geoms
        if objects:
            limits.append(
                SeparationLimit(m, [(robot, objects)], minimum_distance_from_collisions=cfg.object_min_distance, **kw)
            )
        pairs = self_collision_groups(m)
        limits.append(
            SeparationLimit(
                m, pairs, skip_kept_apart=True, minimum_distance_from_collisions=cfg.self_min_distance, **kw
            )
        )
        return limits

    def _check_inputs(self, targets: IKTargets, objects_pose: dict, source: str) -> dict[str, np.ndarray]:
        for field, a in (("IK target pos", targets.pos), ("IK target quat", targets.quat)):
            bad = ~np.isfinite(a)
            if bad.any():
                raise InputError(source, field, "is NaN or infinite", frame=first_bad_frame(bad))
        zero = (np.linalg.norm(targets.quat, axis=-1) < 1e-9) & (targets.rot_weight > 0)
        if zero.any():
            raise InputError(
                source, "IK target quat", "zero quaternion for a body with rot_weight > 0", frame=first_bad_frame(zero)
            )
        unknown = sorted(set(targets.body_names) - {self.model.body(i).name for i in range(self.model.nbody)})
        if unknown:
            raise ValueError(f"IK targets name bodies {unknown} that the G1 model does not have")
        out = {}
        for name, pose in objects_pose.items():
            if name not in self._mocap:
                raise ValueError(f"objects_pose names {name!r}; the scene's free objects are {sorted(self._mocap)}")
            pose = np.asarray(pose, dtype=np.float64)
            if pose.shape != (targets.frames, 7):
                raise InputError(source, f"object {name} pose", f"shape {pose.shape} != ({targets.frames}, 7)")
            bad = ~np.isfinite(pose)
            if bad.any():
                raise InputError(source, f"object {name} pose", "is NaN or infinite", frame=first_bad_frame(bad))
            out[name] = pose
        return out

    def _body_tasks(self, targets: IKTargets) -> list[mink.FrameTask]:
        lm = self.config.task_lm_damping
        return [
            mink.FrameTask(b, "body", float(targets.pos_weight[k]), float(targets.rot_weight[k]), lm_damping=lm)
            for k, b in enumerate(targets.body_names)
        ]

    def _initial_qpos(self, targets: IKTargets) -> np.ndarray:
        """Default joints; root at the target pelvis position and heading (hips' or shoulders' if no pelvis
        orientation).

        The root is then raised until no robot geom is below the floor.
        """
        q = self.q_default.copy()
        names = targets.body_names
        if "pelvis" in names:
            q[:3] = targets.pos[0, names.index("pelvis")]
        else:
            q[:2] = targets.pos[0, :, :2].mean(axis=0)
        yaw = 0.0
        if "pelvis" in names and targets.rot_weight[names.index("pelvis")] > 0:
            yaw = _yaw_of(targets.quat[0, names.index("pelvis")])
        else:
            for left, right in (
                ("left_hip_pitch_link", "right_hip_pitch_link"),
                ("left_shoulder_pitch_link", "right_shoulder_pitch_link"),
            ):
                if left in names and right in names:
                    lateral = targets.pos[0, names.index(left)] - targets.pos[0, names.index(right)]
                    yaw = math.atan2(lateral[1], lateral[0]) - math.pi / 2  # x forward = y lateral turned by -90 deg
                    break
        q[3:7] = yaw_quat(yaw)
        # Lift the root so no robot geom starts below the floor (a low pelvis target with straight default legs).
        self.configuration.update(q)
        data, floor = self.configuration.data, self.model.geom("floor").id
        low = min(mujoco.mj_geomDistance(self.model, data, floor, g, 1.0, None) for g in self._robot_geoms)
        q[2] += max(0.0, self.config.floor_min_distance - low)
        return q

    def _pin_pose(self, targets: IKTargets, t: int, body: str, k: int | None) -> np.ndarray:
        """Pinned pose ``wxyz_xyz`` of a foot at contact onset: onset xy and heading, sole on the floor, level."""
        current = self.configuration.get_transform_frame_to_world(body, "body").wxyz_xyz
        xy, yaw = current[4:6], _yaw_of(current[:4])
        if self.config.pin_anchor == "target" and k is not None:
            xy = targets.pos[t, k, :2]
            if targets.rot_weight[k] > 0:
                yaw = _yaw_of(targets.quat[t, k])
        z = self.sole[body] + self.config.floor_min_distance
        return np.concatenate([yaw_quat(yaw), [xy[0], xy[1], z]])

    def _solve_frame(self, tasks: list, limits: list, max_iterations: int, tolerance: float) -> int:
        """Up to ``max_iterations`` QP steps; stops after a step that moves every DoF less than ``tolerance``."""
        for i in range(max_iterations):
            dq = self._step(tasks, limits)
            self.configuration.integrate_inplace(dq, 1.0)
            if np.abs(dq).max() < tolerance:
                return i + 1
        return max_iterations

    def _step(self, tasks: list, limits: list) -> np.ndarray:
        """One QP step ``dq`` (``limits=`` by keyword: mink 1.3.0 takes a positional 6th argument as
        ``safety_break``)."""
        cfg = self.config
        try:
            return mink.solve_ik(
                self.configuration, tasks, 1.0, cfg.solver, damping=cfg.damping, safety_break=False, limits=limits
            )
        except mink.NoSolutionFound:
            pass  # collision push-out may conflict with the speed limit: retry never requiring motion
        for lim in self.collision_limits:
            lim.relaxed = True
        try:
            self._relaxed_steps += 1
            return mink.solve_ik(
                self.configuration, tasks, 1.0, cfg.solver, damping=cfg.damping, safety_break=False, limits=limits
            )
        except mink.NoSolutionFound:
            self._failed_steps += 1  # dq = 0 is feasible for the relaxed limits; the solver still failed: stay put
            return np.zeros(self.model.nv)
        finally:
            for lim in self.collision_limits:
                lim.relaxed = False


def solve_sequence(
    targets: IKTargets,
    scene: Scene,
    objects_pose: dict[str, np.ndarray] | None = None,
    config: IKConfig | None = None,
    source: str = "<memory>",
) -> np.ndarray:
    """``(T, 36)`` G1 ``qpos`` for ``targets`` in ``scene`` (see :class:`G1Retargeter`)."""
    return G1Retargeter(scene, config).retarget(targets, objects_pose, source=source)
