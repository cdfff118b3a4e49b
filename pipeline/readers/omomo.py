"""OMOMO / InterMimic human-object clips (``.pt``, a ``[T, 591]`` float tensor at 30 fps).

Column layout (InterMimic's ``_load_motion``; z-up metres; quaternions scalar-last ``xyzw``):

======== ==========================================================================
0:3      root position (= the pelvis position)
3:7      root quaternion (= the pelvis body quaternion)
9:162    51 x 3 joint angles of InterMimic's humanoid (not used here)
162:318  52 body positions
318:321  object position;  321:325 object quaternion
330      object contact flag (0/1)
331:383  52 per-body contact labels: 1 touching the object, -1 must not touch, 0 unlabelled
383:591  52 body quaternions
======== ==========================================================================

What the data shows (checked on ``sub3_largebox_003`` and ``sub2_largetable_000``):

* The 52 bodies are in the MuJoCo body order of InterMimic's SMPL-X humanoid (Pelvis,
  L_Hip, L_Knee, L_Ankle, L_Toe, R_Hip, ..., Torso, Spine, Chest, Neck, Head, L_Thorax,
  L_Shoulder, L_Elbow, L_Wrist, 15 left finger joints, the right arm likewise), NOT the
  SMPL-H order: body 10 is a spine joint 1.26 m above the floor, not a foot. This reader
  permutes them into :data:`~pipeline.readers.amass.SMPLH_JOINT_NAMES` order.
* Body quaternions are GLOBAL: for every bone, ``R_parent^-1 (p_child - p_parent)`` is
  constant over all frames to 1e-7 m (local quaternions would not give that). Every body
  frame is the world frame in the humanoid's T-pose (x forward, y left, z up), so
  ``joint_quat`` is directly each body's world orientation (converted to ``wxyz``).
* The object pose maps mesh-local points to the world as ``R(q) v + p``.

Contacts: ``HumanClip.contacts`` is ``label > 0.5`` per body; the object track's contact
is column 330.

Object physics: mass, hand-object and object-floor friction of the object's kind (by the name, e.g.
``largebox``) from :data:`pipeline.materials.OBJECT_KINDS` (the files carry none).

Object mesh: ``mesh=`` or, beside the clip, the object named in the file name
(``sub3_largebox_003.pt`` -> ``largebox``) as ``largebox.obj``, ``largebox_largebox.obj``
(InterMimic), ``largebox/largebox.obj`` or ``largebox_cleaned_simplified.obj`` (OMOMO).
Its collision model (see :func:`collision_kind`): boxes and suitcases ``"hull"``; tables,
chairs, lamps, stands, tripods, mops, vacuums ``"decomposition"``; any other name is decided
by how far the mesh's convex hull stands off its surface (:func:`hull_gap_ratio`). Comparing
hull volume with the bounding box does not work: a table's hull nearly fills its box.

Subject height: ``height_dict.pkl`` beside the clip (``{"sub3": 1.941, ...}``, metres, 17
OMOMO subjects), else the skeleton estimate of :func:`~pipeline.body_height.estimate_height`.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from pipeline.body_height import estimate_height, plausible_height
from pipeline.clip import HumanClip, ObjectTrack
from pipeline.errors import SUBJECT_HEIGHT_M, InputError, first_bad_frame
from pipeline.geometry import MeshGeometry
from pipeline.materials import object_physics_for
from pipeline.readers.amass import SMPLH_FINGERS, SMPLH_JOINT_NAMES, SMPLH_SKELETON
from pipeline.readers.keypoints import load_numpy_pickle
from pipeline.rotations import xyzw_to_wxyz

FPS = 30.0
COLUMNS = 591
#: The file's body order, written with SMPL-H names.
FILE_BODY_ORDER: tuple[str, ...] = (
    (
        "pelvis",
        "left_hip",
        "left_knee",
        "left_ankle",
        "left_foot",
        "right_hip",
        "right_knee",
        "right_ankle",
        "right_foot",
        "spine1",
        "spine2",
        "spine3",
        "neck",
        "head",
        "left_collar",
        "left_shoulder",
        "left_elbow",
        "left_wrist",
    )
    + tuple(f"left_{f}" for f in SMPLH_FINGERS)
    + (
        "right_collar",
        "right_shoulder",
        "right_elbow",
        "right_wrist",
    )
    + tuple(f"right_{f}" for f in SMPLH_FINGERS)
)
TO_SMPLH = np.array([FILE_BODY_ORDER.index(n) for n in SMPLH_JOINT_NAMES])

_HULL_NAMES = ("box", "suitcase")
_DECOMP_NAMES = ("table", "chair", "lamp", "stand", "tripod", "mop", "vacuum", "desk", "shelf")
#: :func:`hull_gap_ratio` above which a mesh counts as concave. Measured: cube, cylinder 0.005;
#: largebox.obj 0.030; largetable_largetable.obj 0.24; a U-shaped trough 0.22.
CONCAVITY_GAP = 0.1


def _load_tensor(path: str | Path) -> np.ndarray:
    import torch

    src = str(path)
    try:
        t = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:  # torch raises many types for a non-tensor / corrupt file
        raise InputError(src, "file", f"not a torch tensor file ({type(e).__name__}: {str(e)[:120]})") from None
    if not isinstance(t, torch.Tensor):
        raise InputError(src, "file", f"holds a {type(t).__name__}, expected a [T, {COLUMNS}] tensor")
    a = t.detach().cpu().numpy().astype(np.float64)
    if a.ndim != 2 or a.shape[1] != COLUMNS:
        raise InputError(src, "tensor", f"shape {tuple(a.shape)} is not (T, {COLUMNS}) (OMOMO/InterMimic layout)")
    if a.shape[0] == 0:
        raise InputError(src, "tensor", "has zero frames")
    return a


def _check_finite(a: np.ndarray, src: str) -> None:
    for name, cols in (
        ("body positions", slice(162, 318)),
        ("object pose", slice(318, 325)),
        ("contacts", slice(330, 383)),
        ("body quaternions", slice(383, 591)),
    ):
        bad = ~np.isfinite(a[:, cols])
        if bad.any():
            raise InputError(
                src, f"{name} (columns {cols.start}:{cols.stop})", "is NaN or infinite", frame=first_bad_frame(bad)
            )


def parse_name(path: str | Path) -> tuple[str | None, str | None]:
    """``(subject, object)`` from ``sub3_largebox_003[_...].pt``; ``(None, None)`` for other names."""
    parts = Path(path).stem.split("_")
    if not re.fullmatch(r"sub\d+", parts[0]):
        return None, None
    words = []
    for p in parts[1:]:
        if p.isdigit():
            break
        words.append(p)
    return parts[0], "_".join(words) or None


def find_mesh(path: str | Path, obj: str | None) -> Path:
    src = str(path)
    if obj is None:
        why = "the file name names no object (expected subN_<object>_NNN.pt); pass --object-mesh PATH"
        raise InputError(src, "mesh", why)
    folder = Path(path).parent
    names = [f"{obj}.obj", f"{obj}_{obj}.obj", f"{obj}/{obj}.obj", f"{obj}_cleaned_simplified.obj"]
    for n in names:
        if (folder / n).is_file():
            return folder / n
    raise InputError(
        src, "mesh", f"no mesh for object {obj!r} in {folder} (looked for {', '.join(names)}); pass --object-mesh PATH"
    )


def _load_mesh(mesh: Path, src: str):
    import trimesh

    if not mesh.is_file():
        raise InputError(src, "mesh", f"{mesh} does not exist")
    try:
        m = trimesh.load(mesh, force="mesh", process=False)
    except Exception as e:  # trimesh raises assorted errors on empty or malformed files
        raise InputError(src, "mesh", f"{mesh} is not a readable mesh ({type(e).__name__}: {str(e)[:100]})") from None
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise InputError(src, "mesh", f"{mesh} has no triangles")
    return m


def hull_gap_ratio(mesh, samples: int = 10_000) -> float:
    """How far the convex hull stands off the object: the 95th percentile, over points sampled
    on the hull's surface, of the distance to the nearest point of the mesh's surface, over the
    bounding-box diagonal. About 0 for convex shapes, large where the hull bridges air."""
    import trimesh
    from scipy.spatial import cKDTree

    on_hull, _ = trimesh.sample.sample_surface(mesh.convex_hull, samples, seed=0)
    on_mesh, _ = trimesh.sample.sample_surface(mesh, 4 * samples, seed=1)
    gap = cKDTree(np.vstack([on_mesh, mesh.vertices])).query(on_hull)[0]
    return float(np.percentile(gap, 95)) / float(np.linalg.norm(mesh.bounds[1] - mesh.bounds[0]))


def collision_kind(name: str, mesh) -> str:
    """``"hull"`` or ``"decomposition"``: by object name, else by :func:`hull_gap_ratio`."""
    low = name.lower()
    if any(k in low for k in _HULL_NAMES):
        return "hull"
    if any(k in low for k in _DECOMP_NAMES):
        return "decomposition"
    return "decomposition" if hull_gap_ratio(mesh) > CONCAVITY_GAP else "hull"


def height_from_dict(path: str | Path, subject: str | None) -> float | None:
    """The subject's height from ``height_dict.pkl`` beside the clip, if both exist."""
    pkl = Path(path).parent / "height_dict.pkl"
    if subject is None or not pkl.is_file():
        return None
    d = load_numpy_pickle(pkl, "height_dict")
    if not isinstance(d, dict):
        raise InputError(pkl, "height_dict", f"is a {type(d).__name__}, expected a dict subject -> metres")
    if subject not in d:
        return None
    height = float(d[subject])
    if not (np.isfinite(height) and SUBJECT_HEIGHT_M[0] <= height <= SUBJECT_HEIGHT_M[1]):
        lo, hi = SUBJECT_HEIGHT_M
        raise InputError(pkl, f"height_dict[{subject!r}]", f"{height:g} m is not a subject height ({lo}-{hi} m)")
    return plausible_height(height)


