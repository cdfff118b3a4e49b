"""A subject's height from its skeleton, and the range a human height lies in.

Estimate (:func:`estimate_height`): the longest tree path from the head joint to an ankle (a foot
when no joint is named like an ankle), each bone ``(c, p)`` taken at its median length over frames
(pose independent), times :data:`HEAD_TO_ANKLE_TO_STATURE`::

    h = k * max_ankle sum_{(c, p) on path(head, ankle)} median_t |x_c(t) - x_p(t)|,   k = 1.118

``k`` was measured on OMOMO subjects of known height (sub2 1.844 m, sub3 1.941 m: 1.121 and 1.115).
The result is in the positions' own units (the readers guess units from it). A human height in
metres is ``0.3 < h < 3`` (:func:`plausible_height`).
"""

from __future__ import annotations

import numpy as np

from pipeline.clip import Skeleton

HEAD_TO_ANKLE_TO_STATURE = 1.118


def find_joint(names: tuple[str, ...], *keys: str) -> int | None:
    """First joint whose lower-cased name contains ``keys[0]`` (then ``keys[1]``, ...)."""
    low = [n.lower() for n in names]
    for k in keys:
        for i, n in enumerate(low):
            if k in n:
                return i
    return None


def _tree_path(parents: tuple[int, ...], a: int, b: int) -> list[tuple[int, int]]:
    """Bones ``(child, parent)`` on the path between joints ``a`` and ``b``; empty if unconnected."""

    def up(j: int) -> list[int]:
        chain = [j]
        while parents[chain[-1]] >= 0:
            chain.append(parents[chain[-1]])
        return chain

    ca, cb = up(a), up(b)
    common = next((j for j in ca if j in cb), None)
    if common is None:
        return []
    bones = [(j, parents[j]) for j in ca[: ca.index(common)]]
    return bones + [(j, parents[j]) for j in cb[: cb.index(common)]]


def estimate_height(joint_pos: np.ndarray, skeleton: Skeleton) -> float | None:
    """Stature (file units) from the head-to-ankle bone path (module doc); ``None`` if those joints are unknown."""
    names = skeleton.joint_names
    head = find_joint(names, "head")
    low = [n.lower() for n in names]
    ankles = [i for i, n in enumerate(low) if "ankle" in n] or [i for i, n in enumerate(low) if "foot" in n]
    if head is None or not ankles:
        return None
    best = 0.0
    for ankle in ankles:
        bones = _tree_path(skeleton.parents, head, ankle)
        length = sum(float(np.median(np.linalg.norm(joint_pos[:, c] - joint_pos[:, p], axis=-1))) for c, p in bones)
        best = max(best, length)
    return best * HEAD_TO_ANKLE_TO_STATURE if best > 0 else None


def plausible_height(h: float | None) -> float | None:
    """``h`` if it is a human height in metres (``0.3 < h < 3``, finite), else ``None``."""
    return float(h) if h is not None and np.isfinite(h) and 0.3 < h < 3.0 else None
