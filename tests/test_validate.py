"""Each validity figure on a hand-made failing case, and the passing case; the dataset summary."""

import numpy as np
import pytest

from physicalize.reference import build_reference, place_on_floor
from physicalize.rollout import initial_state, simulate
from physicalize.validate import foot_slide_frac, summarise, validate
from physicalize.wbc import WholeBodyController
from pipeline.robot import G1_JOINT_NAMES, default_qpos
from pipeline.scene import build_scene


@pytest.fixture(scope="module")
def standing():
    scene = build_scene()
    qpos = place_on_floor(scene.model, np.repeat(default_qpos(scene.profile)[None], 60, 0))
    ref = build_reference(scene.model, qpos, 50)
    q0, v0 = initial_state(scene, ref, {})
    roll = simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0)
    return scene, qpos, roll


def test_a_clean_stand_is_valid(standing):
    scene, qpos, roll = standing
    f = validate(scene, roll, qpos, {})
    assert f["valid"] and f["reason"] == ""
    assert f["external_force_max_n"] == 0.0 and f["root_residual_max_n"] < 1e-6
    assert f["mpjpe_m"] < 0.01 and f["penetration_max_m"] < 0.02 and not f["fell"]


def test_reference_far_away_fails_root_and_mpjpe(standing):
    scene, qpos, roll = standing
    far = qpos.copy()
    far[:, 0] += 0.3
    f = validate(scene, roll, far, {})
    assert not f["valid"] and "root_pos_err_max_m" in f["reason"] and "mpjpe_m" in f["reason"]


def test_external_force_and_fall_are_reported(standing):
    scene, qpos, roll = standing
    from dataclasses import replace

    pushed = replace(roll, external_force=roll.external_force + 5.0, fell_at=30)
    f = validate(scene, pushed, qpos, {})
    assert not f["valid"] and f["reason"].startswith("fell at t=0.60 s") and "external_force_max_n 5 > 0" in f["reason"]


def test_penetration_and_joint_limits_fail(standing):
    scene, qpos, roll = standing
    from dataclasses import replace

    bad = replace(roll, penetration=roll.penetration + 0.05, qpos=roll.qpos.copy())
    bad.qpos[10:, 7 + G1_JOINT_NAMES.index("left_knee_joint")] = 4.0  # far past the knee's range
    f = validate(scene, bad, qpos, {})
    assert "penetration_max_m" in f["reason"] and "joint_limit_violation_frac" in f["reason"]


def test_object_lost_is_reported():
    from pipeline.geometry import ObjectPhysics, Primitive
    from pipeline.scene import SceneObject

    scene = build_scene(
        [SceneObject("box", Primitive("box", (0.1, 0.1, 0.1)), ObjectPhysics(mass=1.0), pose=(1.0, 0, 0.1, 1, 0, 0, 0))]
    )
    qpos = place_on_floor(scene.model, np.repeat(default_qpos(scene.profile)[None], 40, 0))
    ref = build_reference(scene.model, qpos, 50)
    box = np.tile([1.0, 0.0, 0.1, 1.0, 0, 0, 0], (40, 1))
    q0, v0 = initial_state(scene, ref, {"box": box})
    roll = simulate(scene, ref, WholeBodyController(scene.model, scene.profile), q0, v0)
    assert validate(scene, roll, qpos, {"box": box})["valid"]  # the box rests where the reference has it
    moved = box.copy()
    moved[20:, 2] = 0.6  # the reference lifts it; nothing in the simulation does
    f = validate(scene, roll, qpos, {"box": moved})
    assert not f["valid"] and "object lost at t=0.40 s" in f["reason"] and f["object_pos_err_m"] > 0.2


def test_foot_slide_counts_loaded_frames_only():
    xy = np.zeros((5, 2, 2))
    xy[3:, 0, 0] = 0.05  # left foot jumps 5 cm between frames 2 and 3
    loaded = np.ones((5, 2), bool)
    assert foot_slide_frac(xy, loaded) == 0.25
    loaded[3, 0] = False  # not loaded at landing: not a slide
    assert foot_slide_frac(xy, loaded) == 0.0


def test_summary_counts_gain_sets_and_averages_figures():
    clips = [
        {"episode": 0, "valid": True, "mpjpe_m": 0.02, "teacher_gains": 0},
        {"episode": 1, "valid": True, "mpjpe_m": 0.04, "teacher_gains": 1},
        {"episode": 2, "valid": False, "mpjpe_m": 0.06, "teacher_gains": 0},
    ]
    s = summarise(clips)
    assert s["clips"] == 3 and s["valid_frac"] == 2 / 3 and abs(s["mpjpe_m"] - 0.04) < 1e-12
    assert s["clips_per_teacher_gains"] == {"0": 2, "1": 1}
    assert "teacher_gains" not in s and "episode" not in s


def test_summary_averages_a_figure_over_the_clips_that_have_it():
    """Measured crash (8 synthetic SitStand clips, the first one fell): ``fell_at_s`` is a number for a clip that
    fell and None for one that did not; the mean is over the clips that fell, whichever comes first."""
    clips = [
        {"episode": 0, "valid": False, "fell": True, "fell_at_s": 2.0},
        {"episode": 1, "valid": True, "fell": False, "fell_at_s": None},
        {"episode": 2, "valid": False, "fell": True, "fell_at_s": 4.0},
    ]
    s = summarise(clips)
    assert s["fell_at_s"] == 3.0 and "fell" not in s and s["valid_frac"] == 1 / 3
    assert summarise(clips[1:2]).get("fell_at_s") is None
