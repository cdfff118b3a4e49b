"""Publishing to a local stand-in of the hub client, then loading back through LeRobot's loader."""

import shutil
from pathlib import Path

import numpy as np
import pytest
from huggingface_hub import metadata_load
from huggingface_hub.utils import filter_repo_objects

from pipeline.dataset import Episode, Feature, write_dataset
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.hub import load, publish
from pipeline.errors import InputError

pytest.importorskip("lerobot")

FEATURES = [
    Feature("observation.state", "float32", ("a", "b", "c"), "state", "m"),
    Feature("contact", "bool", ("l", "r"), "contacts"),
]


class LocalHub:
    """Stand-in for ``huggingface_hub.HfApi``: repos are folders under ``base``."""

    def __init__(self, base: Path):
        self.base, self.calls, self.tags = base, [], {}

    def create_repo(self, repo_id, *, repo_type=None, private=None, exist_ok=False):
        self.calls.append(("create_repo", repo_id, repo_type, private))
        (self.base / repo_id).mkdir(parents=True, exist_ok=exist_ok)
        return f"https://hub.local/datasets/{repo_id}"

    def upload_folder(
        self,
        *,
        repo_id,
        folder_path,
        repo_type=None,
        ignore_patterns=None,
        allow_patterns=None,
        commit_message=None,
        **_,
    ):
        self.calls.append(("upload_folder", repo_id, repo_type))
        src = Path(folder_path)
        files = [p.relative_to(src).as_posix() for p in src.rglob("*") if p.is_file()]
        for rel in filter_repo_objects(files, allow_patterns=allow_patterns, ignore_patterns=ignore_patterns):
            (self.base / repo_id / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src / rel, self.base / repo_id / rel)

    def delete_tag(self, repo_id, *, tag, repo_type=None):
        self.calls.append(("delete_tag", repo_id, tag))
        self.tags.pop((repo_id, tag), None)

    def create_tag(self, repo_id, *, tag, repo_type=None, revision=None):
        self.calls.append(("create_tag", repo_id, tag, repo_type))
        self.tags[(repo_id, tag)] = revision


@pytest.fixture
def dataset(tmp_path):
    rng = np.random.default_rng(0)
    eps = [
        Episode(
            t, {"observation.state": rng.normal(size=(T, 3)).astype(np.float32), "contact": rng.random((T, 2)) < 0.5}
        )
        for t, T in (("walk", 6), ("sit", 4))
    ]
    card = DatasetCard(
        "Hub test", description="Two episodes.", provenance=["unit test"], synthetic=True, actuator_profile="mjlab"
    )
    root = write_dataset(tmp_path / "ds", "tester/ds", 30, FEATURES, eps, card=card)
    (root / ".cache").mkdir()
    (root / ".cache/leftover.lock").write_text("x")
    return root


def test_publish_then_load(tmp_path, dataset):
    hub = LocalHub(tmp_path / "hub")
    url = publish(dataset, "tester/ds", private=True, api=hub)
    assert url.endswith("tester/ds")
    assert [c[0] for c in hub.calls] == ["create_repo", "upload_folder", "delete_tag", "create_tag"]
    assert hub.calls[0] == ("create_repo", "tester/ds", "dataset", True) and ("tester/ds", "v3.0") in hub.tags
    remote = tmp_path / "hub/tester/ds"
    assert not (remote / ".cache").exists()
    assert sorted(
        p.relative_to(dataset).as_posix() for p in dataset.rglob("*") if p.is_file() and ".cache" not in p.parts
    ) == sorted(p.relative_to(remote).as_posix() for p in remote.rglob("*") if p.is_file())
    card = metadata_load(remote / "README.md")
    assert card["tags"][:3] == ["LeRobot", "unitree-g1", "humanoid"] and "synthetic" in card["tags"]
    assert card["task_categories"] == ["robotics"] and card["license"] == "apache-2.0"
    assert card["configs"] == [{"config_name": "default", "data_files": "data/*/*.parquet"}]
    a, b = load(dataset), load(remote)
    c = load("tester/ds", root=remote)  # by repo id, offline: LeRobot finds the local copy
    assert a.repo_id == "tester/ds" and len(a) == len(b) == len(c) == 10
    for i in range(len(a)):
        x, y, z = a[i], b[i], c[i]
        for k in ("observation.state", "contact", "index", "episode_index", "timestamp"):
            assert np.array_equal(x[k].numpy(), y[k].numpy()) and np.array_equal(x[k].numpy(), z[k].numpy())
        assert x["task"] == y["task"] == z["task"]


def test_publish_refuses_bad_input(tmp_path, dataset):
    hub = LocalHub(tmp_path / "hub")
    with pytest.raises(InputError, match="owner/name"):
        publish(dataset, "ds", api=hub)
    with pytest.raises(InputError, match="repo_id"):
        publish(dataset, "tester/../x", api=hub)
    (dataset / "meta/stats.json").unlink()
    with pytest.raises(InputError, match="meta/stats.json: is missing"):
        publish(dataset, "tester/ds", api=hub)
    with pytest.raises(InputError, match="not a LeRobot dataset"):
        publish(tmp_path / "nothing", "tester/ds", api=hub)
    assert hub.calls == []
    with pytest.raises(InputError, match="not a LeRobot dataset folder"):
        load(tmp_path / "nothing")
