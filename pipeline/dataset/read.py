"""Reading LeRobot v3.0 datasets straight from their parquet columns (pyarrow -> numpy); training
windows over them: :mod:`pipeline.dataset.windows`.

Works on any v3.0 dataset (ours or LeRobot's); the ``lessmimic`` sidecars (feature descriptions,
per-episode provenance) are used when present.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.dataset.card import DatasetCard
from pipeline.dataset.chain import checked_fingerprint
from pipeline.dataset.checksums import read_checksums
from pipeline.dataset.schema import INDEX_COLUMNS, SIDECAR_DATASET, SIDECAR_EPISODES, Episode, Feature
from pipeline.errors import InputError
from pipeline.robot import DEFAULT_PROFILE


def read_info(root: str | Path) -> dict:
    path = Path(root) / "meta/info.json"
    if not path.is_file() and read_checksums(Path(root)) is not None:
        raise InputError(root, "meta/info.json", "missing (the checksums list it): the dataset is incomplete")
    if not path.is_file():
        raise InputError(path, "dataset", "is not a LeRobot dataset (meta/info.json missing)")
    return json.loads(path.read_text())


def read_sidecar(root: str | Path) -> dict:
    """``meta/lessmimic.json`` (``{}`` for a dataset we did not write)."""
    path = Path(root) / SIDECAR_DATASET
    return json.loads(path.read_text()) if path.is_file() else {}


def read_card(root: str | Path) -> DatasetCard | None:
    d = read_sidecar(root).get("card")
    return None if d is None else DatasetCard.from_dict(d)


def read_episode_meta(root: str | Path) -> list[dict]:
    """Per-episode provenance from ``meta/lessmimic_episodes.jsonl``, by episode index."""
    path = Path(root) / SIDECAR_EPISODES
    if not path.is_file():
        return []
    rows = [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    return sorted(rows, key=lambda r: r["episode_index"])


def read_features(root: str | Path) -> tuple[Feature, ...]:
    """The feature spec (LeRobot's index columns excluded) from ``info.json`` and the sidecar."""
    info, docs = read_info(root), read_sidecar(root).get("features", {})
    out = []
    for name, ft in info["features"].items():
        if name in INDEX_COLUMNS:
            continue
        if len(ft["shape"]) != 1 or ft["dtype"] not in ("float32", "int64", "bool"):
            raise InputError(root, name, f"unsupported feature (dtype {ft['dtype']}, shape {ft['shape']})")
        names = ft.get("names") or [f"{name}_{k}" for k in range(ft["shape"][0])]
        doc = docs.get(name, {})
        out.append(Feature(name, ft["dtype"], tuple(names), doc.get("description", ""), doc.get("unit", "")))
    return tuple(out)


def _data_files(root: Path) -> list[Path]:
    files = sorted((root / "data").glob("*/*.parquet"))
    if not files:
        raise InputError(root, "data", "no parquet files under data/")
    return files


def _to_numpy(col: pa.ChunkedArray) -> np.ndarray:
    """A column as ``(N, dim)``: fixed-size lists are unpacked, scalars become one column."""
    parts = []
    for chunk in col.chunks:
        if pa.types.is_fixed_size_list(chunk.type) or pa.types.is_list(chunk.type):
            values = chunk.flatten().to_numpy(zero_copy_only=False)
            parts.append(values.reshape(len(chunk), -1))
        else:
            parts.append(chunk.to_numpy(zero_copy_only=False).reshape(-1, 1))
    return np.concatenate(parts) if len(parts) != 1 else parts[0]


def read_columns(root: str | Path, keys: Sequence[str]) -> dict[str, np.ndarray]:
    """``{key: (N, dim)}`` over the whole dataset in ``index`` order; the dataset's files checked against its
    checksums first, and a stale one refused (:func:`pipeline.dataset.chain.checked_fingerprint`)."""
    root = Path(root)
    checked_fingerprint(root)
    cols = list(dict.fromkeys([*keys, "index"]))
    table = pa.concat_tables([pq.read_table(f, columns=cols) for f in _data_files(root)])
    out = {k: _to_numpy(table.column(k)) for k in cols}
    order = out["index"][:, 0]
    if np.any(np.diff(order) < 0):
        perm = np.argsort(order, kind="stable")
        out = {k: v[perm] for k, v in out.items()}
    if "index" not in keys:
        out.pop("index")
    return out


def episode_ranges(root: str | Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``(from_index, to_index, task)`` per episode, from ``meta/episodes``."""
    root = Path(root)
    files = sorted((root / "meta/episodes").glob("*/*.parquet"))
    t = pa.concat_tables(
        [pq.read_table(f, columns=["episode_index", "tasks", "dataset_from_index", "dataset_to_index"]) for f in files]
    ).sort_by("episode_index")
    tasks = [ts[0] if ts else "" for ts in t.column("tasks").to_pylist()]
    return t.column("dataset_from_index").to_numpy(), t.column("dataset_to_index").to_numpy(), tasks


def iter_episodes(root: str | Path) -> Iterator[Episode]:
    """Every episode back as an :class:`Episode` (data in the feature dtypes, meta from the sidecar)."""
    root = Path(root)
    features = read_features(root)
    cols = read_columns(root, [f.name for f in features])
    starts, ends, tasks = episode_ranges(root)
    metas = {m["episode_index"]: m for m in read_episode_meta(root)}
    for e, (a, b) in enumerate(zip(starts, ends)):
        meta = {k: v for k, v in metas.get(e, {}).items() if k not in ("episode_index", "task", "length")}
        yield Episode(tasks[e], {f.name: cols[f.name][a:b] for f in features}, meta)


def dataset_actuator_profile(root: str | Path) -> str:
    """The actuator profile a dataset's actions are for (physicalized or features): its card's
    (``"<name>: <description>"``), else the episodes' physicalize provenance, else :data:`DEFAULT_PROFILE`."""
    card = read_card(root)
    if card is not None and card.actuator_profile:
        return card.actuator_profile.split(":", 1)[0].strip()
    for meta in read_episode_meta(root):
        for d in (meta, meta.get("provenance") or {}):
            if isinstance(d, dict) and d.get("actuator_profile"):
                return str(d["actuator_profile"])
    return DEFAULT_PROFILE
