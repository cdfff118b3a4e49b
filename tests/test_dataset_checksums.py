"""Checksums and the chain by content (pipeline.dataset.checksums, pipeline.dataset.chain): a dataset whose bytes
changed, or whose upstream was rewritten after it was made, is never read on as if it were sound."""

import json
import os

import pytest
from mocap_paths import expect_input_error

from pipeline.clip import RobotClip
from pipeline.dataset.chain import stale_reason
from pipeline.dataset.checksums import read_checksums
from pipeline.dataset.clips import robot_clips_to_episodes
from pipeline.dataset.read import read_columns, read_info
from pipeline.dataset.schema import SIDECAR_CHECKSUMS
from pipeline.dataset.write import write_dataset
from pipeline.robot import actuator_profile, default_qpos
from pipeline.stage.run import StageRun
from pipeline.stage.state import dataset_fingerprint

DATA = "data/chunk-000/file-000.parquet"


def _write(root, frames: int = 10, overwrite: bool = False):
    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(frames, 0)
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    return write_dataset(root, f"lessmimic/t-{root.name}", 50, features, episodes, overwrite=overwrite)


def test_every_file_is_listed_with_its_sha256(tmp_path):
    root = _write(tmp_path / "retargeted")
    files = read_checksums(root)["files"]
    assert DATA in files and "meta/info.json" in files and "README.md" in files and SIDECAR_CHECKSUMS not in files
    assert len(files) == len([p for p in root.rglob("*") if p.is_file()]) - 1


