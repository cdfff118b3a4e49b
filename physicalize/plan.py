"""Layer 1 of the teacher: a dynamically feasible centre-of-mass plan for the reference's contact
schedule, by ZMP preview control (Kajita et al., ICRA 2003).

The ZMP reference at each frame is the reference's centre of pressure -- the kinematic CoM's ground
projection, moved by the reactions of the forces the hands apply to held objects (:func:`hand_cop_shift`:
a 50 N push leans the human 15 cm into it) -- clipped into the support polygon of the stance feet (the
convex hull of their sole corners; while the reference sits, with its seat support points, :mod:`physicalize.seat`,
unscaled): in double support the polygon scaled by :data:`DOUBLE_SUPPORT_SCALE`
about its centre (the CoM of a quick squat near the heels fell behind them: PickUp's knees then hit the
box, and it fell) and shrunk by :data:`MARGIN`; in single support the stance foot's
polygon scaled by :data:`SINGLE_SUPPORT_SCALE` about its centre, so the ZMP is pulled onto the
middle of the foot and the tracker keeps room to move the CoP for feedback (clipping to the
foot's edge left none: the robot fell behind its plan in every single support). The cart-table model

    x_{k+1} = A x_k + B u_k,   x = (c, c_dot, c_ddot) per horizontal axis,  u = jerk,
    p_k = C x_k = c - (z_c / g) c_ddot

(plus the hands' shift) is driven by the optimal preview law ``u_k = -G_i sum_j (p_j - p*_j) - G_x x_k - sum_{j=1..N}
G_d[j] p*_{k+j}``
(gains from the discrete Riccati equation of the error-augmented system, ``N`` = 1.6 s of preview),
so the planned CoM's ZMP follows the reference inside the support region. The height ``z_c`` is the
mean kinematic CoM height; the CoM's vertical motion is kept from the reference.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.linalg import solve_discrete_are
from scipy.spatial import ConvexHull

from physicalize.reference import Reference
from pipeline.foot_contact import runs

GRAVITY = 9.81
MARGIN = 0.03
# run3 frames before a fall, 7 clips x 3 windows: 1.0 -> 4877 (with the hands' shift and the leg clearance rows: 0.7 ->
# 5459, 0.5 -> 6093)
DOUBLE_SUPPORT_SCALE = 0.5
SINGLE_SUPPORT_SCALE = 0.3  # single-support ZMP within this fraction of the foot about its centre
PREVIEW_S = 1.6
# the plan leaves the seat this long before the reference's seat support ends (SitStand seeds 0-9: 6 -> 9 valid; 0.4 s:
# the thighs pressed 2-3 cm into the seat)
SEAT_LEAD_S = 0.2


@lru_cache(maxsize=16)
def preview_gains(
    dt: float, zc: float, n: int, qe: float = 1.0, r: float = 1e-6
) -> tuple[float, np.ndarray, np.ndarray]:
    """``(G_i, G_x (3,), G_d (n,))`` of the preview controller for sample time ``dt`` and height ``zc``."""
    A = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([[dt**3 / 6], [dt * dt / 2], [dt]])
    C = np.array([[1.0, 0.0, -zc / GRAVITY]])
    A1 = np.block([[np.eye(1), C @ A], [np.zeros((3, 1)), A]])
    B1 = np.vstack([C @ B, B])
    Q = np.zeros((4, 4))
    Q[0, 0] = qe
    P = solve_discrete_are(A1, B1, Q, np.array([[r]]))
    S = np.linalg.inv(r + B1.T @ P @ B1)
    K = S @ B1.T @ P @ A1
    Ac = A1 - B1 @ K
    I1 = np.array([[1.0], [0.0], [0.0], [0.0]])
    X = -Ac.T @ P @ I1
    gd = np.zeros(n)
    gd[0] = -K[0, 0]
    for j in range(1, n):
        gd[j] = (S @ B1.T @ X).item()
        X = Ac.T @ X
    return float(K[0, 0]), K[0, 1:].copy(), gd


def support_polygon(ref: Reference, t: int, seat: bool = True) -> np.ndarray:
    """(k, 2) vertices (counter-clockwise) of the support polygon at frame ``t``: the stance feet's sole
    corners and, with ``seat``, the reference's seat support points (:func:`physicalize.seat.seat_support`)."""
    pts = [ref.corners[t, k, :, :2] for k in range(2) if ref.stance[t, k]]
    if seat and ref.seat is not None:
        pts.append(ref.seat[t][np.isfinite(ref.seat[t, :, 0]), :2])
    pts = np.concatenate(pts)
    hull = ConvexHull(pts)
    return pts[hull.vertices]


def clip_to_polygon(p: np.ndarray, poly: np.ndarray, margin: float = MARGIN) -> np.ndarray:
    """The point of the polygon shrunk by ``margin`` nearest to ``p`` (``p`` itself when inside)."""
    centre = poly.mean(axis=0)
    shrunk = (
        centre
        + (poly - centre)
        * np.clip(1.0 - margin / np.maximum(np.linalg.norm(poly - centre, axis=1), 1e-9), 0.0, 1.0)[:, None]
    )
    edges = np.roll(shrunk, -1, axis=0) - shrunk
    cross = edges[:, 0] * (p[1] - shrunk[:, 1]) - edges[:, 1] * (p[0] - shrunk[:, 0])
    if np.all(cross >= 0):
        return p.copy()
    best, best_d = centre, np.inf
    for a, e in zip(shrunk, edges):
        s = np.clip(np.dot(p - a, e) / max(np.dot(e, e), 1e-12), 0.0, 1.0)
        q = a + s * e
        dist = np.linalg.norm(p - q)
        if dist < best_d:
            best, best_d = q, dist
    return best


