"""Fast, atomic writer of LeRobot v3.0 datasets (the layout ``lerobot==0.4.4`` writes and loads),
(merging shards: :mod:`pipeline.dataset.merge`). Feature/episode conventions: :mod:`pipeline.dataset.schema`.

On disk (all paths relative to the dataset root)::

    data/chunk-000/file-000.parquet           frames (a new file after ~100 MB, 1000 files a chunk)
    meta/info.json  meta/stats.json  meta/tasks.parquet
    meta/episodes/chunk-000/file-000.parquet  per-episode index ranges, tasks and stats
    meta/lessmimic.json                       feature descriptions/units, the card, repo_id
    meta/lessmimic_episodes.jsonl             per episode: episode_index, task, length + its meta
    meta/lessmimic_checksums.json             every file's sha256, the upstream's fingerprint (checksums, chain)
    README.md                                 the dataset card (:mod:`pipeline.dataset.card`)

Column types, parquet schema metadata, ``info.json`` and the episodes table are LeRobot's own
(a test compares them with a dataset LeRobot writes). LeRobot ignores the ``lessmimic`` files and
the README. Per-episode stats hold exact quantiles; the dataset stats aggregate them the way
LeRobot does (exact min/max/mean/std/count; quantiles the count-weighted mean of the episodes').

The dataset is written into a staging folder beside ``root`` and renamed into place only when
complete, so a failure never leaves a partial dataset behind (a process killed with SIGKILL can
leave a hidden ``.<name>.staging-<pid>-<id>`` folder, never a half-written ``<name>``; the next
write of ``<name>`` removes such folders whose process is gone).
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.dataset.card import DatasetCard, render_card
from pipeline.dataset.chain import remember, upstream_record
from pipeline.dataset.checksums import content_fingerprint, write_checksums
from pipeline.dataset.ranges import check_ranges
from pipeline.dataset.schema import (
    CODEBASE_VERSION,
    DATA_PATH,
    EPISODES_PATH,
    INDEX_COLUMNS,
    QUANTILES,
    SIDECAR_DATASET,
    SIDECAR_EPISODES,
    Episode,
    Feature,
    _json_default,
    validate_episode,
    validate_name,
    validate_repo_id,
)
from pipeline.errors import InputError
from pipeline.stage.atomic import remove_dead_staging, replace_folder, staging_folder

_FLUSH_ROWS = 200_000


# --- statistics ----------------------------------------------------------------------------------


def episode_stats(columns: Mapping[str, np.ndarray]) -> dict[str, dict[str, np.ndarray]]:
    """Per column: min/max (in its dtype), mean/std (population), count, exact quantiles per element.

    All columns of an episode go through one ``(T, total_dim)`` float64 matrix (one quantile pass).
    """
    arrays = list(columns.values())
    x = np.concatenate([a.astype(np.float64) for a in arrays], axis=1)
    q = np.quantile(x, QUANTILES, axis=0)
    mn, mx, mean, std = x.min(axis=0), x.max(axis=0), x.mean(axis=0), x.std(axis=0)
    count = np.array([x.shape[0]], dtype=np.int64)
    out, k = {}, 0
    for name, a in columns.items():
        sl = slice(k, k + a.shape[1])
        k += a.shape[1]
        s = {
            "min": mn[sl].astype(a.dtype),
            "max": mx[sl].astype(a.dtype),
            "mean": mean[sl],
            "std": std[sl],
            "count": count,
        }
        s.update({_qkey(p): q[i, sl] for i, p in enumerate(QUANTILES)})
        out[name] = s
    return out


def _qkey(p: float) -> str:
    return f"q{int(round(p * 100)):02d}"


def aggregate_stats(per_episode: Sequence[Mapping[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """Combine episode stats: exact min/max/mean/std (parallel variance), count-weighted quantiles."""
    n = np.array([s["count"][0] for s in per_episode], dtype=np.float64)[:, None]
    total = n.sum()
    means = np.stack([s["mean"] for s in per_episode])
    mean = (means * n).sum(axis=0) / total
    var = ((np.stack([s["std"] for s in per_episode]) ** 2 + (means - mean) ** 2) * n).sum(axis=0) / total
    out = {
        "min": np.min([s["min"] for s in per_episode], axis=0),
        "max": np.max([s["max"] for s in per_episode], axis=0),
        "mean": mean,
        "std": np.sqrt(var),
        "count": np.array([int(total)], dtype=np.int64),
    }
    for p in QUANTILES:
        k = _qkey(p)
        out[k] = (np.stack([s[k] for s in per_episode]) * n).sum(axis=0) / total
    return out


# --- arrow / parquet -----------------------------------------------------------------------------


def _column_specs(features: Sequence[Feature]) -> list[tuple[str, str, int]]:
    return [(f.name, f.dtype, f.shape[0]) for f in features] + [(k, d, 1) for k, d in INDEX_COLUMNS.items()]


def _arrow_array(a: np.ndarray, dim: int) -> pa.Array:
    flat = pa.array(np.ascontiguousarray(a).reshape(-1))
    return flat if dim == 1 else pa.FixedSizeListArray.from_arrays(flat, dim)


def _data_schema(features: Sequence[Feature]) -> pa.Schema:
    """Arrow schema plus the ``huggingface`` metadata ``datasets`` reads (as LeRobot's files carry)."""
    fields, hf = [], {}
    for name, dtype, dim in _column_specs(features):
        t = pa.from_numpy_dtype(np.dtype(dtype))
        value = {"dtype": dtype, "_type": "Value"}
        fields.append(pa.field(name, t if dim == 1 else pa.list_(t, dim)))
        hf[name] = value if dim == 1 else {"feature": value, "length": dim, "_type": "List"}
    return pa.schema(fields, metadata={"huggingface": json.dumps({"info": {"features": hf}})})


def _episodes_table(rows: list[dict], features: Sequence[Feature]) -> pa.Table:
    fixed = [
        ("episode_index", pa.int64()),
        ("tasks", pa.list_(pa.string())),
        ("length", pa.int64()),
        ("data/chunk_index", pa.int64()),
        ("data/file_index", pa.int64()),
        ("dataset_from_index", pa.int64()),
        ("dataset_to_index", pa.int64()),
    ]
    fields = [pa.field(k, t) for k, t in fixed]
    for name, dtype, _ in _column_specs(features):
        value_type = pa.float64() if dtype == "float32" else pa.from_numpy_dtype(np.dtype(dtype))  # as LeRobot
        for stat in ("min", "max", "mean", "std", "count", *map(_qkey, QUANTILES)):
            t = value_type if stat in ("min", "max") else pa.int64() if stat == "count" else pa.float64()
            fields.append(pa.field(f"stats/{name}/{stat}", pa.list_(t)))
    fields += [pa.field("meta/episodes/chunk_index", pa.int64()), pa.field("meta/episodes/file_index", pa.int64())]
    schema = pa.schema(fields)
    return pa.table({f.name: pa.array([r[f.name] for r in rows], type=f.type) for f in schema}, schema=schema)


def _write_tasks(path: Path, tasks: dict[str, int]) -> None:
    """``tasks.parquet`` as LeRobot writes it: a pandas frame indexed by task string."""
    import pandas as pd

    pd.DataFrame({"task_index": list(tasks.values())}, index=list(tasks)).to_parquet(path)


def _write_json(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=4, ensure_ascii=False, default=_json_default))


