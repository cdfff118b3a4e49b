"""The force the hands of a grasp (:mod:`physicalize.grasp`) must apply to a held object, and the friction
that lets them.

With the reference object velocity ``v_o`` and acceleration ``a_o`` (central differences of its track)
and ``lambda(t) = clip((z_o(t) - z_o(t_0)) / lift_blend, 0, 1)`` (0 while the object rests where the hold
started, 1 once lifted), the hands must apply (:meth:`ObjectLoad.force`)
``F = m [a_o,xy; lambda a_o,z] + lambda m g e_z + r mu_s m g min(1, |v_xy| / slide_speed) v_xy/|v_xy|``
(its inertia, its weight once lifted, its sliding friction on its support for the share ``r`` of its
weight that still rests there; ``mu_s``: the object-floor friction by MuJoCo's mixing rule); a one-side
lift carries only :attr:`~physicalize.grasp_config.GraspConfig.side_lift` of the weight (the far side still
rests, and drags: ``r = 1 - side_lift lambda``; between squeezing hands ``r = 1 - lambda``). Squeezing hands
and a hand alone take ``F_k = F / n_hands`` each (:func:`hand_force`); two hands pushing from one side too, except
where that leaves a cone: then they share ``F`` by :func:`press_allocation`. Squeezing: the part along the surface,
``F_t,k = F_k - (F_k . n_k) n_k``, must come from friction, so
``N_k = clip(max(N_min, safety |F_t,k| / mu), 0, N_max)`` and ``f_k = N_k n_k + F_k`` (:func:`normal_force`).
Pressing from one side there is no squeeze to cancel: ``N_k = max(F_k . n_k, safety |F_t,k| / mu, 0)``,
``f_k = F_k + (N_k - F_k . n_k) n_k`` (exactly ``F_k`` for a push along the normal; :func:`press_force`).
``|f_k|`` is capped at :attr:`~physicalize.grasp_config.GraspConfig.max_hand_force`; ``ok`` records whether
the plan is within friction: squeezing, ``mu N_k >= |F_t,k|`` under the caps; pressing from one side, the
force needed itself in the cone, ``mu F_k . n_k >= |F_t,k|`` (a hand that only presses cannot pull: the
InterMimic table, dragged towards the body).

``mu`` and ``condim`` of a hand-object contact follow MuJoCo's mixing rule (:func:`contact_friction`): the
geom with the higher ``priority`` decides, else the larger friction and condim; ``condim 1`` (frictionless)
cannot hold anything and raises (:func:`hand_friction`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.optimize import nnls

from physicalize.grasp_config import GraspConfig
from pipeline.rotations import quat_mat

GRAVITY = 9.81
# N: a planned force this far outside a friction cone still counts as inside (resting objects: numerical noise)
FRICTION_TOL_N = 0.5
# m: press_allocation weighs a moment error of this many N m as 1 N of force error (about half a box's width)
MOMENT_ARM_M = 0.2
PRESS_EPS = 1e-4  # press_allocation's pull towards the least force (per unit edge weight squared)
DIRECTIONS = 8  # tangent directions of a friction cone's edges


def contact_friction(model: mujoco.MjModel, g1: int, g2: int) -> tuple[int, float]:
    """``(condim, mu)`` MuJoCo uses for a contact between geoms ``g1`` and ``g2``: those of the geom
    with the higher ``priority``; at equal priority the larger condim and the larger sliding friction."""
    p1, p2 = model.geom_priority[g1], model.geom_priority[g2]
    if p1 != p2:
        g = g1 if p1 > p2 else g2
        return int(model.geom_condim[g]), float(model.geom_friction[g, 0])
    return int(max(model.geom_condim[g1], model.geom_condim[g2])), float(
        max(model.geom_friction[g1, 0], model.geom_friction[g2, 0])
    )


def hand_friction(model: mujoco.MjModel, hand_geoms: list[list[int]], object_geoms: list[int], name: str) -> float:
    """The least sliding friction of any hand geom (both hands) on any of the object's geoms; raises
    ``ValueError`` for a frictionless pair (condim < 3 or no friction), which cannot hold."""
    mu = np.inf
    for geoms in hand_geoms:
        for hg in geoms:
            for og in object_geoms:
                condim, f = contact_friction(model, hg, og)
                if condim < 3 or f <= 0:
                    raise ValueError(
                        f"hand geom {model.geom(hg).name!r} on {name!r}: condim {condim}, friction {f}: a frictionless "
                        "contact cannot hold"
                    )
                mu = min(mu, f)
    return mu


def floor_friction(model: mujoco.MjModel, geoms: list[int]) -> float:
    """Sliding friction of the object's geoms on the floor: their explicit contact pairs' with the floor
    (:func:`pipeline.scene.add_floor_pairs`), else MuJoCo's mixing rule."""
    floor = model.geom("floor").id
    pairs = {
        int(b if a == floor else a): float(model.pair_friction[p, 0])
        for p, (a, b) in enumerate(zip(model.pair_geom1, model.pair_geom2))
        if floor in (a, b)
    }
    return max(pairs.get(g, contact_friction(model, g, floor)[1]) for g in geoms) if geoms else 0.0


