"""LeRobot v3.0 datasets: what the stages write and read.

* :mod:`pipeline.dataset.schema` -- :class:`Feature`, :class:`Episode`, validation, names, paths;
* :mod:`pipeline.dataset.write` -- :func:`write_dataset` (fast, atomic; the on-disk layout);
* :mod:`pipeline.dataset.merge` -- :func:`merge_datasets` (shards written by parallel workers);
* :mod:`pipeline.dataset.read` -- :func:`iter_episodes`, :func:`read_columns`, :func:`read_features`;
* :mod:`pipeline.dataset.windows` -- :class:`WindowDataset` (training windows straight from parquet, torch);
* :mod:`pipeline.dataset.card` -- the dataset card (``README.md``);
* :mod:`pipeline.dataset.clips` -- clips (:mod:`pipeline.clip`) <-> episodes;
* :mod:`pipeline.dataset.objects` -- their object tracks <-> object features;
* :mod:`pipeline.dataset.hub` -- loading by path or repo id, publishing.

The public names below are imported lazily from those modules (writing does not import torch).
"""

from __future__ import annotations

import importlib

_LAZY = {
    "Feature": "schema",
    "Episode": "schema",
    "dataset_root": "schema",
    "validate_episode": "schema",
    "validate_name": "schema",
    "validate_repo_id": "schema",
    "write_dataset": "write",
    "merge_datasets": "merge",
    "WindowDataset": "windows",
    "iter_episodes": "read",
    "read_columns": "read",
    "read_features": "read",
    "read_info": "read",
    "read_sidecar": "read",
    "read_card": "read",
    "read_episode_meta": "read",
    "episode_ranges": "read",
    "DatasetCard": "card",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(f"{__name__}.{_LAZY[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = list(_LAZY)
