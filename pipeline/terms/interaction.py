"""The paper's per-link interaction feature u_t (Sec. III-A) and the released demo's layout.

For a link at ``x`` with linear velocity ``v`` and the distance field of the nearest object,

    phi = phi(x),   g = grad phi(x),
    v_norm = (v . g) g,   v_tan = v - v_norm,   u = [phi, g, v_norm, v_tan]   (10 per link),

all in the world frame as the paper writes it (:func:`interaction_features`). The *relative*
variant uses ``v - v_c`` instead of ``v``, with ``v_c`` the velocity of the object's closest
surface point (:func:`surface_point_velocity`), which is what matters when the object moves with
the hands (Carry). The interaction window ``I_t = {u_(t-l+1) .. u_t}`` is served by the loaders
(LeRobot ``delta_timestamps``, :class:`pipeline.dataset.windows.WindowDataset`); datasets store u_t.

The demo layout (:func:`demo_features`, the LessMimic web demo's input contract): per query body,
``min(|phi|, max_distance)`` and the unsigned field's gradient in the body's own frame, zero beyond
``max_distance`` (4 per body).

Everything takes numpy arrays or torch tensors alike (RL environments compute the same online).
"""

from __future__ import annotations

from pipeline.rotations import rotation_rows
from pipeline.terms.layout import DEMO_MAX_DISTANCE_M
from pipeline.xp import concat, namespace


def interaction_features(phi, grad, vel):
    """``u = [phi, g, v_norm, v_tan]`` (..., 10) from ``phi (...)``, unit ``grad (..., 3)``, ``vel (..., 3)``."""
    xp = namespace(phi)
    v_norm = (vel * grad).sum(-1)[..., None] * grad
    return concat([phi[..., None], grad, v_norm, vel - v_norm], xp, axis=-1)


def surface_point_velocity(closest, object_index, poses, object_vel):
    """Velocity of the nearest object's surface point ``c``: ``v_o + (R_o w_o) x (c - p_o)``.

    ``closest (T, K, 3)`` world points, ``object_index (T, K)`` into the ``M`` objects, ``poses (T, M, 7)``
    (x, y, z, qw, qx, qy, qz), ``object_vel (T, M, 6)`` in MuJoCo's free-joint convention: linear velocity
    of the origin (world), angular velocity (object frame)."""
    xp = namespace(closest)
    rows = xp.arange(closest.shape[0])[:, None] + 0 * object_index
    pose, vel = poses[rows, object_index], object_vel[rows, object_index]  # (T, K, 7), (T, K, 6)
    R, wb = rotation_rows(pose[..., 3:], xp), vel[..., 3:]
    ww = xp.stack(
        [R[i][0] * wb[..., 0] + R[i][1] * wb[..., 1] + R[i][2] * wb[..., 2] for i in range(3)], -1
    )  # R w_body
    r = closest - pose[..., :3]
    cross = xp.stack(
        [
            ww[..., 1] * r[..., 2] - ww[..., 2] * r[..., 1],
            ww[..., 2] * r[..., 0] - ww[..., 0] * r[..., 2],
            ww[..., 0] * r[..., 1] - ww[..., 1] * r[..., 0],
        ],
        -1,
    )
    return vel[..., :3] + cross


def demo_features(phi, grad, link_rot, max_distance: float = DEMO_MAX_DISTANCE_M):
    """The demo's per-body ``[d, R^T g_u]`` (..., 4), as its viewer computes them from an unsigned distance grid:
    ``d = min(|phi|, max_distance)``, ``g_u = sign(phi) g`` (the unsigned field's gradient: away from the surface
    on both sides), zero where ``|phi| >= max_distance`` (the viewer's value beyond its grid's 1 m padding is
    ``(1, 0, 0, 0)``); ``link_rot (..., 3, 3)`` body-to-world."""
    xp = namespace(phi)
    far = xp.abs(phi) >= max_distance
    g = xp.where(far[..., None], 0.0 * grad, xp.where((phi < 0)[..., None], -grad, grad))
    local = xp.einsum("...ji,...j->...i", link_rot, g)
    return concat([xp.clip(xp.abs(phi), None, max_distance)[..., None], local], xp, axis=-1)
