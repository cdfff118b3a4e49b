"""Files written whole or not at all: into a temporary name beside the target, then ``os.replace``
(atomic on one file system), so a reader, or a run killed with SIGKILL, never sees half a file."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import uuid
from pathlib import Path


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """``path`` holds ``data`` (parent folders created), or is as it was."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def write_json_atomic(path: Path, data: dict) -> None:
    """``data`` as indented JSON with sorted keys (numpy and paths as strings)."""
    write_bytes_atomic(path, (json.dumps(data, indent=2, sort_keys=True, default=str) + "\n").encode())


def write_pickle_atomic(path: Path, obj: object) -> None:
    write_bytes_atomic(path, pickle.dumps(obj))


def write_torch_atomic(path: Path, obj: object) -> None:
    """``torch.save(obj)`` into ``path``, whole or not at all."""
    import io

    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    write_bytes_atomic(path, buf.getvalue())


def staging_folder(target: Path, tag: str = "staging") -> Path:
    """A fresh hidden folder name beside ``target`` for a writer of this process: ``.<name>.<tag>-<pid>-<id>``."""
    return target.parent / f".{target.name}.{tag}-{os.getpid()}-{uuid.uuid4().hex[:8]}"


def replace_folder(staging: Path, target: Path) -> None:
    """Move the finished folder ``staging`` to ``target``, an old ``target`` replaced (the caller checked that it
    may be): the old one moved aside first and put back if the move fails, so ``target`` is always whole."""
    old = staging_folder(target, "old") if target.exists() else None
    if old is not None:
        os.replace(target, old)
    try:
        os.replace(staging, target)
    except BaseException:
        if old is not None:
            os.replace(old, target)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


def remove_dead_staging(target: Path, tag: str = "staging") -> None:
    """Delete the :func:`staging_folder` s of ``target`` left by killed writers (their pid no longer runs)."""
    for old in target.parent.glob(f".{target.name}.{tag}-*-*"):
        try:
            pid = int(old.name.rsplit("-", 2)[1])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(old, ignore_errors=True)
        except (ValueError, PermissionError):
            pass
