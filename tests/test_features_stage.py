"""The features stage on small physicalized datasets (real G1 kinematics, real LeRobot loader)."""

import json

import numpy as np
import pytest

from lessmimic.cli import main
from pipeline.clip import ObjectTrack, PhysicalizedClip, RobotClip
from pipeline.dataset import write_dataset
from pipeline.dataset.clips import physicalized_clips_to_episodes
from pipeline.geometry import Primitive
from pipeline.robot import G1_LINK_NAMES, actuator_profile, default_qpos
from pipeline.stage.paths import stage_dir
from pipeline.terms.link_motion import link_motion

LeRobotDataset = pytest.importorskip("lerobot.datasets.lerobot_dataset").LeRobotDataset
BOX = Primitive("box", (0.15, 0.2, 0.25))


def _clip(T: int, name: str, objects=("box",)) -> PhysicalizedClip:
    """The G1 standing still, a box sliding toward it at 0.2 m/s (a second box far behind, if asked)."""
    q = np.repeat(default_qpos(actuator_profile("mjlab"), root_height=0.78)[None], T, 0)
    tracks, vels = [], []
    for k, n in enumerate(objects):
        pose = np.tile([0.9 if k == 0 else -2.0, 0.0, 0.25, 1.0, 0.0, 0.0, 0.0], (T, 1))
        vel = np.zeros((T, 6))
        if k == 0:
            pose[:, 0] -= 0.2 * np.arange(T) / 50
            vel[:, 0] = -0.2
        tracks.append(ObjectTrack(n, BOX, pose, np.arange(T) > T // 2, 2.0, "hand-made"))
        vels.append(vel)
    robot = RobotClip(q, 50, f"hand-made:{name}", objects=tuple(tracks), task=name)
    return PhysicalizedClip(
        robot,
        np.zeros((T, 35)),
        tuple(vels),
        q[:, 7:],
        np.zeros((T, 29)),
        np.full((T, 2), 170.0),
        q,
        {"valid": True, "reason": ""},
    )


def _physicalized(clips, name="feat"):
    features, episodes = physicalized_clips_to_episodes(clips)
    return write_dataset(stage_dir(name, "physicalized"), f"lessmimic/{name}-physicalized", 50, features, episodes)


def _box_distance(p, centre):
    return np.linalg.norm(np.maximum(np.abs(p - centre) - BOX.size, 0.0), axis=-1)


def test_features_dataset_loads_with_interaction_windows(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    clips = [_clip(30, "PickUp"), _clip(12, "Push")]
    _physicalized(clips)
    assert main(["features", "--name", "feat"]) == 0
    assert "features of 2 clip(s), 42 frames" in capsys.readouterr().out
    root = stage_dir("feat", "features")
    window = [-0.08, -0.06, -0.04, -0.02, 0.0]
    ds = LeRobotDataset("lessmimic/feat-features", root=root, delta_timestamps={"observation.df": window})
    K = len(G1_LINK_NAMES)
    assert ds.num_episodes == 2 and ds.num_frames == 42
    for key, dim in (
        ("observation.df_relative", K * 10),
        ("observation.df_demo", 28),
        ("observation.root_command", 12),
        ("observation.proprio", 93),
        ("action", 29),
        ("object.pose", 7),
        ("observation.state", 36),
    ):
        assert tuple(ds.features[key]["shape"]) == (dim,)
    assert "observation.df_object" not in ds.features  # one object: no index column
    item = ds[31]  # episode 1, frame 1: the first 3 window frames are padding
    assert tuple(item["observation.df"].shape) == (5, K * 10)
    assert item["observation.df_is_pad"].tolist() == [True, True, True, False, False] and item["task"] == "Push"
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["features"]["observation.df"]["names"][:2] == ["pelvis.phi", "pelvis.grad_x"]
    # Values: phi of every link is the exact box distance from its body origin; the box slides at 0.2 m/s,
    # so relative to its surface every link approaches it at 0.2 m/s along the normal (the robot stands still).
    c = clips[0]
    pos = link_motion(c.robot.qpos, c.qvel, G1_LINK_NAMES).pos
    df = np.stack([ds[t]["observation.df"][-1].numpy() for t in range(30)]).reshape(30, K, 10)
    rel = np.stack([ds[t]["observation.df_relative"].numpy() for t in range(30)]).reshape(30, K, 10)
    np.testing.assert_allclose(df[..., 0], _box_distance(pos, c.robot.objects[0].pose[:, None, :3]), atol=1e-5)
    np.testing.assert_allclose(df[..., 4:], 0, atol=1e-6)  # the robot's links do not move
    np.testing.assert_allclose(
        (rel[..., 4:7] * rel[..., 1:4]).sum(-1), (np.array([0.2, 0, 0]) * rel[..., 1:4]).sum(-1), atol=1e-5
    )
    report = json.loads((root / "report.json").read_text())
    assert report["summary"]["frames"] == 42 and report["clips"][0]["frames_per_cpu_s"] > 0
    card = (root / "README.md").read_text()
    assert "delta_timestamps" in card and "| `observation.df_demo` |" in card
    logs = tmp_path / "feat" / "logs" / "features"
    assert (logs / "000_hand-made_PickUp.png").is_file() and (logs / "001_hand-made_Push.png").is_file()
    # A rerun on the same input does nothing; other options need --overwrite.
    stamp = {p: p.stat().st_mtime_ns for p in root.rglob("*")}
    capsys.readouterr()
    assert main(["features", "--name", "feat"]) == 0
    assert "is up to date" in capsys.readouterr().out and stamp == {p: p.stat().st_mtime_ns for p in root.rglob("*")}
    assert main(["features", "--name", "feat", "--links", "pelvis"]) == 2
    assert "--overwrite" in capsys.readouterr().err


def test_two_objects_give_the_nearest_object_per_link(tmp_path, monkeypatch):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    _physicalized([_clip(5, "two", objects=("box", "crate"))])
    assert main(["features", "--name", "feat", "--links", "pelvis,left_wrist_yaw_link"]) == 0
    ds = LeRobotDataset("lessmimic/feat-features", root=stage_dir("feat", "features"))
    assert tuple(ds.features["observation.df"]["shape"]) == (20,)
    assert ds[0]["observation.df_object"].tolist() == [0, 0]  # the box in front is nearer than the crate behind


def test_bad_inputs_are_one_line_errors(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    assert main(["features", "--name", "feat"]) == 2  # nothing physicalized yet
    _physicalized([_clip(5, "a")])
    assert main(["features", "--name", "feat", "--links", "pelvis,left_hand"]) == 2
    bare = _clip(5, "bare")
    _physicalized(
        [
            PhysicalizedClip(
                RobotClip(bare.robot.qpos, 50, "hand-made:bare"),
                bare.qvel,
                (),
                bare.action,
                bare.torque,
                bare.foot_force,
                bare.reference_qpos,
            )
        ],
        name="bare",
    )
    assert main(["features", "--name", "bare"]) == 2
    err = [
        line for line in capsys.readouterr().err.splitlines() if line.startswith("error: ")
    ]  # (the rest: progress bars)
    assert (
        len(err) == 3
        and "no physicalized dataset" in err[0]
        and "'left_hand' is not a body" in err[1]
        and "no object tracks" in err[2]
    )
    assert not stage_dir("feat", "features").exists() and not stage_dir("bare", "features").exists()


def test_nothing_to_do_when_physicalize_kept_no_clip(tmp_path, monkeypatch, capsys):
    """The physicalize stage ran and found no valid clip: features says so and exits 0, writing nothing."""
    from pipeline.stage.atomic import write_json_atomic

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    write_json_atomic(tmp_path / "feat" / "logs" / "physicalized" / "report.json", {"summary": {"episodes_written": 0}})
    assert main(["features", "--name", "feat"]) == 0
    out = capsys.readouterr().out
    assert "nothing to do" in out and "KEEP_INVALID=1" in out
    assert not stage_dir("feat", "features").exists()


def test_an_object_with_zero_scale_is_a_one_line_error(tmp_path, monkeypatch, capsys):
    import pandas as pd

    from pipeline.dataset.checksums import read_checksums, write_checksums

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    root = _physicalized([_clip(5, "a")])
    meta = root / "meta" / "lessmimic_episodes.jsonl"
    meta.write_text(meta.read_text().replace('"scale": [1.0, 1.0, 1.0]', '"scale": [0.0, 1.0, 1.0]'))
    # as a writer would have written it (its checksums agree): the geometry, not the corruption, is the error
    write_checksums(root, read_checksums(root)["upstream"])
    assert '"scale": [0.0' in meta.read_text() and pd.read_json(meta, lines=True).shape[0] == 1
    assert main(["features", "--name", "feat"]) == 2
    err = capsys.readouterr().err
    assert "object box geometry: scale must be three positive finite numbers" in err
