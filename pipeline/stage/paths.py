"""Where a stage reads and writes: ``<datasets root>/<NAME>/<stage>/`` (a LeRobot dataset root),
``<NAME>/logs/<stage>/`` (inspection logs, figures and the run's report) and ``<NAME>/.work/<stage>/``
(what an interrupted run resumes from)."""

from __future__ import annotations

import os
import re
from pathlib import Path

from pipeline.dataset.schema import dataset_root


def datasets_root() -> Path:
    """``$LESSMIMIC_DATASETS`` or ``datasets/`` in the working directory."""
    return Path(os.environ.get("LESSMIMIC_DATASETS", "datasets"))


def stage_dir(name: str, stage: str, root: Path | None = None) -> Path:
    """``<datasets root>/<name>/<stage>``; ``name`` is checked by :func:`pipeline.dataset.schema.validate_name`."""
    return dataset_root(root or datasets_root(), name) / stage


def logs_dir(out: Path) -> Path:
    """``<name>/logs/<stage>`` beside the dataset root ``out`` (so `publish` does not upload them)."""
    return out.parent / "logs" / out.name


def work_dir(out: Path) -> Path:
    """``<name>/.work/<stage>``: the resume state of an unfinished run writing ``out``."""
    return out.parent / ".work" / out.name


def file_stem(source: str) -> str:
    """A portable file name stem for a clip source (``synthetic:PickUp`` -> ``synthetic_PickUp``)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(source).stem) or "clip"
