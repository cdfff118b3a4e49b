"""Parity of an exported policy with its checkpoint, per step on recorded observations: the torch policy acts in the
CPU environment on corpus episodes, every step's observation windows are kept (:func:`recorded_windows`), and torch
and onnxruntime act on all of them (:func:`parity`). The issue's bar: ``max |a_onnx - a_torch| <= 1e-5`` rad.

Closed-loop episodes are not compared one to one: contact-rich loops amplify 1e-6 differences into different
episodes, so the closed loop is compared by the evaluation's cells (``lessmimic eval --policy file.onnx``) against
the spread of the checkpoint's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from train.actors import PolicyActor
from train.envs.cpu.env import EnvConfig, InteractionEnv
from train.episodes import Episode
from train.export.metadata import inputs_of
from train.export.runtime import OnnxPolicy
from train.policy import InteractionPolicy


def recorded_windows(policy: InteractionPolicy, episodes: list[Episode], steps: int) -> tuple[np.ndarray, ...]:
    """``(proprio, root_command, df)`` windows ``(len(episodes) * steps', l, dim)`` (a vision student's: clean ``depth``
    frames in place of df) the torch ``policy`` observed acting on ``episodes`` (at scale 1, together) for up to
    ``steps`` control steps (an episode's windows until it ends)."""
    env = InteractionEnv(EnvConfig.for_policy(policy.layout, threads=1))
    env.reset([(e, 1.0) for e in episodes])
    inputs = inputs_of(policy)
    if inputs[2] == "depth":  # a vision student, its clean camera
        from train.vision.actor import VisionActor
        from train.vision.noise import DepthNoise

        actor = VisionActor(policy, DepthNoise.off())
    else:
        actor = PolicyActor(policy)
    actor.reset(env)
    kept: dict[str, list[np.ndarray]] = {k: [] for k in inputs}
    done = np.zeros(env.num_envs, bool)
    for _ in range(steps):
        for k in inputs:
            kept[k].append(actor.history.terms[k][~done].copy())
        obs, done = env.step(actor.act(env))
        actor.observe(obs)
        if done.all():
            break
    env.close()
    return tuple(np.concatenate(kept[k]).astype(np.float32) for k in inputs)


def parity(policy: InteractionPolicy, onnx_path: str | Path, windows: tuple[np.ndarray, ...]) -> dict:
    """``max_abs`` and ``mean_abs`` [rad] of onnxruntime minus torch joint targets over ``windows``, and their count."""
    x = tuple(torch.from_numpy(w) for w in windows)
    with torch.no_grad():
        want = policy.act(*x).numpy()
    got = OnnxPolicy(onnx_path).act(*x).numpy()
    diff = np.abs(got - want)
    return {"windows": len(want), "max_abs": float(diff.max()), "mean_abs": float(diff.mean())}
