"""Interaction preservation: robot links brought to the object surface where the human touches it.

The human's per-joint object contacts (a joint within ~2 cm of the object surface) are mapped to
robot links (:func:`link_contact_flags`); while a link is flagged, :class:`ContactTask` drives
its distance to the objects (the distance field ``phi`` of the paper, measured between the
link's collision geoms and the objects' collision geoms, the same geoms the physics stage
simulates) to a small gap ``d*``, moving it along the surface direction ``grad phi`` only. The
mapped pose still decides *where* on the object the link goes; the task only closes the gap the
human-to-robot scaling opened (hands above a table, a pelvis above a seat).
"""

from __future__ import annotations

import mink
import mujoco
import numpy as np
from mink.limits.collision_avoidance_limit import compute_contact_normal_jacobian

from pipeline.clip import HumanClip
from pipeline.foot_contact import runs
from pipeline.scene import link_collision_geoms, nearest_geom_pair


def link_contact_flags(clip: HumanClip, link_map: dict[str, str]) -> tuple[tuple[str, ...], np.ndarray]:
    """``(links, flags)``: the robot links of ``link_map`` (human joint -> G1 body, first-seen order)
    and ``(T, L)`` flags, a link flagged when any human joint mapped to it touches an object."""
    links = tuple(dict.fromkeys(link_map.values()))
    flags = np.zeros((clip.frames, len(links)), bool)
    if clip.contacts is not None:
        for joint, body in link_map.items():
            flags[:, links.index(body)] |= clip.contacts[:, clip.skeleton.index(joint)]
    return links, flags


def contact_ramp(flags: np.ndarray, frames: int) -> np.ndarray:
    """``(T, L)`` weights in [0, 1]: 1 on flagged frames, falling linearly to 0 over ``frames``
    frames before each contact starts and after it ends, ``max(0, 1 - n / (frames + 1))`` with
    ``n`` the distance in frames to the nearest flagged frame (so the task fades in and out
    instead of switching, and the link does not jump at the contact's first frame)."""
    from scipy.ndimage import distance_transform_edt

    w = np.zeros(flags.shape)
    for k in range(flags.shape[1]):
        if flags[:, k].any():
            n = distance_transform_edt(~flags[:, k])
            w[:, k] = np.clip(1.0 - n / (frames + 1), 0.0, 1.0)
    return w


