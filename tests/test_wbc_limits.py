"""The whole-body QP keeps the joints inside their MuJoCo range even where the reference leaves it
(closed loop, real physics): a deep squat whose ankle-pitch reference passes its range end, with
arm references beyond their ranges."""

import mujoco
import numpy as np
import pytest

from physicalize.reference import build_reference, place_on_floor
from physicalize.rollout import initial_state, simulate
from physicalize.validate import LIMIT_TOL
from physicalize.wbc import WholeBodyController
from physicalize.wbc_config import WBCConfig
from physicalize.wbc_rows import limit_bounds
from pipeline.geometry import Primitive
from pipeline.robot import G1_JOINT_NAMES, default_qpos
from pipeline.scene import SceneObject, build_scene


@pytest.fixture(scope="module")
def scene():
    return build_scene()


def _col(name: str) -> int:
    return 7 + G1_JOINT_NAMES.index(name)


def _beyond_range_squat(scene, frames: int = 200) -> np.ndarray:
    """Squat (hips ``-a``, knees ``2a``, ankles ``-a``) to ``a = 0.95``: ankle pitch reference -0.95 rad,
    0.08 past its range end (-0.873); meanwhile the left shoulder pitch goes to -3.4 (range end -3.09)
    and the right elbow to 2.4 (range end 2.09)."""
    q = np.repeat(default_qpos(scene.profile)[None], frames, 0)
    s = 0.5 * (1 - np.cos(2 * np.pi * np.arange(frames) / frames))  # 0 -> 1 -> 0
    for side in ("left", "right"):
        q[:, _col(f"{side}_hip_pitch_joint")] -= 0.95 * s
        q[:, _col(f"{side}_knee_joint")] += 1.9 * s
        q[:, _col(f"{side}_ankle_pitch_joint")] -= 0.95 * s
    for name, end in (("left_shoulder_pitch_joint", -3.4), ("right_elbow_joint", 2.4)):
        c = _col(name)
        q[:, c] += (end - q[:, c]) * s
    return place_on_floor(scene.model, q)


def _max_excess(scene, qpos: np.ndarray) -> tuple[np.ndarray, object]:
    m = scene.model
    lo, hi = np.array([m.jnt_range[m.joint(j).id] for j in G1_JOINT_NAMES]).T
    joints = qpos[:, 7:36]
    return np.maximum(lo - joints, joints - hi).max(axis=0)


def _track(scene, qpos, config: WBCConfig):
    ref = build_reference(scene.model, qpos, 50)
    q0, v0 = initial_state(scene, ref, {})
    return simulate(scene, ref, WholeBodyController(scene.model, scene.profile, config), q0, v0)


def test_the_reference_really_leaves_the_range(scene):
    excess = _max_excess(scene, _beyond_range_squat(scene))
    for name in ("left_ankle_pitch_joint", "right_ankle_pitch_joint", "left_shoulder_pitch_joint", "right_elbow_joint"):
        assert excess[G1_JOINT_NAMES.index(name)] > 0.05, name


def test_limit_bounds_are_a_critically_damped_barrier(scene):
    wbc = WholeBodyController(scene.model, scene.profile, WBCConfig(limit_rate=10.0, limit_margin=0.0))
    q = 0.5 * (wbc.q_lo + wbc.q_hi)
    lo, hi = limit_bounds(wbc, wbc.q_lo, np.zeros(29))
    assert np.allclose(lo, 0.0) and np.all(hi > 0)  # at rest on the lower end: no acceleration into it
    lo, hi = limit_bounds(wbc, wbc.q_lo + 0.1, -np.ones(29))  # 0.1 rad away, approaching at 1 rad/s
    assert np.allclose(lo, 20.0 - 10.0)
    lo, hi = limit_bounds(wbc, q, np.zeros(29))  # mid-range at rest: either way, up to a^2 times the half range
    half = 0.5 * (wbc.q_hi - wbc.q_lo)
    assert np.allclose(lo, -100.0 * half) and np.allclose(hi, 100.0 * half)


def test_squat_with_references_beyond_the_range_stays_inside_it(scene):
    qpos = _beyond_range_squat(scene)
    roll = _track(scene, qpos, WBCConfig())
    assert roll.fell_at is None and roll.qp_failures == 0
    excess = _max_excess(scene, roll.qpos)
    assert excess.max() <= LIMIT_TOL, {
        G1_JOINT_NAMES[j]: round(float(excess[j]), 3) for j in np.flatnonzero(excess > LIMIT_TOL)
    }
    assert np.abs(roll.qpos[:, 2] - qpos[:, 2]).max() < 0.05  # still squats
    # without the range rows the same reference drives joints past their range
    free = _max_excess(scene, _track(scene, qpos, WBCConfig(joint_limits=False)).qpos)
    assert free.max() > LIMIT_TOL


def _knee_geoms(m) -> list[int]:
    return [g for g in range(m.ngeom) if m.geom_contype[g] and "knee" in m.body(m.geom_bodyid[g]).name]


def _nearest_knee(scene, qpos: np.ndarray) -> float:
    """Least signed distance between a knee geom and the block over the frames of ``qpos``."""
    m, d = scene.model, mujoco.MjData(scene.model)
    blocks = [g for g in range(m.ngeom) if m.geom_bodyid[g] == m.body("block").id]
    dist = np.inf
    for q in qpos:
        d.qpos[: len(q)] = q
        mujoco.mj_kinematics(m, d)
        dist = min(dist, min(mujoco.mj_geomDistance(m, d, g, b, 0.5, None) for g in _knee_geoms(m) for b in blocks))
    return dist


def _block_scene(x: float):
    half = (0.1, 0.3, 0.3)  # its top above the knees: they meet its front face
    return build_scene(
        [SceneObject("block", Primitive("box", half), pose=(x + half[0], 0.0, half[2], 1.0, 0.0, 0.0, 0.0), fixed=True)]
    )


def test_knees_stay_off_an_object_the_reference_squats_into():
    """A fixed block stands where the squat's knees go (the knees of the tracked squat without the block
    would enter it 1.5 cm): the clearance rows keep the knees off it; without them (``clearance_rate = 0``)
    the knees hit it."""
    q = _beyond_range_squat(build_scene())
    free = _track(build_scene(), q, WBCConfig(clearance_rate=0.0)).qpos
    x = 0.4
    for _ in range(2):
        x -= _nearest_knee(_block_scene(x), free) + 0.015
    scene = _block_scene(x)
    assert abs(_nearest_knee(scene, free) + 0.015) < 0.003
    nearest = {}
    for rate in (WBCConfig().clearance_rate, 0.0):
        roll = _track(scene, q, WBCConfig(clearance_rate=rate))
        nearest[rate] = (_nearest_knee(scene, roll.qpos), roll.fell_at)
    assert nearest[WBCConfig().clearance_rate][0] > -0.002 and nearest[WBCConfig().clearance_rate][1] is None, nearest
    assert nearest[0.0][0] < 0.0 and nearest[0.0][1] is not None, nearest  # the knees hit the block and the robot falls
