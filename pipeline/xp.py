"""numpy and torch written alike: the array namespace ``xp`` that the distance fields, the observation terms, the
rewards and the randomisations are written against, so the CPU and GPU backends share one implementation.

That math is written once, with ``xp`` the ``numpy`` module or the ``torch`` module, using
only what both spell the same (``sqrt abs sign where clip minimum maximum stack floor``,
operators, indexing). The few operations they spell differently live here.
"""

from __future__ import annotations

import numpy as np


def namespace(a):
    """``torch`` for a torch tensor, ``numpy`` for anything else."""
    if type(a).__module__.split(".")[0] == "torch":
        import torch

        return torch
    return np


def is_numpy(xp) -> bool:
    return xp is np


def as_float(a, xp, like=None):
    """``a`` as a floating array of ``xp`` (float64 for numpy; ``like``'s dtype and device for torch)."""
    if xp is np:
        return np.asarray(a, dtype=np.float64)
    import torch

    if like is not None:
        return torch.as_tensor(a, dtype=like.dtype, device=like.device)
    t = torch.as_tensor(a)
    return t if t.is_floating_point() else t.to(torch.float64)


def to_index(a, xp):
    """Integer (int64) copy of ``a``, truncating toward zero."""
    return a.astype(np.int64) if xp is np else a.long()


def nonzero(mask, xp):
    """1-D indices where ``mask`` is true."""
    return np.flatnonzero(mask) if xp is np else mask.nonzero().squeeze(1)


def concat(arrays, xp, axis: int = 0):
    return np.concatenate(arrays, axis) if xp is np else xp.cat(arrays, axis)


def full(n: int, value, like, xp):
    """A length-``n`` array of ``value`` with ``like``'s dtype (and device)."""
    if xp is np:
        return np.full(n, value, dtype=like.dtype)
    return xp.full((n,), value, dtype=like.dtype, device=like.device)


def to_numpy(a) -> np.ndarray:
    return a if isinstance(a, np.ndarray) else a.detach().cpu().numpy()
