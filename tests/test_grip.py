"""Two-handed squeezes kept on the faces the human squeezes (retarget.grip): the anchored wrist targets are the
human's wrists in the object's frame, a squeeze retargeted onto boxes of other sizes keeps opposite faces, and a
real squeeze the scaled G1 loses is put back on the human's faces."""

from dataclasses import replace

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from ingest.synthetic import default_clips
from pipeline.rotations import quat_mat
from pipeline.take import held_frames, human_hold, object_field
from retarget.clip import FPS, retarget_clip
from retarget.grip import RAMP, SQUEEZE, anchored_targets, g1_opposition
from retarget.mapping import load_mapping, map_human
from retarget.objects import map_objects
from retarget.scaling import compute_scale, human_to_targets


def _pickup(size_factor=(1.0, 1.0, 1.0)):
    human = next(c for c in default_clips() if c.task == "PickUp")
    box = human.objects[0]
    geometry = replace(box.geometry, size=tuple(np.array(box.geometry.size) * size_factor))
    return replace(human, objects=(replace(box, geometry=geometry),)).resampled(FPS)


def _g1_opposition(human, robot) -> float:
    field = object_field(human)
    frames = np.flatnonzero(held_frames(human, field)[: robot.frames])
    return g1_opposition(field, robot.qpos, robot.objects, frames, robot.source)


def test_anchored_wrists_sit_in_the_objects_frame_where_the_humans_do():
    human = _pickup()
    mapped = map_human(human, load_mapping(human.skeleton))
    info = compute_scale(mapped)
    targets = human_to_targets(mapped, scale=info)
    objects = map_objects(mapped, info, targets)
    hold = human_hold(human)
    assert hold is not None and hold[1] <= SQUEEZE and hold[0].size > 20  # the synthetic PickUp squeezes its box
    frames = hold[0]
    anchored = anchored_targets(human, targets, objects, frames)
    k = targets.body_names.index("left_wrist_yaw_link")
    wrist = human.joint_pos[:, human.skeleton.index("left_wrist")]
    h, r = human.objects[0].pose, objects[0].pose
    for t in frames[:: max(1, frames.size // 5)]:
        in_robot = quat_mat(r[t, 3:7]).T @ (anchored.pos[t, k] - r[t, :3])
        in_human = quat_mat(h[t, 3:7]).T @ (wrist[t] - h[t, :3])
        assert np.allclose(in_robot, in_human, atol=1e-9)
    far = np.flatnonzero(np.abs(np.arange(targets.frames)[:, None] - frames[None]).min(axis=1) > RAMP)
    assert far.size and np.array_equal(anchored.pos[far], targets.pos[far])  # untouched away from the hold


@pytest.mark.parametrize("size", [(1.0, 0.6, 1.0), (1.0, 1.3, 1.0), (0.7, 0.7, 1.6)])
def test_a_squeeze_retargeted_onto_a_box_of_another_size_keeps_opposite_faces(size):
    human = _pickup(size)
    robot, metrics, _ = retarget_clip(human)
    assert robot.provenance["human_hand_opposition"] <= SQUEEZE
    assert _g1_opposition(human, robot) <= SQUEEZE and metrics["contact_preservation_frac"] >= 0.9


@needs_shared
@pytest.mark.slow
def test_a_real_squeeze_the_scaled_g1_loses_is_put_back_on_the_humans_faces():
    """``sub2_woodchair_001``: the human lifts the chair between its hands (-0.93); the scaled G1's wrists ended on
    faces that do not oppose (0.60); anchored on the human's, the G1's oppose too (measured -0.90)."""
    from pipeline.readers import read_clips

    human = read_clips(SHARED_MOCAP / "interact" / "sub2_woodchair_001.pt")[0]
    robot, metrics, _ = retarget_clip(human)
    assert robot.provenance["human_hand_opposition"] <= SQUEEZE
    assert robot.provenance["g1_hand_opposition_scaled"] > 0.0  # what the scaled pose gave
    assert _g1_opposition(human.resampled(FPS), robot) <= SQUEEZE
    assert metrics["contact_preservation_frac"] >= 0.9
