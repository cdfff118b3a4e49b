"""``lessmimic verify <dataset>``: a whole dataset checked, byte for byte and value for value.

Why: the stages check what they read as they read it, but a dataset copied, downloaded or kept for months needs a
check of its own before it is trusted: every file against its sha256 (:mod:`pipeline.dataset.checksums`), the chain
it belongs to (:mod:`pipeline.dataset.chain`: not made from an upstream since rewritten), ``meta/info.json`` against
the data (frames, episodes) and every value against its column's range (:mod:`pipeline.dataset.ranges`). The first
fault is one :class:`InputError` line naming the file, or the episode, frame and column.

``<dataset>`` is a dataset folder, a ``datasets/<NAME>/`` folder (its stages in chain order), a dataset name under the
datasets root, or a hub repo id (LeRobot's local copy under ``$HF_LEROBOT_HOME``, downloaded when missing).
"""

from __future__ import annotations

import os
from pathlib import Path

from pipeline.dataset.chain import CHAIN, checked_fingerprint
from pipeline.dataset.checksums import verify_files
from pipeline.dataset.ranges import check_ranges
from pipeline.dataset.schema import SIDECAR_CHECKSUMS, validate_repo_id
from pipeline.errors import InputError

NO_CHECKSUMS = "missing: nothing to verify the files against (not written by lessmimic, or before its checksums)"
OFFLINE = "not downloaded here, and the Hub cannot be reached (offline: HF_HUB_OFFLINE=1, or no network)"


def _is_dataset(p: Path) -> bool:
    return (p / "meta").is_dir() or (p / SIDECAR_CHECKSUMS).is_file()


def dataset_folders(target: str | Path) -> list[Path]:
    """The dataset roots ``target`` names (module docstring), or one :class:`InputError` line."""
    from pipeline.stage.paths import datasets_root

    path = Path(target)
    if not path.exists() and not path.is_absolute() and (datasets_root() / str(target)).is_dir():
        path = datasets_root() / str(target)
    if path.is_dir():
        if _is_dataset(path):
            return [path]
        stages = [path / s for s in CHAIN if _is_dataset(path / s)]
        others = sorted(p for p in path.iterdir() if p.name not in CHAIN and p.is_dir() and _is_dataset(p))
        if not stages and not others:
            raise InputError(path, "dataset", "holds no dataset (no meta/ here or in a stage folder below)")
        return stages + others
    if path.exists() or path.is_absolute() or str(target).startswith("."):
        raise InputError(path, "dataset", "is not a dataset folder")
    return [hub_copy(validate_repo_id(str(target)))]


def hub_copy(repo_id: str) -> Path:
    """LeRobot's local copy of hub dataset ``repo_id`` (``$HF_LEROBOT_HOME/<repo_id>``), downloaded when missing;
    offline and not there is one line."""
    from lerobot.utils.constants import HF_LEROBOT_HOME

    local = Path(HF_LEROBOT_HOME) / repo_id
    if _is_dataset(local):
        return local
    from huggingface_hub import snapshot_download

    try:
        snapshot_download(repo_id, repo_type="dataset", revision="v3.0", local_dir=local)
    except Exception as exc:  # noqa: BLE001 - offline, no such repo, no network: all one line
        why = OFFLINE if os.environ.get("HF_HUB_OFFLINE") == "1" or isinstance(exc, OSError) else str(exc)
        raise InputError(repo_id, "hub", why.splitlines()[0] if why else type(exc).__name__) from None
    return local


def verify_dataset(root: Path) -> dict:
    """Check the dataset at ``root`` (module docstring); returns what was checked."""
    from pipeline.dataset.read import episode_ranges, read_columns, read_info

    root = Path(root)
    manifest = verify_files(root)
    if manifest is None:
        raise InputError(root, SIDECAR_CHECKSUMS, NO_CHECKSUMS)
    checked_fingerprint(root)  # the chain: not made from an upstream since rewritten
    info = read_info(root)
    names = [k for k, v in info["features"].items() if v["dtype"] in ("float32", "float64", "int64", "bool")]
    columns = read_columns(root, names)
    rows = len(next(iter(columns.values())))
    starts, ends, _ = episode_ranges(root)
    if rows != info["total_frames"] or len(starts) != info["total_episodes"]:
        says = f"says {info['total_episodes']} episodes, {info['total_frames']} frames"
        why = f"{says}; the data holds {len(starts)}, {rows}"
        raise InputError(root, "meta/info.json", why)
    for e, (a, b) in enumerate(zip(starts, ends)):
        check_ranges({k: v[a:b] for k, v in columns.items()}, info["fps"], f"{root} episode {e}")
    return {
        "dataset": str(root),
        "files": len(manifest["files"]),
        "bytes": sum(f["bytes"] for f in manifest["files"].values()),
        "episodes": len(starts),
        "frames": rows,
        "upstream": (manifest.get("upstream") or {}).get("stage"),
    }
