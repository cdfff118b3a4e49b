"""Export in the released LessMimic web demo's contract (``lessmimic export --format lessmimic-demo``): the three
files its viewer loads (``interaction_policy.json``, ``latent_encoder.onnx``, ``policy.onnx``), for a policy trained
on that contract (``train-bc --contract lessmimic_demo`` under the ``lessmimic_demo`` gains).

What the viewer fixes (its runner and config, read as facts; the repository has no licence, nothing is copied):

* where it fetches the files: the JSON at ``./examples/checkpoints/g1/interaction_policy.json`` from its page, the
  ONNX paths the JSON names also from its page (:mod:`train.export.viewer_site`, ``--viewer-site``);

* ``latent_encoder.onnx``: ``state`` (B, 28) = 7 bodies' distances then their 7 x 3 body-frame gradients ->
  ``latent`` (B, 64); the viewer divides it by ``|z| + 1e-8``. Ours: the VAE's normaliser and encoder mean.
* ``policy.onnx``: ``proprio`` (1, 465) grouped by term, newest step first: 5 x (29 q, 29 qd x 0.05), 5 x 3 gravity
  in the root frame, 5 x 3 root angular velocity (body frame), 5 x 29 last action; ``movement_goal`` (1, 12): the
  target's position in the root's yaw frame with z = 0, the first two columns of ``R_yaw^T R_target`` row by row
  (r00, r01, r10, r11, r20, r21), the target's displacement since the last policy step (yaw frame, z = 0);
  ``task_condition`` (1, 2) = [v, v]; ``interaction_field`` (1, 320) = 5 unit latents, newest first -> ``action``
  (1, 29): absolute joint targets, clipped to +-10 by the viewer and held for 10 x 2 ms under
  ``clip(kp (a - q) - kd qd, ctrlrange)``.

:class:`DemoPolicyGraph` maps those inputs onto our windows, exactly: the terms re-ordered oldest first, ``qd``
divided by 0.05, the rotation columns re-ordered, the displacement divided by the 0.02 s step (our command's
velocity is in m/s), the command of the current step in every step's token (what the contract trains on), the
latents as given; then the policy's own backbone and action normaliser. What the viewer does differently from our
environment stays in its loop and is measured by :mod:`train.export.demo_loop`: zero-filled histories at reset (we
repeat the first step), its 2 ms physics and explicit PD law, its voxel-grid distance field.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import onnx
import torch
from torch import nn

from pipeline.errors import InputError
from pipeline.robot import G1_JOINT_NAMES, LESSMIMIC_DEMO_DF_BODIES, NUM_JOINTS, actuator_profile
from pipeline.stage.atomic import write_bytes_atomic
from pipeline.terms import layout as L
from train.export.metadata import policy_metadata
from train.export.onnx_policy import check_finite, quiet_export
from train.export.viewer_site import VIEWER_URLS, check_site, resolve
from train.policy import InteractionPolicy, load_policy

DEMO_PROFILE = "lessmimic_demo"
DEMO_INPUTS = {"proprio": 465, "movement_goal": 12, "task_condition": 2, "interaction_field": 320}
DEMO_FILES = ("interaction_policy.json", "latent_encoder.onnx", "policy.onnx")
JOINT_VEL_SCALE = 0.05
ACTION_CLIP = 10.0
LATENT = 64
ROT6_DEMO_TO_OURS = [3, 5, 7, 4, 6, 8]  # movement_goal's r00 r01 r10 r11 r20 r21 -> our r00 r10 r20 r01 r11 r21
VIEWER_OBJECT_SDFS = {  # the viewer's own scene assets (its example config's paths), not ours
    k: f"../../lessmimic-live-demo-assets/{k}_sdf.json" for k in ("box", "chair", "crate")
}


def viewer_state(df):
    """The viewer's encoder input ``[7 distances, 7 x 3 gradients]`` (..., 28) of our ``observation.df_demo`` rows,
    which hold them per body, ``[d, gx, gy, gz]`` x 7 (numpy or torch)."""
    per_body = df.reshape(*df.shape[:-1], len(LESSMIMIC_DEMO_DF_BODIES), 4)
    rest = per_body[..., 1:].reshape(*df.shape[:-1], -1)
    return (
        torch.cat([per_body[..., 0], rest], -1)
        if isinstance(df, torch.Tensor)
        else np.concatenate([per_body[..., 0], rest], -1)
    )


class LatentEncoderGraph(nn.Module):
    """``state (B, 28)``, the viewer's order (distances, then gradients) -> ``latent (B, 64)``: re-ordered per body
    as our ``observation.df_demo`` is, then the VAE's normaliser and encoder mean (not unit-norm)."""

    def __init__(self, policy: InteractionPolicy):
        super().__init__()
        self.vae = policy.vae
        k = len(LESSMIMIC_DEMO_DF_BODIES)
        order = [i for b in range(k) for i in (b, k + 3 * b, k + 3 * b + 1, k + 3 * b + 2)]
        self.register_buffer("order", torch.tensor(order), persistent=False)

    def forward(self, state: torch.Tensor) -> torch.Tensor:
        return self.vae.encode(state[:, self.order])