class _DataFiles:
    """Appends frames to ``data/chunk-CCC/file-FFF.parquet``, starting a new file past ``max_mb``."""

    def __init__(self, root: Path, schema: pa.Schema, max_mb: float, chunks_size: int):
        self.root, self.schema, self.max_bytes, self.chunks_size = root, schema, max_mb * 2**20, chunks_size
        self.chunk = self.file = 0
        self.bytes = 0
        self.pending: list[pa.RecordBatch] = []
        self.pending_rows = 0
        self.writer: pq.ParquetWriter | None = None

    def add(self, batch: pa.RecordBatch) -> tuple[int, int]:
        """Queue one episode's frames; returns the (chunk, file) it lands in."""
        if self.bytes and self.bytes + batch.nbytes > self.max_bytes:
            self.close()
            self.chunk, self.file = (
                (self.chunk + 1, 0) if self.file + 1 >= self.chunks_size else (self.chunk, self.file + 1)
            )
            self.bytes = 0
        self.pending.append(batch)
        self.pending_rows += batch.num_rows
        self.bytes += batch.nbytes
        if self.pending_rows >= _FLUSH_ROWS:
            self._flush()
        return self.chunk, self.file

    def _flush(self) -> None:
        if not self.pending:
            return
        if self.writer is None:
            path = self.root / DATA_PATH.format(chunk_index=self.chunk, file_index=self.file)
            path.parent.mkdir(parents=True, exist_ok=True)
            # Dictionary encoding only pays off (and is only cheap) on the low-cardinality index columns.
            self.writer = pq.ParquetWriter(
                path, self.schema, compression="snappy", use_dictionary=["episode_index", "task_index"]
            )
        self.writer.write_table(pa.Table.from_batches(self.pending, self.schema))
        self.pending, self.pending_rows = [], 0

    def close(self) -> None:
        self._flush()
        if self.writer is not None:
            self.writer.close()
            self.writer = None