def read_omomo(path: str | Path, *, mesh: str | Path | None = None, subject_height: float | None = None) -> HumanClip:
    """An OMOMO / InterMimic ``.pt`` clip with its object, as a :class:`HumanClip` (SMPL-H joints)."""
    src = str(path)
    a = _load_tensor(path)
    _check_finite(a, src)
    subject, obj = parse_name(path)
    mesh_path = Path(mesh) if mesh is not None else find_mesh(path, obj)
    obj_name = obj or mesh_path.stem
    m = _load_mesh(mesh_path, src)
    geometry = MeshGeometry(str(mesh_path), collision=collision_kind(obj_name, m))
    T = a.shape[0]
    pos = a[:, 162:318].reshape(T, 52, 3)[:, TO_SMPLH]
    quat = xyzw_to_wxyz(a[:, 383:591].reshape(T, 52, 4))[:, TO_SMPLH]
    contacts = a[:, 331:383][:, TO_SMPLH] > 0.5
    obj_pose = np.concatenate([a[:, 318:321], xyzw_to_wxyz(a[:, 321:325])], axis=1)
    physics, material = object_physics_for(obj_name)
    track = ObjectTrack(
        obj_name,
        geometry,
        obj_pose,
        contact=a[:, 330] > 0.5,
        source=src,
        mass=physics.mass,
        friction=physics.friction,
        floor_friction=physics.floor_friction,
        material=material,
    )
    if subject_height is None:
        subject_height = height_from_dict(path, subject) or plausible_height(estimate_height(pos, SMPLH_SKELETON))
    return HumanClip(
        SMPLH_SKELETON,
        pos,
        FPS,
        src,
        subject_height=subject_height,
        joint_quat=quat,
        contacts=contacts,
        objects=(track,),
    )
