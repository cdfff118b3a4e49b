"""Clean starts (:mod:`physicalize.start`): a retargeted clip cut mid-stride gets a standing prefix in double
support that blends into its first frame; its own frames are kept as they were, and the teacher tracks it."""

from dataclasses import replace

import numpy as np
import pytest

from ingest.synthetic import default_clips
from physicalize.clip import physicalize_clip
from physicalize.reference import build_reference
from physicalize.start import BLEND_S, MOVING_MPS, SETTLE_S, clean_start, prefix_frames, starts_clean
from pipeline.kinematics import qvel_from_qpos
from pipeline.robot import g1_model
from retarget.clip import retarget_clip


def _sole_heights(q: np.ndarray) -> np.ndarray:
    """(2, 4) each foot's sole-corner heights at pose ``q``."""
    return build_reference(g1_model(), q[None], 50.0).corners[0, :, :, 2]


@pytest.fixture(scope="module")
def carry():
    """The synthetic Carry, retargeted (it walks with the box: a gait to cut)."""
    return retarget_clip(next(c for c in default_clips() if c.task == "Carry"))[0]


def _mid_stride(clip):
    """The clip from its first frame after the walk starts with a foot high in swing and the pelvis moving."""
    speed = np.linalg.norm(qvel_from_qpos(clip.qpos, clip.fps)[:, :2], axis=1)
    for t in range(clip.frames - 60):
        if speed[t] > 2 * MOVING_MPS and _sole_heights(clip.qpos[t]).max(axis=1).max() > 0.06:
            return _crop(clip, t)
    raise AssertionError("the synthetic Carry never walks")


def _crop(clip, t):
    objects = tuple(
        replace(o, pose=o.pose[t:], contact=None if o.contact is None else o.contact[t:]) for o in clip.objects
    )
    return replace(clip, qpos=clip.qpos[t:], objects=objects, contacts=clip.contacts[t:])


def test_a_clip_that_starts_standing_gets_no_prefix(carry):
    assert starts_clean(carry) and clean_start(carry) is carry and prefix_frames(carry) == 0


def test_a_mid_stride_clip_gets_a_standing_prefix_that_blends_into_it(carry):
    clip = _mid_stride(carry)
    assert not starts_clean(clip)
    out = clean_start(clip)
    n = prefix_frames(out)
    assert n == round(SETTLE_S * clip.fps) + round(BLEND_S * clip.fps) and n / clip.fps <= 1.5
    np.testing.assert_allclose(out.qpos[n:], clip.qpos, rtol=0, atol=1e-12)  # the clip's own frames unchanged
    np.testing.assert_array_equal(out.contacts[n:], clip.contacts)
    assert not out.contacts[:n].any()
    for o, o0 in zip(out.objects, clip.objects):
        np.testing.assert_array_equal(o.pose[n:], o0.pose)
        np.testing.assert_array_equal(o.pose[:n], np.repeat(o0.pose[:1], n, 0))  # held where the clip finds it
    # standing: every sole corner on the floor, at rest, over the settle
    soles = _sole_heights(out.qpos[0])
    assert np.abs(soles).max() < 0.01
    assert np.abs(np.diff(out.qpos[: round(SETTLE_S * clip.fps)], axis=0)).max() == 0.0
    assert starts_clean(out)
    # no jump where the clip begins: the step into frame n is like the clip's own steps
    v = qvel_from_qpos(out.qpos, out.fps)
    own = np.abs(np.diff(v[n : n + 10], axis=0)).max()
    assert np.abs(v[n] - v[n - 1]).max() < 2 * own + 0.5


def test_the_teacher_tracks_the_prefix_without_falling(carry):
    """physicalize_clip adds the prefix itself, marks it in the figures and the simulated clip, and the robot is
    still up when the clip's own frames begin."""
    clip = _mid_stride(carry)
    sim, roll, figures, _ = physicalize_clip(clip, gains=None)
    n = round((SETTLE_S + BLEND_S) * clip.fps)
    assert figures["start_prefix_s"] == pytest.approx(n / clip.fps)
    assert roll.fell_at is None or roll.fell_at > n
    if sim is not None:
        assert prefix_frames(sim) == n and sim.frames == roll.frames
