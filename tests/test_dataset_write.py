"""The LeRobot v3.0 writer: LeRobot 0.4.4's own loader reads back exactly what was written; the
layout matches what LeRobot writes itself; bad input fails with precise errors; writes are atomic."""

import json
import os

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
import torch

from pipeline.dataset import Episode, Feature, merge_datasets, read_episode_meta, write_dataset
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.write import CODEBASE_VERSION, INDEX_COLUMNS, QUANTILES
from pipeline.errors import InputError

LeRobotDataset = pytest.importorskip("lerobot.datasets.lerobot_dataset").LeRobotDataset

FPS = 30
FEATURES = [
    Feature("observation.state", "float32", tuple(f"s{i}" for i in range(6)), "state", "m"),
    Feature("contact", "bool", ("pelvis.left", "pelvis.right", "hand"), "contact flags"),
    Feature("source_frame", "int64", ("source_frame",), "frame in the source"),
]
TASKS = ["walk", "sit down", "walk"]


def make_episode(T: int, task: str, seed: int, **meta) -> Episode:
    rng = np.random.default_rng(seed)
    data = {
        "observation.state": rng.normal(size=(T, 6)).astype(np.float32),
        "contact": rng.random((T, 3)) < 0.5,
        "source_frame": np.arange(T, dtype=np.int64) + 100 * seed,
    }
    return Episode(task, data, {"source": f"clip{seed}.bvh", "synthetic": seed % 2 == 1, **meta})


def make_episodes(lengths=(7, 5, 9), tasks=TASKS, seed0=0):
    return [make_episode(T, task, seed0 + k) for k, (T, task) in enumerate(zip(lengths, tasks))]


def assert_frames_equal(ds, episodes):
    """Every frame of a LeRobotDataset equals the written episodes, index columns included."""
    i, task_ids = 0, {}
    assert len(ds) == sum(len(e.data["source_frame"]) for e in episodes)
    for e, ep in enumerate(episodes):
        task_ids.setdefault(ep.task, len(task_ids))
        T = len(ep.data["source_frame"])
        for t in range(T):
            item = ds[i]
            np.testing.assert_array_equal(
                item["observation.state"].numpy(), ep.data["observation.state"][t].astype(np.float32)
            )
            np.testing.assert_array_equal(item["contact"].numpy(), ep.data["contact"][t])
            assert item["source_frame"].item() == ep.data["source_frame"][t]
            assert item["timestamp"].item() == np.float32(t / FPS)
            assert (item["frame_index"].item(), item["episode_index"].item(), item["index"].item()) == (t, e, i)
            assert item["task_index"].item() == task_ids[ep.task] and item["task"] == ep.task
            i += 1


