"""Stage fingerprints: they change with an input file or an option, not with reading."""

import json
import os

from pipeline.dataset import write_dataset
from pipeline.dataset.clips import robot_clips_to_episodes
from pipeline.stage.state import KEY, dataset_fingerprint, files_fingerprint, fingerprint, up_to_date, up_to_date_line


def test_fingerprint_changes_with_an_option_not_with_key_order():
    assert fingerprint(input="a", height=None) == fingerprint(height=None, input="a")
    assert fingerprint(input="a", height=None) != fingerprint(input="a", height=1.7)
    assert fingerprint(input="a", keep_invalid=False) != fingerprint(input="a", keep_invalid=True)


def test_files_fingerprint_changes_when_an_input_file_changes(tmp_path):
    folder = tmp_path / "takes"
    (folder / "sub").mkdir(parents=True)
    (folder / "a.bvh").write_text("one")
    (folder / "sub" / "b.bvh").write_text("two")
    first = files_fingerprint([folder])
    assert files_fingerprint([folder]) == first and files_fingerprint([str(folder)]) == first
    st = (folder / "sub" / "b.bvh").stat()
    os.utime(
        folder / "sub" / "b.bvh", ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000)
    )  # touched: same bytes, new mtime
    touched = files_fingerprint([folder])
    assert touched != first
    (folder / "c.bvh").write_text("three")  # a file added
    assert files_fingerprint([folder]) != touched
    assert files_fingerprint([folder / "a.bvh"]) != files_fingerprint([folder / "sub" / "b.bvh"])
    assert files_fingerprint([tmp_path / "missing"]) != files_fingerprint([folder])


def test_by_content_ignores_mtime_and_folder_but_not_bytes(tmp_path):
    a, b = tmp_path / "x" / "gen.py", tmp_path / "y" / "gen.py"
    for p in (a, b):
        p.parent.mkdir()
        p.write_text("print(1)\n")
    os.utime(b, ns=(0, 0))
    assert files_fingerprint([a], by_content=True) == files_fingerprint([b], by_content=True)  # a fresh clone elsewhere
    b.write_text("print(2)\n")
    assert files_fingerprint([a], by_content=True) != files_fingerprint([b], by_content=True)


def test_dataset_fingerprint_stable_across_reads_new_on_new_content(tmp_path):
    """The fingerprint is of the data (issue 55): the same content rewritten keeps it, other content changes it."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from pipeline.clip import RobotClip
    from pipeline.robot import actuator_profile, default_qpos

    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    root = tmp_path / "retargeted"
    write_dataset(root, "lessmimic/t-retargeted", 50, features, episodes)
    first = dataset_fingerprint(root)
    ds = LeRobotDataset("lessmimic/t-retargeted", root=root)
    assert ds.num_frames == 10 and ds[3]["observation.state"].shape == (36,)
    assert dataset_fingerprint(root) == first
    (root / "report.json").write_text("{}")  # a stage's report beside the data is not the data
    assert dataset_fingerprint(root) == first
    write_dataset(root, "lessmimic/t-retargeted", 50, features, episodes, overwrite=True)
    assert dataset_fingerprint(root) == first
    features, episodes = robot_clips_to_episodes([RobotClip(qpos[:9], 50, "hand-made:stand", task="stand")])
    write_dataset(root, "lessmimic/t-retargeted", 50, features, episodes, overwrite=True)
    assert dataset_fingerprint(root) != first


def test_up_to_date_returns_the_matching_report(tmp_path):
    report = tmp_path / "report.json"
    assert up_to_date(report, "abc") is None  # no report
    report.write_text("not json")
    assert up_to_date(report, "abc") is None
    report.write_text(json.dumps({KEY: "abc", "clips": [1]}))
    assert up_to_date(report, "abc") == {KEY: "abc", "clips": [1]}
    assert up_to_date(report, "abd") is None
    assert up_to_date_line("retarget", "default", "retargeted") == (
        "retarget: datasets/default/retargeted/ is up to date (same input and options); nothing to do"
    )
