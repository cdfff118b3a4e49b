"""The whole-body QP controller on the G1 in MuJoCo: stand, squat, pushes (closed loop, real physics)."""

import mujoco
import numpy as np
import pytest

from physicalize.reference import build_reference, place_on_floor
from physicalize.rollout import initial_state, replay, simulate
from physicalize.wbc import WholeBodyController
from pipeline.robot import G1_JOINT_NAMES, default_qpos, sole_corners
from pipeline.rotations import orientation_error
from pipeline.scene import build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def _standing(scene, frames: int) -> np.ndarray:
    return place_on_floor(scene.model, np.repeat(default_qpos(scene.profile)[None], frames, 0))


def _squat(scene, frames: int, depth_rad: float = 0.5, period_s: float = 2.0) -> np.ndarray:
    """Knees bend by ``2 a``, hips and ankles by ``-a``: torso upright, feet flat, pelvis lowered."""
    q = _standing(scene, frames)
    a = depth_rad * 0.5 * (1 - np.cos(2 * np.pi * np.arange(frames) / (50 * period_s)))
    for side in ("left", "right"):
        q[:, 7 + G1_JOINT_NAMES.index(f"{side}_hip_pitch_joint")] -= a
        q[:, 7 + G1_JOINT_NAMES.index(f"{side}_knee_joint")] += 2 * a
        q[:, 7 + G1_JOINT_NAMES.index(f"{side}_ankle_pitch_joint")] -= a
    return place_on_floor(scene.model, q)


def _track(scene, qpos, perturb=None):
    ref = build_reference(scene.model, qpos, 50)
    q0, v0 = initial_state(scene, ref, {})
    return ref, q0, v0, simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0, perturb=perturb)


def test_sole_corners_span_the_foot_capsules(scene):
    c = sole_corners(scene.model, "left_ankle_roll_link")
    assert c.shape == (4, 3)
    assert c[:, 0].max() - c[:, 0].min() > 0.15  # heel to toe
    assert np.allclose(c[:, 2], c[0, 2]) and c[0, 2] < -0.03  # one sole plane below the ankle


def test_orientation_error_is_the_rotation_vector():
    R = np.eye(3)
    c, s = np.cos(0.3), np.sin(0.3)
    Rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    assert np.allclose(orientation_error(Rz, R), [0, 0, 0.3])
    assert np.allclose(orientation_error(R, Rz), [0, 0, -0.3])


def test_stands_10_s(scene):
    qpos = _standing(scene, 500)
    _, _, _, roll = _track(scene, qpos)
    assert roll.fell_at is None and roll.qp_failures == 0
    assert np.abs(roll.qpos[:, :3] - qpos[:, :3]).max() < 0.01
    assert roll.foot_force[5:].sum(axis=1).min() > 0.8 * 9.81 * scene.model.body_subtreemass[1]


def test_squats_down_and_up(scene):
    qpos = _squat(scene, 200)
    assert qpos[:, 2].max() - qpos[:, 2].min() > 0.1  # a real squat
    _, _, _, roll = _track(scene, qpos)
    assert roll.fell_at is None
    assert np.abs(roll.qpos[:, 2] - qpos[:, 2]).max() < 0.03


@pytest.mark.parametrize("force", [50.0, -50.0])
def test_survives_a_50_n_pelvis_push_while_standing(scene, force):
    def push(t, d):
        d.xfrc_applied[scene.model.body("pelvis").id, :3] = [force, 0.0, 0.0] if 25 <= t < 35 else 0.0  # 0.2 s

    qpos = _standing(scene, 150)
    _, _, _, roll = _track(scene, qpos, perturb=push)
    assert roll.external_force.max() == abs(force)
    assert roll.fell_at is None
    assert np.abs(roll.qpos[-1, :2] - qpos[-1, :2]).max() < 0.05


def test_lateral_push_while_standing(scene):
    def push(t, d):
        d.xfrc_applied[scene.model.body("pelvis").id, :3] = [0.0, 50.0, 0.0] if 25 <= t < 35 else 0.0

    _, _, _, roll = _track(scene, _standing(scene, 150), perturb=push)
    assert roll.fell_at is None


def test_replaying_the_actions_reproduces_the_rollout(scene):
    _, q0, v0, roll = _track(scene, _squat(scene, 100))
    qs, vs = replay(scene.model, q0, v0, roll.action)
    assert np.abs(qs[:-1] - roll.qpos).max() <= 1e-6
    assert np.abs(qs[-1] - roll.final_qpos).max() <= 1e-6


def test_controller_torques_match_the_applied_ones_while_standing(scene):
    """The PD targets from the QP torques at the mid-hold state give back those torques (within 2 N m)."""
    qpos = _standing(scene, 60)
    ref = build_reference(scene.model, qpos, 50)
    d = mujoco.MjData(scene.model)
    d.qpos[:], d.qvel[:] = initial_state(scene, ref, {})
    wbc = WholeBodyController(scene.model, scene.profile)
    for t in range(50):
        mujoco.mj_forward(scene.model, d)
        sol = wbc.solve(d, ref.target(t))
        d.ctrl[:] = sol.action
        tau = np.zeros(29)
        for _ in range(4):
            mujoco.mj_step(scene.model, d)
            tau += d.actuator_force / 4
    assert np.abs(tau - sol.tau).max() < 2.0
