"""The dataset schema: the feature spec (:class:`Feature`), episodes (:class:`Episode`), their
validation and conversion, names and the on-disk paths LeRobot v3.0 fixes.

A dataset is a typed feature spec (:class:`Feature`) plus episodes (:class:`Episode`). Conventions:

* every feature is a 1-D array per frame, ``shape == (len(names),)``; per-link arrays are
  flattened with element names such as ``"pelvis.phi"`` (LeRobot cannot merge 2-D features);
* dtypes are ``float32``, ``int64`` or ``bool``. Input of another numeric dtype is converted:
  float64 is rounded to float32 (a value outside the float32 range is rejected as infinite),
  integers/bools become int64, and a ``bool`` feature accepts any numeric array of 0s and 1s.
  Floating data for an ``int64`` feature is rejected, never truncated; NaN/inf is rejected;
* a one-element feature is stored as a scalar column, as LeRobot does (``ds[i][key]`` is then a
  0-d tensor); episode data for it may be ``(T,)`` or ``(T, 1)``;
* ``timestamp = frame_index / fps`` (float32); ``index`` counts frames over the whole dataset;
  tasks are numbered in order of first appearance;
* an episode's ``meta`` is JSON-able provenance, stored one line per episode in
  ``meta/lessmimic_episodes.jsonl`` beside ``episode_index``, ``task`` and ``length``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pipeline.errors import InputError, first_bad_frame

CODEBASE_VERSION = "v3.0"  # lerobot.datasets.lerobot_dataset.CODEBASE_VERSION (checked by a test)
DTYPES = ("float32", "int64", "bool")
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)  # lerobot.datasets.compute_stats.DEFAULT_QUANTILES
#: LeRobot's own per-frame columns, in its order (lerobot.datasets.utils.DEFAULT_FEATURES).
INDEX_COLUMNS = {
    "timestamp": "float32",
    "frame_index": "int64",
    "episode_index": "int64",
    "index": "int64",
    "task_index": "int64",
}
DATA_PATH = "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
EPISODES_PATH = "meta/episodes/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet"
SIDECAR_EPISODES = "meta/lessmimic_episodes.jsonl"
SIDECAR_DATASET = "meta/lessmimic.json"
SIDECAR_CHECKSUMS = "meta/lessmimic_checksums.json"  # every file's sha256: pipeline.dataset.checksums
_NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,95}$")


@dataclass(frozen=True)
class Feature:
    """One per-frame column: ``dtype``, one name per element, a meaning and a unit."""

    name: str
    dtype: str
    names: tuple[str, ...]
    description: str
    unit: str = ""

    def __post_init__(self):
        object.__setattr__(self, "names", tuple(str(n) for n in self.names))
        if not self.name or "/" in self.name or self.name in INDEX_COLUMNS or self.name == "task":
            raise ValueError(f"feature name {self.name!r} is empty, contains '/' or is reserved by LeRobot")
        if self.dtype not in DTYPES:
            raise ValueError(f"feature {self.name!r}: dtype must be one of {DTYPES}, got {self.dtype!r}")
        if not self.names or len(set(self.names)) != len(self.names):
            raise ValueError(f"feature {self.name!r}: element names must be non-empty and unique")

    @property
    def shape(self) -> tuple[int]:
        return (len(self.names),)

    def info_entry(self) -> dict:
        """The feature as LeRobot's ``info.json`` lists it."""
        return {"dtype": self.dtype, "shape": list(self.shape), "names": list(self.names)}


@dataclass
class Episode:
    """One episode: a task string, ``data[feature] -> (T, dim)`` arrays, JSON-able provenance ``meta``."""

    task: str
    data: Mapping[str, np.ndarray]
    meta: dict = field(default_factory=dict)


