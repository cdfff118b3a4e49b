"""Publishing datasets to the Hugging Face hub, and loading them back through LeRobot's loader.

:func:`publish` does what ``LeRobotDataset.push_to_hub`` does for a finished dataset folder:
create the dataset repo, upload the folder (our README.md is the card), and tag the commit with
the format version ``v3.0`` (LeRobot resolves a repo's revision from that tag when it
downloads). The hub client is injectable (``api=``): anything with ``create_repo``,
``upload_folder``, ``delete_tag`` and ``create_tag`` of :class:`huggingface_hub.HfApi`'s
signatures. Credentials are huggingface_hub's own (``HF_TOKEN`` or ``huggingface-cli login``).
"""

from __future__ import annotations

import contextlib
from pathlib import Path

from pipeline.dataset.chain import checked_fingerprint
from pipeline.dataset.read import read_info, read_sidecar
from pipeline.dataset.schema import CODEBASE_VERSION, validate_repo_id
from pipeline.dataset.verify import OFFLINE
from pipeline.errors import InputError

#: Never uploaded: LeRobot's temporary images, and hidden files (e.g. the ``.cache`` that a hub
#: download into a local folder leaves behind).
#: (huggingface_hub matches them with fnmatch, where ``*`` also matches ``/``.)
IGNORE_PATTERNS = ["images/*", ".*", "*/.*"]


def _check_dataset(root: Path) -> dict:
    info = read_info(root)
    if info.get("codebase_version") != CODEBASE_VERSION:
        raise InputError(
            root, "codebase_version", f"is {info.get('codebase_version')!r}, expected {CODEBASE_VERSION!r}"
        )
    for rel in ("meta/stats.json", "meta/tasks.parquet", "README.md"):
        if not (root / rel).is_file():
            raise InputError(root, rel, "is missing: not a complete dataset")
    if not any((root / "meta/episodes").glob("*/*.parquet")) or not any((root / "data").glob("*/*.parquet")):
        raise InputError(root, "data", "meta/episodes or data parquet files are missing")
    return info


def publish(
    root: str | Path, repo_id: str, *, private: bool = False, api=None, commit_message: str | None = None
) -> str:
    """Upload the dataset folder ``root`` to the hub dataset repo ``repo_id`` and tag it ``v3.0``.

    Returns the repo URL. Re-publishing moves the tag to the new commit.
    """
    from huggingface_hub.errors import HfHubHTTPError, RevisionNotFoundError

    root = Path(root)
    validate_repo_id(repo_id)
    if "/" not in repo_id:
        raise InputError(repo_id, "repo_id", "must be 'owner/name' to publish")
    _check_dataset(root)
    if api is None:
        from huggingface_hub import HfApi

        api = HfApi()
    url = api.create_repo(repo_id=repo_id, repo_type="dataset", private=private, exist_ok=True)
    api.upload_folder(
        repo_id=repo_id,
        folder_path=str(root),
        repo_type="dataset",
        ignore_patterns=IGNORE_PATTERNS,
        commit_message=commit_message or f"Upload LeRobot {CODEBASE_VERSION} dataset",
    )
    with contextlib.suppress(RevisionNotFoundError, HfHubHTTPError):
        api.delete_tag(repo_id, tag=CODEBASE_VERSION, repo_type="dataset")
    api.create_tag(repo_id, tag=CODEBASE_VERSION, repo_type="dataset")
    return str(url) if url else f"https://huggingface.co/datasets/{repo_id}"


def load(path_or_repo_id: str | Path, *, root: str | Path | None = None, **kwargs):
    """A ``LeRobotDataset`` from a local dataset folder, or from a repo id (LeRobot's own loader:
    local ``root`` / ``$HF_LEROBOT_HOME/<repo_id>`` first, the hub otherwise). ``kwargs`` go to
    ``LeRobotDataset`` (e.g. ``delta_timestamps``)."""
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    path = Path(path_or_repo_id)
    if path.is_dir():  # a local folder: checked against its checksums, refused when stale (pipeline.dataset.chain)
        read_info(path)  # a missing meta/info.json named as such
        checked_fingerprint(path)
        repo_id = read_sidecar(path).get("repo_id") or f"local/{path.name}"
        return LeRobotDataset(repo_id, root=path, **kwargs)
    if isinstance(path_or_repo_id, Path) or path.is_absolute() or str(path_or_repo_id).startswith(".") or path.exists():
        raise InputError(path, "dataset", "is not a LeRobot dataset folder (meta/info.json missing)")
    repo_id = validate_repo_id(str(path_or_repo_id))
    try:
        ds = LeRobotDataset(repo_id, root=root, **kwargs)
    except OSError as exc:  # huggingface_hub's offline and connection errors are OSErrors: one line, not five
        raise InputError(repo_id, "hub", f"{OFFLINE} ({type(exc).__name__})") from None
    checked_fingerprint(Path(ds.root))
    return ds
