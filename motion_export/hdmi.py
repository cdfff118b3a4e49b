"""HDMI motion folders: ``<stem>/motion.npz`` + ``<stem>/meta.json``, the layout HDMI's motion datasets use and
:func:`pipeline.readers.peers.read_hdmi_motion` imports.

What HDMI reads (``LeCAR-Lab/HDMI``: ``active_adaptation/utils/motion.py: MotionDataset`` and
``envs/mdp/commands/hdmi/command.py: RobotObjectTracking``), facts only:

* ``meta.json`` -- ``fps``, ``joint_names`` (ours: the 29 entity joints; HDMI picks its own joints by name),
  ``body_names`` (the 30 entity bodies, then each object's body: the object last). HDMI finds the tracked object's
  body by its **asset name** (``object_asset_name`` in its task configs: ``body_names.index(...)``), so the object's
  name is an option (:data:`motion_export.HDMI_OBJECT_NAMES`, HDMI's rigid objects; the dataset's own name by default);
* ``motion.npz`` -- ``joint_pos`` / ``joint_vel`` ``[T, 29]`` in ``joint_names`` order; ``body_pos_w``,
  ``body_quat_w`` (``wxyz``), ``body_lin_vel_w``, ``body_ang_vel_w`` ``[T, B, .]`` in ``body_names`` order, world
  frame; the robot's linear velocity is each body's centre of mass (HDMI records Isaac Lab's
  ``body_com_lin_vel_w``; :mod:`motion_export.bodies`), the objects' their origin's; float32;
* ``object_contact`` ``[T, 1]`` bool in ``motion.npz`` -- whether the robot touches the tracked (first) object at
  each frame, which ``RobotObjectTracking`` reads (``motion_data["object_contact"]``: a ``KeyError`` without it)
  for its contact rewards, observations and terminations. It is the object's own contact flags, else (one object)
  any contact link of the episode touching an object (:attr:`pipeline.clip.RobotClip.contacts`); an episode with
  an object and no contact labels is a one-line :class:`~pipeline.errors.InputError`.

At our 50 Hz no resampling happens in HDMI (its ``interpolate`` refuses extra keys such as ``object_contact`` only
when the rates differ). The object's mesh, when it has one, lands beside the folders as ``<name>.obj``
(:mod:`motion_export.sidecar`), where the importer looks for it.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from motion_export.bodies import ENTITY_JOINT_NAMES, body_motion
from motion_export.episodes import ExportEpisode
from motion_export.npz import robot_arrays
from motion_export.writer import Written, fps_value, object_motions
from pipeline.errors import InputError


def with_object_name(ep: ExportEpisode, name: str) -> ExportEpisode:
    """``ep`` with its first (tracked) object named ``name`` (HDMI's asset name); a one-line InputError for an
    episode without objects."""
    objects = ep.clip.objects
    if not objects:
        raise InputError(ep.clip.source, "objects", f"no object to name {name!r}: the episode carries none")
    return replace(ep, clip=replace(ep.clip, objects=(replace(objects[0], name=name), *objects[1:])))


def object_contact(ep: ExportEpisode) -> np.ndarray:
    """``[T, 1]`` bool: the robot touches the first object (module doc)."""
    o, c = ep.clip.objects[0], ep.clip.contacts
    if o.contact is not None:
        flags = o.contact
    elif c is not None and len(ep.clip.objects) == 1:
        flags = c.any(axis=1)
    else:
        why = f"no contact labels for object {o.name!r}: HDMI's object_contact cannot be written"
        raise InputError(ep.clip.source, "contacts", why)
    return np.asarray(flags, bool).reshape(-1, 1)


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>/motion.npz`` and ``<stem>/meta.json`` (module doc)."""
    out = folder / stem
    out.mkdir()
    bodies = body_motion(ep.clip.qpos, ep.qvel)
    robot, objects = robot_arrays(ep, bodies), object_motions(ep)
    robot["body_lin_vel_w"] = bodies.com_lin_vel.astype(np.float32)
    arrays = {"joint_pos": robot["joint_pos"], "joint_vel": robot["joint_vel"]}
    for key, attr in (("body_pos_w", "pos"), ("body_quat_w", "quat"), ("body_lin_vel_w", "lin_vel"),
                      ("body_ang_vel_w", "ang_vel")):  # fmt: skip
        extra = [getattr(o, attr)[:, None] for o in objects]
        arrays[key] = np.concatenate([robot[key], *extra], axis=1).astype(np.float32)
    if objects:
        arrays["object_contact"] = object_contact(ep)
    np.savez(out / "motion.npz", **arrays)
    names = [*bodies.names, *(o.name for o in objects)]
    meta = {"fps": fps_value(ep.fps), "joint_names": list(ENTITY_JOINT_NAMES), "body_names": names}
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    where = tuple(f"body {o.name!r} (index {len(bodies.names) + k} of body_names)" for k, o in enumerate(objects))
    layout = {
        "keys": "meta.json: fps, joint_names, body_names (objects last); motion.npz: joint_pos, joint_vel [T, 29]; "
        "body_pos_w, body_quat_w (wxyz), body_lin_vel_w (robot: centre of mass; objects: origin), body_ang_vel_w "
        "[T, B, .] (world); object_contact [T, 1] bool (the first object)",
        "object_asset_name": objects[0].name if objects else None,
        "loader": "HDMI active_adaptation.utils.motion.MotionDataset + RobotObjectTracking (object_asset_name)",
    }
    return Written((out / "motion.npz", out / "meta.json"), ep.fps, ep.frames, where, layout)
