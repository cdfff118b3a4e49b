"""Ingest: read a user's mocap (or the embedded synthetic default, or a synthetic corpus) into validated clips and
write them as one LeRobot dataset, ``datasets/<NAME>/human/`` (with its ``report.json``),
and one inspection log per clip in ``datasets/<NAME>/logs/human/``.

This is the part of the chain every stage shares; the retarget stage starts from it.

A synthetic training corpus is named like an input path (:func:`synthetic_corpus`):
``synthetic:<seeds>[:<tasks>]``, ``<seeds>`` a comma list of seeds ``S`` and inclusive ranges ``A-B``
(``synthetic:0-24``, ``synthetic:3``, ``synthetic:0,5,7``), ``<tasks>`` a comma list of the generator's tasks
(``synthetic:0-24:PickUp,Push``; default: all four), or ``Chain`` alone (``synthetic:0-3:Chain``): per seed ``s``
one composed clip (:func:`ingest.synthetic.chain_demo`: the fixed order ``CHAIN_ORDERS[s % 12]``, two different
tasks with the walk between them, two objects; every ordered pair once per 12 seeds), source
``synthetic:Chain:<A>-<B>:seed<s>``. ``Chain`` does not mix with the single tasks: a dataset's clips hold one
number of objects.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, replace
from pathlib import Path

from tqdm import tqdm

from ingest import default_input, synthetic
from ingest.default_input import TASKS, default_clips
from ingest.synthetic import CHAIN, CHAIN_ORDERS, chain_demo
from pipeline.clip import HumanClip
from pipeline.collision_mesh import check_meshes
from pipeline.dataset.card import DatasetCard
from pipeline.dataset.clips import human_clips_to_episodes
from pipeline.dataset.objects import objects_note
from pipeline.dataset.write import check_target, write_dataset
from pipeline.errors import InputError
from pipeline.readers import read_clips
from pipeline.stage.atomic import write_json_atomic
from pipeline.stage.inspect_log import write_human_log
from pipeline.stage.paths import file_stem, stage_dir
from pipeline.stage.state import files_fingerprint, fingerprint
from pipeline.suspicious import collecting

HUMAN_FPS = 30


@dataclass(frozen=True)
class IngestResult:
    dataset: Path
    clips: tuple[HumanClip, ...]
    report: dict


SYNTHETIC_PREFIX = "synthetic:"


def is_synthetic_spec(input_path: str | Path | None) -> bool:
    """Whether ``input_path`` names a synthetic corpus (``synthetic:...``) rather than a file or folder."""
    return isinstance(input_path, str) and input_path.startswith(SYNTHETIC_PREFIX)


def _seed(spec: str, text: str) -> int:
    if not re.fullmatch(r"[+-]?\d+", text):
        raise InputError(spec, "seeds", f"{text!r} is not an integer seed or an A-B range of them")
    if int(text) < 0:
        raise InputError(spec, "seeds", f"seed {int(text)} is negative (seeds are integers >= 0)")
    return int(text)


def parse_synthetic_spec(spec: str) -> tuple[tuple[int, ...], tuple[str, ...]]:
    """``synthetic:<seeds>[:<tasks>]`` (module docstring) -> (seeds in the order given, tasks in the generator's
    order); a bad spec is one :class:`InputError` line naming the field (``seeds`` or ``tasks``)."""
    parts = spec.removeprefix(SYNTHETIC_PREFIX).split(":")
    if len(parts) > 2:
        raise InputError(spec, "spec", "expected synthetic:<seeds> or synthetic:<seeds>:<tasks>")
    seeds: list[int] = []
    for item in (s.strip() for s in parts[0].split(",")):
        if not item:
            raise InputError(spec, "seeds", "empty (expected e.g. 0-24, 3 or 0,5,7)")
        if m := re.fullmatch(r"\s*(-?\w+)\s*-\s*(-?\w+)\s*", item):  # A-B (a lone "-3" is a negative seed)
            a, b = _seed(spec, m[1]), _seed(spec, m[2])
            if b < a:
                raise InputError(spec, "seeds", f"range {a}-{b} is empty (A-B needs A <= B)")
            seeds += range(a, b + 1)
        else:
            seeds.append(_seed(spec, item))
    if dup := sorted({s for s in seeds if seeds.count(s) > 1}):
        raise InputError(spec, "seeds", f"seed {dup[0]} is listed twice (every clip's source must be unique)")
    tasks = list(TASKS)
    if len(parts) == 2:
        tasks = [t.strip() for t in parts[1].split(",")]
        for t in tasks:
            if t not in TASKS and t != CHAIN:
                raise InputError(
                    spec, "tasks", f"unknown task {t!r} (known: {', '.join(TASKS)}) or {CHAIN} (composed clips)"
                )
        if len(set(tasks)) < len(tasks):
            raise InputError(spec, "tasks", "a task is listed twice")
        if CHAIN in tasks and len(tasks) > 1:
            n = len(CHAIN_ORDERS[0])
            why = f"its clips hold {n} objects, the single tasks' 1, and a dataset's clips hold one number of objects"
            raise InputError(spec, "tasks", f"{CHAIN} is a corpus of its own ({why})")
    return tuple(seeds), tuple(t for t in (*TASKS, CHAIN) if t in tasks)


def synthetic_corpus(spec: str, fps: float = 30.0) -> list[HumanClip]:
    """The synthetic clips of ``spec`` (:func:`parse_synthetic_spec`): for every seed ``s``,
    ``default_clips(fps, seed=s)`` filtered to the tasks, each clip (and its objects) with the unique source
    ``synthetic:<task>:seed<s>``; all labelled synthetic, as the generator makes them. ``Chain``: per seed its
    composed clip (:func:`ingest.synthetic.chain_demo`), source ``synthetic:Chain:<order>:seed<s>``."""
    seeds, tasks = parse_synthetic_spec(spec)
    clips = []
    for s in seeds:
        for c in [chain_demo(fps, seed=s).clip] if tasks == (CHAIN,) else default_clips(fps, seed=s):
            if c.task in tasks:
                source = f"{c.source}:seed{s}" if c.task == CHAIN else f"synthetic:{c.task}:seed{s}"
                objects = tuple(replace(o, source=source) for o in c.objects)
                clips.append(replace(c, source=source, objects=objects))
    return clips


def load_input(
    input_path: str | None,
    *,
    body_model: str | None = None,
    fps: float | None = None,
    units: str | None = None,
    mesh: str | None = None,
) -> list[HumanClip]:
    """Clips from ``input_path`` (file or folder, or a ``synthetic:<seeds>[:<tasks>]`` corpus:
    :func:`synthetic_corpus`), or the embedded synthetic default when None; ``fps``, ``units`` and ``mesh`` are the
    readers' (:mod:`pipeline.readers`) for files that carry none."""
    if input_path is None:
        return default_clips()
    if is_synthetic_spec(input_path):
        return synthetic_corpus(input_path, fps or 30.0)
    return read_clips(Path(input_path), body_model=body_model, fps=fps, units=units, mesh=mesh)


