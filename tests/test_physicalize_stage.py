"""The physicalize stage end to end on small hand-made retargeted datasets (real MuJoCo, real LeRobot)."""

import json

import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, needs_shared

from lessmimic.cli import main
from physicalize.clip import physicalize_clip
from physicalize.reference import place_on_floor
from physicalize.stage import _clip_key, physicalize_one
from physicalize.wbc_config import TEACHER_GAINS, WBCConfig
from pipeline.clip import ObjectTrack, RobotClip
from pipeline.dataset import write_dataset
from pipeline.dataset.clips import robot_clips_to_episodes
from pipeline.geometry import Primitive
from pipeline.robot import actuator_profile, default_qpos
from pipeline.scene import build_scene
from pipeline.stage.paths import stage_dir
from pipeline.stage.run import StageRun

BOX = Primitive("box", (0.15, 0.15, 0.15))


def _clips() -> list[RobotClip]:
    model = build_scene().model
    stand = place_on_floor(model, np.repeat(default_qpos(actuator_profile("mjlab"))[None], 60, 0))
    jump = stand.copy()
    # the reference lurches 0.6 m in 0.12 s (5 m/s: under the datasets' 15 m/s bound on the root, far beyond the robot):
    # no physical motion follows it
    jump[:, 0] += 0.6 * np.clip((np.arange(60) - 29) / 6, 0.0, 1.0)
    box = np.tile([0.8, 0.0, 0.15, 1.0, 0.0, 0.0, 0.0], (60, 1))
    return [
        RobotClip(
            q,
            50,
            f"hand-made:{name}",
            objects=(ObjectTrack("box", BOX, box.copy(), None, 1.0, "hand-made"),),
            task=name,
        )
        for name, q in (("stand", stand), ("teleport", jump))
    ]


@pytest.fixture
def retargeted(tmp_path, monkeypatch):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    features, episodes = robot_clips_to_episodes(_clips())
    write_dataset(stage_dir("hand", "retargeted"), "lessmimic/hand-retargeted", 50, features, episodes)
    return tmp_path


