"""The stages chained by content: ``human -> retargeted -> physicalized -> features`` under ``datasets/<NAME>/``.

Why: a stage rewritten upstream (another input, ``--overwrite`` whose clips all failed) left the datasets made from
its old content in place, read on as if they were made from the new. Each dataset we write records in its checksum
manifest (:mod:`pipeline.dataset.checksums`) the content fingerprint of the upstream dataset it was made from; a
dataset whose upstream's content is no longer that one is **stale**, and so is every dataset made from a stale one.

* :func:`upstream_record` -- what :func:`pipeline.dataset.write.write_dataset` records: the fingerprint of the
  upstream as this process read it (:func:`checked_fingerprint` remembers it), else as it is now;
* :func:`stale_reason` -- why a dataset is stale (None: it is not, or it cannot be told: no upstream beside it);
* :func:`checked_fingerprint` -- what a reader of a dataset calls first: every byte checked against the manifest,
  a stale dataset refused, both in one :class:`InputError` line; returns the content fingerprint.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.dataset.checksums import content_fingerprint, read_checksums, verify_files
from pipeline.errors import InputError

CHAIN = ("human", "retargeted", "physicalized", "features")
#: The command that makes each stage's dataset, for the line that says what to rerun.
MADE_BY = {"human": "retarget", "retargeted": "retarget", "physicalized": "physicalize", "features": "features"}
_SEEN: dict[Path, str] = {}  # content fingerprints of the datasets this process read or wrote, by absolute path


def upstream_of(root: Path) -> Path | None:
    """The dataset ``root`` is made from: its sibling one stage up the chain, None for ``human`` or a folder
    not named after a stage."""
    root = Path(root)
    if root.name not in CHAIN[1:]:
        return None
    return root.parent / CHAIN[CHAIN.index(root.name) - 1]


def remember(root: Path, fingerprint: str) -> None:
    """Note that this process read (or wrote) ``root`` with this content fingerprint."""
    _SEEN[Path(root).absolute()] = fingerprint


def current_fingerprint(root: Path) -> str | None:
    """The content fingerprint of ``root`` as its manifest says (no bytes read), None without one."""
    manifest = read_checksums(root) if (Path(root) / "meta").is_dir() else None
    return None if manifest is None else content_fingerprint(manifest)


def upstream_record(root: Path) -> dict | None:
    """What the dataset about to be written at ``root`` records of its upstream (module docstring)."""
    up = upstream_of(root)
    if up is None:
        return None
    fp = _SEEN.get(up.absolute()) or current_fingerprint(up)
    return None if fp is None else {"stage": up.name, "fingerprint": fp}


def stale_reason(root: Path) -> str | None:
    """Why the dataset at ``root`` is stale, or None (module docstring). Reads manifests only."""
    root = Path(root)
    manifest = read_checksums(root) if (root / "meta").is_dir() else None
    record = (manifest or {}).get("upstream")
    up = upstream_of(root)
    if not record or up is None or not up.is_dir():
        return None
    now = current_fingerprint(up)
    if now != record.get("fingerprint"):
        what = "was removed or replaced" if now is None else "was rewritten"
        return f"stale: its upstream {up.name}/ {what} after it was made from it"
    if why := stale_reason(up):
        return f"stale: its upstream {up.name}/ is {why}"
    return None


def rerun_hint(root: Path) -> str:
    """The command that brings a stale chain up to date again."""
    first = Path(root)
    while (up := upstream_of(first)) is not None and up.is_dir() and stale_reason(first) and stale_reason(up):
        first = up
    return f"rerun `lessmimic {MADE_BY.get(first.name, 'retarget')} --name {first.parent.name}`"


def checked_fingerprint(root: Path) -> str | None:
    """Verify ``root`` byte for byte against its manifest and refuse it when stale, each in one :class:`InputError`
    line; returns its content fingerprint (None: a dataset without a manifest, which cannot be checked)."""
    root = Path(root)
    manifest = verify_files(root)
    if manifest is None:
        return None
    if why := stale_reason(root):
        raise InputError(root, "chain", f"{why}; {rerun_hint(root)}")
    fp = content_fingerprint(manifest)
    remember(root, fp)
    return fp