def test_lerobot_loads_frame_by_frame(tmp_path):
    eps = make_episodes()
    root = write_dataset(
        tmp_path / "ds", "tester/ds", FPS, FEATURES, eps, card=DatasetCard("Test set", stage="retarget")
    )
    ds = LeRobotDataset("tester/ds", root=root)
    assert ds.meta.total_episodes == 3 and ds.meta.total_tasks == 2 and ds.fps == FPS
    assert ds.meta.robot_type == "unitree_g1"
    assert ds.meta.features["contact"]["names"] == ["pelvis.left", "pelvis.right", "hand"]
    assert_frames_equal(ds, eps)
    # episode ranges and stats as LeRobot sees them
    assert [ds.meta.episodes[k]["dataset_from_index"] for k in range(3)] == [0, 7, 12]
    all_state = np.concatenate([e.data["observation.state"] for e in eps])
    np.testing.assert_allclose(ds.meta.stats["observation.state"]["mean"], all_state.mean(0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(ds.meta.stats["observation.state"]["std"], all_state.std(0), rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(ds.meta.stats["observation.state"]["min"], all_state.min(0))
    assert ds.meta.stats["index"]["count"].tolist() == [21]
    # sidecar and card are there; LeRobot ignored them
    metas = read_episode_meta(root)
    assert [m["source"] for m in metas] == ["clip0.bvh", "clip1.bvh", "clip2.bvh"]
    assert [m["episode_index"] for m in metas] == [0, 1, 2] and metas[1]["synthetic"] is True
    assert (root / "README.md").read_text().startswith("---\n")
    assert not list(tmp_path.glob(".*"))  # no staging left behind


def test_constants_match_lerobot():
    from lerobot.datasets import compute_stats, lerobot_dataset, utils

    assert CODEBASE_VERSION == lerobot_dataset.CODEBASE_VERSION
    assert {k: v["dtype"] for k, v in utils.DEFAULT_FEATURES.items()} == INDEX_COLUMNS
    assert list(utils.DEFAULT_FEATURES) == list(INDEX_COLUMNS)
    assert tuple(compute_stats.DEFAULT_QUANTILES) == QUANTILES


def test_layout_matches_stock_lerobot(tmp_path):
    """Same data through LeRobot's create/add_frame/save_episode/finalize and through us:
    identical info.json, parquet schemas, tasks, episode index ranges and stats keys.
    (A stock 1-element feature cannot be written with numpy 2.4 -- see the report -- so none here.)"""
    feats = FEATURES[:2]
    eps = [Episode(e.task, {k: e.data[k] for k in ("observation.state", "contact")}) for e in make_episodes((4, 3, 2))]
    stock = LeRobotDataset.create(
        "tester/stock",
        fps=FPS,
        features={f.name: {"dtype": f.dtype, "shape": f.shape, "names": list(f.names)} for f in feats},
        root=tmp_path / "stock",
        robot_type="unitree_g1",
        use_videos=False,
    )
    for ep in eps:
        for t in range(len(ep.data["contact"])):
            stock.add_frame({**{k: v[t] for k, v in ep.data.items()}, "task": ep.task})
        stock.save_episode()
    stock.finalize()
    ours = write_dataset(tmp_path / "ours", "tester/ours", FPS, feats, eps)
    s_root = tmp_path / "stock"
    assert json.loads((ours / "meta/info.json").read_text()) == json.loads((s_root / "meta/info.json").read_text())
    for rel in ("data/chunk-000/file-000.parquet", "meta/episodes/chunk-000/file-000.parquet"):
        a, b = pq.read_schema(ours / rel), pq.read_schema(s_root / rel)
        assert a.remove_metadata() == b.remove_metadata(), rel
    hf_a = json.loads(pq.read_schema(ours / "data/chunk-000/file-000.parquet").metadata[b"huggingface"])
    hf_b = json.loads(pq.read_schema(s_root / "data/chunk-000/file-000.parquet").metadata[b"huggingface"])
    assert hf_a["info"] == hf_b["info"]
    pd.testing.assert_frame_equal(
        pd.read_parquet(ours / "meta/tasks.parquet"), pd.read_parquet(s_root / "meta/tasks.parquet")
    )
    ea, eb = (
        pd.read_parquet(ours / "meta/episodes/chunk-000/file-000.parquet"),
        pd.read_parquet(s_root / "meta/episodes/chunk-000/file-000.parquet"),
    )
    cols = ["episode_index", "length", "dataset_from_index", "dataset_to_index", "data/chunk_index", "data/file_index"]
    pd.testing.assert_frame_equal(ea[cols], eb[cols])
    assert ea["tasks"].map(list).tolist() == eb["tasks"].map(list).tolist()
    for col in ea.columns:  # exact stats agree; quantiles differ (LeRobot's are histogram estimates)
        if col.startswith("stats/") and col.rsplit("/", 1)[1] in ("min", "max", "mean", "std", "count"):
            # LeRobot accumulates float32 data in float32 (std = sqrt(E[x^2] - E[x]^2)); ours is float64
            np.testing.assert_allclose(
                np.stack(ea[col]).astype(float), np.stack(eb[col]).astype(float), rtol=1e-4, atol=1e-5, err_msg=col
            )
    sa, sb = (json.loads((r / "meta/stats.json").read_text()) for r in (ours, s_root))
    assert {k: set(v) for k, v in sa.items()} == {k: set(v) for k, v in sb.items()}
    pa_t, pb_t = (
        pq.read_table(ours / "data/chunk-000/file-000.parquet"),
        pq.read_table(s_root / "data/chunk-000/file-000.parquet"),
    )
    assert pa_t.to_pylist() == pb_t.to_pylist()
    # our training reader serves the LeRobot-written dataset the same way
    from pipeline.dataset import WindowDataset

    wa, wb = (WindowDataset(r, ["observation.state", "contact"], history=3) for r in (ours, s_root))
    for k, v in wa.sample(range(len(wa))).items():
        assert torch.equal(v, wb.sample(range(len(wb)))[k]), k


def test_many_files_and_chunks_load(tmp_path):
    eps = make_episodes((40, 30, 50, 20), ["a", "b", "c", "a"])
    root = write_dataset(tmp_path / "multi", "tester/multi", FPS, FEATURES, eps, data_file_size_mb=0.002, chunks_size=2)
    files = sorted(p.relative_to(root).as_posix() for p in (root / "data").glob("*/*.parquet"))
    assert len(files) == 4 and files[-1].startswith("data/chunk-001/")
    assert_frames_equal(LeRobotDataset("tester/multi", root=root), eps)


def test_merge_shards(tmp_path):
    a = write_dataset(
        tmp_path / "a",
        "tester/a",
        FPS,
        FEATURES,
        make_episodes((4, 6), ["walk", "sit"]),
        card=DatasetCard("A", provenance=["shard a"]),
    )
    b = write_dataset(
        tmp_path / "b",
        "tester/b",
        FPS,
        FEATURES,
        make_episodes((5, 3), ["push", "walk"], seed0=10),
        card=DatasetCard("B", provenance=["shard b"]),
    )
    out = merge_datasets([a, b], tmp_path / "merged", "tester/merged")
    eps = make_episodes((4, 6), ["walk", "sit"]) + make_episodes((5, 3), ["push", "walk"], seed0=10)
    ds = LeRobotDataset("tester/merged", root=out)
    assert ds.meta.total_episodes == 4 and list(ds.meta.tasks.index) == ["walk", "sit", "push"]
    assert_frames_equal(ds, eps)
    assert [m["source"] for m in read_episode_meta(out)] == ["clip0.bvh", "clip1.bvh", "clip10.bvh", "clip11.bvh"]
    assert "shard a" in (out / "README.md").read_text() and "shard b" in (out / "README.md").read_text()
    # a shard with another spec or fps is refused
    c = write_dataset(tmp_path / "c", "tester/c", 50, FEATURES, make_episodes((3,), ["walk"]))
    with pytest.raises(InputError, match="fps.*cannot merge"):
        merge_datasets([a, c], tmp_path / "bad", "tester/bad")
    d = write_dataset(
        tmp_path / "d",
        "tester/d",
        FPS,
        FEATURES[:2],
        [Episode("x", {k: v for k, v in make_episode(3, "x", 0).data.items() if k != "source_frame"})],
    )
    with pytest.raises(InputError, match="features.*cannot merge"):
        merge_datasets([a, d], tmp_path / "bad", "tester/bad")
    assert not (tmp_path / "bad").exists()


def test_lerobot_aggregate_accepts_our_shards(tmp_path):
    from lerobot.datasets.aggregate import aggregate_datasets

    a = write_dataset(tmp_path / "a", "tester/a", FPS, FEATURES, make_episodes((4, 6), ["walk", "sit"]))
    b = write_dataset(tmp_path / "b", "tester/b", FPS, FEATURES, make_episodes((5,), ["push"], seed0=10))
    aggregate_datasets(["tester/a", "tester/b"], "tester/agg", roots=[a, b], aggr_root=tmp_path / "agg")
    ds = LeRobotDataset("tester/agg", root=tmp_path / "agg")
    assert_frames_equal(ds, make_episodes((4, 6), ["walk", "sit"]) + make_episodes((5,), ["push"], seed0=10))


# --- bad input -----------------------------------------------------------------------------------


@pytest.mark.parametrize("repo_id", ["a/b/c", "../x", "x/..", "a\\b", "", "-x", "we ird"])
def test_bad_repo_id(tmp_path, repo_id):
    with pytest.raises(InputError, match="repo_id"):
        write_dataset(tmp_path / "ds", repo_id, FPS, FEATURES, make_episodes())


@pytest.mark.parametrize("name", ["..", "a b", ".hidden"])
def test_bad_folder_name(tmp_path, name):
    with pytest.raises(InputError, match="dataset folder name"):
        write_dataset(tmp_path / name, "tester/ds", FPS, FEATURES, make_episodes())


def test_existing_dataset_needs_overwrite(tmp_path):
    root = write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, make_episodes())
    with pytest.raises(InputError, match="already exists; pass --overwrite"):
        write_dataset(root, "tester/ds", FPS, FEATURES, make_episodes((2,), ["new"]))
    write_dataset(root, "tester/ds", FPS, FEATURES, make_episodes((2,), ["new"]), overwrite=True)
    assert json.loads((root / "meta/info.json").read_text())["total_frames"] == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def _bad(ep_data_update, T=5):
    ep = make_episode(T, "walk", 0)
    ep.data.update(ep_data_update(ep.data) if callable(ep_data_update) else ep_data_update)
    return [make_episode(3, "walk", 1), ep]


def _nan_at_3(d):
    x = d["observation.state"].copy()
    x[3, 2] = np.nan
    return {"observation.state": x}


@pytest.mark.parametrize(
    "episodes, match",
    [
        (_bad(_nan_at_3), r"dataset tester/ds episode 1: frame 3: observation.state: is NaN or infinite"),
        (
            _bad({"observation.state": np.zeros((5, 7), np.float32)}),
            r"episode 1: observation.state: shape \(5, 7\) does not match \(T, 6\)",
        ),
        (
            _bad(
                {
                    "observation.state": np.zeros((0, 6), np.float32),
                    "contact": np.zeros((0, 3), bool),
                    "source_frame": np.zeros(0, int),
                }
            ),
            r"episode 1: .*has zero frames",
        ),
        (_bad({"source_frame": np.arange(5) + 0.5}), r"episode 1: source_frame: has floating dtype float64"),
        (
            _bad({"contact": np.full((5, 3), 2)}),
            r"episode 1: frame 0: contact: bool feature holds a value other than 0 or 1",
        ),
        (_bad({"contact": np.zeros((4, 3), bool)}), r"episode 1: data: features have different frame counts"),
        (_bad({"extra": np.zeros((5, 1))}), r"episode 1: data: missing features \[\], unknown features \['extra'\]"),
        (
            _bad({"observation.state": np.full((5, 6), 1e39)}),
            r"episode 1: frame 0: observation.state: is NaN or infinite \(in float32\)",
        ),
        ([], r"no episodes"),
        ([Episode("", make_episode(3, "x", 0).data)], r"episode 0: task: must be a non-empty string"),
        ([Episode("x", make_episode(3, "x", 0).data, {"bad": object()})], r"episode 0: meta: is not JSON-serialisable"),
        ([Episode("x", make_episode(3, "x", 0).data, {"task": "y"})], r"episode 0: meta: keys \['task'\] are reserved"),
    ],
)
def test_bad_episode_data(tmp_path, episodes, match):
    with pytest.raises(InputError, match=match):
        write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, episodes)
    assert list(tmp_path.iterdir()) == []  # nothing left: no dataset, no staging folder


def test_float64_is_converted_to_float32(tmp_path):
    ep = make_episode(4, "walk", 0)
    x = np.random.default_rng(5).normal(size=(4, 6))  # float64
    ep.data["observation.state"] = x
    root = write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, [ep])
    ds = LeRobotDataset("tester/ds", root=root)
    assert ds[2]["observation.state"].dtype.is_floating_point
    np.testing.assert_array_equal(ds[2]["observation.state"].numpy(), x[2].astype(np.float32))


