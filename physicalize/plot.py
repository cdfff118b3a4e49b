"""Per-clip inspection plot (PNG) of a physicalized clip.

Four panels over time: (1) CoM x and y of the retargeted reference, the feasible plan and the
simulation, with the plan's ZMP and the support region's x/y bounds (shaded: the stance feet's sole
corners); (2) pelvis height, reference vs simulated; (3) vertical floor
force on each foot; (4) object heights, reference vs simulated (when the clip has objects).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pipeline.stage.figure import save_figure  # noqa: E402


def plot_physicalized(
    com: dict,
    foot_force: np.ndarray,
    objects: dict[str, tuple[np.ndarray, np.ndarray]],
    fps: float,
    title: str,
    path: Path,
) -> Path:
    """Write the PNG atomically; ``objects`` maps a name to (reference z, simulated z)."""
    T = len(com["simulated"])
    t = np.arange(T) / fps
    fig, axes = plt.subplots(4, 1, figsize=(10, 10), sharex=True)
    for k, (axis, ls) in enumerate((("x", "-"), ("y", "--"))):
        axes[0].plot(t, com["reference"][:, k], color="tab:gray", ls=ls, label=f"reference CoM {axis}")
        axes[0].plot(t, com["planned"][:, k], color="tab:blue", ls=ls, label=f"planned CoM {axis}")
        axes[0].plot(t, com["simulated"][:, k], color="tab:orange", ls=ls, label=f"simulated CoM {axis}")
        if com.get("support") is not None:
            axes[0].fill_between(
                t,
                com["support"][:, 0, k],
                com["support"][:, 1, k],
                color="tab:green",
                alpha=0.12,
                lw=0,
                label=f"support region {axis}",
            )
        if com.get("zmp_planned") is not None:
            axes[0].plot(t, com["zmp_planned"][:, k], color="tab:green", ls=ls, lw=0.8, label=f"planned ZMP {axis}")
    axes[1].plot(t, com["pelvis_ref"], color="tab:gray", label="reference pelvis z")
    axes[1].plot(t, com["pelvis_sim"], color="tab:orange", label="simulated pelvis z")
    for k, side in enumerate(("left", "right")):
        axes[2].plot(t, foot_force[:, k], label=f"{side} foot vertical force")
    for name, (zr, zs) in objects.items():
        axes[3].plot(t, zr[:T], color="tab:gray", label=f"{name} z reference")
        axes[3].plot(t, zs, color="tab:orange", label=f"{name} z simulated")
    for ax, unit in zip(axes, ("m", "m", "N", "m")):
        ax.set_ylabel(unit)
        ax.legend(loc="upper right", fontsize=6)
    axes[3].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    return save_figure(fig, path, dpi=80)
