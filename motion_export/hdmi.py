"""HDMI motion folders: ``<stem>/motion.npz`` + ``<stem>/meta.json``, the layout HDMI's motion datasets use and
:func:`pipeline.readers.peers.read_hdmi_motion` imports.

* ``meta.json`` -- ``fps``, ``joint_names`` (the 29 entity joints), ``body_names`` (the 30 entity bodies, then each
  object's body: the object last);
* ``motion.npz`` -- ``joint_pos`` / ``joint_vel`` ``[T, 29]`` in ``joint_names`` order; ``body_pos_w``,
  ``body_quat_w`` (``wxyz``), ``body_lin_vel_w``, ``body_ang_vel_w`` ``[T, B, .]`` in ``body_names`` order, world
  frame (the robot's from :mod:`motion_export.bodies`, the objects' from their tracks); float32.

The object's mesh, when it has one, lands beside the folders as ``<name>.obj`` (:mod:`motion_export.sidecar`), where
the importer looks for it.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from motion_export.bodies import ENTITY_JOINT_NAMES, body_motion
from motion_export.episodes import ExportEpisode
from motion_export.npz import robot_arrays
from motion_export.writer import Written, fps_value, object_motions


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>/motion.npz`` and ``<stem>/meta.json`` (module doc)."""
    out = folder / stem
    out.mkdir()
    bodies = body_motion(ep.clip.qpos, ep.qvel)
    robot, objects = robot_arrays(ep, bodies), object_motions(ep)
    arrays = {"joint_pos": robot["joint_pos"], "joint_vel": robot["joint_vel"]}
    for key, attr in (("body_pos_w", "pos"), ("body_quat_w", "quat"), ("body_lin_vel_w", "lin_vel"),
                      ("body_ang_vel_w", "ang_vel")):  # fmt: skip
        extra = [getattr(o, attr)[:, None] for o in objects]
        arrays[key] = np.concatenate([robot[key], *extra], axis=1).astype(np.float32)
    np.savez(out / "motion.npz", **arrays)
    names = [*bodies.names, *(o.name for o in objects)]
    meta = {"fps": fps_value(ep.fps), "joint_names": list(ENTITY_JOINT_NAMES), "body_names": names}
    (out / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    where = tuple(f"body {o.name!r} (index {len(bodies.names) + k} of body_names)" for k, o in enumerate(objects))
    layout = {"keys": "meta.json: fps, joint_names, body_names (objects last); motion.npz: joint_pos, joint_vel "
              "[T, 29]; body_pos_w, body_quat_w (wxyz), body_lin_vel_w, body_ang_vel_w [T, B, .] (world)"}  # fmt: skip
    return Written((out / "motion.npz", out / "meta.json"), ep.fps, ep.frames, where, layout)
