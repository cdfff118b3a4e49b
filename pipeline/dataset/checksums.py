"""Every file of a dataset we write, by its sha256, in ``meta/lessmimic_checksums.json`` (a file LeRobot ignores).

Why: a parquet file corrupted after it was written (a flipped byte, a bad copy, an edit) read on as if it were the
data, and a stage's up-to-date check that looked at its upstream's metadata, not its data, let it flow downstream.
The digests are of the bytes, so a file changed with its size and modification time put back is caught.

The manifest::

    {"format": 1, "algorithm": "sha256",
     "files": {"data/chunk-000/file-000.parquet": {"sha256": "...", "bytes": 1234}, "meta/info.json": ..., ...},
     "upstream": {"stage": "retargeted", "fingerprint": "..."} or null}

``files`` lists every file of the dataset as written (``data/``, ``meta/``, ``README.md``); the ``report.json`` a
stage adds beside them, and hidden files (a hub download's ``.cache``), are not data. ``upstream`` is the
:func:`content_fingerprint` of the dataset this one was made from (:mod:`pipeline.dataset.chain`).
:func:`verify_files` checks a dataset against its manifest: a changed, missing or unlisted data file is one
:class:`InputError` line naming the file.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from pipeline.dataset.schema import SIDECAR_CHECKSUMS
from pipeline.errors import InputError

FORMAT = 1
NOT_DATA = ("report.json",)  # beside the data, rewritten by a stage's report: not part of the content


def file_sha256(path: Path) -> str:
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def _listed(root: Path) -> list[Path]:
    """The files a manifest lists: every file below ``root`` but hidden ones, the manifest and :data:`NOT_DATA`."""
    out = []
    for p in sorted(root.rglob("*")):
        rel = p.relative_to(root)
        if p.is_file() and not any(part.startswith(".") for part in rel.parts):
            if rel.as_posix() != SIDECAR_CHECKSUMS and rel.as_posix() not in NOT_DATA:
                out.append(p)
    return out


def write_checksums(root: Path, upstream: dict | None = None) -> dict:
    """Write the manifest of the finished dataset at ``root`` (see the module docstring); returns it."""
    root = Path(root)
    files = {}
    for p in _listed(root):
        files[p.relative_to(root).as_posix()] = {"sha256": file_sha256(p), "bytes": p.stat().st_size}
    manifest = {"format": FORMAT, "algorithm": "sha256", "files": files, "upstream": upstream}
    (root / SIDECAR_CHECKSUMS).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return manifest


def read_checksums(root: Path) -> dict | None:
    """The manifest of ``root``, None when it has none (a dataset we did not write, or one written before it)."""
    path = Path(root) / SIDECAR_CHECKSUMS
    if not path.is_file():
        return None
    try:
        manifest = json.loads(path.read_text())
    except ValueError as exc:
        raise InputError(path, "checksums", f"unreadable ({exc})") from None
    if not isinstance(manifest, dict) or not isinstance(manifest.get("files"), dict):
        raise InputError(path, "checksums", "not a checksum manifest (no files)")
    return manifest


def content_fingerprint(manifest: dict) -> str:
    """A hex digest of a dataset's data as its manifest lists it: equal for byte-identical data wherever it lies."""
    h = hashlib.sha256()
    for rel, entry in sorted(manifest["files"].items()):
        h.update(f"{rel}|{entry['sha256']}\n".encode())
    return h.hexdigest()


def verify_files(root: Path) -> dict | None:
    """Check every file of ``root`` against its manifest (reading every byte); returns the manifest (None when
    the dataset has none). A file whose bytes differ, one listed but missing and a data file not listed are each
    an :class:`InputError` naming it."""
    root = Path(root)
    manifest = read_checksums(root)
    if manifest is None:
        return None
    for rel, entry in sorted(manifest["files"].items()):
        path = root / rel
        if not path.is_file():
            raise InputError(root, rel, "missing (the checksums list it): the dataset is incomplete")
        if file_sha256(path) != entry["sha256"]:
            why = "sha256 differs from the checksums: changed or corrupted since it was written"
            raise InputError(root, rel, f"{why} ({entry['bytes']} -> {path.stat().st_size} bytes)")
    for p in _listed(root):
        rel = p.relative_to(root).as_posix()
        if rel not in manifest["files"]:
            raise InputError(root, rel, "not in the checksums: a file added after the dataset was written")
    return manifest
