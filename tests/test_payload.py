"""The payload cap (physicalize.payload): the heaviest held object the upper body's motors can hold in a
reference's poses, on hand-made loads and on the synthetic PickUp with a box too heavy for the waist."""

from dataclasses import replace

import numpy as np
import pytest

from ingest.synthetic import default_clips
from physicalize.clip import physicalize_clip
from physicalize.payload import MARGIN, capped, held_objects, load_scale
from physicalize.static_torque import static_torque_figures
from pipeline.robot import EFFORT_LIMIT, actuator_profile, default_qpos
from retarget.augment import Variant
from retarget.clip import retarget_clip

FPS = 50.0
OFFSET = np.zeros((2, 3))


def _stooped(frames: int = 20) -> np.ndarray:
    """The default pose, leaning forward at the waist (pitch 0.5 rad): a lever for what the hands hold."""
    q = default_qpos(actuator_profile("mjlab")).copy()
    q[7 + 14] = 0.5  # waist_pitch_joint (index 14 of the 29 joints)
    return np.repeat(q[None], frames, axis=0)


def test_the_scaled_load_asks_exactly_the_margin():
    qpos = _stooped()
    force = np.tile([0.0, 0.0, 400.0], (len(qpos), 2, 1))  # the hands hold up 80 kg
    k = load_scale(qpos, (OFFSET, force), EFFORT_LIMIT)
    assert 0.0 < k < 1.0
    over = static_torque_figures(qpos, (OFFSET, force), EFFORT_LIMIT, FPS)["reference_static_torque_ratio_max"]
    held = static_torque_figures(qpos, (OFFSET, k * force), EFFORT_LIMIT, FPS)["reference_static_torque_ratio_max"]
    assert over > 1.0
    assert held == pytest.approx(MARGIN, abs=1e-9)


def test_no_load_is_never_capped_and_an_overloaded_pose_cannot_be():
    qpos = _stooped()
    assert load_scale(qpos, (OFFSET, np.zeros((len(qpos), 2, 3))), EFFORT_LIMIT) == float("inf")
    weak = np.full(29, 1e-3)  # motors that cannot hold the robot's own arms
    assert load_scale(qpos, (OFFSET, np.tile([0.0, 0.0, 5.0], (len(qpos), 2, 1))), weak) == 0.0


def test_capped_scales_the_held_objects_mass_and_reports_it():
    clip = next(c for c in default_clips() if c.task == "PickUp")
    robot = retarget_clip(clip)[0]
    assert held_objects(np.array([-1, 0, 0, -1])) == [0] and held_objects(np.full(3, -1)) == []
    lighter, figure = capped(robot, [0], 0.5)
    mass = robot.objects[0].physics().mass
    assert lighter.objects[0].mass == pytest.approx(0.5 * mass)
    assert figure["payload_capped"] == [
        {"object": robot.objects[0].name, "demonstrated_kg": mass, "capped_kg": 0.5 * mass, "scale": 0.5}
    ]


def test_a_variant_too_heavy_for_the_waist_is_physicalized_at_the_motors_payload():
    """The PickUp box at 1.2 x and the demonstrated 1.5 kg asks the waist pitch 1.01 x its limit (the longer lever):
    the variant is planned again with the box as heavy as the waist holds, the figure names both masses, it is
    valid, and the physicalized clip's box has the capped mass."""
    clip = next(c for c in default_clips() if c.task == "PickUp")
    variant = retarget_clip(clip, variant=Variant((1.2,) * 3))[0]
    simulated, _, figures, _ = physicalize_clip(variant)
    [cap] = figures["payload_capped"]
    assert cap["demonstrated_kg"] == pytest.approx(1.5) and 1.0 < cap["capped_kg"] < 1.4
    assert figures["reference_static_torque_ratio_max"] <= 1.0 and figures["valid"]
    assert simulated.objects[0].physics().mass == pytest.approx(cap["capped_kg"])


def test_a_demonstrations_own_object_keeps_its_mass():
    """The same PickUp at scale 1.0 with a 3 kg box (1.14 x the waist's limit): the world's mass is not a rule
    to cap; the clip is tracked (or rejected) with its 3 kg and no payload figure."""
    clip = next(c for c in default_clips() if c.task == "PickUp")
    robot = retarget_clip(clip)[0]
    heavy = replace(robot, objects=(replace(robot.objects[0], mass=3.0), *robot.objects[1:]))
    simulated, _, figures, _ = physicalize_clip(heavy)
    assert "payload_capped" not in figures and figures["reference_static_torque_ratio_max"] > 1.0
    assert simulated is None or simulated.objects[0].physics().mass == 3.0
