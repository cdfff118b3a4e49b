"""Retarget quality of a :class:`~pipeline.clip.RobotClip`, measured against OUR collision model.

Every stage (and every peer's output, see :func:`evaluate_file`) is scored by this one module,
so the numbers compare across versions and methods. The collision model is
:func:`pipeline.scene.build_scene` with the clip's objects: the G1 ``*_collision`` geoms
(spheres and capsules), each object's collision geoms (primitives, convex hulls or convex
pieces) placed at its per-frame pose, and the floor plane ``z = 0``. Per frame, MuJoCo's
``mj_kinematics`` places the geoms and ``mj_collision`` lists the penetrating pairs with their
signed distance ``dist < 0`` (exact for these convex shapes); ``mj_geomDistance`` gives
signed distances for pairs that are apart.

Definitions (``T`` frames at ``fps``; every ``*_frac*`` is a count of frames divided by ``T``):

``ground_penetration_frac_1cm`` / ``ground_penetration_max_m``
    ``g(t)`` = height of the lowest point of any robot collision geom (sphere ``z - r``; capsule
    ``z - |a_z| h - r``, ``a`` its unit axis, ``h`` its half-length). Depth ``max(0, -g(t))``;
    frac: frames with depth > 1 cm; max: the largest depth (0 when none).
``object_penetration_frac_1cm`` / ``object_penetration_max_m``
    depth = ``-dist`` of the deepest robot-geom/object-geom contact; frac: frames deeper than
    1 cm; max: the largest depth over the clip (0 when none).
``float_frac_2cm``
    with a human clip: frames where the human has a foot down (:mod:`pipeline.foot_contact`)
    and the lowest point of BOTH robot feet (their collision capsules) is > 2 cm above ``z = 0``.
    Without one: frames where ``g(t) > 2 cm`` and the robot is not supported by an object (no
    pelvis/leg/foot collision geom within 2 cm of an object's collision geom).
``foot_slide_frac_1cm_per_frame`` / ``foot_slide_speed_max_mps``
    robot foot point = the ``left_foot`` / ``right_foot`` sites (sole centre). A foot slides
    at frame ``t >= 1`` when it is in contact at ``t - 1`` and ``t`` and its site moved more
    than 1 cm in ``xy`` between them; frac: frames where some foot slides (per frame, so at the
    clip's own fps). Contact: the human's foot contact at the robot frame's time (nearest
    human frame); without a human, the robot foot's lowest point within 2 cm of the floor
    (height only: a speed test would hide the very slides being measured). Max: the largest
    ``|dxy| fps`` over in-contact frame pairs (0 when none).
``contact_preservation_frac``
    reference contacts: the human's per-joint object-contact flags ``contacts`` for joints in
    ``link_map`` (nearest human frame), else the robot clip's own ``contacts`` over
    ``contact_links``. A frame is preserved when every flagged link is within 2 cm of some
    object: signed distance from the link's collision geoms (for a hand, the hand capsule
    around the palm site; for a link without geoms, those of its nearest descendants, e.g.
    the upper-arm capsule for ``*_shoulder_pitch_link``) to the objects' collision geoms
    <= 2 cm. Each clip is compared with its OWN object track. Frames
    with no flag count as preserved. NaN when nothing can be measured (no reference contacts,
    or flags but no object geometry).
``joint_limit_violation_frac``
    frames where some joint is outside its ``g1.xml`` range by more than 1e-3 rad.
``max_joint_speed_radps``
    ``max |q_j(t+1) - q_j(t)| fps`` over the 29 joints and all frame pairs (0 for one frame).
``self_collision_frac``
    frames where two robot collision geoms that MuJoCo's filter lets collide (different bodies,
    not parent and child, not an ``<exclude>`` pair of ``g1.xml``) penetrate by > 5 mm.
``frames``, ``fps``; ``seconds_wall`` (the producing method's wall time, NaN when unknown);
``frames_per_s`` = ``frames / seconds_wall``.

The pass over the frames is :func:`retarget.collision_sweep.sweep` (its cost is stated there).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.clip import HumanClip, RobotClip
from pipeline.foot_contact import SIDES, detect_foot_contacts
from pipeline.geometry import MeshGeometry
from pipeline.readers import read_clips, read_robot_clip
from pipeline.robot import G1_JOINT_NAMES, JOINTS_QPOS
from retarget.collision_sweep import sweep

METRIC_KEYS: tuple[str, ...] = (
    "ground_penetration_frac_1cm",
    "ground_penetration_max_m",
    "object_penetration_frac_1cm",
    "object_penetration_max_m",
    "float_frac_2cm",
    "foot_slide_frac_1cm_per_frame",
    "foot_slide_speed_max_mps",
    "contact_preservation_frac",
    "joint_limit_violation_frac",
    "max_joint_speed_radps",
    "self_collision_frac",
    "frames",
    "fps",
    "seconds_wall",
    "frames_per_s",
)
PENETRATION_TOL = 0.01
FLOAT_TOL = 0.02
SLIDE_TOL = 0.01
CONTACT_TOL = 0.02
JOINT_LIMIT_TOL = 1e-3
SELF_COLLISION_TOL = 0.005


def _default_link_map() -> dict[str, str]:
    m = {
        "pelvis": "pelvis",
        "spine1": "torso_link",
        "spine2": "torso_link",
        "spine3": "torso_link",
        "neck": "torso_link",
        "head": "torso_link",
    }
    for s in SIDES:
        m |= {
            f"{s}_hip": f"{s}_hip_yaw_link",
            f"{s}_knee": f"{s}_knee_link",
            f"{s}_ankle": f"{s}_ankle_roll_link",
            f"{s}_foot": f"{s}_ankle_roll_link",
            f"{s}_collar": "torso_link",
            f"{s}_shoulder": f"{s}_shoulder_pitch_link",
            f"{s}_elbow": f"{s}_elbow_link",
            f"{s}_wrist": f"{s}_wrist_yaw_link",
        }
        for f in ("index", "middle", "pinky", "ring", "thumb"):
            m |= {f"{s}_{f}{k}": f"{s}_wrist_yaw_link" for k in (1, 2, 3)}
    return m


#: SMPL / SMPL-H joint name -> G1 body whose collision geoms must match that joint's contacts.
#: Hips map to the thigh link (what rests on a seat); fingers to the hand.
DEFAULT_LINK_MAP: dict[str, str] = _default_link_map()


def _nearest_rows(n_target: int, fps_target: float, n_src: int, fps_src: float) -> np.ndarray:
    """Index of the source frame nearest in time to each target frame (clipped to the source)."""
    return np.clip(np.rint(np.arange(n_target) / fps_target * fps_src).astype(int), 0, n_src - 1)


def _reference_contacts(
    robot: RobotClip, human: HumanClip | None, link_map: dict[str, str]
) -> tuple[np.ndarray, list[str]] | None:
    """(T, K) flags over K robot links, from the human (at robot frame times) or the robot's labels."""
    if human is not None:
        names = human.skeleton.joint_names
        cols = [j for j, n in enumerate(names) if n in link_map]
        if human.contacts is None or not cols:
            return np.zeros((robot.frames, 0), bool), []
        rows = _nearest_rows(robot.frames, robot.fps, human.frames, human.fps)
        return human.contacts[np.ix_(rows, cols)], [link_map[names[j]] for j in cols]
    if robot.contacts is None:
        return None
    return robot.contacts, list(robot.contact_links)


