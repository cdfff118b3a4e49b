"""Which human joint drives which G1 body (per-skeleton data files), the part each G1 body plays,
and the G1 measured at ``q = 0``.

Mapping files (``retarget/mappings/*.json``, one per skeleton family)::

    {"name": "smpl", "description": "...", "required": ["pelvis", "left_hip", ...], "links":
     {"left_ankle_roll_link": {"joint": "left_ankle", "aim": "left_foot", "pos_weight": 1.0, "rot_weight": 0.5}, ...}}

``required``: joints that identify the skeleton; ``joint``: the human joint the body follows;
``aim``: a joint giving the segment direction ``aim - joint`` (``"-elbow"``: ``joint - elbow``);
``joint``/``aim`` may list candidates (first present wins); weights: the IK task costs. Files are
tried most specific first (most required joints, then name). The part each G1 body plays is the
G1's structure (:data:`G1_ROLES`); the G1 is measured at ``q = 0`` by FK (:func:`g1_rest`).

A clip is mapped once (:func:`map_human`): its :func:`human_points` and joint rotations, which the
scale, the reference pose, the drivers and the targets all read.

Segment frames, the reference pose and the rotation offsets are in :mod:`retarget.frames`.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError
from pipeline.robot import g1_model
from pipeline.rotations import rotation_from_wxyz

MAPPINGS_DIR = Path(__file__).with_name("mappings")
SIDES = ("left", "right")
Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class LinkMap:
    """One G1 body driven by one human joint; segment direction ``aim_sign (p[aim] - p[joint])``."""

    body: str
    joint: str
    aim: str
    aim_sign: float
    pos_weight: float
    rot_weight: float


@dataclass(frozen=True)
class Mapping:
    """A mapping file resolved for one skeleton."""

    name: str
    path: str
    required: tuple[str, ...]
    links: tuple[LinkMap, ...]
    description: str = ""

    @property
    def body_names(self) -> tuple[str, ...]:
        return tuple(link.body for link in self.links)

    def link(self, body: str) -> LinkMap:
        return next(link for link in self.links if link.body == body)

    def body_of_kind(self, kind: str, side: str | None = None) -> str | None:
        """The mapped body playing ``kind`` (on ``side``), or None."""
        return next((b for b in self.body_names if (G1_ROLES[b].kind, G1_ROLES[b].side) == (kind, side)), None)


@dataclass(frozen=True)
class BodyRole:
    """The part a G1 body plays: ``kind`` (pelvis, torso, thigh, shank, foot, upper_arm, forearm,
    hand); ``group``, its scale and anchor (``leg``: about the ground point, ``trunk``: from the
    pelvis target, ``arm``: from the same side's upper-arm target); ``offset_frame``, the body whose
    target frame carries its position offset (None: none); ``robot_aim``, G1 bodies or sites whose
    mean is the G1's counterpart of the human ``aim``; ``offset_body``, whose offset it takes
    (None: its own; knees and feet move with their hip)."""

    kind: str
    side: str | None
    group: str
    offset_frame: str | None
    robot_aim: tuple[str, ...]
    offset_body: str | None = None


def _g1_roles() -> dict[str, BodyRole]:
    roles = {
        "pelvis": BodyRole("pelvis", None, "leg", "pelvis", ("torso_link",)),
        "torso_link": BodyRole(
            "torso", None, "trunk", "torso_link", ("left_shoulder_roll_link", "right_shoulder_roll_link")
        ),
    }
    for s in SIDES:
        hip = f"{s}_hip_pitch_link"
        roles[hip] = BodyRole("thigh", s, "leg", "pelvis", (f"{s}_knee_link",))
        roles[f"{s}_knee_link"] = BodyRole("shank", s, "leg", "pelvis", (f"{s}_ankle_roll_link",), hip)
        roles[f"{s}_ankle_roll_link"] = BodyRole("foot", s, "leg", "pelvis", (f"site:{s}_foot",), hip)
        for b in (f"{s}_shoulder_pitch_link", f"{s}_shoulder_roll_link"):
            roles[b] = BodyRole("upper_arm", s, "trunk", "torso_link", (f"{s}_elbow_link",))
        roles[f"{s}_elbow_link"] = BodyRole("forearm", s, "arm", None, (f"{s}_wrist_yaw_link",))
        roles[f"{s}_wrist_yaw_link"] = BodyRole("hand", s, "arm", None, (f"site:{s}_palm",))
    return roles


#: Every G1 body a mapping file may drive, and its part.
G1_ROLES: dict[str, BodyRole] = _g1_roles()
#: Bodies every mapping must drive (pelvis frame, floor and leg scale need them).
CORE_BODIES = ("pelvis", "torso_link") + tuple(
    f"{s}_{b}" for s in SIDES for b in ("hip_pitch_link", "knee_link", "ankle_roll_link")
)


@dataclass(frozen=True)
class G1Rest:
    """The G1 at ``q = 0`` on ``z = 0``: ``pos`` of bodies and ``site:<name>`` sites, body ``rot``;
    ``sole``: the lowest foot collision point before that shift; ``height``: the top of the head."""

    pos: dict[str, np.ndarray]
    rot: dict[str, np.ndarray]
    sole: float
    height: float


def _geom_extent(model, data, g: int, sign: float = -1.0) -> float:
    """Lowest (``sign=-1``) or highest world z of geom ``g``: exact for spheres and capsules
    (radius, half-length along local z), its local bounding box otherwise."""
    R, c, size = data.geom_xmat[g].reshape(3, 3), data.geom_xpos[g, 2], model.geom_size[g]
    if model.geom_type[g] in (mujoco.mjtGeom.mjGEOM_SPHERE, mujoco.mjtGeom.mjGEOM_CAPSULE):
        half = size[1] if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE else 0.0
        return float(c + sign * (size[0] + half * abs(R[2, 2])))
    return float(c + R[2] @ model.geom_aabb[g, :3] + sign * np.abs(R[2]) @ model.geom_aabb[g, 3:])


@functools.lru_cache(maxsize=1)
def g1_rest() -> G1Rest:
    """Forward kinematics of ``g1.xml`` at ``q = 0`` (identity root), shifted so the soles touch ``z = 0``."""
    model = g1_model()
    mujoco.mj_forward(model, data := mujoco.MjData(model))
    collide = [g for g in range(model.ngeom) if model.geom_contype[g] or model.geom_conaffinity[g]]
    feet = {model.body(f"{s}_ankle_roll_link").id for s in SIDES}
    sole = min(_geom_extent(model, data, g) for g in collide if model.geom_bodyid[g] in feet)
    shift = np.array([0.0, 0.0, sole])
    pos = {model.body(b).name: data.xpos[b] - shift for b in range(1, model.nbody)}
    pos.update({f"site:{model.site(s).name}": data.site_xpos[s] - shift for s in range(model.nsite)})
    rot = {model.body(b).name: data.xmat[b].reshape(3, 3).copy() for b in range(1, model.nbody)}
    top = max(_geom_extent(model, data, g, 1.0) for g in collide)
    return G1Rest(pos, rot, float(sole), float(top - sole))


def g1_points(mapping: Mapping) -> dict[str, np.ndarray]:
    """The G1's :func:`human_points` at ``q = 0``: body origins, and aim points (means of ``robot_aim``)."""
    rest = g1_rest()
    P = {b: rest.pos[b][None] for b in mapping.body_names}
    P.update({b + ">": np.mean([rest.pos[a] for a in G1_ROLES[b].robot_aim], axis=0)[None] for b in mapping.body_names})
    return P


def human_points(joint_pos: np.ndarray, skeleton: Skeleton, mapping: Mapping) -> dict[str, np.ndarray]:
    """``P[body]``: the driving joint's positions ``(T, 3)``; ``P[body + ">"]``: the joint moved
    along its segment direction, ``p[joint] + aim_sign (p[aim] - p[joint])``."""
    P = {}
    for link in mapping.links:
        p = joint_pos[:, skeleton.index(link.joint)]
        P[link.body], P[link.body + ">"] = p, p + link.aim_sign * (joint_pos[:, skeleton.index(link.aim)] - p)
    return P


@dataclass(frozen=True)
class MappedHuman:
    """One human clip seen through its mapping, each array computed once per clip: ``points`` =
    :func:`human_points` of ``clip.joint_pos`` (``P[body]``, ``P[body + ">"]``, ``(T, 3)``); ``rot``
    ``(T, J, 3, 3)`` the joints' global rotations ``R_j(t)`` from ``clip.joint_quat`` (None without)."""

    clip: HumanClip
    mapping: Mapping
    points: dict[str, np.ndarray]
    rot: np.ndarray | None


def map_human(clip: HumanClip, mapping: Mapping) -> MappedHuman:
    """``clip`` mapped by ``mapping`` (:class:`MappedHuman`): the one :func:`human_points` of its frames."""
    rot = None
    if clip.joint_quat is not None:
        rot = rotation_from_wxyz(clip.joint_quat.reshape(-1, 4)).as_matrix().reshape(clip.frames, -1, 3, 3)
    return MappedHuman(clip, mapping, human_points(clip.joint_pos, clip.skeleton, mapping), rot)


def _names(value, path: Path, field: str) -> list[str]:
    names = [value] if isinstance(value, str) else value
    if not isinstance(names, list) or not names or not all(isinstance(n, str) and n.lstrip("-") for n in names):
        raise InputError(path, field, f"must be a joint name or a non-empty list of names, got {value!r}")
    return names


def read_spec(path: Path) -> dict:
    """A mapping file, checked (:class:`InputError` naming the file and the field)."""
    try:
        spec = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as e:
        raise InputError(path, "file", f"not a readable JSON mapping ({e})") from None
    if not isinstance(spec, dict) or not isinstance(spec.get("links"), dict):
        raise InputError(path, "links", "missing: a mapping file needs a 'links' object {G1 body: {...}}")
    links = {}
    for body, e in spec["links"].items():
        where = f"links.{body}"
        if body not in G1_ROLES or not isinstance(e, dict):
            raise InputError(path, where, f"must be one of the G1 bodies {', '.join(G1_ROLES)}, mapped to an object")
        for w in ("pos_weight", "rot_weight"):
            if not isinstance(e.get(w), (int, float)) or not np.isfinite(e[w]) or e[w] < 0:
                raise InputError(path, f"{where}.{w}", f"must be a non-negative number, got {e.get(w)!r}")
        links[body] = {
            "joint": _names(e.get("joint"), path, f"{where}.joint"),
            "aim": _names(e.get("aim"), path, f"{where}.aim"),
            "pos_weight": float(e["pos_weight"]),
            "rot_weight": float(e["rot_weight"]),
        }
    missing = [b for b in CORE_BODIES if b not in links]
    if missing:
        raise InputError(path, "links", f"must drive {', '.join(missing)} (pelvis, torso and both legs are needed)")
    roles = [G1_ROLES[b] for b in links]
    hanging = {r.side for r in roles if r.group == "arm"} - {r.side for r in roles if r.kind == "upper_arm"}
    if hanging:
        raise InputError(
            path, "links", f"the {', '.join(sorted(hanging))} elbow/wrist need a shoulder link to hang from"
        )
    return {
        "name": str(spec.get("name", Path(path).stem)),
        "description": str(spec.get("description", "")),
        "required": tuple(_names(spec.get("required"), path, "required")),
        "links": links,
    }


def mapping_files() -> list[Path]:
    """The shipped mapping files, most specific first (most required joints, then by name)."""
    return sorted(MAPPINGS_DIR.glob("*.json"), key=lambda p: (-len(read_spec(p)["required"]), p.name))


def _resolve(spec: dict, path: Path, names: set[str]) -> Mapping | list[str]:
    """The mapping for a skeleton with joint ``names``, or what it misses."""
    missing = [n for n in spec["required"] if n not in names]
    links = []
    for body, e in spec["links"].items():
        joint = next((n for n in e["joint"] if n in names), None)
        aim = next((n for n in e["aim"] if n.lstrip("-") in names), None)
        missing += [" or ".join(c.lstrip("-") for c in e[k]) for k, v in (("joint", joint), ("aim", aim)) if v is None]
        if joint is not None and aim is not None:
            sign = -1.0 if aim.startswith("-") else 1.0
            links.append(LinkMap(body, joint, aim.lstrip("-"), sign, e["pos_weight"], e["rot_weight"]))
    if missing:
        return list(dict.fromkeys(missing))
    return Mapping(spec["name"], str(path), spec["required"], tuple(links), spec["description"])


def load_mapping(skeleton: Skeleton, explicit: str | None = None, *, source: str | None = None) -> Mapping:
    """The mapping for ``skeleton``: the file ``explicit`` (a path, or a shipped name such as
    ``"smpl"``), else the first shipped file that fits (:func:`mapping_files` order).

    No fit: :class:`InputError` naming ``source``, field ``skeleton``, listing the skeleton's
    joints and, per file tried, the joints it missed.
    """
    paths = mapping_files()
    if explicit is not None:
        path = Path(explicit) if Path(explicit).suffix == ".json" else MAPPINGS_DIR / f"{explicit}.json"
        if not path.is_file():
            raise InputError(
                source, "mapping", f"no mapping file {explicit!r} ({path}); shipped: {', '.join(p.stem for p in paths)}"
            )
        paths = [path]
    names, tried = set(skeleton.joint_names), []
    for path in paths:
        result = _resolve(read_spec(path), path, names)
        if isinstance(result, Mapping):
            return result
        tried.append(
            f"{path.name} (missing {', '.join(result[:6])}{f' and {len(result) - 6} more' if len(result) > 6 else ''})"
        )
    raise InputError(
        source,
        "skeleton",
        f"no joint mapping fits this skeleton; it has {len(names)} joints: "
        f"{', '.join(skeleton.joint_names)}; tried {'; '.join(tried)}; add a mapping file to "
        f"{MAPPINGS_DIR} (every file there is tried; the command line has no option naming one)",
    )
