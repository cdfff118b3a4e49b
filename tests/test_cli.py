"""The command line: help, bad names, and the foundation's chain on the embedded default."""

import json
import subprocess
import sys

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from lessmimic.cli import main


def test_help_lists_every_command():
    out = subprocess.run(
        [sys.executable, "-m", "lessmimic.cli", "--help"], capture_output=True, text=True, check=True
    ).stdout
    for cmd in (
        "retarget",
        "physicalize",
        "features",
        "inspect",
        "load",
        "publish",
        "merge",
        "subset",
        "eval",
        "export-motion",
    ):
        assert cmd in out


@pytest.mark.parametrize("name", ["a/b", "../up", "x\\y", ""])
def test_bad_dataset_name_is_one_line_error(name, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    assert main(["retarget", "--name", name]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "name" in err and "\n" not in err
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_default_chain_retarget_physicalize_features(tmp_path, monkeypatch, capsys):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    assert main(["retarget"]) == 0
    root = tmp_path / "default" / "human"
    ds = LeRobotDataset("lessmimic/default-human", root=root)
    assert ds.num_episodes == 4
    report = json.loads((root / "report.json").read_text())
    assert report["synthetic"] is True and report["frames"] == ds.num_frames
    assert sorted(c["task"] for c in report["clips"]) == ["Carry", "PickUp", "Push", "SitStand"]
    assert "SYNTHETIC" in (root / "README.md").read_text()
    assert len(list((tmp_path / "default" / "logs" / "human").glob("*.mcap"))) == 4
    robot = LeRobotDataset("lessmimic/default-retargeted", root=tmp_path / "default" / "retargeted")
    assert robot.num_episodes == 4 and robot.fps == 50
    card = (tmp_path / "default" / "retargeted" / "README.md").read_text()
    for feature in ("observation.state", "observation.qvel", "contact", "source_frame"):
        assert f"| `{feature}` |" in card
    assert "| world, z-up |" in card and "`source_frame` is the index" in card  # object pose row; notes
    assert robot[0]["source_frame"].item() == 0 and robot[robot.num_frames - 1]["source_frame"].item() > 0
    assert len(list((tmp_path / "default" / "logs" / "retargeted").glob("*.mcap"))) == 4
    assert len(list((tmp_path / "default" / "logs" / "retargeted").glob("*.png"))) == 4
    # A second run is up to date; one with another option refuses to overwrite, with one line; the dataset stays intact.
    capsys.readouterr()
    assert main(["retarget"]) == 0
    assert (
        capsys.readouterr().out
        == "retarget: datasets/default/retargeted/ is up to date (same input and options); nothing to do\n"
    )
    assert main(["retarget", "--height", "1.7"]) == 2
    err = capsys.readouterr().err
    assert "--overwrite" in err and err.count("\n") == 1
    assert LeRobotDataset("lessmimic/default-human", root=root).num_frames == ds.num_frames
    assert not (tmp_path / "default" / ".work" / "retargeted").exists()  # resume cache removed when finished
    code = main(["physicalize"])  # every clip is simulated, valid or not, and reported
    report = json.loads((tmp_path / "default" / "logs" / "physicalized" / "report.json").read_text())
    assert [c["task"] for c in report["clips"]] == ["PickUp", "SitStand", "Push", "Carry"]
    assert all(c["valid"] or c["reason"] for c in report["clips"])
    assert report["summary"]["valid_frac"] == 1.0, [c["reason"] for c in report["clips"]]  # every default demo is valid
    assert code == 0
    capsys.readouterr()
    assert main(["physicalize"]) == 0  # up to date, whether or not a clip was valid (and a dataset written)
    assert "physicalized/ is up to date" in capsys.readouterr().out
    assert main(["load", str(root)]) == 0
    out = capsys.readouterr().out
    assert f"4 episodes, {ds.num_frames} frames at 30 fps" in out and "observation.joint_pos: float32 (66,)" in out
    # The third stage, on the four physicalized episodes.
    assert report["summary"]["episodes_written"] == 4
    assert main(["features"]) == 0 and main(["features"]) == 0
    assert "features/ is up to date" in capsys.readouterr().out
    feats = LeRobotDataset(
        "lessmimic/default-features",
        root=tmp_path / "default" / "features",
        delta_timestamps={"observation.df": [-0.08, -0.06, -0.04, -0.02, 0.0]},
    )
    physicalized = LeRobotDataset("lessmimic/default-physicalized", root=tmp_path / "default" / "physicalized")
    assert feats.num_episodes == physicalized.num_episodes and feats.num_frames == physicalized.num_frames > 0
    item = feats[feats.num_frames - 1]
    assert tuple(item["observation.df"].shape) == (5, 140) and not item["observation.df_is_pad"].any()
    assert item["observation.df"][:, 0].min() >= 0 and tuple(item["observation.df_demo"].shape) == (28,)
    assert len(list((tmp_path / "default" / "logs" / "features").glob("*.png"))) == feats.num_episodes


def _tree(folder):
    """Every file's size and mtime, every folder by name (a writer's lock comes and goes in a dataset's folder: the
    folder's own mtime moves, no file does)."""
    return {
        str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns) if p.is_file() else "folder"
        for p in sorted(folder.rglob("*"))
    }


def test_retarget_rerun_on_the_same_input_does_nothing(tmp_path, monkeypatch, capsys):
    from ingest.default_input import default_clips

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path / "datasets"))
    clip = next(c for c in default_clips() if c.task == "Push")
    take = tmp_path / "take.npz"

    def save(frames: int) -> None:  # a short keypoints take (a few seconds of IK)
        np.savez(
            take,
            joint_pos=clip.joint_pos[:frames],
            joint_names=np.array(clip.skeleton.joint_names),
            parents=np.array(clip.skeleton.parents),
            fps=clip.fps,
        )

    save(15)
    args = ["retarget", "--input", str(take), "--name", "take"]
    assert main(args) == 0
    before = _tree(tmp_path / "datasets")
    capsys.readouterr()
    assert main(args + ["-j", "2"]) == 0  # the number of worker processes does not change the output
    out, err = capsys.readouterr()
    assert (
        out == "retarget: datasets/take/retargeted/ is up to date (same input and options); nothing to do\n"
        and err == ""
    )
    assert _tree(tmp_path / "datasets") == before  # nothing rewritten, not even touched
    assert main(args + ["--height", "1.6"]) == 2  # another option
    save(16)  # another input
    assert main(args) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all("retargeted: dataset: already exists; pass --overwrite" in e for e in err)
    assert _tree(tmp_path / "datasets") == before
    assert main(args + ["--overwrite"]) == 0
    capsys.readouterr()
    assert main(args) == 0 and "is up to date" in capsys.readouterr().out