class DemoPolicyGraph(nn.Module):
    """The demo's four inputs -> 29 joint targets through our policy (module docstring)."""

    def __init__(self, policy: InteractionPolicy):
        super().__init__()
        self.policy, self.history = policy.eval(), policy.layout.history

    def forward(self, proprio, movement_goal, task_condition, interaction_field) -> torch.Tensor:
        b, h, j = proprio.shape[0], self.history, NUM_JOINTS
        sizes = [h * 2 * j, h * 3, h * 3, h * j]
        joints, gravity, ang_vel, last = torch.split(proprio, sizes, dim=1)
        joints = joints.reshape(b, h, 2 * j)
        ours = torch.cat(
            [
                joints[..., :j],
                joints[..., j:] / JOINT_VEL_SCALE,
                gravity.reshape(b, h, 3),
                ang_vel.reshape(b, h, 3),
                last.reshape(b, h, j),
            ],
            -1,
        ).flip(1)  # oldest first
        g = movement_goal
        command = torch.cat([g[:, 0:3], g[:, ROT6_DEMO_TO_OURS], g[:, 9:12] * L.CONTROL_FPS, task_condition], -1)
        command = command[:, None].expand(b, h, command.shape[-1])
        z = interaction_field.reshape(b, h, LATENT).flip(1)
        tokens = self.policy.tokens_from_latents(ours, command, z)
        return self.policy.norm["action"].denormalize(self.policy.backbone(tokens))


def demo_inputs(policy: InteractionPolicy, proprio, root_command, df) -> dict[str, np.ndarray]:
    """Our windows ``(B, l, dim)`` (the demo contract's: command with its task condition, demo DF) as the demo's four
    inputs, the latents through the policy's own VAE: the inverse of :class:`DemoPolicyGraph`'s mapping (for the
    parity check; the viewer builds them from its own state)."""
    p, c, d = (torch.as_tensor(x, dtype=torch.float32) for x in (proprio, root_command, df))
    b, j = p.shape[0], NUM_JOINTS
    new = p.flip(1)  # newest first
    joints = torch.cat([new[..., :j], new[..., j : 2 * j] * JOINT_VEL_SCALE], -1).reshape(b, -1)
    parts = [joints, new[..., 2 * j : 2 * j + 3].reshape(b, -1), new[..., 2 * j + 3 : 2 * j + 6].reshape(b, -1)]
    parts.append(new[..., 2 * j + 6 :].reshape(b, -1))
    now = c[:, -1]
    goal = torch.zeros(b, 12)
    goal[:, 0:3] = now[:, 0:3]
    goal[:, ROT6_DEMO_TO_OURS] = now[:, 3:9]
    goal[:, 9:12] = now[:, 9:12] / L.CONTROL_FPS
    field = policy.latents(d).flip(1).reshape(b, -1)
    out = {"proprio": torch.cat(parts, -1), "movement_goal": goal, "task_condition": now[:, 12:14]}
    return {**{k: v.numpy() for k, v in out.items()}, "interaction_field": field.numpy()}