def normal_force(load: np.ndarray, n: np.ndarray, mu: float, cfg: GraspConfig) -> tuple[float, bool]:
    """``(N, ok)``: squeeze force for a hand carrying ``load`` (3,) through a contact of inward
    normal ``n`` and friction ``mu``; ``ok``: ``mu N >= |load_t|``."""
    tangential = float(np.linalg.norm(load - (load @ n) * n))
    N = float(np.clip(max(cfg.min_normal_force, cfg.safety * tangential / mu), 0.0, cfg.max_normal_force))
    return N, mu * N >= tangential - 1e-9


def press_force(load: np.ndarray, n: np.ndarray, mu: float, cfg: GraspConfig) -> tuple[np.ndarray, bool]:
    """``(f, ok)``: the force a hand pressing on an object from one side (inward normal ``n``, friction ``mu``)
    applies for its share ``load`` (3,) of the needed force: ``load`` plus the normal force that makes its
    tangential part at most ``mu / safety`` of the normal one, ``f = load + (N - load.n) n`` with
    ``N = max(load.n, safety |load_t| / mu, 0)``; ``ok``: ``load`` itself lies in the friction cone,
    ``mu load.n >= |load_t|`` (within :data:`FRICTION_TOL_N`): a hand that only presses cannot pull."""
    push = float(load @ n)
    tangential = float(np.linalg.norm(load - push * n))
    N = min(max(push, cfg.safety * tangential / mu, 0.0), cfg.max_hand_force)
    return load + (N - push) * n, mu * push >= tangential - FRICTION_TOL_N


def hand_force(
    share: np.ndarray, n: np.ndarray, mu: float, squeezed: bool, cfg: GraspConfig
) -> tuple[np.ndarray, bool]:
    """``(f_k, ok)``: the force of a hand carrying ``share`` (3,) through inward normal ``n``, squeezing
    (:func:`normal_force`) or pressing from one side (:func:`press_force`), capped at ``max_hand_force``
    (``ok`` False when capped)."""
    if squeezed:
        N, ok = normal_force(share, n, mu, cfg)
        f_k = N * n + share
    else:  # pushing from one side: no squeeze to cancel
        f_k, ok = press_force(share, n, mu, cfg)
    nf = np.linalg.norm(f_k)
    if nf > cfg.max_hand_force:
        f_k *= cfg.max_hand_force / nf
        ok = False
    return f_k, ok


@dataclass(frozen=True)
class ObjectLoad:
    """A held object's mass, floor friction and reference track's motion over a hold starting at frame
    ``start``: velocity ``v`` and acceleration ``a`` (T, 3), lifted share ``lam`` (T,) of its weight."""

    mass: float
    floor_mu: float
    v: np.ndarray
    a: np.ndarray
    lam: np.ndarray

    @classmethod
    def of(
        cls,
        model: mujoco.MjModel,
        body: int,
        geoms: list[int],
        pos: np.ndarray,
        start: int,
        fps: float,
        cfg: GraspConfig,
    ) -> ObjectLoad:
        """The load of object ``body`` (collision ``geoms``) along its reference positions ``pos`` (T, 3)."""
        T, dt = len(pos), 1.0 / fps
        v = np.gradient(pos, dt, axis=0) if T > 1 else np.zeros_like(pos)
        a = np.gradient(v, dt, axis=0) if T > 2 else np.zeros_like(pos)
        lam = np.clip((pos[:, 2] - pos[start, 2]) / cfg.lift_blend, 0.0, 1.0)
        return cls(float(model.body_subtreemass[body]), floor_friction(model, geoms), v, a, lam)

    def slides(self, t: int, cfg: GraspConfig) -> bool:
        """At frame ``t`` the object is pushed along its support: not lifted, moving over ``slide_speed`` / 2."""
        return bool(self.lam[t] < 1.0 and np.linalg.norm(self.v[t, :2]) > 0.5 * cfg.slide_speed)

    def support(self, t: int, cfg: GraspConfig) -> np.ndarray:
        """(m, 3) the directions of the force the support adds when a hand presses the object into it at frame
        ``t``: none once lifted; while it slides (reference speed over ``slide_speed`` / 2), ``e_z - mu_s v/|v|``
        (kinetic friction against the motion: the support cannot help push); slower, ``e_z`` alone (the support
        takes a push down; its friction holds a resting object but never starts one moving)."""
        if self.lam[t] >= 1.0:
            return np.zeros((0, 3))
        if self.slides(t, cfg):
            v = self.v[t, :2] / np.linalg.norm(self.v[t, :2])
            return np.r_[-self.floor_mu * v, 1.0][None]
        return np.array([[0.0, 0.0, 1.0]])

    def force(self, t: int, squeezed: bool, cfg: GraspConfig) -> np.ndarray:
        """``F`` (3,) the hands must apply at frame ``t`` (module docstring), between squeezing hands or from
        one side."""
        mass, v, a, lam = self.mass, self.v[t], self.a[t], self.lam[t]
        speed = float(np.linalg.norm(v[:2]))
        drag = np.zeros(3)
        if speed > 1e-6:  # sliding on its support: kinetic friction against the motion
            drag[:2] = self.floor_mu * mass * GRAVITY * min(1.0, speed / cfg.slide_speed) * v[:2] / speed
        rest = 1 - lam if squeezed else 1 - cfg.side_lift * lam  # share of its weight still on its support
        F = mass * np.r_[a[:2], lam * a[2]] + lam * mass * GRAVITY * np.array([0, 0, 1.0]) + rest * drag
        if not squeezed:  # lifted from one side only: the far side still rests on its support
            F[2] -= (1 - cfg.side_lift) * lam * mass * (GRAVITY + a[2])
        return F


