"""Synthetic gait references for the G1: the walks of ``tests/test_gait.py`` and the gait envelope of
``make bench-physicalize``.

A gait is a footstep sequence: after a standing phase, each step lifts one foot for ``swing_s``
(sole height ``h sin(pi s)``, horizontal position and heading blended by a smooth step from the
foot's previous footstep to its next), followed by ``double_s`` of double support; the pelvis is
above the middle of the two feet at the default height with their mean heading. The whole body
is solved per frame by mink IK (feet and pelvis as frame tasks, posture from the actuator profile's
default pose), :func:`physicalize.reference.place_on_floor` puts the lowest sole on the floor, and
:func:`physicalize.feasible.feasible_reference` makes the CoM consistent with the support schedule
(the ZMP plan moves it over the stance foot in single support).

* :func:`stepping_in_place`: ``steps`` steps on the spot, alternating feet.
* :func:`walk_with_turn`: ``steps`` steps of ``step_m`` (each foot moves ``2 step_m`` per step, the
  first and last steps half that), the heading turning by ``turn_rad`` over the walk.
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np

from physicalize.feasible import feasible_reference
from physicalize.reference import Reference, build_reference, place_on_floor
from pipeline.robot import FOOT_BODIES, NQ_ROBOT, default_qpos
from pipeline.rotations import yaw_quat
from pipeline.scene import Scene
from pipeline.terms.layout import CONTROL_FPS

FPS = float(CONTROL_FPS)


def _smooth(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3 - 2 * s)


def footstep_gait(
    scene: Scene,
    footsteps: list[tuple[int, np.ndarray, float]],
    *,
    stand_s: float = 1.0,
    swing_s: float = 0.5,
    double_s: float = 0.25,
    lift_m: float = 0.06,
    end_s: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(qpos (T, 36), foot_pos (T, 2, 3), foot_yaw (T, 2))``: the kinematic gait of ``footsteps``
    ``[(foot 0 left / 1 right, (x, y) target, yaw target)]`` starting from the default standing pose."""
    m = scene.model
    q0 = place_on_floor(m, default_qpos(scene.profile)[None])[0]
    d = mujoco.MjData(m)
    d.qpos[:NQ_ROBOT] = q0
    mujoco.mj_kinematics(m, d)
    feet = [m.body(b).id for b in FOOT_BODIES]
    start = np.array([d.xpos[f] for f in feet])
    pelvis_h = q0[2]
    n_stand, n_swing, n_double, n_end = (int(round(x * FPS)) for x in (stand_s, swing_s, double_s, end_s))
    T = n_stand + len(footsteps) * (n_swing + n_double) + n_end
    pos = np.repeat(start[None], T, 0)
    yaw = np.zeros((T, 2))
    t = n_stand
    for k, xy, psi in footsteps:
        p0, y0 = pos[t - 1, k].copy(), yaw[t - 1, k]
        s = np.arange(1, n_swing + 1) / n_swing
        a = _smooth(s)[:, None]
        pos[t : t + n_swing, k, :2] = (1 - a) * p0[:2] + a * np.asarray(xy)
        pos[t : t + n_swing, k, 2] = start[k, 2] + lift_m * np.sin(np.pi * s)
        yaw[t : t + n_swing, k] = (1 - a[:, 0]) * y0 + a[:, 0] * psi
        pos[t + n_swing :, k] = [xy[0], xy[1], start[k, 2]]
        yaw[t + n_swing :, k] = psi
        t += n_swing + n_double
    # IK: feet, pelvis (mid-feet, default height, mean heading), posture
    config = mink.Configuration(m)
    config.update(np.concatenate([q0, m.qpos0[NQ_ROBOT:]]))
    foot_tasks = [mink.FrameTask(b, "body", position_cost=100.0, orientation_cost=30.0) for b in FOOT_BODIES]
    pelvis_task = mink.FrameTask("pelvis", "body", position_cost=10.0, orientation_cost=10.0)
    torso_task = mink.FrameTask("torso_link", "body", position_cost=0.0, orientation_cost=5.0)
    posture = mink.PostureTask(m, cost=0.3)
    posture.set_target(np.concatenate([q0, m.qpos0[NQ_ROBOT:]]))
    limits = [mink.ConfigurationLimit(m)]
    out = np.zeros((T, NQ_ROBOT))
    for t in range(T):
        for k in range(2):
            foot_tasks[k].set_target(mink.SE3.from_rotation_and_translation(mink.SO3(yaw_quat(yaw[t, k])), pos[t, k]))
        mid = pos[t].mean(axis=0)
        psi = yaw[t].mean()
        pelvis_task.set_target(
            mink.SE3.from_rotation_and_translation(mink.SO3(yaw_quat(psi)), np.array([mid[0], mid[1], pelvis_h]))
        )
        torso_task.set_target(mink.SE3.from_rotation_and_translation(mink.SO3(yaw_quat(psi)), np.zeros(3)))
        for _ in range(30 if t == 0 else 4):
            dq = mink.solve_ik(
                config, [*foot_tasks, pelvis_task, torso_task, posture], 1.0, "daqp", damping=1e-2, limits=limits
            )
            config.integrate_inplace(dq, 1.0)
        out[t] = config.q[:NQ_ROBOT]
    return place_on_floor(m, out), pos, yaw