class ContactTask(mink.Task):
    r"""Drive the distance between robot links and the objects to ``gap`` (one row per link).

    For link ``l`` with collision geoms ``G_l`` and the object collision geoms ``O``, let
    ``(g, o) = argmin d(g, o)`` over ``G_l x O`` (``mj_geomDistance``, signed: < 0 when they
    penetrate), ``p_g, p_o`` its nearest points and ``n`` the unit normal from ``p_g`` to
    ``p_o`` (reversed when penetrating, so it always points out of the object towards the link's
    outside). Then

    ``e_l = phi_l - gap``,   ``J_l = d phi_l / dq = n^T (J_o(p_o) - J_g(p_g))``

    (``J_o = 0`` for a mocap object). Links farther than ``reach`` from every object, and links
    with weight 0, contribute a zero row. Per-frame weights ``w_l`` in [0, 1] scale the cost:
    ``cost_l = cost w_l``. ``phi_l - gap`` is clipped to ``[-reach, reach]``.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        links: tuple[str, ...],
        object_geoms: list[int],
        *,
        cost: float = 5.0,
        gap: float = 0.01,
        reach: float = 0.3,
        lm_damping: float = 0.0,
    ):
        if cost < 0 or reach <= gap or gap < 0:
            raise ValueError(
                f"ContactTask: need cost >= 0 and 0 <= gap < reach, got cost {cost}, gap {gap}, reach {reach}"
            )
        super().__init__(cost=np.zeros(len(links)), gain=1.0, lm_damping=lm_damping)
        self.model, self.links, self.gap, self.reach, self.base_cost = model, tuple(links), gap, reach, cost
        self.link_geoms = [link_collision_geoms(model, b) for b in links]
        self.object_geoms = list(object_geoms)
        self.weights = np.zeros(len(links))
        self._fromto = np.empty(6)
        self._normal = np.empty(3)
        self._jac1, self._jac2 = np.empty((3, model.nv)), np.empty((3, model.nv))
        self._cache: tuple[np.ndarray, tuple[np.ndarray, np.ndarray]] | None = None

    def set_weights(self, weights: np.ndarray) -> None:
        """Per-link weights in [0, 1] for the coming frame."""
        self.weights = np.clip(np.asarray(weights, dtype=float), 0.0, 1.0)
        self.cost = self.base_cost * self.weights
        self._cache = None

    def distances(self, configuration: mink.Configuration) -> np.ndarray:
        """``(L,)`` link-object distances ``phi_l`` (``reach`` when farther)."""
        return self._evaluate(configuration)[0]

    def _evaluate(self, configuration: mink.Configuration) -> tuple[np.ndarray, np.ndarray]:
        if self._cache is not None and np.array_equal(self._cache[0], configuration.q):
            return self._cache[1]  # error and Jacobian at the same q: one distance pass
        m, d = self.model, configuration.data
        phi, J = np.full(len(self.links), self.reach), np.zeros((len(self.links), m.nv))
        for k, geoms in enumerate(self.link_geoms):
            if self.weights[k] <= 0.0:
                continue
            best, g, o = nearest_geom_pair(m, d, geoms, self.object_geoms, self.reach, self._fromto)
            if g < 0:
                continue
            row = compute_contact_normal_jacobian(m, d, g, o, self._fromto, self._normal, self._jac1, self._jac2)
            phi[k], J[k] = best, (row if best >= 0 else -row)
        self._cache = (configuration.q.copy(), (phi, J))
        return phi, J

    def compute_error(self, configuration: mink.Configuration) -> np.ndarray:
        phi = self._evaluate(configuration)[0]
        active = (self.weights > 0) & (phi < self.reach)
        return np.where(active, np.clip(phi - self.gap, -self.reach, self.reach), 0.0)

    def compute_jacobian(self, configuration: mink.Configuration) -> np.ndarray:
        return self._evaluate(configuration)[1]


class FootClearance:
    r"""Moving objects give way to planted feet.

    A pinned foot cannot step aside (it is pinned), and a mocap object is not optimised, so an
    object set down onto a planted robot foot (the robot's feet are longer, relative to its
    scaled body, than the human's) would leave an unresolvable penetration: the collision limit
    could only push the foot into the floor. Instead, each object carries a held horizontal offset
    ``o``; at every frame, for every planted foot within ``margin`` of the object
    (``phi = min d(g, o)`` over the foot's and the object's collision geoms),

    ``o <- o + min(margin - phi, step) u``,   ``u`` = horizontal unit vector from the foot
    origin to the object's nearest point,

    so the object is moved away at most ``step`` per frame (no jumps) and keeps the offset
    afterwards (a resting object does not slide back). Objects far from both feet (bounding
    spheres apart by more than ``margin``) cost one distance check. An object at rest in the input
    must not slide in the output either: :func:`hold_resting` gives each run of resting frames the
    offset it ends with (the Carry box, standing untouched, slid 5 cm away from the approaching
    foot; in physics it stood at its first pose and was kicked 16 cm).
    """

    def __init__(
        self, model: mujoco.MjModel, feet: tuple[str, ...], objects: tuple[str, ...], *, margin: float, step: float
    ):
        if margin <= 0 or step <= 0:
            raise ValueError(f"FootClearance: margin and step must be > 0, got {margin}, {step}")
        self.model, self.margin, self.step = model, margin, step
        self.feet = [self._rigid(f) for f in feet]
        self.objects = {name: self._rigid(name) for name in objects}
        self.offset = {name: np.zeros(3) for name in objects}
        self._fromto = np.empty(6)

    def _rigid(self, body: str) -> tuple[int, list[int], float]:
        """``(body id, collision geoms, bounding radius about the body origin)`` of a body with geoms of its own."""
        bid, geoms = self.model.body(body).id, link_collision_geoms(self.model, body)
        if any(self.model.geom_bodyid[g] != bid for g in geoms):
            raise ValueError(f"FootClearance: {body!r} needs collision geoms of its own")
        return bid, geoms, max(float(np.linalg.norm(self.model.geom_pos[g]) + self.model.geom_rbound[g]) for g in geoms)

    def update(self, data: mujoco.MjData, planted: np.ndarray) -> bool:
        """Grow the offsets for this frame's planted feet (``data``: kinematics at the frame's
        warm start, mocap already offset). True when an offset changed (re-apply and re-run
        the kinematics)."""
        m, changed = self.model, False
        for s, (foot, foot_geoms, r_foot) in enumerate(self.feet):
            if not planted[s]:
                continue
            for name, (body, geoms, r_body) in self.objects.items():
                if np.linalg.norm(data.xpos[body] - data.xpos[foot]) > r_foot + r_body + self.margin:
                    continue
                best, g, _ = nearest_geom_pair(m, data, foot_geoms, geoms, self.margin, self._fromto)
                if g < 0:
                    continue
                u = (self._fromto[3:] - data.xpos[foot])[:2]
                if np.linalg.norm(u) < 1e-6:
                    u = (data.xpos[body] - data.xpos[foot])[:2]
                self.offset[name][:2] += min(self.margin - best, self.step) * u / max(np.linalg.norm(u), 1e-9)
                changed = True
        return changed


REST_SPEED = 0.02  # m/s: an input object slower than this is at rest


def hold_resting(pose_in: np.ndarray, pose_out: np.ndarray, fps: float, rest_speed: float = REST_SPEED) -> np.ndarray:
    """``pose_out`` (T, 7) with the clearance offset ``o_t = p_out,t - p_in,t`` held constant over each
    run of frames ``a..b`` where the input object is at rest (``|p_in,t - p_in,t-1| fps < rest_speed``,
    frame ``a`` included): ``o_t = o_b`` there, so a resting object stands where the planted feet
    finally left it from the start of its rest, instead of sliding away from them. Frames where the
    input moves keep their per-frame offsets; orientations are untouched."""
    out = pose_out.copy()
    off = pose_out[:, :3] - pose_in[:, :3]
    speed = np.r_[np.inf, np.linalg.norm(np.diff(pose_in[:, :3], axis=0), axis=1) * fps]
    rest = speed < rest_speed
    rest[0] = rest[1] if len(rest) > 1 else True  # the first frame rests with the second
    for a, b in runs(rest):
        a = max(a - 1, 0)  # the frame it arrives at rest on rests too
        out[a:b, :3] = pose_in[a:b, :3] + off[b - 1]
    return out
