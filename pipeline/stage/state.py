"""Fingerprints: what a stage's output depends on. Each stage records in its ``report.json`` a
``fingerprint`` of what it was run on (its input files or the previous stage's dataset, and the
options that change its output); a rerun with the same fingerprint finds the output up to date and
does nothing (the rule itself: :meth:`pipeline.stage.run.StageRun.finished`).

A stage builds its fingerprint with :func:`fingerprint` over its parts (:func:`files_fingerprint`
for input files, :func:`dataset_fingerprint` for the previous stage's dataset, plain values for
options); :func:`up_to_date` reads a report (or a run's ``run.json``) back if it records one.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable
from pathlib import Path

from pipeline.dataset.chain import checked_fingerprint

KEY = "fingerprint"


def fingerprint(**parts: object) -> str:
    """A hex digest of ``parts`` (JSON values; key order does not matter)."""
    text = json.dumps(parts, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _files_under(path: Path) -> list[Path]:
    """``path`` itself if a file, else every file below it (sorted); nothing if it is missing."""
    if path.is_file():
        return [path]
    return sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else []


def files_fingerprint(paths: Iterable[str | Path], *, by_content: bool = False) -> str:
    """A hex digest naming every file in ``paths`` (files or folders, searched recursively) by its
    absolute path, size and modification time (``st_mtime_ns``); with ``by_content``, by its name
    and its bytes' sha256 instead (small files whose mtime a fresh clone changes: source code)."""
    h = hashlib.sha256()
    for root in map(Path, paths):
        h.update(f"root|{root.name if by_content else root.resolve()}\n".encode())
        for p in _files_under(root):
            if by_content:
                stamp = hashlib.sha256(p.read_bytes()).hexdigest()
            else:
                st = p.stat()
                stamp = f"{st.st_size}|{st.st_mtime_ns}"
            h.update(f"{p.relative_to(root) if p != root else p.name}|{stamp}\n".encode())
    return h.hexdigest()


def dataset_fingerprint(root: str | Path) -> str:
    """A hex digest of a LeRobot dataset's content: the sha256 of every data file, from its checksum manifest
    after every byte was checked against it (:func:`pipeline.dataset.chain.checked_fingerprint`: a corrupted or
    stale dataset is one :class:`~pipeline.errors.InputError` line), so a stage records the exact data it read.
    A dataset without a manifest (written before them): the bytes of ``meta/info.json``, of the ``meta/episodes``
    parquet files and of its ``report.json`` (those a stage rewrites every run)."""
    root = Path(root)
    if (checked := checked_fingerprint(root)) is not None:
        return checked
    h = hashlib.sha256()
    for p in [root / "meta" / "info.json", *_files_under(root / "meta" / "episodes"), root / "report.json"]:
        if p.is_file():
            h.update(f"{p.relative_to(root).as_posix()}|{hashlib.sha256(p.read_bytes()).hexdigest()}\n".encode())
    return h.hexdigest()


def up_to_date(report_path: str | Path, fp: str) -> dict | None:
    """The report at ``report_path`` if it records the fingerprint ``fp``, else None (no report,
    an unreadable one, or one from a run on other input or options)."""
    try:
        report = json.loads(Path(report_path).read_text())
    except (OSError, ValueError):
        return None
    return report if isinstance(report, dict) and report.get(KEY) == fp else None


def up_to_date_line(command: str, name: str, stage: str) -> str:
    """The one line ``lessmimic <command>`` prints when ``datasets/<name>/<stage>/`` is up to date."""
    return f"{command}: datasets/{name}/{stage}/ is up to date (same input and options); nothing to do"
