"""Writing inspection plots: a matplotlib figure saved as a PNG atomically (temp file, then rename)."""

from __future__ import annotations

import os
from pathlib import Path


def save_figure(fig, path: Path, dpi: int) -> Path:
    """Save ``fig`` to ``path`` (PNG) through a hidden temp file renamed into place, close it, return ``path``."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.png")
    fig.savefig(tmp, dpi=dpi)
    plt.close(fig)
    os.replace(tmp, path)
    return path
