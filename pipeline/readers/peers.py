"""Other retargeters' G1 outputs -> :class:`RobotClip`, so our metrics can score them.

BeyondMimic / mjlab motion ``.npz`` (OmniRetarget writes it too)
    ``fps``; ``joint_pos`` ``[T, 36]`` (root xyz, root quaternion ``wxyz``, 29 joints) or
    ``[T, 29]`` (joints only; the root then comes from ``body_pos_w`` / ``body_quat_w`` of the
    ``pelvis`` body, else body 0); ``joint_names`` ``[29]``; optional ``object_pos_w`` ``[T, 3]``
    and ``object_quat_w`` ``[T, 4]``. Joints are reordered by name into
    :data:`~pipeline.robot.G1_JOINT_NAMES` (mjlab's order, which the OmniRetarget file already
    uses). A file without ``joint_names`` (what BeyondMimic's and mjlab's ``csv_to_npz.py``
    write: ``joint_pos [T, 29]`` and 30 bodies) is in Isaac Lab's breadth-first order
    (BeyondMimic) or MuJoCo's depth-first one (mjlab), told apart by the bodies' forward
    kinematics (:mod:`pipeline.readers.npz_order`); neither matching (or both) needs the names, ``joint_names=``
    (``--joint-names``: they name a nameless file's columns; a file naming its own joints otherwise is an
    :class:`InputError`). ``object_quat_w`` is
    ``wxyz``: in ``sub3_largebox_003_mj_w_obj.npz`` it equals the ``largebox_link`` entry of
    ``body_quat_w`` (MuJoCo order, 1e-7) and the human clip's ``xyzw`` object quaternion with its
    scalar moved first.

    The object's geometry is not in the file: pass ``object_geometry=`` (e.g. a
    :class:`~pipeline.geometry.MeshGeometry` of ``largebox.obj``); without it the object is left
    out (with a warning). ``object_scale`` scales that geometry. OmniRetarget scales the
    *trajectory* by the robot/human ratio (object ``xy`` x 0.68, and ``z`` about its resting
    height: the box still rests at the human clip's 0.184 m), not the mesh, so 1.0 is right for
    that file.

HDMI motion folder (``motion.npz`` + ``meta.json``)
    ``meta.json``: ``fps``, ``joint_names`` (possibly fewer than 29: HDMI's 25-joint G1 has no wrist pitch/yaw),
    ``body_names`` (the robot's links, then any object body, e.g. ``largebox``); ``motion.npz``: ``joint_pos``
    ``[T, J]``, ``body_pos_w`` ``[T, B, 3]``, ``body_quat_w`` ``[T, B, 4]`` ``wxyz``. The root is the ``pelvis``
    body. A ``joint_names`` entry named exactly ``root`` (HDMI's LAFAN1 walks: ``joint_pos`` ``[T, 26]``, its first
    column a placeholder for the free joint) is not a joint: it and its ``joint_pos`` column are dropped (the root
    still comes from the pelvis body); any other name that is not a G1 joint is an :class:`InputError`. Joints the
    file lacks that carry no weight (the wrists, :data:`HELD_JOINT_KEYS`) are held at the actuator profile's
    default pose and named in ``provenance["held_joints"]``; a file without a leg, waist or arm joint is an
    :class:`InputError`. A body that is not a G1 link is the object: its geometry is
    ``object_geometry=``, else ``<name>.obj`` in the folder or its parent; none is an :class:`InputError`.
    ``object_contact`` ``[T, 1]`` (HDMI's tracked object in contact; bool, or 0/1 floats in some of its samples)
    becomes the first object's contact flags.

GMR ``.pkl`` (a pickle of numpy arrays)
    ``fps``, ``root_pos`` ``[T, 3]``, ``root_rot`` ``[T, 4]`` scalar-last ``xyzw``, ``dof_pos``
    ``[T, 29]`` in the Unitree G1 29-DoF order (= mjlab's; GMR stores no names), optional
    ``local_body_pos`` and ``link_body_list`` (kept in ``provenance``). Loaded with a
    numpy-only unpickler. GMR has no object; the toolkit's exporter (:mod:`motion_export.gmr`) adds one as
    ``object_name``, ``object_pos`` ``[T, 3]`` and ``object_rot`` ``[T, 4]`` ``xyzw`` (GMR's quaternion order),
    read like the ``.npz``'s object (its geometry from ``object_geometry=``, else left out with a warning).

Unitree G1 retargeting ``.csv`` (Unitree's public LAFAN1 retargeting; what mjlab's ``csv_to_npz.py`` reads)
    one row per frame, comma-separated, no header: root position (3), root quaternion ``xyzw`` (4), the 29 joint
    angles in the Unitree G1 order (= mjlab's); 36 numbers. The file carries no frame rate: ``fps`` (default
    :data:`UNITREE_CSV_FPS`, the rate of Unitree's files and ``csv_to_npz.py``'s ``input_fps`` default). A first
    row of 36 names is a header and skipped.
"""

