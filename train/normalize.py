"""Per-element standardisation of observations and actions.

For a column ``x`` with per-element mean ``m`` and standard deviation ``s`` (population, over every
frame it was fitted on), ``normalize(x) = (x - m) / max(s, min_std)`` and ``denormalize(y) = y * max(s, min_std) + m``.
The floor keeps a constant element (a joint that never moves in the data) from dividing by zero; ``clip``
(optional) bounds the normalised value to ``[-clip, clip]``, so an input far outside the data seen in
training cannot blow up the network that reads it.

The statistics live in non-persistent buffers (they follow ``.to(device)`` but stay out of ``state_dict``) and
go into checkpoints as plain lists (:meth:`Normalizer.to_dict` / :meth:`Normalizer.from_dict`).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from pipeline.dataset.read import read_columns

MIN_STD = 1e-3


class Normalizer(nn.Module):
    """``(x - mean) / std`` per element, ``std`` already floored; optionally clipped to ``[-clip, clip]``."""

    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, mean: Sequence[float], std: Sequence[float], clip: float | None = None):
        super().__init__()
        mean_t = torch.as_tensor(np.asarray(mean, dtype=np.float32))
        std_t = torch.as_tensor(np.asarray(std, dtype=np.float32))
        if mean_t.ndim != 1 or mean_t.shape != std_t.shape:
            raise ValueError(f"mean and std must be 1-D of one length, got {tuple(mean_t.shape)}, {tuple(std_t.shape)}")
        if not (torch.isfinite(mean_t).all() and torch.isfinite(std_t).all() and (std_t > 0).all()):
            raise ValueError("mean must be finite and std finite and > 0")
        self.register_buffer("mean", mean_t, persistent=False)
        self.register_buffer("std", std_t, persistent=False)
        self.clip = None if clip is None else float(clip)

    @property
    def dim(self) -> int:
        return int(self.mean.shape[0])

    @classmethod
    def from_array(cls, x, min_std: float = MIN_STD, clip: float | None = None) -> Normalizer:
        """Statistics of ``x (N, D)`` (numpy or torch), computed in float64."""
        a = x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)
        a = a.reshape(-1, a.shape[-1]).astype(np.float64)
        if a.shape[0] == 0:
            raise ValueError("cannot fit a normaliser on zero rows")
        return cls(a.mean(0), np.maximum(a.std(0), min_std), clip)

    @classmethod
    def from_dataset(
        cls,
        root: str | Path,
        column: str,
        episodes: Sequence[int] | None = None,
        min_std: float = MIN_STD,
        clip: float | None = None,
    ) -> Normalizer:
        """Statistics of a dataset column over all frames, or over the frames of ``episodes``."""
        cols = read_columns(root, [column, "episode_index"])
        x = cols[column]
        if episodes is not None:
            x = x[np.isin(cols["episode_index"][:, 0], np.asarray(list(episodes)))]
        return cls.from_array(x, min_std, clip)

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        y = (x - self.mean) / self.std
        return y if self.clip is None else y.clamp(-self.clip, self.clip)

    def denormalize(self, y: torch.Tensor) -> torch.Tensor:
        return y * self.std + self.mean

    def to_dict(self) -> dict:
        """Plain lists (a checkpoint stays readable with ``torch.load(weights_only=True)``)."""
        return {"mean": self.mean.cpu().tolist(), "std": self.std.cpu().tolist(), "clip": self.clip}

    @classmethod
    def from_dict(cls, d: dict) -> Normalizer:
        return cls(d["mean"], d["std"], d.get("clip"))

    def extra_repr(self) -> str:
        return f"dim={self.dim}, clip={self.clip}"