def source_fingerprint(input_path: str | None) -> str:
    """What the human clips of ``input_path`` depend on: every input file's path, size and mtime (the embedded
    default: its generator's source code; a ``synthetic:`` corpus: that code and the spec's seeds and tasks, so
    ``synthetic:0-2`` and ``synthetic:0,1,2`` are the same input). A bad corpus spec is its one-line
    :class:`InputError` here, before any work."""
    generator = [Path(default_input.__file__), *sorted(Path(synthetic.__file__).parent.glob("*.py"))]
    if input_path is None:
        return "embedded default " + files_fingerprint(generator, by_content=True)
    if is_synthetic_spec(input_path):
        seeds, tasks = parse_synthetic_spec(input_path)
        return "synthetic corpus " + fingerprint(
            generator=files_fingerprint(generator, by_content=True), seeds=seeds, tasks=tasks
        )
    return files_fingerprint([input_path])


def input_label(input_path: str | None) -> str:
    """How a report names the input."""
    return input_path or "embedded synthetic default"


def ingest(
    input_path: str | None,
    name: str,
    *,
    overwrite: bool = False,
    body_model: str | None = None,
    root: Path | None = None,
    read: dict | None = None,
) -> IngestResult:
    """Read, validate and resample to :data:`HUMAN_FPS`, write the dataset, reload it with LeRobot; ``read``: the
    readers' options (``fps``, ``units``, ``mesh``: :func:`load_input`)."""
    out = stage_dir(name, "human", root)
    check_target(out, overwrite)  # before any work, so the user sees only this line
    t0 = time.perf_counter()
    with collecting() as suspicious:  # printed once each, and in the report (pipeline.suspicious)
        loaded = load_input(input_path, body_model=body_model, **(read or {}))
    check_meshes(loaded)  # before any work: a degenerate mesh is found here, not by the retargeting of its clip
    clips = [c.resampled(HUMAN_FPS) for c in tqdm(loaded, desc="read", unit="clip")]
    synthetic = any(c.synthetic for c in clips)
    features, episodes = human_clips_to_episodes(clips)
    card = DatasetCard(
        title=f"{name}: human motion (ingested)",
        description=(
            "SYNTHETIC human-object demonstrations generated by the toolkit (not real mocap). " if synthetic else ""
        )
        + "Human joint positions (z-up, metres) resampled to a fixed fps, with object poses and contact flags.",
        provenance=[c.source for c in clips],
        robot="none: human motion (SMPL-like skeleton or the source's own)",
        fps=HUMAN_FPS,
        synthetic=synthetic,
        stage="human",
        # Our own synthetic demos are Apache-2.0; user mocap keeps its source's terms.
        license="apache-2.0" if all(c.synthetic for c in clips) else "other",
        notes=(
            []
            if all(c.synthetic for c in clips)
            else ["Derived from the sources listed above: their licence terms apply."]
        )
        + [objects_note(clips)],
    )
    write_dataset(out, f"lessmimic/{name}-human", HUMAN_FPS, features, episodes, card=card, overwrite=overwrite)
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    reloaded = LeRobotDataset(f"lessmimic/{name}-human", root=out)
    logs = out.parent / "logs" / "human"  # beside the dataset root, so `publish` does not upload them
    for i, c in enumerate(tqdm(clips, desc="inspection logs", unit="clip")):
        write_human_log(c, logs / f"{i:03d}_{file_stem(c.source)}.mcap")
    seconds = time.perf_counter() - t0
    report = {
        "stage": "human",
        "input": input_label(input_path),
        "synthetic": synthetic,
        "clips": [
            {
                "episode": i,
                "source": c.source,
                "task": c.task,
                "frames": c.frames,
                "fps": c.fps,
                "joints": len(c.skeleton.joint_names),
                "objects": [o.name for o in c.objects],
                "synthetic": c.synthetic,
            }
            for i, c in enumerate(clips)
        ],
        "frames": reloaded.num_frames,
        "episodes": reloaded.num_episodes,
        "seconds_wall": seconds,
        "warnings": suspicious,
    }
    write_json_atomic(out / "report.json", report)
    return IngestResult(out, tuple(clips), report)