def ground_clearance(robot: RobotClip) -> np.ndarray:
    """(T,) height of the robot's lowest collision-geom point above the floor ``z = 0``."""
    return sweep(robot, None, contact_tol=CONTACT_TOL).lowest().min(axis=1)


def _frac(flags: np.ndarray) -> float:
    return float(np.mean(flags)) if flags.size else 0.0


def _max(x: np.ndarray) -> float:
    return float(np.max(x)) if x.size else 0.0


def foot_slide(sites: np.ndarray, contact: np.ndarray, fps: float) -> tuple[float, float]:
    """(frac of frames with a foot moving > 1 cm in xy while in contact at t-1 and t, max speed)."""
    step = np.linalg.norm(np.diff(sites[:, :, :2], axis=0), axis=-1)  # (T-1, 2)
    held = contact[1:] & contact[:-1]
    slides = ((step > SLIDE_TOL) & held).any(axis=1)
    return float(slides.sum()) / len(sites), _max(step[held]) * fps


def joint_metrics(qpos: np.ndarray, fps: float, lower: np.ndarray, upper: np.ndarray) -> tuple[float, float]:
    """(frac of frames with a joint beyond its range by > 1e-3 rad, max |dq/dt| by forward differences)."""
    q = qpos[:, JOINTS_QPOS]
    out = ((q < lower - JOINT_LIMIT_TOL) | (q > upper + JOINT_LIMIT_TOL)).any(axis=1)
    speed = _max(np.abs(np.diff(q, axis=0))) * fps
    return _frac(out), speed


