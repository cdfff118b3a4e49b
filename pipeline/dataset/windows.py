"""History windows for training, straight from a LeRobot v3.0 dataset's parquet columns (torch).

:class:`WindowDataset` serves them far faster than ``LeRobotDataset(..., delta_timestamps=...)`` with the same
values and padding semantics: the window of frame ``i`` is frames ``i-history+1 .. i``; a frame before its
episode's first frame is replaced by that first frame and flagged ``True`` in ``<key>_is_pad``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch

from pipeline.dataset.read import episode_ranges, read_columns, read_info
from pipeline.errors import InputError
from pipeline.terms.layout import HISTORY


class WindowDataset(torch.utils.data.Dataset):
    """History windows over parquet columns, as a ``torch.utils.data.Dataset``.

    ``ds[i]`` -> ``{key: (history, dim) tensor, f"{key}_is_pad": (history,) bool tensor,
    "index": i, "episode_index": e}``; :meth:`sample` does the same for a batch of indices in one
    vectorised gather (``(B, history, dim)`` and ``(B, history)``). LeRobot returns a one-element
    feature as ``(history,)``; here it is ``(history, 1)``.
    """

    def __init__(self, root: str | Path, keys: Sequence[str], history: int = HISTORY):
        if history < 1:
            raise ValueError(f"history must be >= 1, got {history}")
        self.root, self.keys, self.history = Path(root), tuple(keys), int(history)
        info = read_info(self.root)
        unknown = [k for k in self.keys if k not in info["features"]]
        if unknown:
            raise InputError(self.root, "keys", f"unknown features {unknown}")
        self.fps = info["fps"]
        cols = read_columns(self.root, [*self.keys, "episode_index", "index"])
        if not np.array_equal(cols["index"][:, 0], np.arange(len(cols["index"]))):
            raise InputError(self.root, "index", "frames are not numbered 0..N-1")
        self.data = {k: torch.from_numpy(np.require(cols[k], requirements=["C", "W"])) for k in self.keys}
        starts, ends, _ = episode_ranges(self.root)
        ep = cols["episode_index"][:, 0]
        self.episode_index = torch.from_numpy(ep.copy())
        self.ep_start = torch.from_numpy(starts[ep].astype(np.int64))
        self.offsets = torch.arange(-self.history + 1, 1, dtype=torch.int64)

    def __len__(self) -> int:
        return int(self.episode_index.shape[0])

    def sample(self, indices) -> dict:
        """Windows for a batch of frame indices: ``(B, history, dim)`` per key, ``(B, history)`` pads."""
        idx = torch.as_tensor(indices, dtype=torch.int64).reshape(-1)
        want = idx[:, None] + self.offsets  # offsets <= 0: only the episode start can be crossed
        start = self.ep_start.index_select(0, idx)[:, None]
        pad = want < start
        rows = torch.maximum(want, start).reshape(-1)
        shape = (idx.shape[0], self.history)
        out = {k: v.index_select(0, rows).view(*shape, v.shape[1]) for k, v in self.data.items()}
        out.update({f"{k}_is_pad": pad for k in self.keys})
        out["index"], out["episode_index"] = idx, self.episode_index.index_select(0, idx)
        return out

    def __getitem__(self, i: int) -> dict:
        if not -len(self) <= i < len(self):
            raise IndexError(i)
        b = self.sample([i % len(self)])
        return {k: v[0] for k, v in b.items()}
