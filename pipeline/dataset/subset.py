"""A corpus cut by geometry variant: the training side of the held-out protocol.

An augmented corpus (``lessmimic retarget --augment-scales``: :mod:`retarget.augment`) holds every clip in several
object variants, each episode's variant in its provenance (``provenance["augment"]["label"]``: ``x0.6``,
``x1-cylinder``, ...). :func:`subset_corpus` writes the three datasets a training run reads (``retargeted``,
``physicalized``, ``features``) with only the episodes of the chosen variants as another corpus, and
``subset.json`` beside them naming the source corpus, the variants kept and the variants held out. A policy trained
on it has never seen the held-out variants, so the evaluation on the full corpus scores them as extrapolation.
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

from pipeline.dataset.read import iter_episodes, read_card, read_episode_meta, read_features, read_info
from pipeline.dataset.write import write_dataset
from pipeline.errors import InputError
from pipeline.geometry import provenance_variant
from pipeline.stage.atomic import write_json_atomic
from pipeline.stage.lock import LOCK_NAME
from pipeline.stage.paths import stage_dir

STAGES = ("retargeted", "physicalized", "features")  # what a training run reads
SUBSET_FILE = "subset.json"


def corpus_variants(name: str) -> list[str]:
    """The variant labels of corpus ``name`` (its retargeted dataset), in first-seen order."""
    root = stage_dir(name, "retargeted")
    read_info(root)  # a missing dataset is its one-line error
    labels = [provenance_variant(m.get("provenance")) for m in read_episode_meta(root)]
    if None in labels:
        raise InputError(root, "provenance.augment", "this corpus was not augmented (retarget --augment-scales)")
    return list(dict.fromkeys(labels))


def subset_corpus(name: str, out: str, variants: Sequence[str], *, overwrite: bool = False) -> dict:
    """Write corpus ``out`` from corpus ``name`` keeping the episodes of ``variants`` (module docstring); returns
    what ``subset.json`` holds. An unknown variant, a subset that holds every variant (nothing held out) or an
    existing ``out`` without ``overwrite`` is a one-line :class:`InputError`; nothing partial is left behind."""
    known = corpus_variants(name)
    keep = list(dict.fromkeys(variants))
    if unknown := [v for v in keep if v not in known]:
        raise InputError(stage_dir(name, "retargeted"), "variants", f"{unknown[0]!r} is not in it ({', '.join(known)})")
    held = [v for v in known if v not in keep]
    if not held:
        raise InputError(name, "variants", "the subset keeps every variant: nothing is held out for the evaluation")
    for stage in STAGES:
        read_info(stage_dir(name, stage))
    final = stage_dir(out, STAGES[0]).parent
    if _holds_more_than_its_lock(final) and not overwrite:
        raise InputError(final, "out", "exists; pass --overwrite to replace it")
    tmp = final.with_name(f".{final.name}.tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    summary = {"source": name, "variants": keep, "held_out": held, "episodes": {}}
    for stage in STAGES:
        src = stage_dir(name, stage)
        info, card = read_info(src), read_card(src)
        kept = (e for e in iter_episodes(src) if provenance_variant(e.meta.get("provenance")) in keep)
        note = f"A subset of corpus `{name}`: the geometry variants {', '.join(keep)}; held out {', '.join(held)}."
        write_dataset(
            tmp / stage,
            f"lessmimic/{out}-{stage}",
            info["fps"],
            read_features(src),
            kept,
            robot_type=info["robot_type"],
            card=None if card is None else replace(card, notes=[*card.notes, note]),
        )
        summary["episodes"][stage] = read_info(tmp / stage)["total_episodes"]
    write_json_atomic(tmp / SUBSET_FILE, summary)
    if final.exists():  # the old corpus out, its lock kept (the writer holding it is this command)
        for old in final.iterdir():
            if old.name != LOCK_NAME:
                shutil.rmtree(old) if old.is_dir() else old.unlink()
    final.mkdir(parents=True, exist_ok=True)
    for new in tmp.iterdir():
        os.replace(new, final / new.name)
    tmp.rmdir()
    return summary


def _holds_more_than_its_lock(folder: Path) -> bool:
    """Whether ``folder`` exists with more in it than the writer lock (:mod:`pipeline.stage.lock`) this command
    took."""
    return folder.exists() and any(p.name != LOCK_NAME for p in folder.iterdir())


def read_subset(name: str) -> dict | None:
    """Corpus ``name``'s ``subset.json`` (what it was cut from, and what it holds out), None when it is not a
    subset."""
    path = stage_dir(name, STAGES[0]).parent / SUBSET_FILE
    return json.loads(path.read_text()) if path.is_file() else None