def test_valid_clip_written_invalid_one_reported(retargeted, capsys):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    assert main(["physicalize", "--name", "hand"]) == 0
    out = capsys.readouterr().out
    assert "invalid: hand-made:teleport: " in out and "root_pos_err_max_m" in out
    root = stage_dir("hand", "physicalized")
    report = json.loads((root / "report.json").read_text())
    stand, jump = report["clips"]
    assert stand["valid"] and stand["replay_err_max_m"] <= 1e-6 and stand["object_pos_err_m"] < 0.01
    assert not jump["valid"] and jump["reason"]
    assert report["summary"]["valid_frac"] == 0.5 and report["summary"]["episodes_written"] == 1
    ds = LeRobotDataset("lessmimic/hand-physicalized", root=root)
    assert ds.num_episodes == 1 and ds.num_frames == 60
    for key, dim in (
        ("action", 29),
        ("observation.torque", 29),
        ("observation.state", 36),
        ("observation.qvel", 35),
        ("object.pose", 7),
        ("object.vel", 6),
        ("reference.state", 36),
    ):
        assert tuple(ds.features[key]["shape"]) == (dim,)
    assert "mjlab" in (root / "README.md").read_text()
    logs = retargeted / "hand" / "logs" / "physicalized"
    assert (logs / "001_hand-made_teleport.png").is_file() and (logs / "000_hand-made_stand.mcap").is_file()
    # every file stays as it was (the writer's lock and its failure snapshot come and go in datasets/hand/: the folder's
    # own mtime moves)
    written = {p: p.stat().st_mtime_ns for p in retargeted.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(["physicalize", "--name", "hand"]) == 0  # same input and options: up to date, nothing rewritten
    assert (
        capsys.readouterr().out
        == "physicalize: datasets/hand/physicalized/ is up to date (same input and options); nothing to do\n"
    )
    assert {p: p.stat().st_mtime_ns for p in retargeted.rglob("*") if p.is_file()} == written
    assert main(["physicalize", "--name", "hand", "--keep-invalid"]) == 2  # another option: needs --overwrite
    assert "physicalized: dataset: already exists; pass --overwrite" in capsys.readouterr().err
    assert main(["physicalize", "--name", "hand", "--overwrite", "--keep-invalid"]) == 0
    assert LeRobotDataset("lessmimic/hand-physicalized", root=root).num_episodes == 2
    features, episodes = robot_clips_to_episodes(
        _clips()[:1]
    )  # another retargeted dataset: the physicalized one is stale, and a rerun redoes it without --overwrite
    write_dataset(stage_dir("hand", "retargeted"), "lessmimic/hand-retargeted", 50, features, episodes, overwrite=True)
    assert main(["physicalize", "--name", "hand", "--keep-invalid"]) == 0
    assert LeRobotDataset("lessmimic/hand-physicalized", root=root).num_episodes == 1


def test_the_next_gain_set_is_tried_when_a_rollout_is_invalid():
    """Rejection sampling over the QP's gain sets: a set with 5% of the motors' torque cannot stand, so the next
    set's valid rollout is kept; when every set fails, the rollout that fell last is kept (the first on a tie) with
    the others' reasons. Measured: 2% of the torque falls at 0.32 s, 5% at 0.40 s."""
    stand = _clips()[0]
    weak = WBCConfig(effort_scale=0.05)
    _, roll, f, _ = physicalize_clip(stand, gains=(weak, TEACHER_GAINS[0]))
    assert f["valid"] and (f["teacher_gains"], f["teacher_attempts"]) == (1, 2) and roll.frames == 60
    _, _, f, _ = physicalize_clip(stand, gains=(weak, weak))
    assert not f["valid"] and (f["teacher_gains"], f["teacher_attempts"]) == (0, 2) and "; gain set 1: " in f["reason"]
    for order, kept in (((0.02, 0.05), 1), ((0.05, 0.02), 0)):
        _, roll, f, _ = physicalize_clip(stand, gains=tuple(WBCConfig(effort_scale=e) for e in order), search=None)
        assert f["teacher_gains"] == kept and f["fell_at_s"] == pytest.approx(0.40)
        assert f"; gain set {1 - kept}: fell at t=0.32 s" in f["reason"] and roll.fell_at == 20
    robot, _, f, _ = physicalize_clip(stand)
    assert (
        f["valid"] and (f["teacher_gains"], f["teacher_attempts"]) == (0, 1) and robot.provenance["teacher_gains"] == 0
    )


@needs_shared
def test_a_table_raised_by_hands_that_cannot_hold_it_is_rejected_a_slide_never():
    """The interact table lifted by its near edge needs a grip that pressing hands cannot give: rejected before
    tracking, with its figure. The InterMimic table dragged towards the body needs a pull too (outside the cone), but
    it slides on the floor: tracked, and reported valid or failed with its class, never rejected."""
    from pipeline.readers import read_clips
    from retarget.clip import retarget_clip

    lifted = retarget_clip(read_clips(SHARED_MOCAP / "interact" / "sub2_largetable_004.pt")[0])[0]
    robot, roll, f, _ = physicalize_clip(lifted)
    assert robot is None and roll is None and not f["valid"] and f["rejected"] == "needs a grip"
    assert f["take_kind"] == "lift" and f["reference_hold_infeasible_frac"] > 0.5
    assert f["reason"].startswith("rejected: needs a grip: pressing hands cannot give")
    dragged = retarget_clip(read_clips(SHARED_MOCAP / "intermimic" / "sub2_largetable_000.pt")[0])[0]
    robot, roll, f, _ = physicalize_clip(dragged)
    assert f["take_kind"] == "slide" and f["reference_hold_infeasible_frac"] > 0.5
    assert not f.get("rejected") and roll is not None and (f["valid"] or f["failure"])


def test_bad_arguments_are_one_line_errors(retargeted, capsys):
    assert main(["physicalize", "--name", "hand", "--profile", "nope"]) == 2
    assert main(["physicalize", "--name", "missing"]) == 2
    assert main(["physicalize", "--name", "hand", "--teacher", "residual"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 3
        and "unknown actuator profile" in err[0]
        and "no retargeted dataset" in err[1]
        and "unknown teacher" in err[2]
    )
    assert not stage_dir("hand", "physicalized").exists()


def test_a_finished_clip_is_resumed_from_the_cache(tmp_path):
    clip = _clips()[0]
    run = StageRun(tmp_path / "physicalized", "fp")
    run.begin(overwrite=False)
    first = run.map(physicalize_one, [(0, clip)], key=_clip_key)[0]
    assert len(list(run.clips.glob("*.pkl"))) == 1
    again = run.map(physicalize_one, [(0, clip)], key=_clip_key)[0]
    assert np.array_equal(first.rollout.action, again.rollout.action) and again.figures == first.figures


def test_a_kept_failure_past_the_value_ranges_is_reported_not_written():
    """``--keep-invalid`` writes a failed clip only when its simulated data are within the dataset's value ranges
    (which the writer would refuse the whole dataset for): a wrist flung 0.75 rad past its stop in a fall is reported
    with the reason and left out; the same failure within the ranges is written."""
    from dataclasses import replace

    from physicalize.stage import _writable

    teleport = physicalize_one((1, _clips()[1]), search=None)
    assert not teleport.figures["valid"] and _writable([teleport], 50) == [teleport]
    qpos = teleport.robot.qpos.copy()
    qpos[30, 7 + 19] = -2.72544  # left_wrist_roll_joint, range +-1.97 rad
    flung = replace(teleport, robot=replace(teleport.robot, qpos=qpos), figures=dict(teleport.figures))
    assert _writable([flung, teleport], 50) == [teleport]
    assert flung.figures["reason"].endswith(
        "; not written (--keep-invalid): frame 30: observation.state: element 26 is -2.72544: a joint past its range "
        "by more than 0.25 rad"
    )