from __future__ import annotations

import csv
import json
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.clip import ObjectTrack, RobotClip, check_array
from pipeline.errors import InputError
from pipeline.geometry import MeshGeometry, ObjectGeometry
from pipeline.readers.keypoints import load_npz, load_numpy_pickle
from pipeline.readers.npz_order import nameless_order
from pipeline.robot import G1_JOINT_NAMES, G1_LINK_NAMES, actuator_profile, g1_model
from pipeline.rotations import xyzw_to_wxyz

UNITREE_CSV_FPS = 30.0  # Unitree's G1 retargeting CSVs are sampled at 30 Hz (mjlab csv_to_npz.py's input_fps)
UNITREE_CSV_COLUMNS = 36  # root xyz, root quaternion xyzw, 29 joints
HELD_JOINT_KEYS = ("wrist",)  # joints a motion file may lack: they carry no weight, held at the default pose
HDMI_ROOT_PLACEHOLDER = "root"  # HDMI's joint_names entry (and joint_pos column) for the free joint: dropped


def _array(d, key: str, width: int | None, src: str, frames: int | None = None) -> np.ndarray:
    """``d[key]`` as float64 ``[T, width]``, finite, with ``frames`` rows when given."""
    if key not in d:
        raise InputError(src, key, f"missing (keys are {', '.join(sorted(d))})")
    return check_array(d[key], (None, width), key, src, frames=frames)


def _fps(d, src: str) -> float:
    if "fps" not in d:
        raise InputError(src, "fps", "missing")
    fps = float(np.asarray(d["fps"]).reshape(-1)[0])
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(src, "fps", f"must be positive, got {fps}")
    return fps


def reorder_joints(names, src: str) -> np.ndarray:
    """Column index of each :data:`G1_JOINT_NAMES` joint in a file whose joints are ``names``."""
    names = [str(n) for n in names]
    missing = [n for n in G1_JOINT_NAMES if n not in names]
    if missing:
        raise InputError(src, "joint_names", f"missing G1 joints: {', '.join(missing)}")
    if len(names) != len(G1_JOINT_NAMES):
        extra = [n for n in names if n not in G1_JOINT_NAMES]
        raise InputError(
            src, "joint_names", f"{len(names)} names for 29 G1 joints (unknown: {', '.join(extra) or 'duplicates'})"
        )
    return np.array([names.index(n) for n in G1_JOINT_NAMES])


def _root_from_bodies(d, src: str, frames: int) -> np.ndarray:
    """Root pose ``[T, 7]`` from ``body_pos_w``/``body_quat_w`` (the ``pelvis`` body, else body 0)."""
    for key in ("body_pos_w", "body_quat_w"):
        if key not in d:
            raise InputError(src, key, "missing: joint_pos has no root columns, so the root must come from the bodies")
    names = [str(n) for n in d["body_names"]] if "body_names" in d else []
    b = names.index("pelvis") if "pelvis" in names else 0
    pos, quat = np.asarray(d["body_pos_w"], np.float64), np.asarray(d["body_quat_w"], np.float64)
    if pos.ndim != 3 or quat.ndim != 3 or pos.shape[0] != frames or quat.shape[0] != frames:
        raise InputError(src, "body_pos_w", f"shapes {pos.shape}, {quat.shape} do not match {frames} frames")
    return np.concatenate([pos[:, b], quat[:, b]], axis=1)