def retarget_metrics(
    robot: RobotClip,
    human: HumanClip | None = None,
    *,
    link_map: dict[str, str] | None = None,
    seconds_wall: float | None = None,
) -> dict:
    """The quality metrics of ``robot`` (keys :data:`METRIC_KEYS`; see the module doc)."""
    link_map = DEFAULT_LINK_MAP if link_map is None else link_map
    T, fps = robot.frames, robot.fps
    refs = _reference_contacts(robot, human, link_map)
    swept = sweep(robot, refs, contact_tol=CONTACT_TOL, support_tol=FLOAT_TOL if human is None else None)
    low = swept.lowest()
    ground = np.maximum(0.0, -low.min(axis=1))
    feet_h = swept.foot_heights(low)
    if human is not None:
        fc = detect_foot_contacts(human).both[_nearest_rows(T, fps, human.frames, human.fps)]
        floating = fc.any(axis=1) & (feet_h > FLOAT_TOL).all(axis=1)
    else:
        fc = feet_h <= FLOAT_TOL
        floating = (low.min(axis=1) > FLOAT_TOL) & ~swept.supported
    slide_frac, slide_speed = foot_slide(swept.sites, fc, fps)
    lo, hi = (np.array([swept.model.jnt_range[swept.model.joint(j).id, k] for j in G1_JOINT_NAMES]) for k in (0, 1))
    limit_frac, speed = joint_metrics(robot.qpos, fps, lo, hi)
    wall = float("nan") if seconds_wall is None else float(seconds_wall)
    values = {
        "ground_penetration_frac_1cm": _frac(ground > PENETRATION_TOL),
        "ground_penetration_max_m": _max(ground),
        "object_penetration_frac_1cm": _frac(swept.obj_depth > PENETRATION_TOL),
        "object_penetration_max_m": _max(swept.obj_depth),
        "float_frac_2cm": _frac(floating),
        "foot_slide_frac_1cm_per_frame": slide_frac,
        "foot_slide_speed_max_mps": slide_speed,
        "contact_preservation_frac": _frac(swept.preserved) if swept.measurable else float("nan"),
        "joint_limit_violation_frac": limit_frac,
        "max_joint_speed_radps": speed,
        "self_collision_frac": _frac(swept.self_depth > SELF_COLLISION_TOL),
        "frames": int(T),
        "fps": float(fps),
        "seconds_wall": wall,
        "frames_per_s": T / wall if wall > 0 else float("nan"),
    }
    return {k: values[k] for k in METRIC_KEYS}


def summarise(per_clip: list[dict]) -> dict:
    """All clips at once: frame-weighted means of the fractions (over clips where finite), max of
    the maxima, total ``frames`` and ``seconds_wall``, ``frames_per_s`` = total frames / total
    seconds (clips with a known wall time), ``fps`` when all clips share it (else NaN), ``clips``."""
    out: dict = {}
    frames = np.array([c["frames"] for c in per_clip], float)
    for k in METRIC_KEYS:
        v = np.array([c[k] for c in per_clip], float)
        ok = np.isfinite(v)
        if "frac" in k:
            w = frames[ok]
            out[k] = float(np.dot(v[ok], w) / w.sum()) if ok.any() and w.sum() > 0 else float("nan")
        elif "max" in k:
            out[k] = float(v[ok].max()) if ok.any() else float("nan")
    out["frames"] = int(frames.sum())
    fps = {c["fps"] for c in per_clip}
    out["fps"] = float(fps.pop()) if len(fps) == 1 else float("nan")
    wall = np.array([c["seconds_wall"] for c in per_clip], float)
    timed = np.isfinite(wall)
    out["seconds_wall"] = float(wall[timed].sum()) if timed.any() else float("nan")
    out["frames_per_s"] = (
        float(frames[timed].sum() / wall[timed].sum()) if timed.any() and wall[timed].sum() > 0 else float("nan")
    )
    return {**{k: out[k] for k in METRIC_KEYS}, "clips": len(per_clip)}


def evaluate_file(
    path: str | Path,
    *,
    human_path: str | Path | None = None,
    object_mesh: str | Path | None = None,
    link_map: dict[str, str] | None = None,
    seconds_wall: float | None = None,
    joint_names: Sequence[str] | None = None,
) -> dict:
    """Metrics of a peer's G1 motion file (BeyondMimic/OmniRetarget ``.npz``, GMR ``.pkl``).

    ``object_mesh``: the object's mesh (its convex hull collides), needed for object metrics;
    ``human_path``: the human clip it came from (its first clip), for foot contacts and contact
    flags, aligned by time to the robot frames. The robot is scored against its OWN object
    track (OmniRetarget scales the object's trajectory; the human's track is not used).
    ``seconds_wall``: the peer's own run time when known (else ``frames_per_s`` is NaN).
    ``joint_names``: the column order of a ``.npz`` that names none of its joints (``--joint-names``).
    """
    geometry = MeshGeometry(str(object_mesh)) if object_mesh is not None else None
    robot = read_robot_clip(path, object_geometry=geometry, joint_names=joint_names)
    human = read_clips(human_path, mesh=object_mesh)[0] if human_path is not None else None
    return retarget_metrics(robot, human, link_map=link_map, seconds_wall=seconds_wall)
