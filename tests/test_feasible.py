"""The whole-body reference re-solved by IK (physicalize.feasible): the CoM follows the plan, stance
feet stay on their footsteps, joint limits hold, objects stay frozen, footsteps from a sliding foot."""

import numpy as np
import pytest

from physicalize.feasible import FeasibleConfig, ReferenceIK, feasible_reference, resolve_reference
from physicalize.footsteps import foot_targets
from physicalize.plan import plan_com
from physicalize.reference import build_reference, place_on_floor
from pipeline.geometry import Primitive
from pipeline.robot import default_qpos, sole_corners
from pipeline.scene import SceneObject, build_scene

FPS = 50.0


@pytest.fixture(scope="module")
def scene():
    box = SceneObject("box", Primitive("box", (0.1, 0.1, 0.1)), pose=(0.6, 0.0, 0.1, 1.0, 0.0, 0.0, 0.0))
    return build_scene([box])  # a free object after the robot: its dofs must stay frozen


def _standing_reference(scene, frames: int):
    qpos = place_on_floor(scene.model, np.repeat(default_qpos(scene.profile)[None], frames, 0))
    return build_reference(scene.model, qpos, FPS)


def _smooth_step(frames: int, start: int, length: int) -> np.ndarray:
    s = np.clip((np.arange(frames) - start) / length, 0.0, 1.0)
    return s * s * (3 - 2 * s)


def _limits(scene) -> tuple[np.ndarray, np.ndarray]:
    return scene.model.jnt_range[1:30, 0], scene.model.jnt_range[1:30, 1]


def _check_feet_and_limits(scene, ref, qpos, ik: ReferenceIK, tol_m: float = 1e-3):
    new = build_reference(scene.model, qpos, FPS)
    planted = ik.foot_targets.planted
    err = np.linalg.norm(new.foot_pos - ik.foot_targets.pos, axis=-1)[planted]
    assert planted.sum() > 0 and err.max() < tol_m
    lo, hi = _limits(scene)
    assert (qpos[:, 7:] >= lo - 1e-6).all() and (qpos[:, 7:] <= hi + 1e-6).all()
    return new


def test_com_follows_a_shifted_plan_with_feet_on_their_footsteps(scene):
    """Standing in double support, the plan shifts the CoM 4 cm sideways and 3 cm forward and back:
    the re-solved CoM follows within 3 mm, both feet stay at their footsteps within 1 mm."""
    T = 120
    ref = _standing_reference(scene, T)
    plan = ref.com.copy()
    s = _smooth_step(T, 10, 40) - _smooth_step(T, 70, 40)
    plan[:, 1] += 0.04 * s
    plan[:, 0] += 0.03 * s
    ik = ReferenceIK(scene.model)
    qpos = ik.solve(ref, plan)
    assert qpos.shape == (T, 36) and np.isfinite(qpos).all()
    new = _check_feet_and_limits(scene, ref, qpos, ik)
    assert np.linalg.norm(new.com - plan, axis=1).max() < 3e-3
    assert np.abs(new.com[60, :2] - ref.com[60, :2]).min() > 0.025  # it did move (not the reference's CoM)
    assert ik.stats["relaxed_steps"] == 0 and ik.stats["failed_steps"] == 0


def test_single_support_plan_moves_the_com_over_the_stance_foot(scene):
    """The right foot is declared in swing for 0.8 s: the ZMP plan moves the CoM over the left foot
    (~10 cm), the IK follows it within a few mm with the left foot pinned within 1 mm, and the
    re-solved reference keeps the original stance schedule."""
    T = 150
    ref = _standing_reference(scene, T)
    ref.stance[50:90, 1] = False
    stats: dict = {}
    out = feasible_reference(scene.model, ref, plan_com, replan=False, stats=stats)
    plan = plan_com(ref)[0]
    assert np.array_equal(out.stance, ref.stance) and np.allclose(out.com_plan, plan)
    assert abs(plan[70, 1] - ref.foot_pos[70, 0, 1]) < 0.05 and plan[70, 1] - plan[0, 1] > 0.05  # over the left foot
    assert np.linalg.norm(out.com - plan, axis=1).max() < 5e-3 and stats["com_err_max_m"] < 5e-3
    left = np.linalg.norm(out.foot_pos[:, 0] - out.foot_pos[0, 0], axis=-1)
    assert left.max() < 1e-3
    lo, hi = _limits(scene)
    assert (out.qpos[:, 7:] >= lo - 1e-6).all() and (out.qpos[:, 7:] <= hi + 1e-6).all()


def test_second_pass_plans_on_the_resolved_reference(scene):
    """passes=2: the plan is made again on the first re-solve (flat footsteps), the motion re-solved to it."""
    T = 100
    ref = _standing_reference(scene, T)
    ref.stance[40:70, 0] = False
    stats: dict = {}
    out = feasible_reference(scene.model, ref, passes=2, stats=stats)
    assert out.com_plan is stats["plan"][0] and np.linalg.norm(out.com - out.com_plan, axis=1).max() < 5e-3
    assert not np.allclose(out.com_plan, plan_com(ref)[0], atol=1e-4)  # planned on the re-solved reference
    with pytest.raises(ValueError):
        feasible_reference(scene.model, ref, passes=0)


