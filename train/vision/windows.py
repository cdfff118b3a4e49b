"""The distillation's training windows (:class:`DepthWindows`): per-frame tensors once, windows as row indices (as
:class:`train.bc.WindowTensors` keeps the MoCap windows), depth stored as uint16 millimetres.

A 64 x 40 frame is 5.1 kB in uint16 (10.2 kB as float32); a window of 5 frames by reference costs one int64 row of
5 indices, not 5 frames: a laptop distillation's ~10^5 frames fit in ~0.5 GB. The depth's round trip loses at most
0.5 mm (:func:`train.vision.noise.depth_to_mm`), far below the sensor noise the student is trained under.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np
import torch

from pipeline.errors import InputError
from train.vision.noise import MM, depth_to_mm


class DepthBatch(NamedTuple):
    proprio: torch.Tensor  # (B, l, P)
    root_command: torch.Tensor  # (B, l, C)
    depth: torch.Tensor  # (B, l, H, W) float32 metres
    latent: torch.Tensor  # (B, l, latent): pi_full's VAE latent of the same steps (alignment loss)
    action: torch.Tensor  # (B, A): pi_full's joint targets at the window's last step


@dataclass
class DepthWindows:
    """Per-frame ``proprio (M, P)``, ``root_command (M, C)``, ``depth (M, H, W)`` uint16 mm, ``latent (M, z)``;
    per window ``rows (N, l)`` (frame indices, oldest first) and its label ``action (N, A)``."""

    proprio: torch.Tensor
    root_command: torch.Tensor
    depth: torch.Tensor
    latent: torch.Tensor
    rows: torch.Tensor
    action: torch.Tensor

    def __post_init__(self):
        m, n = self.proprio.shape[0], self.rows.shape[0]
        if any(getattr(self, k).shape[0] != m for k in ("root_command", "depth", "latent")) or len(self.action) != n:
            raise ValueError("frame tensors need one row per frame and action one row per window")
        if self.depth.dtype != torch.uint16:
            raise ValueError(f"depth must be uint16 millimetres, got {self.depth.dtype}")
        if n and (int(self.rows.min()) < 0 or int(self.rows.max()) >= m):
            raise ValueError("rows index outside the frames")

    def __len__(self) -> int:
        return int(self.rows.shape[0])

    @property
    def frames(self) -> int:
        return int(self.proprio.shape[0])

    @staticmethod
    def concat(parts: Sequence[DepthWindows]) -> DepthWindows:
        offsets = np.cumsum([0] + [p.frames for p in parts[:-1]])
        rows = torch.cat([p.rows + int(o) for p, o in zip(parts, offsets)])
        cat = {f.name: torch.cat([getattr(p, f.name) for p in parts]) for f in fields(DepthWindows) if f.name != "rows"}
        return DepthWindows(**cat, rows=rows)

    def state(self) -> dict[str, torch.Tensor]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def gather(self, idx: torch.Tensor) -> DepthBatch:
        r = self.rows[idx]
        depth = self.depth[r].to(torch.float32) / MM
        return DepthBatch(self.proprio[r], self.root_command[r], depth, self.latent[r], self.action[idx])

    def sample(self, batch: int, generator: torch.Generator) -> DepthBatch:
        """``batch`` windows drawn uniformly with replacement."""
        return self.gather(torch.randint(len(self), (batch,), generator=generator))


class WindowRecorder:
    """Builds :class:`DepthWindows` during rollouts: :meth:`frame` stores environment ``i``'s newest frame,
    :meth:`window` the window ending at it (the episode's first frame repeated before its start, as the policy's
    history pads) with its label."""

    def __init__(self, envs: int, history: int):
        self.history = history
        self.ids: list[list[int]] = [[] for _ in range(envs)]
        self.parts: dict[str, list[np.ndarray]] = {k: [] for k in ("proprio", "root_command", "depth", "latent")}
        self.rows: list[list[int]] = []
        self.action: list[np.ndarray] = []
        self.count = 0

    def frames(self, which: np.ndarray, proprio, root_command, depth_m, latent) -> None:
        """The newest frame of the environments ``which`` (a boolean mask) from ``(N, ...)`` arrays."""
        idx = np.flatnonzero(which)
        self.parts["proprio"].append(proprio[idx])
        self.parts["root_command"].append(root_command[idx])
        self.parts["depth"].append(depth_to_mm(depth_m[idx]))
        self.parts["latent"].append(latent[idx])
        for k, i in enumerate(idx):
            self.ids[i].append(self.count + k)
        self.count += len(idx)

    def windows(self, which: np.ndarray, action: np.ndarray) -> None:
        """The windows ending at the newest frame of the environments ``which``, labelled ``action (N, A)``."""
        for i in np.flatnonzero(which):
            last = self.ids[i][-self.history :]
            self.rows.append([last[0]] * (self.history - len(last)) + last)
            self.action.append(action[i])

    def tensors(self) -> DepthWindows:
        cat = {k: torch.from_numpy(np.concatenate(v)) for k, v in self.parts.items()}
        for k in ("proprio", "root_command", "latent"):
            cat[k] = cat[k].float()
        rows = torch.as_tensor(np.array(self.rows, dtype=np.int64).reshape(-1, self.history))
        action = torch.as_tensor(np.array(self.action), dtype=torch.float32)
        return DepthWindows(**cat, rows=rows, action=action)


def check_depth_memory(frames: int, height: int, width: int, cap_mb: float, where) -> None:
    """A one-line :class:`InputError` if ``frames`` depth frames (uint16) would exceed ``cap_mb`` megabytes."""
    need = frames * height * width * 2 / 1e6
    if need > cap_mb:
        raise InputError(
            where,
            "depth_memory_mb",
            f"up to {frames} depth frames of {width} x {height} need {need:.0f} MB, over the cap of {cap_mb:g} MB: "
            "fewer iterations or episodes, a smaller image, or a larger cap",
        )
