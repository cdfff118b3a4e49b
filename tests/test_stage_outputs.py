"""Nothing outside a command's outputs (pipeline.stage.outputs): MuJoCo's log in the dataset's logs/, the Arrow cache
of a reload in a temporary folder removed afterwards."""

import mujoco
import numpy as np

from pipeline.stage.outputs import mujoco_log_into, temporary_arrow_cache


def test_mujoco_warnings_go_to_the_given_log_not_the_working_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    model = mujoco.MjModel.from_xml_string(
        "<mujoco><worldbody><body><freejoint/><geom size='.1'/></body></worldbody></mujoco>"
    )
    data = mujoco.MjData(model)
    log = tmp_path / "x" / "logs" / "mujoco.log"
    with mujoco_log_into(log):
        data.qpos[:] = np.nan  # "Nan, Inf or huge value in QPOS": a warning MuJoCo writes to MUJOCO_LOG.TXT
        mujoco.mj_step(model, data)
    assert "WARNING" in log.read_text() and "QPOS" in log.read_text()
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


def test_a_reload_caches_into_a_temporary_folder_removed_after(tmp_path, monkeypatch):
    import datasets.config
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from pipeline.clip import RobotClip
    from pipeline.dataset.clips import robot_clips_to_episodes
    from pipeline.dataset.write import write_dataset
    from pipeline.robot import actuator_profile, default_qpos

    default = tmp_path / "hf-datasets-cache"
    monkeypatch.setattr(datasets.config, "HF_DATASETS_CACHE", default)
    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    root = write_dataset(tmp_path / "retargeted", "lessmimic/t-retargeted", 50, features, episodes)
    with temporary_arrow_cache() as cache:
        assert LeRobotDataset("lessmimic/t-retargeted", root=root).num_frames == 10
        assert any(cache.rglob("*.arrow"))
    assert not cache.exists() and not default.exists()
    assert datasets.config.HF_DATASETS_CACHE == default