def test_a_changed_file_with_its_size_and_mtime_restored_is_caught(tmp_path):
    root = _write(tmp_path / "physicalized")
    path = root / DATA
    st = path.stat()
    data = bytearray(path.read_bytes())
    data[len(data) // 2 : len(data) // 2 + 64] = bytes(b ^ 0xFF for b in data[len(data) // 2 : len(data) // 2 + 64])
    path.write_bytes(bytes(data))
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert path.stat().st_size == st.st_size and path.stat().st_mtime_ns == st.st_mtime_ns
    for call in (lambda: read_columns(root, ["observation.state"]), lambda: dataset_fingerprint(root)):
        expect_input_error(call, tmp_path, file=root, field=DATA, match="sha256 differs from the checksums")


def test_a_missing_info_or_an_added_data_file_is_named(tmp_path):
    root = _write(tmp_path / "features")
    (root / "data/chunk-000/file-001.parquet").write_bytes((root / DATA).read_bytes())
    expect_input_error(lambda: read_columns(root, ["observation.state"]), tmp_path, file=root,
                       field="data/chunk-000/file-001.parquet", match="not in the checksums")  # fmt: skip
    (root / "data/chunk-000/file-001.parquet").unlink()
    (root / "meta/info.json").unlink()
    expect_input_error(lambda: read_info(root), tmp_path, file=root, field="meta/info.json", match="missing")
    expect_input_error(lambda: dataset_fingerprint(root), tmp_path, file=root, field="meta/info.json")


def test_a_rewritten_upstream_makes_the_chain_below_it_stale(tmp_path, capsys):
    name = tmp_path / "x"
    human, retargeted, physicalized = (_write(name / s) for s in ("human", "retargeted", "physicalized"))
    assert read_checksums(retargeted)["upstream"] == {"stage": "human", "fingerprint": dataset_fingerprint(human)}
    assert stale_reason(retargeted) is None and stale_reason(physicalized) is None
    before = dataset_fingerprint(retargeted)
    _write(human, overwrite=True)  # the same content again: nothing is stale
    assert stale_reason(physicalized) is None
    _write(human, frames=12, overwrite=True)  # e.g. `retarget --overwrite` whose clips all failed
    assert stale_reason(retargeted) == "stale: its upstream human/ was rewritten after it was made from it"
    assert stale_reason(physicalized) == "stale: its upstream retargeted/ is " + stale_reason(retargeted)
    e = expect_input_error(lambda: read_columns(physicalized, ["observation.state"]), tmp_path, file=physicalized,
                           field="chain")  # fmt: skip
    assert str(e).endswith("; rerun `lessmimic retarget --name x`")
    expect_input_error(lambda: dataset_fingerprint(retargeted), tmp_path, file=retargeted, field="chain")
    # a rerun redoes a stale dataset without --overwrite (another dataset there still needs it)
    run = StageRun(retargeted, "fp-new")
    run.begin(overwrite=False)
    assert run.replaces and "retargeted: stale: its upstream human/ was rewritten" in capsys.readouterr().out
    _write(retargeted, frames=12, overwrite=run.replaces)
    assert stale_reason(retargeted) is None and dataset_fingerprint(retargeted) != before
    assert stale_reason(physicalized) == "stale: its upstream retargeted/ was rewritten after it was made from it"


def test_a_dataset_without_checksums_is_read_as_before(tmp_path):
    root = _write(tmp_path / "retargeted")
    (root / SIDECAR_CHECKSUMS).unlink()  # a dataset LeRobot (or an older toolkit) wrote
    assert read_columns(root, ["observation.state"])["observation.state"].shape == (10, 36)
    assert len(dataset_fingerprint(root)) == 64


def test_the_manifest_is_json_lerobot_does_not_read(tmp_path):
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    root = _write(tmp_path / "retargeted")
    assert json.loads((root / SIDECAR_CHECKSUMS).read_text())["algorithm"] == "sha256"
    assert LeRobotDataset("lessmimic/t-retargeted", root=root).num_frames == 10


@pytest.mark.parametrize("stage", ["human", "retargeted"])
def test_a_dataset_outside_a_chain_is_never_stale(tmp_path, stage):
    root = _write(tmp_path / stage)
    assert read_checksums(root)["upstream"] is None and stale_reason(root) is None


def test_impossible_values_are_refused_at_write_and_caught_by_verify(tmp_path, capsys):
    import numpy as np
    import pyarrow as pa
    import pyarrow.parquet as pq

    from lessmimic.cli import main
    from pipeline.dataset.checksums import write_checksums

    qpos = default_qpos(actuator_profile("mjlab"))[None].repeat(10, 0)
    qpos[4, 7] += 6.0  # a hip bent 6 rad: far beyond its range
    features, episodes = robot_clips_to_episodes([RobotClip(qpos, 50, "hand-made:stand", task="stand")])
    where = "dataset lessmimic/t-bad episode 0"
    expect_input_error(
        lambda: write_dataset(tmp_path / "bad", "lessmimic/t-bad", 50, features, episodes),
        tmp_path,
        file=where,
        field="observation.state",
        frame=4,
        match="element 7 is .*past its range",
    )
    root = _write(tmp_path / "physicalized")
    assert main(["verify", str(root)]) == 0
    assert capsys.readouterr().out.startswith(f"{root}: ok: 8 files")
    table = pq.read_table(root / DATA)  # a joint velocity of 344 rad/s, checksums rewritten to match: ranges catch it
    qvel = np.stack(table.column("observation.qvel").to_numpy(zero_copy_only=False)).astype(np.float32)
    qvel[3, 10] = 344.0
    column = pa.FixedSizeListArray.from_arrays(pa.array(qvel.reshape(-1)), qvel.shape[1])
    table = table.set_column(table.schema.get_field_index("observation.qvel"), table.schema.field("observation.qvel"),
                             column)  # fmt: skip
    pq.write_table(table, root / DATA)
    assert main(["verify", str(root)]) == 2
    assert "sha256 differs" in capsys.readouterr().err
    write_checksums(root, read_checksums(root)["upstream"])
    assert main(["verify", str(root)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"error: {root} episode 0: frame 3: observation.qvel: element 10 is 344")


def test_load_and_verify_name_what_is_wrong_in_one_line(tmp_path, capsys, monkeypatch):
    from lessmimic.cli import main

    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    root = _write(tmp_path / "x" / "physicalized")
    assert main(["verify", "x"]) == 0 and main(["load", str(root)]) == 0
    capsys.readouterr()
    (root / "meta/info.json").unlink()
    for cmd in (["load", str(root)], ["verify", "x"]):
        assert main(cmd) == 2
        assert capsys.readouterr().err.strip() == f"error: {root}: meta/info.json: missing (the checksums list it): " \
            "the dataset is incomplete"  # fmt: skip
    assert main(["load", "owner/not-downloaded"]) == 2  # offline (the tests' HF_HUB_OFFLINE=1)
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("error: owner/not-downloaded: hub: not downloaded here, and the Hub")
