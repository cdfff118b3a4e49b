"""Per-clip PNG of the DF signals, like the paper's Fig. 3.

Top: the mean DF distance phi across the feature links, with the min-max band. Middle: the
magnitude of the link-mean gradient |mean_k grad phi_k| (each grad is a unit vector, so this is 1
when all links see the object from the same side and smaller when they surround it) and the mean
normal speed |v_norm| (approach and pressing). Contact phases (any link touching an object, from the
simulation) are shaded and their transitions marked with dashed lines.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.stage.figure import save_figure  # noqa: E402


def plot_df(df: np.ndarray, contact: np.ndarray | None, fps: float, title: str, path: Path) -> Path:
    """Write the PNG atomically; ``df (T, K, 10)`` per-link features, ``contact (T,)`` any link in contact."""
    T = len(df)
    t = np.arange(T) / fps
    phi = df[..., 0]
    fig, axes = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    axes[0].fill_between(t, phi.min(1), phi.max(1), color="tab:blue", alpha=0.2, lw=0, label="phi range across links")
    axes[0].plot(t, phi.mean(1), color="tab:blue", label="mean phi")
    axes[0].set_ylabel("distance (m)")
    axes[1].plot(t, np.linalg.norm(df[..., 1:4].mean(1), axis=-1), color="tab:red", label="|mean grad phi|")
    axes[1].plot(t, np.linalg.norm(df[..., 4:7], axis=-1).mean(1), color="tab:purple", label="mean |v_norm| (m/s)")
    if contact is not None and contact.any():
        edges = np.flatnonzero(np.diff(contact.astype(np.int8))) + 1
        for ax in axes:
            ax.fill_between(
                t, 0, 1, where=contact, transform=ax.get_xaxis_transform(), color="tab:green", alpha=0.1, lw=0
            )
            for e in edges:
                ax.axvline(t[e], color="k", ls="--", lw=0.8)
        axes[0].plot([], [], color="tab:green", alpha=0.3, lw=6, label="contact")
    for ax in axes:
        ax.legend(loc="upper right", fontsize=7)
    axes[1].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path, dpi=80)
