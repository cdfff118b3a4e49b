"""Reading datasets from parquet: history windows equal LeRobot's ``delta_timestamps`` items."""

import numpy as np
import pytest
import torch

from pipeline.dataset import Episode, Feature, WindowDataset, iter_episodes, read_columns, read_features, write_dataset
from pipeline.errors import InputError

LeRobotDataset = pytest.importorskip("lerobot.datasets.lerobot_dataset").LeRobotDataset

FPS = 50
H = 5
FEATURES = [
    Feature("observation.state", "float32", tuple(f"q{i}" for i in range(4)), "state", "rad"),
    Feature("contact", "bool", ("l", "r"), "contacts"),
    Feature("source_frame", "int64", ("source_frame",), "source frame"),
]
LENGTHS = (3, 8, 1, 6)  # a 3-frame and a 1-frame episode: windows padded on every step


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    rng = np.random.default_rng(1)
    eps = [
        Episode(
            f"task{k % 2}",
            {
                "observation.state": rng.normal(size=(T, 4)).astype(np.float32),
                "contact": rng.random((T, 2)) < 0.5,
                "source_frame": np.arange(T) + 10 * k,
            },
            {"k": k},
        )
        for k, T in enumerate(LENGTHS)
    ]
    root = write_dataset(tmp_path_factory.mktemp("read") / "ds", "tester/ds", FPS, FEATURES, eps)
    return root, eps


def test_windows_equal_lerobot_delta_timestamps(dataset):
    root, _ = dataset
    keys = ["observation.state", "contact", "source_frame"]
    deltas = [k / FPS for k in range(-H + 1, 1)]
    ref = LeRobotDataset("tester/ds", root=root, delta_timestamps={k: deltas for k in keys})
    ours = WindowDataset(root, keys, history=H)
    assert len(ours) == len(ref) == sum(LENGTHS)
    starts = np.cumsum((0,) + LENGTHS[:-1])
    for i in sorted({*starts.tolist(), *(starts + 1).tolist(), 5, 9, 10, len(ref) - 1}):
        a, b = ref[i], ours[i]
        for k in keys:
            want = a[k].numpy().reshape(H, -1)  # LeRobot gives a 1-element feature as (H,)
            assert b[k].shape == (H, FEATURES[keys.index(k)].shape[0])
            np.testing.assert_array_equal(b[k].numpy(), want, err_msg=f"{k} at {i}")
            np.testing.assert_array_equal(b[f"{k}_is_pad"].numpy(), a[f"{k}_is_pad"].numpy(), err_msg=f"{k} pad at {i}")
        assert b["episode_index"].item() == a["episode_index"].item() and b["index"].item() == i


def test_batched_sample_equals_items(dataset):
    root, _ = dataset
    ds = WindowDataset(root, ["observation.state", "contact"], history=H)
    idx = np.array([0, 3, 4, 11, 17, 2])
    batch = ds.sample(idx)
    assert batch["observation.state"].shape == (6, H, 4) and batch["contact_is_pad"].shape == (6, H)
    assert batch["observation.state"].dtype == torch.float32 and batch["contact"].dtype == torch.bool
    for j, i in enumerate(idx):
        item = ds[int(i)]
        for k in ("observation.state", "contact", "observation.state_is_pad"):
            assert torch.equal(batch[k][j], item[k])
    loader = torch.utils.data.DataLoader(ds, batch_size=4, shuffle=False)
    first = next(iter(loader))
    assert torch.equal(first["observation.state"], ds.sample([0, 1, 2, 3])["observation.state"])
    with pytest.raises(IndexError):
        ds[len(ds)]


def test_history_one_and_unknown_key(dataset):
    root, eps = dataset
    ds = WindowDataset(root, ["observation.state"], history=1)
    np.testing.assert_array_equal(ds[3]["observation.state"][0].numpy(), eps[1].data["observation.state"][0])
    assert not ds[3]["observation.state_is_pad"].any()
    with pytest.raises(InputError, match="unknown features"):
        WindowDataset(root, ["nope"])


def test_iter_episodes_and_columns_round_trip(dataset):
    root, eps = dataset
    back = list(iter_episodes(root))
    assert [e.task for e in back] == [e.task for e in eps] and [e.meta for e in back] == [{"k": k} for k in range(4)]
    for a, b in zip(back, eps):
        for k in b.data:
            np.testing.assert_array_equal(a.data[k], np.asarray(b.data[k]).reshape(len(b.data[k]), -1))
    assert read_features(root) == tuple(FEATURES)
    cols = read_columns(root, ["index", "frame_index"])
    assert cols["index"][:, 0].tolist() == list(range(sum(LENGTHS)))