@dataclass(frozen=True)
class HandLoads:
    """Forces the hands apply to held objects, ``force`` (T, 2, 3) at ``point`` (T, 2, 3) (world), and the
    robot's ``mass``: their reactions move the feet's centre of pressure (:func:`hand_cop_shift`)."""

    point: np.ndarray
    force: np.ndarray
    mass: float


def hand_cop_shift(com: np.ndarray, loads: HandLoads) -> np.ndarray:
    """(T, 2) shift ``e`` of the feet's centre of pressure from the CoM projection that the hands' reactions
    ``F_k = -f_k`` at ``h_k`` cause in static balance (moments about the CoP ``p`` on the floor, ``z = 0``)::

        e_x = (sum_k h_k,z F_k,x - (h_k,x - c_x) F_k,z) / (m g - sum_k F_k,z)     (y alike)

    A push of 50 N at 1 m height moves it about 15 cm behind the CoM: the human leans into the push."""
    F = -loads.force
    h = loads.point
    load = loads.mass * GRAVITY - F[..., 2].sum(axis=1)
    e = np.stack(
        [(h[..., 2] * F[..., i] - (h[..., i] - com[:, None, i]) * F[..., 2]).sum(axis=1) for i in range(2)], -1
    )
    return e / load[:, None]


def zmp_reference(
    ref: Reference, single_support_scale: float = SINGLE_SUPPORT_SCALE, shift: np.ndarray | None = None
) -> np.ndarray:
    """(T, 2) ZMP reference: the reference's centre of pressure, the kinematic CoM projection moved by
    the hands' ``shift`` (:func:`hand_cop_shift`), clipped into each frame's support polygon (scaled by
    :data:`DOUBLE_SUPPORT_SCALE`, in single support by ``single_support_scale``, about its centre). The
    last :data:`SEAT_LEAD_S` of each seated run use the feet alone: a human stands up with the CoM
    behind the heels and momentum; the tracked G1 lagged the plan by 3-6 cm, lifted off behind its
    heels and fell back (SitStand, 6 of 10 seeds valid; 9 with the lead)."""
    cop = ref.com[:, :2] if shift is None else ref.com[:, :2] + shift
    out = np.zeros((ref.frames, 2))
    seated = np.zeros(ref.frames, bool) if ref.seat is None else np.isfinite(ref.seat[:, :, 0]).any(axis=1)
    for a, b in runs(seated):  # the plan stands on the feet before the seat lets go
        seated[max(a, b - int(round(SEAT_LEAD_S * ref.fps))) : b] = False
    for t in range(ref.frames):
        poly = support_polygon(ref, t, seat=bool(seated[t]))
        c = poly.mean(axis=0)
        if seated[t]:  # sitting: the hull of the feet and the seat
            out[t] = clip_to_polygon(cop[t], poly)
        elif ref.stance[t].all():
            out[t] = clip_to_polygon(cop[t], c + DOUBLE_SUPPORT_SCALE * (poly - c))
        else:
            out[t] = clip_to_polygon(cop[t], c + single_support_scale * (poly - c), 0.0)
    return out


def plan_com(ref: Reference, loads: HandLoads | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(com_plan (T, 3), zmp_ref (T, 2), zmp_plan (T, 2)): the preview-controlled CoM, starting at
    the reference's first CoM and CoM velocity. With the hands' ``loads`` the centre of pressure is
    the cart-table ZMP plus their shift ``e``: the cart tracks ``zmp_ref - e`` (both returned with ``e``)."""
    dt = 1.0 / ref.fps
    zc = float(np.mean(ref.com[:, 2] - np.min(ref.corners[..., 2], axis=(1, 2))))
    n = int(round(PREVIEW_S / dt))
    gi, gx, gd = preview_gains(dt, zc, n)
    shift = np.zeros((ref.frames, 2)) if loads is None else hand_cop_shift(ref.com, loads)
    cop_ref = zmp_reference(ref, shift=shift)
    pref = cop_ref - shift
    T = ref.frames
    padded = np.concatenate([pref, np.repeat(pref[-1:], n, axis=0)])
    A = np.array([[1.0, dt, dt * dt / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    B = np.array([dt**3 / 6, dt * dt / 2, dt])
    x = np.zeros((3, 2))
    x[0] = ref.com[0, :2]
    if T > 2:
        x[1] = np.median(np.diff(ref.com[:6, :2], axis=0), axis=0) / dt  # as the initial state's velocity
    err = np.zeros(2)
    com, zmp = np.zeros((T, 2)), np.zeros((T, 2))
    for k in range(T):
        p = x[0] - zc / GRAVITY * x[2]
        com[k], zmp[k] = x[0], p
        err += p - pref[k]
        u = -gi * err - gx @ x - gd @ padded[k + 1 : k + 1 + n]
        x = A @ x + np.outer(B, u)
    return np.column_stack([com, ref.com[:, 2]]), cop_ref, zmp + shift
