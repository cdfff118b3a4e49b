"""Object contact for the retarget IK (retarget/contact.py): link flags, the fade ramp, ContactTask, resting objects."""

from __future__ import annotations

import mink
import mujoco
import numpy as np
import pytest

from ingest.default_input import default_clips
from pipeline.geometry import Primitive
from pipeline.robot import default_qpos
from pipeline.scene import SceneObject, build_scene, link_collision_geoms, object_collision_geoms
from retarget.contact import ContactTask, contact_ramp, hold_resting, link_contact_flags

WRIST = "right_wrist_yaw_link"


def test_link_flags_are_the_union_of_the_mapped_joints():
    clip = next(c for c in default_clips() if c.task == "PickUp")
    link_map = {"left_wrist": "left_wrist_yaw_link", "right_wrist": WRIST, "right_elbow": WRIST}
    links, flags = link_contact_flags(clip, link_map)
    assert links == ("left_wrist_yaw_link", WRIST) and flags.shape == (clip.frames, 2)
    j = clip.skeleton.index
    np.testing.assert_array_equal(flags[:, 0], clip.contacts[:, j("left_wrist")])
    np.testing.assert_array_equal(flags[:, 1], clip.contacts[:, j("right_wrist")] | clip.contacts[:, j("right_elbow")])
    assert flags[:, 1].any()


def test_ramp_fades_linearly_around_each_contact():
    flags = np.zeros((20, 2), bool)
    flags[8:11, 0] = True
    w = contact_ramp(flags, 3)
    np.testing.assert_allclose(w[:, 1], 0.0)
    np.testing.assert_allclose(w[4:15, 0], [0, 0.25, 0.5, 0.75, 1, 1, 1, 0.75, 0.5, 0.25, 0])
    assert w[:4, 0].sum() == 0 and w[15:, 0].sum() == 0
    np.testing.assert_array_equal(contact_ramp(flags, 0), flags.astype(float))


def _scene_with_box(offset: float):
    """The G1 in its default pose and a fixed 10 cm box ``offset`` below the right wrist (< 0: overlapping)."""
    scene = build_scene([SceneObject("box", Primitive("box", (0.05, 0.05, 0.05)), fixed=True)])
    m, d = scene.model, mujoco.MjData(scene.model)
    d.qpos[:36] = default_qpos(scene.profile)
    mujoco.mj_kinematics(m, d)
    g, box = link_collision_geoms(m, WRIST)[0], m.body("box").id
    m.body_pos[box] = d.geom_xpos[g] - [0.0, 0.0, 0.2]
    mujoco.mj_kinematics(m, d)
    gap = mujoco.mj_geomDistance(m, d, g, object_collision_geoms(m, scene)[0], 1.0, np.empty(6))
    m.body_pos[box] += [0.0, 0.0, gap - offset]
    return scene


def _solve(scene, task_cost: float, weight: float, steps: int = 60):
    m = scene.model
    cfg = mink.Configuration(m)
    q = cfg.q.copy()
    q[:36] = default_qpos(scene.profile)
    cfg.update(q)
    task = ContactTask(
        m, (WRIST, "left_wrist_yaw_link"), object_collision_geoms(m, scene), cost=task_cost, gap=0.01, reach=0.3
    )
    task.set_weights(np.array([weight, 1.0]))
    pelvis = mink.FrameTask("pelvis", "body", position_cost=100.0, orientation_cost=100.0)
    pelvis.set_target_from_configuration(cfg)
    posture = mink.PostureTask(m, cost=1e-3)
    posture.set_target_from_configuration(cfg)
    start = task.distances(cfg).copy()
    for _ in range(steps):
        v = mink.solve_ik(cfg, [task, pelvis, posture], 1.0, "daqp", damping=1e-3)
        cfg.integrate_inplace(v, 1.0)
    return start, task.distances(cfg), task


@pytest.mark.parametrize("offset", [0.08, -0.02])
def test_task_brings_the_link_to_the_gap_from_above_and_from_inside(offset):
    scene = _scene_with_box(offset)
    start, end, _ = _solve(scene, 5.0, 1.0)
    assert start[0] == pytest.approx(offset, abs=1e-3)  # the construction put the box where intended
    assert abs(end[0] - 0.01) < 2e-3, (start, end)
    assert end[1] == pytest.approx(0.3)  # the left wrist is out of reach: a zero row, it stays


def test_zero_weight_leaves_the_link_where_it_is():
    scene = _scene_with_box(0.08)
    start, end, task = _solve(scene, 5.0, 0.0)
    assert end[0] == pytest.approx(0.3)  # weight 0: not even measured
    cfg = mink.Configuration(scene.model)
    assert not task.compute_error(cfg).any()


def test_rejects_a_gap_beyond_reach():
    scene = _scene_with_box(0.08)
    with pytest.raises(ValueError, match="gap"):
        ContactTask(scene.model, (WRIST,), object_collision_geoms(scene.model, scene), gap=0.5, reach=0.3)


def test_a_resting_object_takes_the_offset_its_rest_ends_with():
    """Rest 0-19, carried 20-39, rest 40-59; clearance offsets that grow inside the rests: each rest
    (with the frame it arrives on) holds its last offset, the carried frames keep theirs."""
    fps, T = 50.0, 60
    p_in = np.zeros((T, 7))
    p_in[:, 3] = 1.0
    p_in[20:40, 0] = np.linspace(0.02, 0.4, 20)
    p_in[40:, 0] = 0.4
    off = np.zeros((T, 3))
    off[5:15, 1] = np.linspace(0.002, 0.02, 10)  # pushed while resting (an approaching foot)
    off[15:, 1] = 0.02
    off[25:, 1] += 0.01  # pushed while carried
    off[45:50, 0] = np.linspace(0.004, 0.02, 5)  # pushed after it was set down
    off[50:, 0] = 0.02
    p_out = p_in.copy()
    p_out[:, :3] += off
    held = hold_resting(p_in, p_out, fps)
    np.testing.assert_allclose(
        held[:20, :3] - p_in[:20, :3], np.tile([0.0, 0.02, 0.0], (20, 1))
    )  # never slides before its first move
    np.testing.assert_allclose(held[20:39], p_out[20:39])  # moving frames keep their offsets
    np.testing.assert_allclose(held[39:], np.tile(held[-1], (21, 1)))  # stands still from the frame it arrives at rest
    np.testing.assert_allclose(held[-1, :3], p_in[-1, :3] + off[-1])
    np.testing.assert_array_equal(held[:, 3:], p_in[:, 3:])