def check_demo_policy(policy: InteractionPolicy, checkpoint: str | Path) -> None:
    """One-line :class:`InputError` unless ``policy`` was trained on the demo contract, its gains and sizes."""
    lay = policy.layout
    if lay.contract != "lessmimic_demo":
        why = f"{lay.contract!r}: retrain with `train-bc --contract lessmimic_demo` (its DF and latents differ)"
        raise InputError(checkpoint, "layout.contract", why)
    if lay.actuator_profile != DEMO_PROFILE:
        why = f"{lay.actuator_profile!r}: the demo drives {DEMO_PROFILE!r} gains (a corpus of PROFILE={DEMO_PROFILE})"
        raise InputError(checkpoint, "layout.actuator_profile", why)
    if lay.history != 5 or policy.config.latent != LATENT or tuple(lay.links) != LESSMIMIC_DEMO_DF_BODIES:
        raise InputError(checkpoint, "layout", "the demo reads 5 steps of 64 latents of its 7 bodies")


def viewer_config(policy: InteractionPolicy, checkpoint: str | Path) -> dict:
    """``interaction_policy.json``: the keys the viewer reads, with the policy's gains, and our metadata beside."""
    profile = actuator_profile(DEMO_PROFILE)
    return {
        "policy_type": "interaction",
        "onnx": {"path": VIEWER_URLS["policy.onnx"]},  # fetched from the viewer's page, not the JSON's folder
        "latent_encoder": {"path": VIEWER_URLS["latent_encoder.onnx"]},
        "sdf": {
            "objects": VIEWER_OBJECT_SDFS,
            "query_body_names": list(LESSMIMIC_DEMO_DF_BODIES),
            "scene_object_body_names": list(VIEWER_OBJECT_SDFS),
            "max_valid_distance": L.DEMO_MAX_DISTANCE_M,
        },
        "history_length": policy.layout.history,
        "action_clip": ACTION_CLIP,
        "policy_joint_names": list(G1_JOINT_NAMES),
        "action_scale": [1.0] * NUM_JOINTS,
        "stiffness": profile.kp.tolist(),
        "damping": profile.kd.tolist(),
        "default_joint_pos": [0.0] * NUM_JOINTS,
        "control_type": "joint_position",
        "scene_xml": "g1/g1_interaction.xml",
        "lessmimic": policy_metadata(policy, checkpoint),
    }


def _onnx(graph: nn.Module, example: tuple, inputs: list[str], output: str) -> bytes:
    return quiet_export(graph, example, inputs, output).model_proto.SerializeToString()


def export_demo(
    checkpoint: str | Path,
    out: str | Path | None = None,
    overwrite: bool = False,
    viewer_site: str | Path | None = None,
) -> Path:
    """Write the demo's three files for the policy at ``checkpoint`` into the folder ``out`` (default beside it:
    ``lessmimic_demo/``), or where the viewer whose site folder is ``viewer_site`` fetches them
    (:mod:`train.export.viewer_site`: ``<site>/examples/checkpoints/g1/``; the JSON names the ONNX files by their
    path from the viewer's page, so a plain ``out`` folder's three files go there too); one-line
    :class:`InputError` for a policy of another contract or gains, non-finite weights, both ``out`` and
    ``viewer_site``, a site folder without the viewer's page, or existing files without ``overwrite``; nothing is
    written on any error."""
    checkpoint = Path(checkpoint)
    if viewer_site is not None and out is not None:
        raise InputError(viewer_site, "viewer_site", f"and --out {out} both given: the site decides where files go")
    if viewer_site is not None:
        out = resolve(check_site(viewer_site), VIEWER_URLS[DEMO_FILES[0]]).parent
    out = Path(out) if out is not None else checkpoint.parent / "lessmimic_demo"
    existing = [f for f in DEMO_FILES if (out / f).exists()]
    if existing and not overwrite:
        raise InputError(out / existing[0], "output", "exists: pass --overwrite to replace it")
    policy = load_policy(checkpoint)
    check_demo_policy(policy, checkpoint)
    check_finite(policy, checkpoint)
    example = {k: torch.zeros(2, n) for k, n in DEMO_INPUTS.items()}  # batch 2: torch.export specialises a 1
    encoder = _onnx(LatentEncoderGraph(policy).eval(), (torch.zeros(2, 28),), ["state"], "latent")
    graph = _onnx(DemoPolicyGraph(policy).eval(), tuple(example.values()), list(DEMO_INPUTS), "action")
    for blob in (encoder, graph):
        onnx.checker.check_model(onnx.load_from_string(blob))
    config = (json.dumps(viewer_config(policy, checkpoint), indent=2) + "\n").encode()
    for name, blob in zip(DEMO_FILES, (config, encoder, graph)):
        write_bytes_atomic(out / name, blob)
    return out