def stepping_in_place(scene: Scene, steps: int = 10, **kw) -> tuple[np.ndarray, list]:
    """``(qpos, footsteps)`` of ``steps`` steps on the spot (left foot first)."""
    d = mujoco.MjData(scene.model)
    d.qpos[:NQ_ROBOT] = default_qpos(scene.profile)
    mujoco.mj_kinematics(scene.model, d)
    home = [d.xpos[scene.model.body(b).id][:2].copy() for b in FOOT_BODIES]
    footsteps = [(i % 2, home[i % 2], 0.0) for i in range(steps)]
    return footstep_gait(scene, footsteps, **kw)[0], footsteps


def walk_with_turn(
    scene: Scene, steps: int = 10, step_m: float = 0.12, turn_rad: float = np.pi / 4, **kw
) -> tuple[np.ndarray, list]:
    """``(qpos, footsteps)`` of a walk of ``steps`` steps curving left by ``turn_rad`` (left foot first).

    Footstep ``i`` lands at arc length ``s_i = (i + 1) step_m`` of the centre line (the last one
    beside the other foot, ``s_{i-1}``), so each foot moves ``2 step_m`` per step (``step_m`` on the
    first); the heading at arc length ``s`` is ``turn_rad s / s_end``, feet ``+-half`` the stance width beside it."""
    d = mujoco.MjData(scene.model)
    d.qpos[:NQ_ROBOT] = default_qpos(scene.profile)
    mujoco.mj_kinematics(scene.model, d)
    half = abs(d.xpos[scene.model.body(FOOT_BODIES[0]).id][1] - d.xpos[scene.model.body(FOOT_BODIES[1]).id][1]) / 2
    x0 = d.xpos[scene.model.body(FOOT_BODIES[0]).id][0]
    s_end = (steps - 1) * step_m
    ds = step_m / 20
    arc = np.arange(0.0, s_end + ds, ds)
    heading = turn_rad * arc / s_end
    path = np.zeros((len(arc), 2))
    path[1:, 0] = x0 + np.cumsum(np.cos(heading[:-1]) * ds)
    path[1:, 1] = np.cumsum(np.sin(heading[:-1]) * ds)
    path[0, 0] = x0
    footsteps = []
    for i in range(steps):
        k = i % 2
        j = int(round(min(i + 1, steps - 1) * step_m / ds))
        normal = np.array([-np.sin(heading[j]), np.cos(heading[j])])
        footsteps.append((k, path[j] + (half if k == 0 else -half) * normal, float(heading[j])))
    return footstep_gait(scene, footsteps, **kw)[0], footsteps


def gait_reference(scene: Scene, qpos: np.ndarray) -> Reference:
    """The feasible tracking reference of a synthetic gait ``qpos`` (stance schedule from the motion)."""
    ref = build_reference(scene.model, qpos, FPS)
    return feasible_reference(scene.model, ref)
