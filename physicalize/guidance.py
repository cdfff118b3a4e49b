"""Object guidance: a virtual wrench that holds each free object on its reference track, for measuring what a
rollout would do if the object went where the reference says (:class:`ObjectGuidance`). Never data: the wrench is
an external force, which the validity bar ``external_force_max_n`` (0 N) fails, so a guided clip is never valid.

Each physics step the object's centre of mass gets ``f = s m (k_p (p_ref - p) + k_d (v_ref - v))`` and its body
``tau = s I_w (k_p log(R_ref R^T) + k_d (w_ref - w))`` (``I_w``: its inertia in the world frame, ``s``: the
guidance's ``scale``), with the reference interpolated between control frames at the physics step's time. ResMimic
(a virtual object force curriculum in GPU RL) and SPIDER (virtual contact constraints annealed to zero) anneal such
a force to zero; here it measures (issue #54, ``make bench-physicalize-real BENCH_ARGS="--guide 1"``): on the six
shared box slides at scale 1 every rollout kept stands to the end with its box on its track, at 3-5 N on average
(BENCHMARKS.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from pipeline.rotations import orientation_error, quat_mat


@dataclass(frozen=True)
class GuidedBody:
    """One free object's reference track at control rate: positions ``pos`` (T, 3), rotations ``rot`` (T, 3, 3),
    linear and angular velocities ``vel``, ``omega`` (T, 3, world), and where it sits in the model."""

    body: int
    qpos_adr: int
    dof_adr: int
    pos: np.ndarray
    rot: np.ndarray
    vel: np.ndarray
    omega: np.ndarray


@dataclass
class ObjectGuidance:
    """``perturb(t, data)`` for :class:`physicalize.rollout.Tracker`: the module docstring's wrench on every
    object of ``bodies``; ``peak_n``: the largest force it applied since it was built."""

    model: mujoco.MjModel
    bodies: list[GuidedBody]
    fps: float
    scale: float
    kp: float = 100.0
    kd: float = 20.0
    peak_n: float = 0.0

    @classmethod
    def of(cls, scene, objects: dict[str, np.ndarray], fps: float, scale: float) -> ObjectGuidance:
        """The guidance of ``scene``'s free objects along their tracks ``objects`` ({name: (T, 7) pos + wxyz})."""
        if not scale > 0:
            raise ValueError(f"object guidance scale must be > 0, got {scale}")
        m, bodies = scene.model, []
        for name, track in objects.items():
            if name not in scene.object_qpos_adr:
                continue  # a fixed object: nothing to hold
            track = np.asarray(track, float)
            rot = np.stack([quat_mat(q / np.linalg.norm(q)) for q in track[:, 3:7]])
            vel = np.gradient(track[:, :3], 1.0 / fps, axis=0) if len(track) > 1 else np.zeros((1, 3))
            omega = np.zeros_like(vel)
            for k in range(len(track) - 1):  # world angular velocity from frame k to k + 1
                omega[k] = orientation_error(rot[k + 1], rot[k]) * fps
            omega[-1] = omega[-2] if len(track) > 1 else 0.0
            joint = m.joint(f"{name}_free").id
            body, adr, dof = scene.object_body_id[name], scene.object_qpos_adr[name], int(m.jnt_dofadr[joint])
            bodies.append(GuidedBody(body, adr, dof, track[:, :3], rot, vel, omega))
        return cls(m, bodies, fps, scale)

    def __call__(self, t: int, d: mujoco.MjData) -> None:
        s = d.time * self.fps  # the reference's frame at this physics step
        for g in self.bodies:
            k0 = int(np.clip(np.floor(s), 0, len(g.pos) - 1))
            k1, a = min(k0 + 1, len(g.pos) - 1), float(np.clip(s - k0, 0.0, 1.0))
            p_ref, v_ref = (1 - a) * g.pos[k0] + a * g.pos[k1], (1 - a) * g.vel[k0] + a * g.vel[k1]
            w_ref = (1 - a) * g.omega[k0] + a * g.omega[k1]
            R = d.xmat[g.body].reshape(3, 3)
            R_ref = g.rot[k1] if a >= 0.5 else g.rot[k0]
            mass = float(self.model.body_mass[g.body])
            Ri = d.ximat[g.body].reshape(3, 3)
            inertia = Ri @ np.diag(self.model.body_inertia[g.body]) @ Ri.T
            v, w = d.qvel[g.dof_adr : g.dof_adr + 3], R @ d.qvel[g.dof_adr + 3 : g.dof_adr + 6]
            f = self.scale * mass * (self.kp * (p_ref - d.qpos[g.qpos_adr : g.qpos_adr + 3]) + self.kd * (v_ref - v))
            tau = self.scale * inertia @ (self.kp * orientation_error(R_ref, R) + self.kd * (w_ref - w))
            d.xfrc_applied[g.body] = np.r_[f, tau]
            self.peak_n = max(self.peak_n, float(np.linalg.norm(f)))