# --- the writer ----------------------------------------------------------------------------------


def check_target(root: Path, overwrite: bool) -> None:
    """``root`` may be (re)written: a valid folder name, and absent unless ``overwrite``."""
    validate_name(root.name, "dataset folder name")
    if root.exists() and not overwrite:
        raise InputError(
            root,
            "dataset",
            "already exists; pass --overwrite (OVERWRITE=1 with make, overwrite=True in Python) to replace it",
        )
    if root.exists() and not root.is_dir():
        raise InputError(root, "dataset", "exists and is not a folder")


def _commit(staging: Path, root: Path, overwrite: bool) -> None:
    """Move the finished staging folder to ``root`` (replacing an old dataset only if ``overwrite``)."""
    check_target(root, overwrite)
    replace_folder(staging, root)


def write_dataset(
    root: str | Path,
    repo_id: str,
    fps: int,
    features: Sequence[Feature],
    episodes: Iterable[Episode],
    *,
    robot_type: str = "unitree_g1",
    card: DatasetCard | None = None,
    overwrite: bool = False,
    data_file_size_mb: float = 100,
    chunks_size: int = 1000,
) -> Path:
    """Write ``episodes`` as a LeRobot v3.0 dataset at ``root``, atomically; returns ``root``.

    ``episodes`` is consumed once, as a stream (frames are flushed to parquet every ~200k rows).
    Raises :class:`InputError` for a bad name, an existing ``root`` without ``overwrite``, or
    episode data that does not match ``features`` (naming the episode, frame and feature).
    """
    root = Path(root)
    validate_repo_id(repo_id)
    if isinstance(fps, bool) or not isinstance(fps, (int, np.integer)) or fps <= 0:
        raise InputError(repo_id, "fps", f"must be a positive integer (LeRobot stores integer fps), got {fps!r}")
    features = tuple(features)
    if not features or len({f.name for f in features}) != len(features):
        raise InputError(repo_id, "features", "must be a non-empty list with unique names")
    if card is not None and card.fps is not None and card.fps != fps:
        raise InputError(repo_id, "card fps", f"{card.fps} differs from the dataset fps {fps}")
    check_target(root, overwrite)
    root.parent.mkdir(parents=True, exist_ok=True)
    remove_dead_staging(root)
    staging = staging_folder(root)
    try:
        staging.mkdir()
        _write_into(staging, repo_id, int(fps), features, episodes, robot_type, card, data_file_size_mb, chunks_size)
        manifest = write_checksums(staging, upstream_record(root))
        _commit(staging, root, overwrite)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    remember(root, content_fingerprint(manifest))
    return root


