"""The whole-body QP controller steps and walks (closed loop, real MuJoCo physics): 10 steps in place,
a 10-step walk turning 45 degrees, and a 20 N x 0.2 s pelvis push during that walk."""

import mujoco
import numpy as np
import pytest

from physicalize.rollout import initial_state, simulate
from physicalize.synthetic_gait import gait_reference, stepping_in_place, walk_with_turn
from physicalize.wbc import WholeBodyController
from pipeline.robot import FOOT_BODIES
from pipeline.scene import build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def _feet(scene, qpos: np.ndarray) -> np.ndarray:
    m = scene.model
    d = mujoco.MjData(m)
    ids = [m.body(b).id for b in FOOT_BODIES]
    out = np.zeros((len(qpos), 2, 3))
    for t, q in enumerate(qpos):
        d.qpos[:] = q
        mujoco.mj_kinematics(m, d)
        out[t] = d.xpos[ids]
    return out


def _run(scene, qpos, perturb=None):
    ref = gait_reference(scene, qpos)
    q0, v0 = initial_state(scene, ref, {})
    return ref, simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0, perturb=perturb)


def _single_support_phases(force: np.ndarray, k: int) -> int:
    """Runs of >= 5 frames where foot ``k`` carries < 5 N (it is in the air) while the other carries the robot."""
    air = (force[:, k] < 5.0) & (force[:, 1 - k] > 200.0)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], air.astype(int), [0]])))
    return int(((edges[1::2] - edges[::2]) >= 5).sum())


def _check_steps(scene, ref, roll, footsteps, tol_m: float = 0.03, extra_phases: int = 0):
    assert roll.fell_at is None and roll.qp_failures == 0
    assert roll.frames == ref.frames
    feet = _feet(scene, roll.qpos)
    assert (feet[:, :, 2].max(axis=0) - feet[0, :, 2] > 0.04).all()  # both feet really lifted (> 4 cm)
    for k in range(2):
        steps = sum(f[0] == k for f in footsteps)
        assert steps <= _single_support_phases(roll.foot_force, k) <= steps + extra_phases  # 5 single supports each
        last = [xy for foot, xy, _ in footsteps if foot == k][-1]
        assert np.linalg.norm(feet[-1, k, :2] - last) < tol_m  # back on its footstep
    return feet


def test_steps_in_place_10_steps(scene):
    qpos, footsteps = stepping_in_place(scene, steps=10, lift_m=0.08, swing_s=0.4, double_s=0.15)
    ref, roll = _run(scene, qpos)
    feet = _check_steps(scene, ref, roll, footsteps)
    assert np.linalg.norm(feet[:, :, :2] - feet[:1, :, :2], axis=-1).max() < 0.03  # stepping on the spot
    assert np.abs(roll.qpos[:, :2] - ref.qpos[:, :2]).max() < 0.05


def test_walks_10_steps_with_a_45_degree_turn(scene):
    qpos, footsteps = walk_with_turn(scene, steps=10, step_m=0.12, turn_rad=np.pi / 4, swing_s=0.4, double_s=0.15)
    ref, roll = _run(scene, qpos)
    _check_steps(scene, ref, roll, footsteps)
    assert np.linalg.norm(roll.qpos[-1, :2] - roll.qpos[0, :2]) > 0.9  # it walked (~1.05 m)
    w, z = roll.qpos[-1, 3], roll.qpos[-1, 6]
    assert abs(2 * np.arctan2(z, w) - np.pi / 4) < 0.1  # and turned 45 degrees
    assert np.linalg.norm(roll.qpos[:, :2] - ref.qpos[:, :2], axis=1).max() < 0.05


@pytest.mark.parametrize("force", [(20.0, 0.0), (0.0, 20.0), (0.0, -20.0)])
def test_survives_a_20_n_pelvis_push_while_walking(scene, force):
    """The push (0.2 s) starts in a single support of the walk."""
    qpos, footsteps = walk_with_turn(scene, steps=10, step_m=0.12, turn_rad=np.pi / 4, swing_s=0.4, double_s=0.15)
    pelvis = scene.model.body("pelvis").id

    def push(t, d):
        d.xfrc_applied[pelvis, :3] = [*force, 0.0] if 164 <= t < 174 else 0.0

    ref, roll = _run(scene, qpos, perturb=push)
    assert not ref.stance[164:174].all(axis=1).any()  # single support throughout the push
    assert roll.external_force.max() == 20.0
    _check_steps(scene, ref, roll, footsteps, tol_m=0.05, extra_phases=1)  # a push may unload a foot once more
