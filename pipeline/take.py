"""What a take asks of the robot, read from its reference alone: the take's kind from the object's own track
(:func:`take_kind`), and the frames the human holds the object with both hands (:func:`held_frames`).

**Kinds.** An object track ``(T, 7)`` (xyz, quaternion wxyz per frame) is measured against its first frame, where
the object rests: ``rise_m = max_t (z_t - z_0)``, its height above its first height, and ``travel_m = max_t
|xy_t - xy_0|``, its furthest horizontal distance from where it started (the orientation is not used). Then, in
this order:

* ``small move``: ``rise_m <= SMALL_MOVE_M`` and ``travel_m <= SMALL_MOVE_M`` (0.25 m): the object barely leaves
  its place (a chair nudged or turned where it stands);
* ``slide``: ``rise_m <= SLIDE_RISE_M`` (0.10 m) and ``travel_m > SMALL_MOVE_M``: the floor carries the weight
  while the hands push (a box pushed or dragged along the floor, a table dragged with one edge raised: its origin
  rises a few cm);
* ``overhead``: ``rise_m >= OVERHEAD_RISE_M`` (1.4 m): raised above the head (a table lifted overhead);
* ``lift``: anything else, lifted 0.1-1.4 m, carried or in place: the hands carry the weight.

Measured on the 20 shared OMOMO takes (``../shared/mocap``): slides rise <= 0.07 m and travel 1.1-2.0 m (every
``largebox`` and ``plasticbox`` take of sub8, three tables dragged); lifts rise 0.67-1.08 m; overhead raises
1.78 m; small moves rise 0.12-0.13 m and travel <= 0.19 m. The thresholds sit in the gaps between these groups,
not at any one take.

**Held frames** (:func:`held_frames`). The human holds the object with both hands at frame ``t`` when each hand
(its wrist and the joints below it: the fingers, where the skeleton has them) is labelled in contact
(``HumanClip.contacts``) or comes within :data:`HOLD_GAP_M` of the object's surface (the object field's ``phi``),
whether or not the object is up. The fingers count because OMOMO often labels the fingers, not the wrist
(``sub8_plasticbox_002``, a two-handed push: both wrists are never labelled together, both hands' fingers on 36%
of the frames), and a touching hand's wrist joint sits 4-10 cm off the surface (on the shared takes the 2 cm test
at the wrists alone adds frames to one take only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.clip import HumanClip, Skeleton, check_array
from pipeline.distance.field import ObjectField
from pipeline.geometry import MeshGeometry, ObjectGeometry

SMALL_MOVE_M = 0.25  # an object that rises and travels no more than this barely moves
SLIDE_RISE_M = 0.10  # an object that rises no more than this, and travels further, slides on the floor
OVERHEAD_RISE_M = 1.4  # an object that rises this much or more is raised above the head
HOLD_GAP_M = 0.02  # a hand this close to the object's surface holds it (labelled or not)

SMALL_MOVE, SLIDE, OVERHEAD, LIFT = "small move", "slide", "overhead", "lift"
KINDS = (SLIDE, LIFT, OVERHEAD, SMALL_MOVE)  #: every kind, in the order tables list them


@dataclass(frozen=True)
class TakeKind:
    """A take's kind (module docstring) and the two figures that decide it [m]."""

    kind: str
    rise_m: float
    travel_m: float


def take_kind(object_pose: np.ndarray) -> TakeKind:
    """The kind of a take from its object's reference track ``object_pose`` (T, 7) (module docstring)."""
    pose = check_array(object_pose, (None, 7), "object pose", "take_kind")
    rise = float(np.max(pose[:, 2] - pose[0, 2]))
    travel = float(np.max(np.linalg.norm(pose[:, :2] - pose[0, :2], axis=1)))
    if rise <= SMALL_MOVE_M and travel <= SMALL_MOVE_M:
        kind = SMALL_MOVE
    elif rise <= SLIDE_RISE_M:
        kind = SLIDE
    elif rise >= OVERHEAD_RISE_M:
        kind = OVERHEAD
    else:
        kind = LIFT
    return TakeKind(kind, rise, travel)


def hand_joints(skeleton: Skeleton, side: str) -> list[int]:
    """Indices of ``<side>_wrist`` and every joint below it (its fingers); ``[]`` when there is no such wrist."""
    name = f"{side}_wrist"
    if name not in skeleton.joint_names:
        return []
    hand = [skeleton.index(name)]
    for j, parent in enumerate(skeleton.parents):  # parents precede children: one pass finds every descendant
        if parent in hand:
            hand.append(j)
    return hand


def geometry_field(geometry: ObjectGeometry) -> ObjectField:
    """The distance field of one clip's object (a mesh's field is built without a disk cache)."""
    return ObjectField.from_geometry(geometry, **({"cache": False} if isinstance(geometry, MeshGeometry) else {}))


def object_field(human: HumanClip, index: int = 0) -> ObjectField:
    """The distance field of the human clip's object ``index`` (:func:`geometry_field`)."""
    return geometry_field(human.objects[index].geometry)


def held_frames(human: HumanClip, field: ObjectField | None = None, index: int = 0) -> np.ndarray:
    """(T,) bool: both hands hold object ``index`` (module docstring): per hand, any of its joints labelled in
    contact or within :data:`HOLD_GAP_M` of the surface. All False without the object or either wrist.
    ``field``: the object's :func:`object_field` when already built."""
    hands = [hand_joints(human.skeleton, side) for side in ("left", "right")]
    if len(human.objects) <= index or not all(hands):
        return np.zeros(human.frames, bool)
    field = object_field(human, index) if field is None else field
    pose = human.objects[index].pose
    held = np.ones(human.frames, bool)
    for hand in hands:
        phi = np.asarray(field.query_links(human.joint_pos[:, hand], pose).phi)
        touching = phi.min(axis=1) <= HOLD_GAP_M
        if human.contacts is not None:
            touching |= human.contacts[:, hand].any(axis=1)
        held &= touching
    return held


def wrist_normals(field: ObjectField, wrists: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(n, 2, 3) the object's outward surface normals nearest the two wrists ``wrists`` (n, 2, 3) at object poses
    ``pose`` (n, 7): the field's gradient."""
    return np.asarray(field.query_links(wrists, pose).grad)


def human_hold(human: HumanClip, index: int = 0, field: ObjectField | None = None) -> tuple[np.ndarray, float] | None:
    """``(frames, opposition)``: the take's :func:`held_frames` (indices) and the mean of ``n_l . n_r`` over them (the
    outward surface normals nearest the left and the right wrist: -1 on opposite faces, a squeeze; +1 on one face,
    a push); None without such frames, the object or either wrist. ``field``: the object's :func:`object_field`
    when already built."""
    names = human.skeleton.joint_names
    if len(human.objects) <= index or "left_wrist" not in names or "right_wrist" not in names:
        return None
    field = object_field(human, index) if field is None else field
    frames = np.flatnonzero(held_frames(human, field, index))
    if not frames.size:
        return None
    wrists = human.joint_pos[frames][:, [human.skeleton.index("left_wrist"), human.skeleton.index("right_wrist")]]
    return frames, mean_opposition(wrist_normals(field, wrists, human.objects[index].pose[frames]))


def mean_opposition(normals: np.ndarray) -> float:
    """The mean over frames of ``n_l . n_r`` for (T, 2, 3) left and right hand normals: -1 opposite faces (a
    squeeze), +1 one face (a push)."""
    return float(np.mean(np.einsum("ti,ti->t", normals[:, 0], normals[:, 1])))
