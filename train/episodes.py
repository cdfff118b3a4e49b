"""Training episodes: a physicalized clip (the simulated state an episode starts from, the root command it
follows, the object track it is scored against) joined with the retargeted clip it came from (the reference
the physicalize teacher tracks, :mod:`train.teacher`), from a corpus's datasets ``datasets/<NAME>/physicalized/``
and ``datasets/<NAME>/retargeted/`` (joined by their ``source``).

An episode runs one of :data:`TASKS` (the clip's task label) with its object at a per-axis ``scale``
(:func:`scaled_objects`): only the geometry changes, never the command, so success at another scale must come
from the distance fields.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from pipeline.clip import ObjectTrack, PhysicalizedClip, RobotClip
from pipeline.dataset.clips import episodes_to_physicalized_clips, episodes_to_robot_clips
from pipeline.dataset.read import dataset_actuator_profile
from pipeline.errors import InputError
from pipeline.geometry import Primitive, provenance_variant
from pipeline.robot import DEFAULT_PROFILE
from pipeline.stage.paths import stage_dir

TASKS = ("PickUp", "SitStand", "Push", "Carry")


@dataclass(frozen=True)
class Episode:
    """One training/evaluation episode source: the simulated clip, its retargeted reference and the actuator
    profile the clip was physicalized under (the environment's and the teacher's: its actions are for those gains)."""

    task: str
    simulated: PhysicalizedClip
    reference: RobotClip
    profile: str = DEFAULT_PROFILE

    @property
    def frames(self) -> int:
        return self.simulated.frames

    @property
    def fps(self) -> float:
        return self.simulated.robot.fps


def episode_variant(episode: Episode) -> str | None:
    """The episode's geometry variant (:func:`pipeline.geometry.variant_label`, from its reference's provenance:
    ``retarget.augment``); None when its corpus was not augmented."""
    return provenance_variant(episode.reference.provenance)


def load_episodes(name: str, tasks: tuple[str, ...] = TASKS, *, valid_only: bool = True) -> list[Episode]:
    """The episodes of corpus ``name`` whose task is one of ``tasks`` (valid physicalized clips only, unless
    ``valid_only`` is False); a missing dataset or an unknown task is a one-line :class:`InputError`."""
    for task in tasks:
        if task not in TASKS:
            raise InputError(task, "task", f"unknown task; known: {', '.join(TASKS)}")
    sim_root, ref_root = stage_dir(name, "physicalized"), stage_dir(name, "retargeted")
    for root, stage in ((sim_root, "physicalize"), (ref_root, "retarget")):
        if not (root / "meta" / "info.json").is_file():
            raise InputError(root, "meta/info.json", f"no dataset here: run `lessmimic {stage} --name {name}` first")
    references = {c.source: c for c in episodes_to_robot_clips(ref_root)}
    profile = dataset_actuator_profile(sim_root)
    out = []
    for clip in episodes_to_physicalized_clips(sim_root):
        if clip.robot.task not in tasks or (valid_only and not clip.validation.get("valid", False)):
            continue
        if clip.robot.source not in references:
            raise InputError(ref_root, "source", f"{clip.robot.source!r} has no retargeted clip to teach from")
        out.append(Episode(clip.robot.task, clip, references[clip.robot.source], profile))
    if not out:
        raise InputError(sim_root, "episodes", f"no valid episode of {', '.join(tasks)} in this dataset")
    return out


def _floor_offset(geometry) -> float:
    """How far the object's frame origin sits above its lowest point when upright (0 for a chair: its frame is on
    the floor)."""
    if isinstance(geometry, Primitive):
        return float(geometry.half_extents[2])
    return 0.0


def scaled_objects(objects: tuple[ObjectTrack, ...], scale) -> tuple[ObjectTrack, ...]:
    """The objects at a per-axis ``scale`` (object frame), their tracks shifted so that what rested on the floor
    still does (a box's centre rises with its half-height; a chair's frame is on the floor)."""
    scale = np.broadcast_to(np.asarray(scale, dtype=float), (3,))
    out = []
    for o in objects:
        geometry = o.geometry.scaled(scale)
        pose = o.pose.copy()
        pose[:, 2] += _floor_offset(geometry) - _floor_offset(o.geometry)
        out.append(replace(o, geometry=geometry, pose=pose))
    return tuple(out)


def check_scale(scale, where: str | Path | None = None) -> tuple[float, float, float]:
    """A per-axis object scale within the paper's evaluation range 0.4-1.6 (one number: all axes)."""
    s = tuple(float(v) for v in np.broadcast_to(np.asarray(scale, dtype=float), (3,)))
    if not all(0.4 - 1e-9 <= v <= 1.6 + 1e-9 for v in s):
        raise InputError(where, "scale", f"{s} outside the evaluated range 0.4-1.6")
    return s  # type: ignore[return-value]
