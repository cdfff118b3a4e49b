"""The per-clip plot: its series are right on a clip whose answer is known, and the PNG is written."""

import numpy as np

from ingest.default_input import default_clips
from retarget.clip import FPS, retarget_clip
from retarget.plot import clip_series, plot_clip


def test_push_plot(tmp_path):
    clip = next(c for c in default_clips() if c.task == "Push")
    robot, _, _ = retarget_clip(clip)
    s = clip_series(robot)
    assert s["foot_z"].shape == s["hand_dist"].shape == (robot.frames, 2) and s["joint_speed"].shape == (robot.frames,)
    assert s["foot_z"].min() > -0.01  # soles never more than 1 cm below the floor
    human = clip.resampled(FPS)
    wrists = [human.skeleton.index("left_wrist"), human.skeleton.index("right_wrist")]
    touching = human.contacts[:, wrists].all(axis=1)[: robot.frames]
    assert touching.any() and np.nanmax(s["hand_dist"][touching]) < 0.02  # hands on the box while pushing
    assert np.nanmin(s["hand_dist"][~touching]) >= -0.01
    np.testing.assert_allclose(s["joint_speed"][:-1], np.abs(np.diff(robot.qpos[:, 7:], axis=0)).max(axis=1) * FPS)
    png = plot_clip(robot, human, tmp_path / "push.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and not list(tmp_path.glob(".*tmp*"))