def _object_name(d, given: str | None) -> str:
    if given:
        return given
    for key in ("object_names", "object_name"):  # written by the toolkit's exporter (motion_export)
        if key in d and np.asarray(d[key]).size:
            return str(np.asarray(d[key]).reshape(-1)[0])
    for n in (str(x) for x in d.get("body_names", [])):
        if n.endswith("_link") and not any(n.startswith(p) for p in ("left_", "right_", "waist_", "torso", "pelvis")):
            return n[: -len("_link")]
    return "object"


def read_beyondmimic_npz(
    path: str | Path,
    *,
    object_geometry: ObjectGeometry | None = None,
    object_scale: float = 1.0,
    object_name: str | None = None,
    joint_names: Sequence[str] | None = None,
) -> RobotClip:
    """A BeyondMimic / mjlab motion ``.npz`` as a :class:`RobotClip` (see the module doc)."""
    src = str(path)
    d, _ = load_npz(path)
    fps = _fps(d, src)
    jp = _array(d, "joint_pos", None, src)
    T = jp.shape[0]
    if jp.shape[1] not in (29, 36):
        raise InputError(src, "joint_pos", f"shape {jp.shape} is not (T, 36) or (T, 29)")
    names = d.get("joint_names")
    order = "reordered by name to mjlab G1 order"
    if joint_names is not None and names is not None and [str(n) for n in names] != [str(n) for n in joint_names]:
        why = "the file names its joints, in another order than the names given (--joint-names): leave them out"
        raise InputError(src, "joint_names", why)
    if joint_names is not None and names is None:
        names, order = joint_names, "no joint names: the names given (--joint-names); reordered to mjlab's"
    if names is None:
        found, names = nameless_order(d, src)
        order = f"no joint names: {found} order, told by the bodies' forward kinematics; reordered to mjlab's"
    joints = jp[:, -29:][:, reorder_joints(names, src)]
    root = jp[:, :7] if jp.shape[1] == 36 else _root_from_bodies(d, src, T)
    objects, provenance = (), {"format": "beyondmimic_npz", "file": src, "joint_order": order}
    if "object_pos_w" in d:
        pose = np.concatenate([_array(d, "object_pos_w", 3, src, T), _array(d, "object_quat_w", 4, src, T)], axis=1)
        objects = _object_track(pose, _object_name(d, object_name), object_geometry, object_scale, src, provenance)
    return RobotClip(
        np.concatenate([root, joints], axis=1),
        fps,
        src,
        objects=objects,
        method="peer:beyondmimic_npz",
        provenance=provenance,
    )


def _object_track(
    pose: np.ndarray, name: str, geometry: ObjectGeometry | None, scale: float, src: str, provenance: dict
) -> tuple[ObjectTrack, ...]:
    """The file's object track with ``geometry`` (scaled by ``scale``); without a geometry none, with a warning and
    ``provenance["object_left_out"]`` naming it (a folder reader then looks for ``<name>.obj`` beside the file)."""
    if geometry is None:
        warnings.warn(
            f"{src}: object {name!r} left out: pass object_geometry= to include it", UserWarning, stacklevel=3
        )
        provenance["object_left_out"] = name
        return ()
    geometry = geometry if scale == 1.0 else geometry.scaled(scale)
    return (ObjectTrack(name, geometry, pose, source=src),)