@needs_shared
@pytest.mark.slow
def test_omomo_folder_is_retargeted_and_physicalized(tmp_path, monkeypatch):
    """The OMOMO box clip end to end through the CLI: a folder input with its object mesh, retargeted, then
    physicalized (feasible reference, base teacher) into an episode kept with its validation figures and verdict,
    its kind of take, its clean start and its object's physics from the materials table (the clip's validity under
    them is the real-data bench's to measure: ``make bench-physicalize-real``)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from pipeline.materials import OBJECT_KINDS

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    assert main(["retarget", "--input", str(SHARED_MOCAP / "omomo"), "--name", "omomo"]) == 0
    ds = LeRobotDataset("lessmimic/omomo-human", root=tmp_path / "omomo" / "human")
    assert ds.num_episodes == 1 and ds.num_frames == 196
    robot = LeRobotDataset("lessmimic/omomo-retargeted", root=tmp_path / "omomo" / "retargeted")
    assert robot.num_episodes == 1 and robot.fps == 50
    # the physicalize stage: the box is picked up and carried in MuJoCo with the base teacher
    assert main(["physicalize", "--name", "omomo", "--keep-invalid"]) == 0
    report = json.loads((tmp_path / "omomo" / "physicalized" / "report.json").read_text())
    (clip,) = report["clips"]
    assert clip["valid"] or clip["failure"], clip["reason"]  # valid, or failed with its class
    assert clip["take_kind"] == "lift" and clip["human_hand_opposition"] < -0.5  # a two-handed squeeze lift
    prefix = round(clip["start_prefix_s"] * 50)
    assert prefix > 0 and clip["frames"] == robot.num_frames + prefix  # it starts moving: a standing prefix
    assert clip["replay_err_max_m"] <= 1e-6
    physicalized = LeRobotDataset("lessmimic/omomo-physicalized", root=tmp_path / "omomo" / "physicalized")
    assert physicalized.num_episodes == 1
    meta = [json.loads(line) for line in (tmp_path / "omomo" / "physicalized" / "meta" / "lessmimic_episodes.jsonl")
            .read_text().splitlines()]  # fmt: skip
    (obj,) = meta[0]["objects"]
    kind = OBJECT_KINDS["largebox"]
    assert (obj["mass"], obj["friction"], obj["floor_friction"], obj["material"]) == (
        kind.mass.nominal, kind.hand_friction.nominal, kind.floor_friction.nominal, kind.material
    )  # fmt: skip


@needs_shared
def test_inspect_peer_robot_file_with_its_object(tmp_path):
    from mcap.reader import make_reader

    out = tmp_path / "peer.mcap"
    npz = SHARED_MOCAP / "omniretarget" / "sub3_largebox_003_mj_w_obj.npz"
    assert (
        main(
            [
                "inspect",
                str(npz),
                "--robot",
                "--object-mesh",
                str(SHARED_MOCAP / "omomo" / "largebox.obj"),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    with out.open("rb") as f:
        summary = make_reader(f).get_summary()
    counts = {summary.channels[c].topic: n for c, n in summary.statistics.channel_message_counts.items()}
    assert counts["/tf"] == 325 and counts["/scene"] == 1


@needs_shared
def test_evaluate_retarget_on_the_peer_file(tmp_path, capsys):
    out = tmp_path / "m.json"
    npz = SHARED_MOCAP / "omniretarget" / "sub3_largebox_003_mj_w_obj.npz"
    args = [
        "evaluate-retarget",
        str(npz),
        "--object-mesh",
        str(SHARED_MOCAP / "omomo" / "largebox.obj"),
        "--out",
        str(out),
    ]
    assert main(args) == 0
    m = json.loads(out.read_text())
    assert m["frames"] == 325 and m["fps"] == 50
    assert 0.4 < m["object_penetration_frac_1cm"] < 0.55  # the peer penetrates the box (~47% measured elsewhere)
