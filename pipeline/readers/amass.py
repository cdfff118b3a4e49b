"""AMASS (SMPL+H / SMPL-X parameters in ``.npz``) -> :class:`HumanClip`, and the SMPL-H skeleton.

An AMASS file stores body-model *parameters* (``poses``, ``trans``, ``betas``, ``gender``,
``mocap_framerate`` or ``mocap_frame_rate``), not joint positions. Positions need the user's
licensed body model (SMPL+H or SMPL-X from MPI), run through the ``smplx`` package offline.
Without one the reader stops with a one-line error telling the user to pass
``--body-model PATH``; the file itself is validated first, so a bad file says so either way.

``poses`` layouts: 156 = SMPL+H (root 3, body 63, left hand 45, right hand 45); 165 = SMPL-X
(root, body, jaw 3, eyes 6, hands 90). Hand poses are full axis-angle (no PCA) relative to a
flat hand, as AMASS writes them. AMASS worlds are z-up metres already.

Output: the 52 SMPL-H joints in :data:`SMPLH_JOINT_NAMES` order; global orientations are
``R_g[j] = R_g[parent] R_local[j]`` from the axis-angle pose (the frames are SMPL's canonical
joint frames mapped to the world by the root orientation); subject height is the vertical
extent of the shaped model's vertices in its canonical zero pose (SMPL's canonical frame is
y-up).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from pipeline.body_height import plausible_height
from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError, first_bad_frame
from pipeline.readers.keypoints import load_npz
from pipeline.rotations import wxyz_from_rotation

SMPLH_FINGERS = tuple(f"{f}{k}" for f in ("index", "middle", "pinky", "ring", "thumb") for k in (1, 2, 3))
#: The 22 joints of the SMPL body (SMPL-H and SMPL-X share them, in this order, before the hands) and their parents.
SMPL_BODY_JOINT_NAMES: tuple[str, ...] = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
)  # fmt: skip
SMPL_BODY_PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)
SMPLH_JOINT_NAMES: tuple[str, ...] = (
    SMPL_BODY_JOINT_NAMES + tuple(f"left_{f}" for f in SMPLH_FINGERS) + tuple(f"right_{f}" for f in SMPLH_FINGERS)
)
_FINGER_PARENTS = tuple(p for _ in range(5) for p in (-1, 0, 1))  # wrist, then within a finger
SMPLH_PARENTS: tuple[int, ...] = (
    SMPL_BODY_PARENTS
    + tuple(20 if p < 0 else 22 + 3 * (k // 3) + p for k, p in enumerate(_FINGER_PARENTS))
    + tuple(21 if p < 0 else 37 + 3 * (k // 3) + p for k, p in enumerate(_FINGER_PARENTS))
)
SMPLH_SKELETON = Skeleton(SMPLH_JOINT_NAMES, SMPLH_PARENTS)

_POSE_DIMS = {156: "smplh", 165: "smplx"}
_DISPLAY = {"smplh": "SMPL+H", "smplx": "SMPL-X"}
_CHUNK = 512


def _load(path: str | Path) -> dict[str, np.ndarray]:
    src = str(path)
    data, skipped = load_npz(path)
    for key in ("poses", "trans"):
        if key not in data:
            raise InputError(src, key, f"missing (keys are {', '.join(sorted(data) + skipped)})")
    if "gender" in skipped:
        raise InputError(src, "gender", "stored as a pickled object, which is never loaded; re-save it as a string")
    rate = data.get("mocap_framerate", data.get("mocap_frame_rate"))
    if rate is None:
        raise InputError(src, "mocap_framerate", "missing (neither mocap_framerate nor mocap_frame_rate)")
    data["fps"] = np.asarray(rate, dtype=np.float64).reshape(-1)[:1]
    return data


def _validate(data: dict[str, np.ndarray], src: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """``poses [T, 156|165]``, ``trans [T, 3]``, ``betas``, gender, all finite."""
    poses, trans = np.asarray(data["poses"], np.float64), np.asarray(data["trans"], np.float64)
    if poses.ndim != 2 or poses.shape[1] not in _POSE_DIMS:
        raise InputError(src, "poses", f"shape {poses.shape} is not (T, 156) SMPL+H or (T, 165) SMPL-X")
    if poses.shape[0] == 0:
        raise InputError(src, "poses", "has zero frames")
    if trans.shape != (poses.shape[0], 3):
        raise InputError(src, "trans", f"shape {trans.shape} does not match ({poses.shape[0]}, 3)")
    for name, a in (("poses", poses), ("trans", trans)):
        bad = ~np.isfinite(a)
        if bad.any():
            raise InputError(src, name, "is NaN or infinite", frame=first_bad_frame(bad))
    betas = np.asarray(data.get("betas", np.zeros(10)), np.float64).reshape(-1)
    if not np.all(np.isfinite(betas)):
        raise InputError(src, "betas", "is NaN or infinite")
    gender = data.get("gender", np.array("neutral"))
    gender = gender.item() if isinstance(gender, np.ndarray) else gender
    gender = (gender.decode() if isinstance(gender, bytes) else str(gender)).strip().lower()
    if gender not in ("male", "female", "neutral"):
        raise InputError(src, "gender", f"{gender!r} is not male, female or neutral")
    fps = float(data["fps"][0]) if data["fps"].size else float("nan")
    if not np.isfinite(fps) or fps <= 0:
        raise InputError(src, "mocap_framerate", f"must be positive, got {fps}")
    return poses, trans, betas, gender


def _model_file(body_model: str | Path, kind: str, gender: str, src: str) -> Path:
    """The model file: ``body_model`` itself, or inside it ``SMPLH_MALE.pkl``, ``smplh/SMPLH_MALE.npz``,
    ``male/model.npz`` (AMASS's layout), ``smplh/male/model.npz``."""
    p = Path(body_model)
    if p.is_file():
        return p
    if not p.is_dir():
        raise InputError(
            src, "body_model", f"{p} does not exist; pass --body-model PATH to the SMPL+H/SMPL-X model file or folder"
        )
    stem = f"{kind.upper()}_{gender.upper()}"
    for cand in (
        p / f"{stem}.pkl",
        p / f"{stem}.npz",
        p / kind / f"{stem}.pkl",
        p / kind / f"{stem}.npz",
        p / gender / "model.npz",
        p / kind / gender / "model.npz",
    ):
        if cand.is_file():
            return cand
    raise InputError(
        src, "body_model", f"no {_DISPLAY[kind]} {gender} model in {p} (looked for {stem}.pkl/.npz, {gender}/model.npz)"
    )


def global_orientations(poses: np.ndarray) -> np.ndarray:
    """``[T, 52, 4]`` wxyz world orientations of the SMPL-H joints from axis-angle ``poses``."""
    T = poses.shape[0]
    aa = poses[:, :156] if poses.shape[1] == 156 else np.concatenate([poses[:, :66], poses[:, 75:165]], axis=1)
    local = Rotation.from_rotvec(aa.reshape(-1, 3)).as_matrix().reshape(T, 52, 3, 3)
    glob = np.empty_like(local)
    for j, p in enumerate(SMPLH_PARENTS):
        glob[:, j] = local[:, j] if p < 0 else glob[:, p] @ local[:, j]
    return wxyz_from_rotation(Rotation.from_matrix(glob.reshape(-1, 3, 3))).reshape(T, 52, 4)


def _run_model(model_path: Path, kind: str, gender: str, poses, trans, betas, src: str) -> tuple[np.ndarray, float]:
    """Joint positions ``[T, 52, 3]`` and the canonical-pose height, via ``smplx``."""
    import smplx
    import torch
    from smplx.joint_names import JOINT_NAMES

    cls = smplx.SMPLH if kind == "smplh" else smplx.SMPLX
    try:
        model = cls(
            model_path=str(model_path),
            ext=model_path.suffix.lstrip("."),
            gender=gender,
            use_pca=False,
            flat_hand_mean=True,
            num_betas=len(betas),
            batch_size=1,
        )
    except Exception as e:  # smplx raises AssertionError / KeyError / pickle errors on a wrong file
        raise InputError(
            src, "body_model", f"{model_path} is not a usable {_DISPLAY[kind]} model ({type(e).__name__}: {e})"
        ) from None
    idx = [JOINT_NAMES.index(n) for n in SMPLH_JOINT_NAMES]
    hands = (66, 111, 156) if kind == "smplh" else (75, 120, 165)
    f32 = lambda a: torch.as_tensor(np.ascontiguousarray(a), dtype=torch.float32)  # noqa: E731
    out = []
    with torch.no_grad():
        for s in range(0, poses.shape[0], _CHUNK):
            p, n = poses[s : s + _CHUNK], len(poses[s : s + _CHUNK])
            kw = dict(
                betas=f32(np.repeat(betas[None], n, 0)),
                global_orient=f32(p[:, :3]),
                body_pose=f32(p[:, 3:66]),
                left_hand_pose=f32(p[:, hands[0] : hands[1]]),
                right_hand_pose=f32(p[:, hands[1] : hands[2]]),
                transl=f32(trans[s : s + _CHUNK]),
            )
            if kind == "smplx":
                kw.update(
                    jaw_pose=f32(p[:, 66:69]),
                    leye_pose=f32(p[:, 69:72]),
                    reye_pose=f32(p[:, 72:75]),
                    expression=torch.zeros(n, model.num_expression_coeffs),
                )
            out.append(model(**kw).joints[:, idx].numpy().astype(np.float64))
        rest = model(betas=f32(betas[None])).vertices[0].numpy()
    return np.concatenate(out), float(rest[:, 1].max() - rest[:, 1].min())


def read_amass(path: str | Path, body_model: str | Path | None = None) -> HumanClip:
    """An AMASS ``.npz`` as a z-up metre :class:`HumanClip` of the 52 SMPL-H joints.

    ``body_model``: the licensed SMPL+H / SMPL-X model file, or a folder holding it
    (``SMPLH_FEMALE.pkl``, ``smplh/SMPLH_FEMALE.npz``, ``female/model.npz``, ...).
    """
    src = str(path)
    data = _load(path)
    poses, trans, betas, gender = _validate(data, src)
    kind = _POSE_DIMS[poses.shape[1]]
    if body_model is None:
        raise InputError(
            src,
            "body_model",
            f"AMASS stores {_DISPLAY[kind]} parameters, not joint positions: pass --body-model PATH "
            "(your licensed SMPL+H or SMPL-X model file or folder)",
        )
    model_file = _model_file(body_model, kind, gender, src)
    joints, height = _run_model(model_file, kind, gender, poses, trans, betas, src)
    height = plausible_height(height)
    return HumanClip(
        SMPLH_SKELETON, joints, float(data["fps"][0]), src, subject_height=height, joint_quat=global_orientations(poses)
    )
