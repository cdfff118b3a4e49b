"""Nothing outside a command's outputs: what libraries would write elsewhere goes into the dataset's folder or away.

Why: every retarget left two Arrow cache folders of its own dataset (1.5-3x its size) in
``~/.cache/huggingface/datasets`` (LeRobot's reload after a write goes through ``datasets``, which caches there), and
MuJoCo's warnings landed in a ``MUJOCO_LOG.TXT`` in whatever folder the command ran from.

* :func:`temporary_arrow_cache` -- ``datasets``' cache in a temporary folder, removed afterwards;
* :func:`mujoco_log_into` -- MuJoCo's warnings appended to ``datasets/<NAME>/logs/mujoco.log`` instead (worker
  processes forked from this one inherit the handler).
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def temporary_arrow_cache() -> Iterator[Path]:
    """``datasets``' Arrow cache (``HF_DATASETS_CACHE``) in a fresh temporary folder for the block, removed after."""
    tmp = Path(tempfile.mkdtemp(prefix="lessmimic-arrow-"))
    old_env = os.environ.get("HF_DATASETS_CACHE")
    os.environ["HF_DATASETS_CACHE"] = str(tmp)  # read when `datasets` is first imported
    config = sys.modules.get("datasets.config")
    old_config = getattr(config, "HF_DATASETS_CACHE", None)
    if config is not None:  # imported already: its constant is read at every load
        config.HF_DATASETS_CACHE = tmp
    try:
        yield tmp
    finally:
        if old_env is None:
            os.environ.pop("HF_DATASETS_CACHE", None)
        else:
            os.environ["HF_DATASETS_CACHE"] = old_env
        config = sys.modules.get("datasets.config")
        if config is not None:
            config.HF_DATASETS_CACHE = old_config or Path(old_env or config.DEFAULT_HF_DATASETS_CACHE)
        shutil.rmtree(tmp, ignore_errors=True)


@contextmanager
def mujoco_log_into(path: Path) -> Iterator[Path]:
    """MuJoCo's warnings appended to ``path`` (made on the first warning) instead of ``./MUJOCO_LOG.TXT``."""
    import mujoco

    def warn(message: str) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "a", encoding="utf-8") as f:
            f.write(f"WARNING: {message}\n")

    old = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(warn)
    try:
        yield path
    finally:
        mujoco.set_mju_user_warning(old)
