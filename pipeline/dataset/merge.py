"""Merging datasets: shards written by parallel workers (or several runs) into one, atomically."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import replace
from pathlib import Path

from pipeline.dataset.card import DatasetCard
from pipeline.dataset.read import iter_episodes, read_card, read_features, read_info
from pipeline.dataset.schema import Episode
from pipeline.dataset.write import write_dataset
from pipeline.errors import InputError


def _merged_card(roots: Sequence[Path]) -> DatasetCard | None:
    cards = [c for c in (read_card(r) for r in roots) if c is not None]
    if not cards:
        return None
    provenance = list(dict.fromkeys(p for c in cards for p in c.provenance))
    notes = list(dict.fromkeys(n for c in cards for n in c.notes))
    return replace(cards[0], provenance=provenance, notes=notes, synthetic=any(c.synthetic for c in cards))


def merge_datasets(
    roots: Sequence[str | Path],
    out_root: str | Path,
    repo_id: str,
    overwrite: bool = False,
    *,
    card: DatasetCard | None = None,
) -> Path:
    """Concatenate datasets (same fps, robot type and features) into one at ``out_root``.

    Episodes keep their order (shard by shard) and are renumbered; ``index`` is recomputed;
    tasks are renumbered by first appearance; per-episode provenance is carried over. The card
    defaults to the first shard's with the shards' provenance and notes combined. Atomic, like
    :func:`write_dataset`; raises :class:`InputError` naming the first mismatching shard.
    """
    roots = [Path(r) for r in roots]
    if not roots:
        raise InputError(str(out_root), "roots", "no datasets to merge")
    infos = [read_info(r) for r in roots]
    ref = infos[0]
    for r, info in zip(roots[1:], infos[1:]):
        for key in ("fps", "robot_type", "features"):
            if info[key] != ref[key]:
                raise InputError(r, key, f"differs from {roots[0]} ({info[key]!r} vs {ref[key]!r}); cannot merge")

    def episodes() -> Iterator[Episode]:
        for r in roots:  # one shard in memory at a time
            yield from iter_episodes(r)

    return write_dataset(
        out_root,
        repo_id,
        ref["fps"],
        read_features(roots[0]),
        episodes(),
        robot_type=ref["robot_type"],
        card=card or _merged_card(roots),
        overwrite=overwrite,
        data_file_size_mb=ref.get("data_files_size_in_mb", 100),
        chunks_size=ref.get("chunks_size", 1000),
    )