def cone_edges(n: np.ndarray, mu: float, k: int = DIRECTIONS) -> np.ndarray:
    """(k, 3) edges of the friction cone about the unit normal ``n`` (inscribed polygon): ``n + mu t_i``."""
    a = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(n, t1)
    ang = 2 * np.pi * np.arange(k) / k
    return n[None] + mu * (np.cos(ang)[:, None] * t1[None] + np.sin(ang)[:, None] * t2[None])


def press_allocation(
    F: np.ndarray,
    tau_z: float,
    arms: np.ndarray,
    normals: np.ndarray,
    mu: float,
    cfg: GraspConfig,
    support: np.ndarray | None = None,
) -> tuple[np.ndarray, bool]:
    """``(f (K, 3), ok)``: the forces of ``K`` hands pressing on one object from one side (inward ``normals``
    (K, 3), friction ``mu``, points at ``arms`` (K, 3) from its centre of mass) that, with what its support adds,
    sum to ``F`` and turn it about the vertical by ``tau_z``. Each ``f_k`` is a non-negative combination
    ``E_k w_k`` of its cone's edges (:func:`cone_edges`, friction ``mu / safety``), so no hand pulls or rubs past
    its cone; the support adds any non-negative combination of its ``support`` edges (m, 3) (:meth:`ObjectLoad.support`:
    a hand may press a resting object down, the floor takes it and its friction grows), acting under the centre of
    mass (no moment about the vertical): ``min ||[E S] w - F||^2 + (M w - tau_z)^2 / l^2 + eps ||w||^2, w >= 0``
    (non-negative least squares; ``M``: each hand edge's moment ``(r_k x e)_z``; ``l`` = :data:`MOMENT_ARM_M`: a
    moment error of ``l`` N m weighs as 1 N). An equal split (``F / K`` each) turns the object whenever the hands
    are not placed symmetrically about its centre of mass, and leaves a hand's cone wherever the hands face
    different ways (sub8_largebox_001, one hand on the lid, one on a side: 98% of its held frames against 0% for
    the hands and floor together). Where the reduced cones cannot give ``F`` the full ones (``mu``) are tried;
    ``ok``: ``F`` is met within :data:`FRICTION_TOL_N` + 5% of ``|F|``; each ``|f_k|`` is capped at
    ``max_hand_force``."""
    K, scale, tol = len(normals), 1.0 / MOMENT_ARM_M, FRICTION_TOL_N + 0.05 * float(np.linalg.norm(F))
    S = np.zeros((0, 3)) if support is None else np.asarray(support, float).reshape(-1, 3)
    for cone in (mu / cfg.safety, mu):
        E = [cone_edges(n, cone) for n in normals]  # K x (DIRECTIONS, 3)
        V = np.concatenate(E + [S]).T  # (3, DIRECTIONS K + m)
        M = np.r_[np.concatenate([np.cross(arms[k], E[k])[:, 2] for k in range(K)]), np.zeros(len(S))]
        A = np.vstack([V, scale * M, np.sqrt(PRESS_EPS) * np.eye(V.shape[1])])
        w, _ = nnls(A, np.r_[F, scale * tau_z, np.zeros(V.shape[1])])
        ok = float(np.linalg.norm(V @ w - F)) <= tol
        if ok:
            break
    f = np.stack([w[DIRECTIONS * k : DIRECTIONS * (k + 1)] @ E[k] for k in range(K)])
    norms = np.linalg.norm(f, axis=1)
    over = norms > cfg.max_hand_force
    f[over] *= (cfg.max_hand_force / norms[over])[:, None]
    return f, ok and not over.any()


def inertia_zz(m: mujoco.MjModel, body: int, rot: np.ndarray) -> np.ndarray:
    """(T,) the object's moment of inertia about the vertical through its centre of mass, at orientations ``rot``
    (T, 3, 3): ``e_z^T R R_i diag(I) R_i^T R^T e_z``."""
    Ri = quat_mat(m.body_iquat[body])
    z = rot[:, 2, :] @ Ri  # (T, 3): e_z in the principal frame
    return (z**2) @ m.body_inertia[body]
