"""Dataset write and training-loader throughput: ours vs stock LeRobot 0.4.4, side by side.

    python bench/bench_dataset.py [--episodes 100] [--frames 300] [--stock-episodes 8] [--stock-items 300]

Same data for both writers: per frame a 36-float state, a 20-float velocity and 4 contact
booleans (60 values). The stock writer is LeRobotDataset.create + add_frame + save_episode +
finalize on the first ``--stock-episodes`` episodes (it is ~200x slower). The loader serves
5-frame history windows: ours batched (WindowDataset.sample, batches of 1024) and per item
(ds[i]); stock is LeRobotDataset with delta_timestamps on a few hundred items.
Runs offline; everything is written to a temporary folder.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

_TMP = tempfile.TemporaryDirectory(prefix="bench-dataset-")
os.environ["HF_HUB_OFFLINE"] = "1"
os.environ["HF_HOME"] = os.path.join(_TMP.name, "hf")
os.environ["HF_LEROBOT_HOME"] = os.path.join(_TMP.name, "lerobot")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from pipeline.dataset import Episode, Feature, WindowDataset, write_dataset  # noqa: E402

HISTORY = 5
FEATURES = [
    Feature("observation.state", "float32", tuple(f"q{i}" for i in range(36)), "qpos"),
    Feature("observation.qvel", "float32", tuple(f"v{i}" for i in range(20)), "qvel"),
    Feature("contact", "bool", ("l_foot", "r_foot", "l_hand", "r_hand"), "contacts"),
]


def make_episodes(n: int, T: int) -> list[Episode]:
    rng = np.random.default_rng(0)
    return [
        Episode(
            f"task {k % 3}",
            {
                "observation.state": rng.normal(size=(T, 36)).astype(np.float32),
                "observation.qvel": rng.normal(size=(T, 20)).astype(np.float32),
                "contact": rng.random((T, 4)) < 0.5,
            },
        )
        for k in range(n)
    ]


def bench_write_ours(root: Path, eps: list[Episode]) -> float:
    n = sum(len(e.data["contact"]) for e in eps)
    t0 = time.perf_counter()
    write_dataset(root, "bench/ours", 50, FEATURES, eps)
    return n / (time.perf_counter() - t0)


def bench_write_stock(root: Path, eps: list[Episode], repo_id: str = "bench/stock") -> float:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    feats = {f.name: {"dtype": f.dtype, "shape": f.shape, "names": list(f.names)} for f in FEATURES}
    n = sum(len(e.data["contact"]) for e in eps)
    t0 = time.perf_counter()
    ds = LeRobotDataset.create(repo_id, fps=50, features=feats, root=root, robot_type="unitree_g1", use_videos=False)
    for ep in eps:
        for t in range(len(ep.data["contact"])):
            ds.add_frame({**{k: v[t] for k, v in ep.data.items()}, "task": ep.task})
        ds.save_episode()
    ds.finalize()
    return n / (time.perf_counter() - t0)


def bench_loader_ours(root: Path, batches: int, batch: int = 1024) -> tuple[float, float, float]:
    t0 = time.perf_counter()
    ds = WindowDataset(root, ["observation.state", "observation.qvel", "contact"], history=HISTORY)
    t_open = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    idx = [rng.integers(0, len(ds), batch) for _ in range(batches)]
    t0 = time.perf_counter()
    for b in idx:
        ds.sample(b)
    batched = batches * batch / (time.perf_counter() - t0)
    items = rng.integers(0, len(ds), 5000)
    t0 = time.perf_counter()
    for i in items:
        ds[int(i)]
    return batched, len(items) / (time.perf_counter() - t0), t_open


def bench_loader_stock(root: Path, n_items: int) -> float:
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    keys = ["observation.state", "observation.qvel", "contact"]
    ds = LeRobotDataset(
        "bench/ours", root=root, delta_timestamps={k: [d / 50 for d in range(-HISTORY + 1, 1)] for k in keys}
    )
    items = np.random.default_rng(0).integers(0, len(ds), n_items)
    t0 = time.perf_counter()
    for i in items:
        ds[int(i)]
    return n_items / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=100)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--stock-episodes", type=int, default=8)
    ap.add_argument("--stock-items", type=int, default=300)
    ap.add_argument("--batches", type=int, default=200)
    a = ap.parse_args()
    tmp = Path(_TMP.name)
    eps = make_episodes(a.episodes, a.frames)
    ours_root = tmp / "ours"
    import torch

    print(
        f"data: {a.episodes} episodes x {a.frames} frames, 60 values/frame (36+20 float32, 4 bool); history {HISTORY}; "
        f"{os.cpu_count()} CPUs, {torch.get_num_threads()} torch threads",
        flush=True,
    )
    bench_write_ours(tmp / "warm_ours", eps[:1])  # warm-up (lazy imports) for both writers, untimed
    bench_write_stock(tmp / "warm_stock", [Episode(e.task, {k: v[:3] for k, v in e.data.items()}) for e in eps[:1]])
    w_ours = bench_write_ours(ours_root, eps)
    w_stock = bench_write_stock(tmp / "stock", eps[: a.stock_episodes])
    l_batch, l_item, t_open = bench_loader_ours(ours_root, a.batches)
    l_stock = bench_loader_stock(ours_root, a.stock_items)
    rows = [
        (
            "write (frames/s)",
            f"{w_ours:,.0f}",
            f"{w_stock:,.0f}",
            f"{w_ours / w_stock:,.0f}x",
            f"ours {a.episodes * a.frames} frames; stock {a.stock_episodes * a.frames}",
        ),
        (
            "load, batched (samples/s)",
            f"{l_batch:,.0f}",
            f"{l_stock:,.1f}",
            f"{l_batch / l_stock:,.0f}x",
            f"batches of 1024; open {t_open:.2f} s; stock ds[i] x {a.stock_items}",
        ),
        ("load, per item (samples/s)", f"{l_item:,.0f}", f"{l_stock:,.1f}", f"{l_item / l_stock:,.0f}x", "ds[i]"),
    ]
    head = ("measure", "ours", "stock lerobot", "speed-up", "notes")
    widths = [max(len(r[k]) for r in [head, *rows]) for k in range(5)]
    for r in [head, tuple("-" * w for w in widths), *rows]:
        print("  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip())


if __name__ == "__main__":
    main()
