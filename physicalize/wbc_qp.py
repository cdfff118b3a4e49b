"""The whole-body QP's assembly (called by :meth:`physicalize.wbc.WholeBodyController.solve`) over
``x = (qdd, f)``: ``qdd`` the robot's 35 generalized accelerations, ``f`` the 3-D contact forces
(``nf`` values: the stance feet's sole corners, then the seat's support points):

* the cost ``1/2 x^T P x + q^T x``, summed task by task (:class:`Costs`);
* the equality rows ``A x = b``: the floating base's Newton-Euler rows and the stance feet's
  acceleration rows (:func:`equality_rows`);
* the hard inequality rows ``G x <= h``: the friction pyramids (:func:`friction_rows`), the seated
  feet's least load (:func:`seated_load_rows`), the torque bounds (:func:`torque_map`);
* the soft rows ``G_s qdd - s <= h_s``, ``s >= 0`` with the slack's cost (:func:`with_slack`)."""

from __future__ import annotations

import numpy as np

from pipeline.robot import JOINTS_QVEL

UP_FRAME = np.array([[0, 0, 1.0], [1, 0, 0], [0, 1, 0]])  # a sole corner's contact frame: the floor's normal, tangents


class Costs:
    """The QP's cost over ``x = (qdd (nv), f (nf))``, accumulated in place (the order of the sums is the
    order of the calls)."""

    def __init__(self, nv: int, nf: int):
        self.nv, self.nf, self.n = nv, nf, nv + nf
        self.P = np.zeros((self.n, self.n))
        self.q = np.zeros(self.n)

    def task(self, J: np.ndarray, b: np.ndarray, w) -> None:
        """Add ``||J qdd - b||^2_W`` (``w``: one weight or one per row): ``P += J^T W J``, ``q -= J^T W b``."""
        nv, P, q = self.nv, self.P, self.q
        w = np.broadcast_to(np.asarray(w, dtype=float), b.shape)[:, None]
        P[:nv, :nv] += J.T @ (w * J)
        q[:nv] -= J.T @ (w[:, 0] * b)

    def rows(self, A: np.ndarray, b: np.ndarray, w) -> None:
        """Add ``||A x - b||^2_W`` over the whole ``x`` (``A`` (k, n)): the tasks of the held object's loop."""
        w = np.broadcast_to(np.asarray(w, dtype=float), b.shape)[:, None]
        self.P += A.T @ (w * A)
        self.q -= A.T @ (w[:, 0] * b)

    def regularize(self, w_qdd: float, w_force: float) -> None:
        """Add ``w_qdd ||qdd||^2 + w_force ||f||^2``."""
        nv = self.nv
        self.P[:nv, :nv] += w_qdd * np.eye(nv)
        self.P[nv:, nv:] += w_force * np.eye(self.nf)


def equality_rows(
    M: np.ndarray,
    h: np.ndarray,
    tau_ext: np.ndarray,
    Jc: np.ndarray,
    feet: list[tuple[np.ndarray, np.ndarray]],
    nf: int,
) -> tuple[np.ndarray, np.ndarray]:
    """``(A, b)``: the floating base ``M_u qdd - J_{c,u}^T f = -h_u + tau_ext,u`` (6 rows) and each stance
    foot's ``J_foot qdd = a_foot* - Jdot_foot qd`` (``feet``: its ``(J (6, nv), a* - Jdot qd)``)."""
    A = [np.hstack([J, np.zeros((6, nf))]) for J, _ in feet]
    b = [a for _, a in feet]
    return np.vstack([np.hstack([M[:6], -Jc[:, :6].T])] + A), np.concatenate([-h[:6] + tau_ext[:6]] + b)


def friction_rows(frames: list[np.ndarray], mu: float, col0: int, n: int) -> tuple[list, list]:
    """``([G], [h])`` (empty without contact points): per contact point ``j`` with frame rows ``(n, t1, t2)``
    (the normal into the body the force acts on first: the robot for its soles and seat, the held object for the
    hands, :mod:`physicalize.object_loop`) and its force in columns ``col0 + 3 j``, ``|f_j.t_i| <= mu/sqrt 2 f_j.n``
    (the pyramid inscribed in the cone: ``|f_t| <= mu f_n`` in every direction) and ``f_j.n >= 0``, as 5 rows
    ``G x <= 0``."""
    if not frames:
        return [], []
    mu = mu / np.sqrt(2.0)
    G = np.zeros((5 * len(frames), n))
    for j, (fn, t1, t2) in enumerate(frames):
        G[5 * j : 5 * j + 5, col0 + 3 * j : col0 + 3 * j + 3] = [
            t1 - mu * fn,
            -t1 - mu * fn,
            t2 - mu * fn,
            -t2 - mu * fn,
            -fn,
        ]
    return [G], [np.zeros(5 * len(frames))]


def seated_load_rows(n_stance: int, nv: int, n: int, least: float) -> tuple[np.ndarray, np.ndarray]:
    """``(G, h)``: each stance foot's four corner forces push up at least ``least`` [N] together,
    ``-sum_i f_i,z <= -least`` (seated, else the robot tipped back, feet in the air)."""
    G = np.zeros((n_stance, n))
    for s in range(n_stance):
        G[s, nv + 12 * s + 2 : nv + 12 * s + 12 : 3] = -1.0
    return G, np.full(n_stance, -least)


def torque_map(M: np.ndarray, h: np.ndarray, tau_ext: np.ndarray, Jc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(T, t)`` with the joint torques ``tau = T x + t``: ``T = [M_a, -J_{c,a}^T]``, ``t = h_a - tau_ext,a``."""
    return np.hstack([M[JOINTS_QVEL], -Jc[:, JOINTS_QVEL].T]), h[JOINTS_QVEL] - tau_ext[JOINTS_QVEL]


def with_slack(
    costs: Costs,
    G: np.ndarray,
    h: np.ndarray,
    A: np.ndarray,
    Gs: np.ndarray,
    hs: np.ndarray,
    weight: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(P, q, G, h, A)`` over ``(x, s)``: the soft rows ``Gs qdd - s <= hs`` with a slack ``s >= 0`` of
    cost ``weight ||s||^2`` appended (the QP stays feasible where a soft row cannot hold); unchanged
    without soft rows."""
    P, q, n, nv, ns = costs.P, costs.q, costs.n, costs.nv, len(hs)
    if not ns:
        return P, q, G, h, A
    Gl = np.zeros((2 * ns, n + ns))
    Gl[:ns, :nv] = Gs
    Gl[:ns, n:] = -np.eye(ns)
    Gl[ns:, n:] = -np.eye(ns)
    G = np.vstack([np.hstack([G, np.zeros((G.shape[0], ns))]), Gl])
    h = np.concatenate([h, hs, np.zeros(ns)])
    P = np.block([[P, np.zeros((n, ns))], [np.zeros((ns, n)), weight * np.eye(ns)]])
    q = np.concatenate([q, np.zeros(ns)])
    A = np.hstack([A, np.zeros((A.shape[0], ns))])
    return P, q, G, h, A