def test_joint_limits_hold_when_the_plan_asks_too_much(scene):
    """A plan 80 cm in front of the feet is out of reach: the IK stays inside the joint limits, keeps
    the feet planted and gets the CoM as far forward as it can, without chattering."""
    T = 80
    ref = _standing_reference(scene, T)
    plan = ref.com.copy()
    plan[:, 0] += 0.8 * _smooth_step(T, 5, 40)
    ik = ReferenceIK(scene.model)
    qpos = ik.solve(ref, plan)
    new = _check_feet_and_limits(scene, ref, qpos, ik)
    assert new.com[-1, 0] - ref.com[-1, 0] > 0.3
    assert np.linalg.norm(new.com[-1] - plan[-1]) > 0.1  # not reached: the limits won
    d = np.diff(qpos[20:, 7:], axis=0)
    reversals = ((d[1:] * d[:-1] < 0) & (np.abs(d[1:]) > 1e-3) & (np.abs(d[:-1]) > 1e-3)).sum(axis=0)
    assert reversals.max() <= 3  # no chatter (a joint reversing frame after frame between two solutions)


def test_objects_stay_frozen_and_qpos_is_the_robot(scene):
    ref = _standing_reference(scene, 10)
    qpos = resolve_reference(scene.model, ref, ref.com)
    assert qpos.shape == (10, 36)
    ik = ReferenceIK(scene.model)
    ik.solve(ref, ref.com)
    adr = scene.object_qpos_adr["box"]
    assert np.allclose(ik.configuration.q[adr : adr + 7], scene.model.qpos0[adr : adr + 7])


def test_footsteps_from_a_sliding_stance_foot(scene):
    """A stance run whose reference foot slides 10 cm: only the frames within the tolerance of the
    slowest frame's footstep are planted, the footstep is flat on the floor, the targets stay continuous."""
    T = 60
    ref = _standing_reference(scene, T)
    slide = 0.10 * _smooth_step(T, 0, 30)  # moving for 30 frames, then still
    ref.foot_pos[:, 0, 0] += slide
    ref.stance[:, 0] = True
    sole_z = np.array([sole_corners(scene.model, b)[0, 2] for b in ("left_ankle_roll_link", "right_ankle_roll_link")])
    ft = foot_targets(ref, sole_z, tolerance=0.02)
    far = np.abs(slide - slide[-1]) > 0.02
    assert not ft.planted[far, 0].any() and ft.planted[~far, 0].all() and ft.planted[:, 1].all()
    assert np.allclose(ft.pos[~far, 0], [ref.foot_pos[-1, 0, 0], ref.foot_pos[-1, 0, 1], -sole_z[0]])
    assert np.allclose(ft.quat[~far, 0, 1:3], 0.0)  # flat: no roll or pitch
    assert np.linalg.norm(np.diff(ft.pos[:, 0], axis=0), axis=-1).max() < 0.02


def test_a_low_pitched_swing_is_lifted_and_levelled(scene):
    """A human-like shuffle: the left foot swings 30 cm with its toe pitched down and its sole at most
    1 cm up; its targets rise to the clearance at mid-swing, level. The right foot's 7 cm swing is kept."""
    T, a, b = 60, 20, 40
    ref = _standing_reference(scene, T)
    s = (np.arange(a, b) - (a - 1)) / (b - a + 1)
    for k, (lift, pitch) in enumerate(((0.01, 0.35), (0.07, 0.0))):
        ref.stance[a:b, k] = False
        ref.foot_pos[a:b, k, 0] += 0.3 * s
        ref.foot_pos[b:, k, 0] += 0.3
        ref.foot_pos[a:b, k, 2] += lift * np.sin(np.pi * s) ** 2
        ref.sole_height[a:b, k] = lift * np.sin(np.pi * s) ** 2
        ref.foot_quat[a:b, k] = [np.cos(pitch / 2), 0.0, np.sin(pitch / 2), 0.0]
    sole_z = np.array([sole_corners(scene.model, b)[0, 2] for b in ("left_ankle_roll_link", "right_ankle_roll_link")])
    plain, lifted = foot_targets(ref, sole_z, 0.02), foot_targets(ref, sole_z, 0.02, clearance=0.04)
    mid = (a + b) // 2
    assert lifted.pos[mid, 0, 2] + sole_z[0] == pytest.approx(0.04, abs=0.002)  # sole 4 cm up at mid-swing
    assert plain.pos[mid, 0, 2] + sole_z[0] < 0.015
    assert np.all(lifted.pos[a:b, 0, 2] >= plain.pos[a:b, 0, 2] - 1e-12)
    assert np.allclose(lifted.quat[a:b, 0, 1:3], 0.0) and not np.allclose(plain.quat[a:b, 0, 1:3], 0.0)  # level
    np.testing.assert_array_equal(lifted.pos[:, 1], plain.pos[:, 1])  # a swing that clears the floor is kept
    np.testing.assert_array_equal(lifted.pos[: a - 1], plain.pos[: a - 1])
    assert np.linalg.norm(np.diff(lifted.pos[:, 0], axis=0), axis=-1).max() < 0.03  # no jump


def test_config_rejects_a_model_without_the_robot_first():
    with pytest.raises(ValueError):
        import mujoco

        ReferenceIK(
            mujoco.MjModel.from_xml_string(
                "<mujoco><worldbody><body name='a'><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
            ),
            FeasibleConfig(),
        )
