"""``lessmimic export-motion``: the episodes of a G1 motion dataset (:mod:`motion_export.episodes`) written in one
of :data:`FORMATS` into one folder, each motion with its sidecar (:mod:`motion_export.sidecar`), whole or not at all.

The folder (default ``datasets/<NAME>/export/<format>/``; a retargeted stage's ``.../export/<format>-retargeted/``)
holds per episode ``<stem>`` = ``<episode index, 4 digits>_<clip source>``: the motion (``<stem>.npz``, ``<stem>/``
for HDMI, ``<stem>.pkl``, ``<stem>.csv``), ``<stem>.json`` (its sidecar), object meshes beside them, and
``export.json`` (what was exported: the format, source, and per episode its files and frames). It is written into
a temporary folder beside it and renamed into place when complete (an old export is replaced only with
``overwrite``); a failure removes everything the call created. ``hdmi_object`` renames each episode's first object
to an HDMI asset name before anything is written (its mesh is copied under that name; the sidecar keeps the
dataset's name as ``dataset_name``).

Bad input is a one-line :class:`~pipeline.errors.InputError` naming the file and field, before anything is written:
an unknown format, an HDMI object name with another format or outside HDMI's, anything
:func:`motion_export.episodes.select_episodes` refuses, an existing output without ``overwrite``.
"""

from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from motion_export import FORMAT_NAMES, HDMI_OBJECT_NAMES, gmr, hdmi, npz, unitree_csv
from motion_export.episodes import ExportSource, select_episodes
from motion_export.sidecar import objects_entry, sidecar
from pipeline.errors import InputError
from pipeline.stage.atomic import remove_dead_staging, replace_folder, staging_folder
from pipeline.stage.paths import file_stem, stage_dir

#: format name -> its writer (``write(episode, folder, stem) -> Written``)
FORMATS = dict(zip(FORMAT_NAMES, (npz.write, npz.write_beyondmimic, hdmi.write, gmr.write, unitree_csv.write)))
MANIFEST = "export.json"


@dataclass(frozen=True)
class ExportSummary:
    """What an export wrote: the folder, the format, the episodes (source indices), the files with their sizes
    [bytes], exported frames and seconds of motion, and the seconds spent reading the dataset and writing."""

    out: Path
    fmt: str
    episodes: tuple[int, ...]
    files: tuple[tuple[str, int], ...]
    frames: int
    seconds: float
    read_s: float
    write_s: float

    @property
    def bytes(self) -> int:
        return sum(size for _, size in self.files)


def default_out(name: str, fmt: str, stage: str) -> Path:
    """``datasets/<name>/export/<fmt>/`` (``<fmt>-retargeted`` for the retargeted stage)."""
    return stage_dir(name, "export") / (fmt if stage == "physicalized" else f"{fmt}-{stage}")


def episode_stem(index: int, source: str) -> str:
    return f"{index:04d}_{file_stem(source)}"


def _write_all(source: ExportSource, fmt: str, folder: Path, hdmi_object: str | None) -> tuple[list[dict], int, float]:
    """Every episode and its sidecar into ``folder``; the manifest rows, exported frames and seconds of motion."""
    rows, frames, seconds = [], 0, 0.0
    for ep in tqdm(source.episodes, desc=f"export {fmt}", unit="episode"):
        stem = episode_stem(ep.index, ep.clip.source)
        dataset_names = [o.name for o in ep.clip.objects]
        if hdmi_object is not None:
            ep = hdmi.with_object_name(ep, hdmi_object)
        written = FORMATS[fmt](ep, folder, stem)
        objects = objects_entry(ep, folder, stem, list(written.objects_in))
        for entry, name in zip(objects, dataset_names):
            entry["dataset_name"] = name
        motion = written.motion_entry(folder)
        doc = sidecar(source, ep, fmt, motion, objects)
        (folder / f"{stem}.json").write_text(json.dumps(doc, indent=2, default=str) + "\n")
        rows.append({"episode_index": ep.index, "clip": ep.clip.source, "valid": ep.valid, "files": motion["files"],
                     "sidecar": f"{stem}.json", "frames": written.frames})  # fmt: skip
        frames, seconds = frames + written.frames, seconds + written.frames / written.fps
    return rows, frames, seconds