def validate_name(name: str, what: str = "dataset name") -> str:
    """A dataset / repo name: letters, digits, ``.``, ``_``, ``-``; no path separators, no ``..``."""
    if not isinstance(name, str) or not _NAME_RE.match(name) or ".." in name or name.endswith("."):
        raise InputError(
            name,
            what,
            "must be 1-96 letters, digits, '.', '_' or '-', start with a letter or digit, "
            "and contain no path separator or '..'",
        )
    return name


def validate_repo_id(repo_id: str) -> str:
    """``name`` or ``owner/name``, each part a valid :func:`validate_name`."""
    parts = repo_id.split("/") if isinstance(repo_id, str) else [repo_id]
    if len(parts) > 2:
        raise InputError(repo_id, "repo_id", "must be 'name' or 'owner/name'")
    for p in parts:
        validate_name(p, "repo_id")
    return repo_id


def dataset_root(base: str | Path, name: str) -> Path:
    """``base / name`` after checking ``name`` cannot escape ``base``."""
    return Path(base) / validate_name(name)


# --- validation and conversion -----------------------------------------------------------------


def _convert(f: Feature, a, where: str) -> np.ndarray:
    """``(T, dim)`` array of the feature's dtype, or an InputError naming the episode and frame."""
    a = np.asarray(a)
    if a.ndim == 1 and f.shape == (1,):
        a = a[:, None]
    if a.ndim != 2 or a.shape[1] != f.shape[0]:
        raise InputError(where, f.name, f"shape {a.shape} does not match (T, {f.shape[0]})")
    if a.shape[0] == 0:
        raise InputError(where, f.name, "has zero frames")
    if not (np.issubdtype(a.dtype, np.number) or a.dtype == np.bool_):
        raise InputError(where, f.name, f"dtype {a.dtype} is not numeric")
    if f.dtype == "float32":
        with np.errstate(over="ignore", invalid="ignore"):
            out = a.astype(np.float32)
        bad = ~np.isfinite(out)
        if bad.any():
            raise InputError(where, f.name, "is NaN or infinite (in float32)", frame=first_bad_frame(bad))
        return out
    if np.issubdtype(a.dtype, np.floating):
        bad = ~np.isfinite(a)
        if bad.any():
            raise InputError(where, f.name, "is NaN or infinite", frame=first_bad_frame(bad))
    if f.dtype == "int64":
        if np.issubdtype(a.dtype, np.floating):
            raise InputError(where, f.name, f"has floating dtype {a.dtype}; int64 features take integers")
        return a.astype(np.int64)
    if a.dtype != np.bool_:
        bad = (a != 0) & (a != 1)
        if bad.any():
            raise InputError(where, f.name, "bool feature holds a value other than 0 or 1", frame=first_bad_frame(bad))
    return a.astype(np.bool_)


def validate_episode(features: Sequence[Feature], ep: Episode, where: str) -> dict[str, np.ndarray]:
    """Checked and converted ``{name: (T, dim)}``; ``where`` names dataset and episode in errors."""
    if not isinstance(ep.task, str) or not ep.task.strip():
        raise InputError(where, "task", "must be a non-empty string")
    names = [f.name for f in features]
    missing, extra = set(names) - set(ep.data), set(ep.data) - set(names)
    if missing or extra:
        raise InputError(where, "data", f"missing features {sorted(missing)}, unknown features {sorted(extra)}")
    out = {f.name: _convert(f, ep.data[f.name], where) for f in features}
    lengths = {k: v.shape[0] for k, v in out.items()}
    if len(set(lengths.values())) > 1:
        raise InputError(where, "data", f"features have different frame counts {lengths}")
    reserved = {"episode_index", "task", "length"} & set(ep.meta)
    if reserved:
        raise InputError(where, "meta", f"keys {sorted(reserved)} are reserved (the sidecar sets them)")
    try:
        json.dumps(ep.meta, default=_json_default)
    except (TypeError, ValueError) as e:
        raise InputError(where, "meta", f"is not JSON-serialisable: {e}") from None
    return out


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    raise TypeError(f"{type(o).__name__} is not JSON-serialisable")
