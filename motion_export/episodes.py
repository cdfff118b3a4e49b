"""Which episodes of which dataset an export holds, read through the dataset readers.

A G1 motion dataset is a stage of :data:`MOTION_STAGES` under ``datasets/<NAME>/``:

* ``physicalized`` (the default): the simulated clips (:func:`pipeline.dataset.clips.episodes_to_physicalized_clips`);
  ``qvel`` and the objects' velocities are the simulation's; the episode's validation figures come along. Only
  valid episodes are exported unless ``include_invalid`` (``--all``); a dataset physicalized without
  ``--keep-invalid`` holds valid episodes only;
* ``retargeted``: the kinematic clips (:func:`pipeline.dataset.clips.episodes_to_robot_clips`), velocities by
  central differences of ``qpos`` and of the object poses (:func:`pipeline.kinematics.qvel_from_qpos`, as the
  dataset's ``observation.qvel``); no validation figures (never simulated).

``episode`` picks one episode by its index in the dataset (valid or not: it is named). Anything else is a one-line
:class:`~pipeline.errors.InputError` naming the file and field: another stage (``human``, ``features``), a missing
dataset, a dataset whose ``observation.state`` is not the G1's 36 ``qpos`` columns, an index out of range, or no
episode to export.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_export import MOTION_STAGES
from pipeline.clip import START_PREFIX_KEY, RobotClip
from pipeline.dataset.clips import episodes_to_physicalized_clips, episodes_to_robot_clips
from pipeline.dataset.read import dataset_actuator_profile, read_info
from pipeline.errors import InputError
from pipeline.kinematics import qvel_from_qpos
from pipeline.robot import QPOS_NAMES
from pipeline.stage.paths import stage_dir


@dataclass(frozen=True)
class ExportEpisode:
    """One episode to export: its index in the source dataset, the clip (``qpos``, objects, provenance), ``qvel
    [T, 35]`` (MuJoCo's: root linear world, root angular in the root frame, joints), per object ``[T, 6]`` velocities
    (linear world, angular in the object frame), the validation figures (None: never simulated) and where the
    velocities come from."""

    index: int
    clip: RobotClip
    qvel: np.ndarray
    object_vel: tuple[np.ndarray, ...]
    validation: dict | None
    velocity_source: str

    @property
    def frames(self) -> int:
        return self.clip.frames

    @property
    def fps(self) -> float:
        return self.clip.fps

    @property
    def prefix_frames(self) -> int:
        """Frames of the synthetic start prefix before the clip's own (:mod:`physicalize.start`; 0: none)."""
        return int(self.clip.provenance.get(START_PREFIX_KEY, 0) or 0)

    @property
    def valid(self) -> bool | None:
        return None if self.validation is None else bool(self.validation.get("valid", False))


@dataclass(frozen=True)
class ExportSource:
    """The dataset exported from: corpus ``name``, its ``stage`` and folder, the actuator profile its actions are
    for, how many episodes it holds, and the episodes chosen."""

    name: str
    stage: str
    root: Path
    profile: str
    total: int
    episodes: tuple[ExportEpisode, ...]


def check_motion_dataset(name: str, stage: str) -> Path:
    """The folder of a G1 motion dataset ``datasets/<name>/<stage>/`` (module doc), or a one-line InputError."""
    root = stage_dir(name, stage)
    if stage not in MOTION_STAGES:
        why = f"{stage!r} is not a G1 motion stage: export one of {', '.join(MOTION_STAGES)}"
        raise InputError(root, "stage", why)
    info_path = root / "meta" / "info.json"
    if not info_path.is_file():
        verb = "physicalize" if stage == "physicalized" else "retarget"
        raise InputError(info_path, "meta/info.json", f"no dataset here: run `lessmimic {verb} --name {name}` first")
    state = read_info(root)["features"].get("observation.state") or {}
    if tuple(state.get("names") or ()) != QPOS_NAMES:
        raise InputError(
            info_path,
            "features",
            "no observation.state of the G1's 36 qpos (root, quaternion wxyz, 29 joints): not a G1 motion dataset",
        )
    return root


def _read(root: Path, stage: str) -> list[ExportEpisode]:
    if stage == "physicalized":
        return [
            ExportEpisode(k, c.robot, c.qvel, c.object_vel, dict(c.validation), "simulation")
            for k, c in enumerate(episodes_to_physicalized_clips(root))
        ]
    out = []
    for k, clip in enumerate(episodes_to_robot_clips(root)):
        vel = tuple(qvel_from_qpos(o.pose, clip.fps) for o in clip.objects)
        out.append(ExportEpisode(k, clip, qvel_from_qpos(clip.qpos, clip.fps), vel, None, "central differences"))
    return out


def select_episodes(
    name: str, stage: str = "physicalized", *, episode: int | None = None, include_invalid: bool = False
) -> ExportSource:
    """The episodes of ``datasets/<name>/<stage>/`` to export (module doc)."""
    root = check_motion_dataset(name, stage)
    total = int(read_info(root)["total_episodes"])
    if episode is not None and not 0 <= episode < total:
        why = f"{episode} is out of range: the dataset has {total} episodes (0-{total - 1})"
        raise InputError(root, "episode", why)
    episodes = _read(root, stage)
    if episode is not None:
        chosen = [episodes[episode]]
    else:
        chosen = [e for e in episodes if include_invalid or e.valid is not False]
    if not chosen:
        raise InputError(root, "episodes", f"none of the {total} episodes is valid (pass --all to export them)")
    return ExportSource(name, stage, root, dataset_actuator_profile(root), total, tuple(chosen))