def test_bad_fps_and_features(tmp_path):
    with pytest.raises(InputError, match="fps: must be a positive integer"):
        write_dataset(tmp_path / "ds", "tester/ds", 29.97, FEATURES, make_episodes())
    with pytest.raises(InputError, match="card fps: 25 differs from the dataset fps 30"):
        write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, make_episodes(), card=DatasetCard("x", fps=25))
    with pytest.raises(ValueError, match="reserved"):
        Feature("index", "int64", ("i",), "")
    with pytest.raises(ValueError, match="dtype"):
        Feature("x", "float64", ("i",), "")
    with pytest.raises(ValueError, match="contains '/'"):
        Feature("a/b", "float32", ("i",), "")


def test_failure_mid_write_leaves_nothing(tmp_path):
    def episodes():
        yield make_episode(5, "walk", 0)
        yield make_episode(5, "walk", 1)
        raise RuntimeError("worker crashed")

    with pytest.raises(RuntimeError, match="worker crashed"):
        write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, episodes())
    assert list(tmp_path.iterdir()) == []
    # and an existing dataset survives a failed overwrite untouched
    root = write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, make_episodes())
    before = {p: p.read_bytes() for p in root.rglob("*") if p.is_file()}
    with pytest.raises(RuntimeError):
        write_dataset(root, "tester/ds", FPS, FEATURES, episodes(), overwrite=True)
    assert {p: p.read_bytes() for p in root.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ds"]


def test_staging_left_by_a_killed_writer_is_removed(tmp_path):
    import subprocess
    import sys

    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True, check=True
    )
    pid = int(dead.stdout)
    orphan = tmp_path / f".ds.staging-{pid}-deadbeef"
    (orphan / "meta").mkdir(parents=True)
    alive = tmp_path / f".ds.staging-{os.getpid()}-cafecafe"  # a writer still running: kept
    alive.mkdir()
    write_dataset(tmp_path / "ds", "tester/ds", FPS, FEATURES, make_episodes())
    assert not orphan.exists() and alive.exists()