def read_gmr_pkl(
    path: str | Path,
    *,
    object_geometry: ObjectGeometry | None = None,
    object_scale: float = 1.0,
    object_name: str | None = None,
) -> RobotClip:
    """A GMR ``.pkl`` motion as a :class:`RobotClip` (see the module doc)."""
    src = str(path)
    d = load_numpy_pickle(path, "file")
    if not isinstance(d, dict):
        raise InputError(src, "file", f"holds a {type(d).__name__}, expected a GMR dict")
    fps = _fps(d, src)
    dof = _array(d, "dof_pos", 29, src)
    T = dof.shape[0]
    root_pos, root_rot = _array(d, "root_pos", 3, src, T), _array(d, "root_rot", 4, src, T)
    provenance = {"format": "gmr_pkl", "file": src, "joint_order": "GMR G1 29-DoF order (= mjlab)"}
    if d.get("link_body_list") is not None:
        provenance["link_body_list"] = [str(n) for n in d["link_body_list"]]
    objects = ()
    if d.get("object_pos") is not None:
        rot = xyzw_to_wxyz(_array(d, "object_rot", 4, src, T))
        pose = np.concatenate([_array(d, "object_pos", 3, src, T), rot], axis=1)
        name = object_name or str(d.get("object_name") or "object")
        objects = _object_track(pose, name, object_geometry, object_scale, src, provenance)
    qpos = np.concatenate([root_pos, xyzw_to_wxyz(root_rot), dof], axis=1)
    return RobotClip(qpos, fps, src, objects=objects, method="peer:gmr_pkl", provenance=provenance)


def csv_numbers(row: list[str]) -> list[float] | None:
    """The row's fields as numbers, or None when one is not a number."""
    try:
        return [float(c) for c in row]
    except ValueError:
        return None


def read_unitree_csv(path: str | Path, *, fps: float = UNITREE_CSV_FPS) -> RobotClip:
    """A Unitree G1 retargeting ``.csv`` (36 numbers a row: root xyz, root quaternion ``xyzw``, 29 joints; see the
    module doc) as a :class:`RobotClip` at ``fps``; a row of another width or a field that is not a number is a
    one-line :class:`InputError` naming its row."""
    src = str(path)
    try:
        with open(path, newline="") as f:
            rows = [(k, r) for k, r in enumerate(csv.reader(f)) if any(c.strip() for c in r)]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(src, "file", f"not a readable CSV file ({exc})") from None
    if rows and len(rows[0][1]) == UNITREE_CSV_COLUMNS and csv_numbers(rows[0][1]) is None:
        rows = rows[1:]  # a header of 36 names
    if not rows:
        raise InputError(src, "rows", "has zero frames")
    values = np.empty((len(rows), UNITREE_CSV_COLUMNS))
    for t, (k, row) in enumerate(rows):
        if len(row) != UNITREE_CSV_COLUMNS:
            raise InputError(src, f"row {k + 1}", f"has {len(row)} columns, expected {UNITREE_CSV_COLUMNS}", frame=t)
        numbers = csv_numbers(row)
        if numbers is None:
            raise InputError(src, f"row {k + 1}", "has a field that is not a number", frame=t)
        values[t] = numbers
    qpos = np.concatenate([values[:, :3], xyzw_to_wxyz(values[:, 3:7]), values[:, 7:]], axis=1)
    provenance = {
        "format": "unitree_csv",
        "file": src,
        "joint_order": "Unitree G1 29-DoF order (= mjlab)",
        "fps": f"{fps:g} Hz given (the file carries no rate)",
    }
    return RobotClip(qpos, fps, src, method="peer:unitree_csv", provenance=provenance)


