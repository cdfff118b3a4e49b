"""The ``kinematic`` teacher: no physics, the retargeted clip as it is, stored in the physicalized layout.

This is the data of the paper's "Ours - Syn." ablation (Table 2: "replaces teacher-generated physically valid
trajectories with raw retargeted mocap data"), so that the same features stage and training command run on it
(``make corpus CORPUS=corpus-syn TEACHER=kinematic``). Per control frame ``t``:

* ``qpos``: the retargeted robot pose and the objects' reference poses (nothing simulated);
* ``qvel``: central differences of the poses (:func:`pipeline.kinematics.qvel_from_qpos`; the free joints'
  angular velocity in the body frame, as MuJoCo's);
* ``action``: the next frame's joint positions (the targets that would move the joints along the clip;
  the last frame keeps its own), ``torque`` zero (no actuator ran);
* the physics figures are measured on the poses as they are, with the same functions and bars as a simulated
  clip (:func:`physicalize.validate.validate`): the deepest contact penetration (``mj_forward``), foot sliding under
  the floor forces ``mj_forward`` finds, joint limits. The figures that compare a simulation with its reference
  (tracking errors, falls, object loss) are 0 by construction and left out, and so is the root residual: measured
  with the clip's own accelerations (``mj_inverse``) it is the robot's whole weight, ~325 N at the median frame of
  the synthetic corpus, because MuJoCo's soft contacts give almost no force at the 1e-5 m penetrations of a
  kinematic pose, so it says nothing about the motion.

Every clip is kept: ``valid`` is True (raw mocap is the ablation's data, whatever its physics), and the verdict
of the physics bars is ``physics_valid`` with its ``physics_reason``, so the dataset says how far from
physical its clips are.
"""

from __future__ import annotations

import time
from dataclasses import replace

import mujoco
import numpy as np

from physicalize.balance import com_series
from physicalize.problem import object_qpos, scene_for
from physicalize.reference import build_reference
from physicalize.rollout import Rollout
from physicalize.stepping import foot_floor_forces
from physicalize.validate import validate
from pipeline.clip import RobotClip
from pipeline.contacts import ContactSets
from pipeline.kinematics import qvel_from_qpos
from pipeline.robot import FREE_NQ, JOINTS_QPOS, NUM_JOINTS


def kinematic_rollout(clip: RobotClip, profile: str) -> tuple[object, Rollout, dict[str, np.ndarray]]:
    """``(scene, rollout, object tracks {name: (T, 7)})``: the clip's poses as a :class:`Rollout` (module docstring);
    the penetration and the feet's floor forces are what ``mj_forward`` finds at each pose."""
    t0 = time.perf_counter()
    scene = scene_for(clip, profile)
    m, T = scene.model, clip.frames
    qpos = np.concatenate([clip.qpos, object_qpos(scene, clip, T)], axis=1)
    qvel = [qvel_from_qpos(clip.qpos, clip.fps)]
    for adr in scene.object_qpos_adr.values():
        qvel.append(qvel_from_qpos(qpos[:, adr : adr + FREE_NQ], clip.fps))
    qvel = np.concatenate(qvel, axis=1)
    joints = clip.qpos[:, JOINTS_QPOS]
    action = np.concatenate([joints[1:], joints[-1:]], axis=0)
    d, robot = mujoco.MjData(m), ContactSets.of(m)
    penetration, foot_force = np.zeros(T), np.zeros((T, 2))
    for t in range(T):
        d.qpos[:], d.qvel[:] = qpos[t], qvel[t]
        mujoco.mj_forward(m, d)
        if d.ncon:
            penetration[t] = max(float(-d.contact.dist[: d.ncon].min()), 0.0)
        foot_force[t] = foot_floor_forces(robot, d)
    contact = clip.contacts if clip.contacts is not None else np.zeros((T, len(clip.contact_links)), bool)
    roll = Rollout(
        qpos=qpos,
        qvel=qvel,
        action=action,
        torque=np.zeros((T, NUM_JOINTS)),
        foot_force=foot_force,
        contact=contact,
        penetration=penetration,
        external_force=np.zeros(T),
        qp_failures=0,
        fell_at=None,
        seconds=time.perf_counter() - t0,
        final_qpos=qpos[-1].copy(),
        final_qvel=qvel[-1].copy(),
    )
    tracks = {name: qpos[:, adr : adr + FREE_NQ] for name, adr in scene.object_qpos_adr.items()}
    return scene, roll, tracks


NOT_MEASURED = ("root_residual_max_n", "mpjpe_m", "root_pos_err_max_m", "object_pos_err_m", "object_rot_err_rad")


def kinematic_figures(scene, roll: Rollout, clip: RobotClip, tracks: dict[str, np.ndarray]) -> dict:
    """The clip's physics figures under the simulated clips' bars, kept as ``physics_valid`` / ``physics_reason``;
    ``valid`` is True (every clip is the ablation's data) and ``kinematic`` marks the clip as not simulated."""
    figures = validate(scene, roll, clip.qpos, tracks)
    for key in NOT_MEASURED:
        figures.pop(key, None)
    figures["physics_valid"], figures["physics_reason"] = figures["valid"], figures["reason"]
    figures.update(valid=True, reason="", failure=None, kinematic=True, teacher_gains=0, teacher_attempts=0)
    return figures


def kinematic_clip(clip: RobotClip, profile: str = "mjlab") -> tuple[RobotClip, Rollout, dict, dict]:
    """``(clip, rollout, figures, CoM series)`` as :func:`physicalize.clip.physicalize_clip` returns them, for the
    clip as it is (module docstring)."""
    scene, roll, tracks = kinematic_rollout(clip, profile)
    figures = kinematic_figures(scene, roll, clip, tracks)
    robot = replace(clip, method="kinematic", provenance={**clip.provenance, "teacher": "kinematic"})
    com = com_series(clip, scene, build_reference(scene.model, clip.qpos, clip.fps), None, roll)
    return robot, roll, figures, com
