"""The ``kinematic`` teacher (the -Syn ablation's data): the retargeted clip as it is, in the physicalized layout,
with its physics measured but not enforced (real MuJoCo, real LeRobot)."""

import json

import numpy as np
from test_physicalize_stage import _clips, retargeted  # noqa: F401 - the fixture

from lessmimic.cli import main
from physicalize.kinematic import kinematic_clip
from pipeline.dataset.clips import episodes_to_physicalized_clips
from pipeline.robot import JOINTS_QPOS
from pipeline.stage.paths import stage_dir


def test_the_clip_is_kept_as_it_is_with_finite_difference_velocities_and_next_frame_actions():
    stand, teleport = _clips()
    robot, roll, figures, _ = kinematic_clip(teleport)
    np.testing.assert_array_equal(robot.qpos, teleport.qpos)  # nothing simulated
    np.testing.assert_array_equal(roll.qpos[:, 36:], teleport.objects[0].pose)
    # the 0.6 m lurch, 0.1 m a frame over frames 30-35, by central differences
    np.testing.assert_allclose(roll.qvel[[29, 35], 0], 0.5 * 0.1 * 50)
    np.testing.assert_allclose(roll.qvel[30:35, 0], 0.1 * 50)
    np.testing.assert_allclose(roll.qvel[:29, :6], 0.0, atol=1e-9)
    np.testing.assert_array_equal(roll.action[:-1], teleport.qpos[1:, JOINTS_QPOS])
    np.testing.assert_array_equal(roll.action[-1], teleport.qpos[-1, JOINTS_QPOS])
    assert not roll.torque.any()
    # the jump lands the robot in the box: kept (raw mocap is the ablation's data), measured, not physics-valid
    assert figures["valid"] and figures["kinematic"] and not figures["physics_valid"]
    assert figures["penetration_max_m"] > 0.02 and "penetration_max_m" in figures["physics_reason"]
    assert "root_residual_max_n" not in figures and "mpjpe_m" not in figures  # not measurable on a kinematic clip
    _, _, figures, _ = kinematic_clip(stand)
    assert figures["physics_valid"] and figures["penetration_max_m"] < 1e-3


def test_the_stage_writes_every_clip_and_says_it_is_not_simulated(retargeted):  # noqa: F811
    assert main(["physicalize", "--name", "hand", "--teacher", "kinematic"]) == 0
    root = stage_dir("hand", "physicalized")
    report = json.loads((root / "report.json").read_text())
    assert report["summary"]["episodes_written"] == 2  # the teleporting clip too: raw mocap is the ablation's data
    assert all(c["kinematic"] and c["valid"] for c in report["clips"])
    assert "NOT simulated" in (root / "README.md").read_text()
    clips = episodes_to_physicalized_clips(root)
    assert [c.robot.method for c in clips] == ["kinematic", "kinematic"]
    assert main(["features", "--name", "hand"]) == 0  # the features stage reads it as any physicalized dataset