def _write_into(root, repo_id, fps, features, episodes, robot_type, card, data_file_size_mb, chunks_size) -> None:
    schema = _data_schema(features)
    files = _DataFiles(root, schema, data_file_size_mb, chunks_size)
    tasks: dict[str, int] = {}
    rows, all_stats = [], []
    total = 0
    (root / "meta").mkdir()
    sidecar = (root / SIDECAR_EPISODES).open("w", encoding="utf-8")
    try:
        for ep_idx, ep in enumerate(episodes):
            data = validate_episode(features, ep, f"dataset {repo_id} episode {ep_idx}")
            check_ranges(data, fps, f"dataset {repo_id} episode {ep_idx}")
            T = next(iter(data.values())).shape[0]
            task_idx = tasks.setdefault(ep.task, len(tasks))
            frame = np.arange(T, dtype=np.int64)
            data.update(
                {
                    "timestamp": (frame / fps).astype(np.float32)[:, None],
                    "frame_index": frame[:, None],
                    "episode_index": np.full((T, 1), ep_idx, dtype=np.int64),
                    "index": (frame + total)[:, None],
                    "task_index": np.full((T, 1), task_idx, dtype=np.int64),
                }
            )
            batch = pa.RecordBatch.from_arrays(
                [_arrow_array(data[n], d) for n, _, d in _column_specs(features)], schema=schema
            )
            chunk, file = files.add(batch)
            stats = episode_stats({name: data[name] for name, _, _ in _column_specs(features)})
            all_stats.append(stats)
            row = {
                "episode_index": ep_idx,
                "tasks": [ep.task],
                "length": T,
                "data/chunk_index": chunk,
                "data/file_index": file,
                "dataset_from_index": total,
                "dataset_to_index": total + T,
                "meta/episodes/chunk_index": 0,
                "meta/episodes/file_index": 0,
            }
            for name, s in stats.items():
                row.update({f"stats/{name}/{k}": v.tolist() for k, v in s.items()})
            rows.append(row)
            sidecar.write(
                json.dumps({"episode_index": ep_idx, "task": ep.task, "length": T, **ep.meta}, default=_json_default)
                + "\n"
            )
            total += T
    finally:
        files.close()
        sidecar.close()
    if not rows:
        raise InputError(f"dataset {repo_id}", "episodes", "no episodes to write")
    path = root / EPISODES_PATH.format(chunk_index=0, file_index=0)
    path.parent.mkdir(parents=True)
    pq.write_table(_episodes_table(rows, features), path, compression="snappy")
    _write_tasks(root / "meta/tasks.parquet", tasks)
    names = [n for n, _, _ in _column_specs(features)]
    _write_json(root / "meta/stats.json", {n: aggregate_stats([s[n] for s in all_stats]) for n in names})
    _write_json(
        root / "meta/info.json",
        _info(fps, features, robot_type, len(rows), total, len(tasks), data_file_size_mb, chunks_size),
    )
    _write_json(
        root / SIDECAR_DATASET,
        {
            "format": 1,
            "repo_id": repo_id,
            "features": {f.name: {"description": f.description, "unit": f.unit} for f in features},
            "card": None if card is None else card.to_dict(),
        },
    )
    (root / "README.md").write_text(
        render_card(card or DatasetCard(title=repo_id), repo_id, fps, features, len(rows), total)
    )


def _info(fps, features, robot_type, episodes, frames, tasks, data_file_size_mb, chunks_size) -> dict:
    """``meta/info.json`` exactly as LeRobot 0.4.4 writes it for a dataset without videos."""
    feats = {f.name: f.info_entry() for f in features}
    feats.update({k: {"dtype": d, "shape": [1], "names": None} for k, d in INDEX_COLUMNS.items()})
    return {
        "codebase_version": CODEBASE_VERSION,
        "robot_type": robot_type,
        "total_episodes": episodes,
        "total_frames": frames,
        "total_tasks": tasks,
        "chunks_size": chunks_size,
        "data_files_size_in_mb": data_file_size_mb,
        "video_files_size_in_mb": 200,
        "fps": fps,
        "splits": {"train": f"0:{episodes}"},
        "data_path": DATA_PATH,
        "video_path": None,
        "features": feats,
    }
