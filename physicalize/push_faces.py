"""Pushing hands on the faces that can give the push.

A hand that only presses on an object (no squeeze, the object sliding on its support) can apply any force in its
friction cone about the face's inward normal ``n``, nothing else. The human's hands often are not where a G1 hand can
push: humans rub across a face or press down on a lid with skin and a grip the G1's hands lack. Measured on the six
shared box slides (issue 54): the wrench that held each box on its track was **89-99% outside the cone of the
holding hands' normals** (across the faces they touch), the hands sat on one face at 55 deg to the motion
(``n . u`` = 0.57, where the cone half-angle at the planner's friction ``mu / safety`` is 19 deg) or on the lid
pressing down 15-29 N for a few newtons along.

So a hand's hold is moved onto the face of the object whose normal can push the reference's motion ``u`` (the
object's horizontal velocity in its own frame, averaged over the hold weighted by speed):

* the object's side faces are the clusters (within :data:`FACE_ANGLE_DEG`) of its collision hull's near-vertical
  triangles, each with its outward horizontal normal, its supporting plane and its extent along the face and up;
* faces ``A`` and ``B`` are the two whose inward normals are closest to ``u``. Where ``A`` is within the reduced cone
  (angle to ``u`` <= ``atan(mu / safety)``) every pushing hand goes there; otherwise the two hands of a two-hand push
  take the corner between ``A`` and ``B``, the left hand on the face whose inward normal lies clockwise of ``u``
  (``(u x n)_z < 0``: the face on a pusher's left), the right hand on the other; a hand alone takes ``A`` where ``A``
  pushes the motion forward (``sub8_plasticbox_000``: 64 -> 26 deg off the motion, valid; kept at 64 deg the box is
  lost);
* a hand already on a face that can push ``u`` alone, or whose target face is the far side of the object from its own
  (inward normals more than 100 deg apart), stays where the human put it; so do the hands where neither a face nor a
  corner (the two nearest faces both pushing forward, ``n . u > 0``, on either side of ``u``) can give a pair's push
  (``sub2_largetable_004``: the table dragged towards the body, its faces across the motion at 73 deg);
* the new point is the old one projected onto the new face (clamped :data:`EDGE_MARGIN_M` inside its edges) at the old
  point's stand-off from its face; a hand alone is moved along the face onto the vertical through the centre of mass, so
  that its push does not turn the object (a point contact's push turns it unless its line passes through the centre of
  mass; two hands balance their moments in the force plan, :func:`physicalize.grasp_force.press_allocation`).

Only objects with a convex hull (a mesh or box geom) and holds whose object slides more than ``push_travel`` without
lifting are touched; squeezes, lifts and carries keep the human's hand placement.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
import trimesh

from physicalize.grasp_config import GraspConfig
from physicalize.hand_reach import ObjectTracks
from pipeline.foot_contact import label_runs
from pipeline.rotations import pose_rotations, quat_mat

FACE_ANGLE_DEG = 25.0  # hull triangles whose horizontal normals are this close form one face
MIN_FACE_SHARE = 0.25  # a face has at least this share of the largest face's area
EDGE_MARGIN_M = 0.06  # a moved hand point stays this far inside its face's edges
FAR_SIDE_COS = -0.17  # a hand never moves to a face whose inward normal is > 100 deg from its own
STANDOFF_M = 0.03  # a hand with no face of its own (recruited) is placed with its tracked point this far off the face


@dataclass(frozen=True)
class Face:
    """One side face of an object in its body frame, for the world's vertical ``up`` (a unit vector of that frame: the
    scanned objects' frames are not z-up): outward unit normal ``n`` (perpendicular to ``up``), supporting plane
    ``n . x = offset``, and its extent along the horizontal tangent ``t = up x n`` (``span``) and along ``up``
    (``height``)."""

    n: np.ndarray
    up: np.ndarray
    offset: float
    span: tuple[float, float]
    height: tuple[float, float]

    @property
    def t(self) -> np.ndarray:
        return np.cross(self.up, self.n)

    def place(self, c: np.ndarray, standoff: float, through: np.ndarray | None = None) -> np.ndarray:
        """The point ``c`` (body frame) moved onto this face, inside its edges, ``standoff`` outside its plane; with
        ``through``, moved along the face onto the vertical through that point (a lone hand's push through the
        object's centre of mass)."""
        along = _clamp(float((c if through is None else through) @ self.t), self.span)
        height = _clamp(float(c @ self.up), self.height)
        return along * self.t + height * self.up + (self.offset + standoff) * self.n


def _clamp(x: float, lim: tuple[float, float]) -> float:
    lo, hi = lim[0] + EDGE_MARGIN_M, lim[1] - EDGE_MARGIN_M
    return 0.5 * (lim[0] + lim[1]) if lo > hi else min(max(x, lo), hi)


def body_vertices(m: mujoco.MjModel, geoms: list[int]) -> np.ndarray:
    """(V, 3) the vertices of a body's mesh and box collision ``geoms`` in the body frame (empty: none)."""
    pts = []
    for g in geoms:
        if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH:
            mid = m.geom_dataid[g]
            v = m.mesh_vert[m.mesh_vertadr[mid] : m.mesh_vertadr[mid] + m.mesh_vertnum[mid]]
        elif m.geom_type[g] == mujoco.mjtGeom.mjGEOM_BOX:
            v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * m.geom_size[g]
        else:
            continue
        pts.append(m.geom_pos[g] + v @ quat_mat(m.geom_quat[g]).T)
    return np.concatenate(pts) if pts else np.zeros((0, 3))


@dataclass(frozen=True)
class Hull:
    """An object's convex hull in its body frame: ``vertices`` (V, 3), ``triangles`` (F, 3) vertex indices, their
    outward unit ``normals`` (F, 3) and ``areas`` (F,); the body's centre of mass ``com`` (3,)."""

    vertices: np.ndarray
    triangles: np.ndarray
    normals: np.ndarray
    areas: np.ndarray
    com: np.ndarray

    def support(self, direction: np.ndarray) -> float:
        """``max_x direction . x`` over the hull: the offset of its supporting plane with that normal."""
        return float((self.vertices @ direction).max())

    def side_faces(self, up: np.ndarray) -> list[Face]:
        """The hull's side faces for the vertical ``up`` (body frame): its triangles within 60 deg of vertical
        grouped by their horizontal normals (within :data:`FACE_ANGLE_DEG`), each group with at least
        :data:`MIN_FACE_SHARE` of the largest group's area."""
        flat = self.normals - np.outer(self.normals @ up, up)
        side = np.flatnonzero(np.abs(self.normals @ up) < 0.5)
        clusters: list[list[int]] = []
        mean: list[np.ndarray] = []
        cos = np.cos(np.radians(FACE_ANGLE_DEG))
        for f in side[np.argsort(-self.areas[side])]:
            h = flat[f] / np.linalg.norm(flat[f])
            for c, nm in enumerate(mean):
                if h @ nm / np.linalg.norm(nm) >= cos:
                    clusters[c].append(f)
                    mean[c] = nm + self.areas[f] * h
                    break
            else:
                clusters.append([f])
                mean.append(self.areas[f] * h)
        area = np.array([self.areas[c].sum() for c in clusters]) if clusters else np.zeros(0)
        faces = []
        for c, nm in enumerate(mean):
            if area[c] < MIN_FACE_SHARE * area.max():
                continue
            n = nm / np.linalg.norm(nm)
            on = self.vertices[self.triangles[clusters[c]].ravel()]  # a scanned box tapers: its plane touches one rim
            t = np.cross(up, n)
            span = (float((on @ t).min()), float((on @ t).max()))
            faces.append(Face(n, up, self.support(n), span, (float((on @ up).min()), float((on @ up).max()))))
        return faces


def object_hull(m: mujoco.MjModel, geoms: list[int]) -> Hull | None:
    """The convex hull of a body's mesh and box collision ``geoms``; ``None`` without such geoms or for a flat set."""
    vertices = body_vertices(m, geoms)
    if len(vertices) < 4:
        return None
    try:
        hull = trimesh.convex.convex_hull(vertices)
    except Exception:  # qhull refuses a flat or degenerate set: no faces to push on
        return None
    com = m.body_ipos[m.geom_bodyid[geoms[0]]].copy()
    return Hull(np.asarray(hull.vertices), np.asarray(hull.faces), np.asarray(hull.face_normals), hull.area_faces, com)


def push_direction(pose: np.ndarray, fps: float) -> np.ndarray:
    """(3,) the unit horizontal direction the object moves in its own frame over the track ``pose`` (T, 7) (its
    horizontal velocities rotated into its frame, summed: the speed-weighted mean direction); zeros when it does
    not move."""
    v = np.gradient(pose[:, :3], 1.0 / fps, axis=0) if len(pose) > 1 else np.zeros((1, 3))
    v[:, 2] = 0.0
    u = np.einsum("tji,tj->i", pose_rotations(pose), v)
    norm = np.linalg.norm(u)
    return u / norm if norm > 1e-9 else np.zeros(3)


def push_face(
    hull: Hull, up: np.ndarray, c: np.ndarray, n_in: np.ndarray, u: np.ndarray, hand: int, partner: bool, mu: float
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(c', n_in')`` (body frame) the point and inward normal of hand ``hand`` (0 left, 1 right) moved onto the face
    that can push ``u`` (module docstring), or ``None`` to keep its point ``c`` and inward normal ``n_in``; ``up``:
    the world's vertical in the body frame; ``partner``: the other hand pushes the object too; ``mu``: the friction
    the planner allows (``mu / safety``)."""
    faces = hull.side_faces(up)
    if not faces or not u.any():
        return None
    half = np.arctan(mu)
    inward = np.array([-f.n for f in faces])
    A = int(np.argmax(inward @ u))
    own = n_in - (n_in @ up) * up
    on_side = abs(n_in @ up) < 0.7 and np.linalg.norm(own) > 1e-6  # a recruited hand has no face of its own
    if on_side:
        own /= np.linalg.norm(own)
        if np.arccos(np.clip(own @ u, -1, 1)) <= half:
            return None  # its own face pushes u within the cone
    if np.arccos(np.clip(inward[A] @ u, -1, 1)) <= half or (not partner and inward[A] @ u > 0):
        target = A
    elif partner and (corner := _corner(inward, u, up)) is not None:
        target = corner[hand]
    else:
        return None  # neither a face nor a corner can give the push: the human's hands stay (sub2_largetable_004)
    if on_side and (inward[target] @ own > 0.98 or inward[target] @ own < FAR_SIDE_COS):
        return None
    standoff = float(np.clip(c @ -n_in - hull.support(-n_in), 0.0, 0.1)) if n_in.any() else STANDOFF_M
    return faces[target].place(c, standoff, None if partner else hull.com), inward[target]


def _corner(inward: np.ndarray, u: np.ndarray, up: np.ndarray) -> tuple[int, int] | None:
    """``(left, right)`` the faces (indices into the inward normals ``inward`` (F, 3)) of the corner that brackets the
    motion ``u``: the two faces nearest it, both pushing it forward (``n . u > 0``) and on either side of it, the left
    hand's clockwise of it (``(u x n) . up < 0``); None when no such pair exists."""
    if len(inward) < 2:
        return None
    A, B = np.argsort(-(inward @ u))[:2]
    if inward[B] @ u <= 0:
        return None
    left = [np.cross(u, inward[j]) @ up < 0 for j in (A, B)]
    if left[0] == left[1]:
        return None
    return (int(A), int(B)) if left[0] else (int(B), int(A))


def pushed(pose: np.ndarray, push_travel: float, lift: float) -> bool:
    """The object slides along its support over the track ``pose`` (T, 7): it moves more than ``push_travel``
    horizontally and rises less than ``lift``."""
    travel = float(np.linalg.norm(pose[:, :2] - pose[0, :2], axis=1).max())
    return travel > push_travel and float(pose[:, 2].max() - pose[0, 2]) < lift


@dataclass
class PushFaces:
    """Moves each pushing hand's hold onto the face that can push (module docstring): ``hulls`` per object index
    (``None``: not a hull), the hands' object ``key`` (T, 2) (-1 none), ``opposed`` (T,) squeezes, object ``poses``
    (index -> (T, 7)), ``fps``, the planner's friction ``mu`` (``mu / safety``), ``push_travel`` and ``lift`` (m)."""

    hulls: dict[int, Hull | None]
    key: np.ndarray
    opposed: np.ndarray
    poses: dict[int, np.ndarray]
    fps: float
    mu: float
    push_travel: float
    lift: float

    @classmethod
    def of(
        cls,
        m: mujoco.MjModel,
        objs: ObjectTracks,
        key: np.ndarray,
        opposed: np.ndarray,
        fps: float,
        mu: float,
        cfg: GraspConfig,
    ) -> PushFaces:
        """The planner for the objects ``objs`` the hands hold (``key`` (T, 2), shared: :meth:`recruit` sets it)."""
        held = sorted(set(key[key >= 0].tolist()))
        hulls = {i: object_hull(m, objs.geoms[i]) for i in held}
        poses = {i: objs.pose(i)[: len(key)] for i in held}
        return cls(hulls, key, opposed, poses, fps, mu, cfg.push_travel, cfg.lift_blend)

    def __call__(
        self, i: int, k: int, a: int, b: int, c: np.ndarray, n_in: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Hand ``k``'s anchor ``(c, n_in)`` (object ``i``'s frame) for its hold ``[a, b)``, moved or as it is."""
        pose, hull = self.poses[i][a:b], self.hulls.get(i)
        if hull is None or self.opposed[a:b].any() or not pushed(pose, self.push_travel, self.lift):
            return c, n_in
        partner = bool((self.key[a:b, 1 - k] == i).mean() >= 0.5)
        up = quat_mat(pose[0, 3:7])[2]  # the world's vertical in the object's frame
        moved = push_face(hull, up, c, n_in, push_direction(pose, self.fps), k, partner, self.mu)
        return (c, n_in) if moved is None else moved

    def recruit(self, dist: np.ndarray, reach: float, labels: np.ndarray) -> np.ndarray:
        """Where one hand pushes object ``i`` alone and no face of it can give the push within the cone, the other
        hand joins (:attr:`key` set in place) when it is free over that hold and its surface is within ``reach`` of
        the object on the median frame (``dist`` (T, 2), inf out of reach): a single point contact pushes only within
        its friction cone (sub8_plasticbox_001: the box slid 37 deg off the face's normal and was lost; the free hand
        hovered 6-7 cm from it). Returns ``labels`` (T, 2) with the recruited holds set (so they are not kept off)."""
        labels = labels.copy()
        for k in range(2):
            for a, b, i in label_runs(self.key[:, k].copy()):
                o = 1 - k
                pose, hull = self.poses[i][a:b], self.hulls.get(i)
                if (self.key[a:b, o] >= 0).any() or hull is None or self.opposed[a:b].any():
                    continue
                if not pushed(pose, self.push_travel, self.lift) or not np.median(dist[a:b, o]) < reach:
                    continue
                u, up = push_direction(pose, self.fps), quat_mat(pose[0, 3:7])[2]
                inward = np.array([-f.n for f in hull.side_faces(up)]).reshape(-1, 3)
                alone = len(inward) and np.arccos(np.clip((inward @ u).max(), -1, 1)) <= np.arctan(self.mu)
                if not alone and _corner(inward, u, up) is not None:
                    self.key[a:b, o] = i
                    labels[a:b, o] = True
        return labels
