"""GMR motion ``.pkl``: a pickled dict of numpy arrays, as GMR's retargeting scripts save it and
:func:`pipeline.readers.peers.read_gmr_pkl` reads it.

* ``fps`` -- an int when integral (GMR saves its rate as a number);
* ``root_pos`` ``[T, 3]`` (world), ``root_rot`` ``[T, 4]`` scalar-last ``xyzw`` (GMR's order, not MuJoCo's);
* ``dof_pos`` ``[T, 29]`` in the Unitree G1 29-DoF order (= mjlab's entity order; GMR stores no joint names);
* ``local_body_pos`` ``[T, 30, 3]`` -- every entity body's position in the root (pelvis) frame,
  ``R_root^T (p_body - p_root)``, and ``link_body_list`` (their names), the fields TWIST-style loaders read;
* beside them (not GMR's own: GMR has no object), per object ``object_name``, ``object_pos`` ``[T, 3]`` and
  ``object_rot`` ``[T, 4]`` ``xyzw``; a second object ``object_2_name`` etc.

float64 arrays (GMR's), a plain ``pickle`` (protocol 4) that the numpy-only unpickler of the readers accepts.
"""

from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from motion_export.bodies import BodyMotion, body_motion, entity_joints
from motion_export.episodes import ExportEpisode
from motion_export.writer import Written, fps_value
from pipeline.dataset.objects import object_column
from pipeline.robot import JOINTS_QPOS, ROOT_POS, ROOT_QUAT
from pipeline.rotations import rotation_from_wxyz, wxyz_to_xyzw


def local_body_pos(bodies: BodyMotion, root_pos: np.ndarray, root_quat: np.ndarray) -> np.ndarray:
    """``[T, B, 3]`` body positions in the root frame: ``R_root^T (p_body - p_root)`` (``root_quat`` ``wxyz``)."""
    T, B = bodies.pos.shape[:2]
    rel = (bodies.pos - root_pos[:, None]).reshape(T * B, 3)
    inv = rotation_from_wxyz(np.repeat(root_quat, B, axis=0)).inv()
    return inv.apply(rel).reshape(T, B, 3)


def gmr_dict(ep: ExportEpisode, bodies: BodyMotion) -> dict:
    """The pickled dict (module doc)."""
    q = ep.clip.qpos
    d = {
        "fps": fps_value(ep.fps),
        "root_pos": q[:, ROOT_POS].copy(),
        "root_rot": wxyz_to_xyzw(q[:, ROOT_QUAT]),
        "dof_pos": entity_joints(q[:, JOINTS_QPOS]),
        "local_body_pos": local_body_pos(bodies, q[:, ROOT_POS], q[:, ROOT_QUAT]),
        "link_body_list": list(bodies.names),
    }
    for k, o in enumerate(ep.clip.objects):
        col = object_column(k)
        d[f"{col}_name"], d[f"{col}_pos"], d[f"{col}_rot"] = o.name, o.pose[:, :3].copy(), wxyz_to_xyzw(o.pose[:, 3:])
    return d


def write(ep: ExportEpisode, folder: Path, stem: str) -> Written:
    """``<stem>.pkl`` (module doc)."""
    path = folder / f"{stem}.pkl"
    path.write_bytes(pickle.dumps(gmr_dict(ep, body_motion(ep.clip.qpos, ep.qvel)), protocol=4))
    where = tuple(f"{object_column(k)}_pos, {object_column(k)}_rot (xyzw)" for k in range(len(ep.clip.objects)))
    layout = {"keys": "fps; root_pos [T, 3]; root_rot [T, 4] xyzw; dof_pos [T, 29] (Unitree = mjlab order); "
              "local_body_pos [T, 30, 3] (pelvis frame); link_body_list"}  # fmt: skip
    return Written((path,), ep.fps, ep.frames, where, layout)