def _joints_with_held(names: list[str], jp: np.ndarray, src: str) -> tuple[np.ndarray, list[str]]:
    """(T, 29) joints in mjlab order from a file whose ``J`` columns are ``names``; missing wrist joints held at
    the mjlab profile's default (their names returned), any other missing joint an :class:`InputError`."""
    missing = [n for n in G1_JOINT_NAMES if n not in names]
    bad = [n for n in missing if not any(k in n for k in HELD_JOINT_KEYS)]
    if bad:
        raise InputError(src, "joint_names", f"missing G1 joints that carry weight: {', '.join(bad)}")
    unknown = [n for n in names if n not in G1_JOINT_NAMES]
    if unknown:
        raise InputError(src, "joint_names", f"not G1 joints: {', '.join(unknown)}")
    default = actuator_profile("mjlab").default_joint_pos
    out = np.repeat(default[None], jp.shape[0], 0)
    for j, n in enumerate(G1_JOINT_NAMES):
        if n in names:
            out[:, j] = jp[:, names.index(n)]
    return out, missing


def object_mesh_beside(path: Path, name: str) -> MeshGeometry | None:
    """``<name>.obj`` in ``path``'s folder or the one above it, as a mesh geometry (None: none there)."""
    for folder in (path.parent, path.parent.parent):
        candidate = folder / f"{name}.obj"
        if candidate.is_file():
            return MeshGeometry(str(candidate))
    return None


def read_hdmi_motion(folder: str | Path, *, object_geometry: ObjectGeometry | None = None) -> RobotClip:
    """An HDMI motion folder (``motion.npz`` + ``meta.json``) as a :class:`RobotClip` (see the module doc)."""
    folder = Path(folder)
    src = str(folder)
    try:
        meta = json.loads((folder / "meta.json").read_text())
    except (OSError, ValueError) as exc:
        raise InputError(folder / "meta.json", "file", f"not a readable JSON file ({exc})") from None
    for key in ("fps", "joint_names", "body_names"):
        if key not in meta:
            raise InputError(folder / "meta.json", key, "missing")
    d, _ = load_npz(folder / "motion.npz")
    names = [str(n) for n in meta["joint_names"]]
    jp = _array(d, "joint_pos", len(names), src)
    T = jp.shape[0]
    keep = [k for k, n in enumerate(names) if n != HDMI_ROOT_PLACEHOLDER]  # the free joint's column: not a joint
    joints, held = _joints_with_held([names[k] for k in keep], jp[:, keep], src)
    bodies = [str(n) for n in meta["body_names"]]
    if "pelvis" not in bodies:
        raise InputError(folder / "meta.json", "body_names", "no pelvis body: the root is unknown")
    for key in ("body_pos_w", "body_quat_w"):
        if key not in d:
            raise InputError(src, key, f"missing from motion.npz (keys are {', '.join(sorted(d))})")
    pos, quat = np.asarray(d["body_pos_w"], np.float64), np.asarray(d["body_quat_w"], np.float64)
    if pos.shape[:2] != (T, len(bodies)) or quat.shape[:2] != (T, len(bodies)):
        raise InputError(src, "body_pos_w", f"shapes {pos.shape}, {quat.shape} do not match ({T}, {len(bodies)}, .)")
    b = bodies.index("pelvis")
    root = np.concatenate([pos[:, b], quat[:, b]], axis=1)
    links = {g1_model().body(i).name for i in range(1, g1_model().nbody)} | set(G1_LINK_NAMES)
    objects = []
    contact = np.asarray(d["object_contact"]).reshape(T, -1).any(axis=1) if "object_contact" in d else None
    for k in (k for k, n in enumerate(bodies) if n not in links):
        name = bodies[k]
        geometry = object_geometry or object_mesh_beside(folder / "motion.npz", name)
        if geometry is None:
            raise InputError(src, f"object {name}", "has no geometry: pass --object-mesh or put <name>.obj beside it")
        pose = np.concatenate([pos[:, k], quat[:, k]], axis=1)
        objects.append(ObjectTrack(name, geometry, pose, contact=None if objects else contact, source=src))
    provenance = {"format": "hdmi_motion", "file": src, "joint_order": "reordered by name to mjlab G1 order"}
    if held:
        provenance["held_joints"] = held
    return RobotClip(
        np.concatenate([root, joints], axis=1),
        float(meta["fps"]),
        src,
        objects=tuple(objects),
        method="peer:hdmi_motion",
        provenance=provenance,
    )