def _out_error(exc: OSError, out: Path, tmp: Path) -> InputError | None:
    """An OS error on the way to writing ``out`` (``/sys/x``, a read-only folder, a full disk) as the one line naming
    ``out``: a path in the staging folder ``tmp`` as the one it was to have in ``out``, a folder above ``out`` that
    could not be made as ``out``'s folder; None when the error is about another path (one read, say)."""
    reason = exc.strerror or str(exc) or type(exc).__name__
    for name in (exc.filename, exc.filename2):
        if name is None:
            continue
        path = Path(os.fsdecode(name))
        if path == tmp or tmp in path.parents:
            return InputError(out / path.relative_to(tmp), "out", f"cannot be written: {reason}")
        if path == out or path in out.parents:
            folder = "" if path == out else f" (its folder {path} cannot be made)"
            return InputError(out, "out", f"cannot be written{folder}: {reason}")
    return None


def export_motion(
    name: str,
    fmt: str,
    out: str | Path | None = None,
    *,
    stage: str = "physicalized",
    episode: int | None = None,
    include_invalid: bool = False,
    overwrite: bool = False,
    hdmi_object: str | None = None,
) -> ExportSummary:
    """Export corpus ``name``'s ``stage`` as ``fmt`` into ``out`` (module doc); returns what was written.
    ``hdmi_object`` names the first object as HDMI's asset (one of :data:`motion_export.HDMI_OBJECT_NAMES`)."""
    if fmt not in FORMATS:
        raise InputError(stage_dir(name, stage), "format", f"unknown format {fmt!r}; known: {', '.join(FORMATS)}")
    if hdmi_object is not None and (fmt != "hdmi" or hdmi_object not in HDMI_OBJECT_NAMES):
        why = f"{hdmi_object!r} with format {fmt}: HDMI only, one of {', '.join(HDMI_OBJECT_NAMES)}"
        raise InputError(stage_dir(name, stage), "hdmi_object", why)
    t0 = time.perf_counter()
    source = select_episodes(name, stage, episode=episode, include_invalid=include_invalid)
    if out is not None and not Path(out).parent.is_dir():  # a given --out never makes the folders above it
        raise InputError(out, "out", f"its folder {Path(out).parent} does not exist (make it first)")
    out = Path(out) if out is not None else default_out(name, fmt, stage)
    if out.exists() and not overwrite:
        raise InputError(out, "out", "exists; pass --overwrite (OVERWRITE=1 with make) to replace it")
    if out.exists() and not out.is_dir():
        raise InputError(out, "out", "exists and is not a folder")
    created = [p for p in (out.parent, *out.parent.parents) if not p.exists()]
    tmp = staging_folder(out)
    t1 = time.perf_counter()
    try:
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            remove_dead_staging(out)
            tmp.mkdir()
            rows, frames, seconds = _write_all(source, fmt, tmp, hdmi_object)
            manifest = {"format": fmt, "dataset": name, "stage": stage, "root": str(source.root),
                        "episodes_in_dataset": source.total, "episodes": rows}  # fmt: skip
            (tmp / MANIFEST).write_text(json.dumps(manifest, indent=2, default=str) + "\n")
            files = tuple((str(p.relative_to(tmp)), p.stat().st_size) for p in sorted(tmp.rglob("*")) if p.is_file())
            replace_folder(tmp, out)
        except OSError as exc:  # named as the folder asked for, never the staging folder beside it
            named = _out_error(exc, out, tmp)
            if named is None:
                raise
            raise named from exc
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for p in created:  # the folders this call made, innermost first, if still empty
            if p.is_dir() and not any(p.iterdir()):
                p.rmdir()
        raise
    episodes = tuple(e.index for e in source.episodes)
    return ExportSummary(out, fmt, episodes, files, frames, seconds, t1 - t0, time.perf_counter() - t1)
