"""Generic keypoints: ``.npz`` / ``.csv`` joint positions, and the unit and up-axis helpers every
reader shares (the height estimate is :mod:`pipeline.body_height`).

Conventions
-----------
* Units: a scale factor to metres, ``m`` 1, ``cm`` 0.01, ``mm`` 0.001, ``inch`` 0.0254.
  ``"auto"`` picks the unit that makes the estimated subject height closest (in log
  ratio) to a 1.7 m human; it therefore misreads a 1.07 m child in cm as inches.
* Up axis: ``"z"`` leaves points alone; ``"y"`` applies :data:`~pipeline.rotations.Y_UP_TO_Z_UP`
  (+90 deg about x: ``(x, y, z) -> (x, -z, y)``), a proper rotation, so handedness is kept.
* Height: the skeleton's head-to-ankle estimate, :func:`pipeline.body_height.estimate_height`
  (``None`` without joints named like ``head`` and ``ankle``/``foot``).

Keypoint files
--------------
``.npz``: ``joint_pos`` (or ``positions``) ``[T, J, 3]``, ``joint_names`` ``[J]``, ``fps``;
optional ``parents`` ``[J]`` (-1 = root; default all -1), ``units`` and ``up`` strings.
``.csv``: a header row, an optional ``frame`` column, an optional ``time`` column (seconds,
gives the fps as 1 / median dt), then ``<joint>_x, <joint>_y, <joint>_z`` triples.
"""

from __future__ import annotations

import csv
import pickle
import struct
import tokenize
import zipfile
import zlib
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from pipeline.body_height import estimate_height, plausible_height
from pipeline.clip import HumanClip, Skeleton
from pipeline.errors import InputError, first_bad_frame
from pipeline.rotations import Y_UP_TO_Z_UP

UNIT_SCALE: dict[str, float] = {"m": 1.0, "cm": 0.01, "mm": 0.001, "inch": 0.0254}
HUMAN_HEIGHT_M = 1.7


_PICKLE_ALLOWED = {
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
    ("numpy.core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"),
    ("numpy._core.multiarray", "scalar"),
}


class _NumpyUnpickler(pickle.Unpickler):
    """Unpickles builtins and numpy arrays/scalars only: a pickle cannot run code through us."""

    def find_class(self, module: str, name: str):
        if (module, name) in _PICKLE_ALLOWED:
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"refusing to load {module}.{name}")


def load_numpy_pickle(path: str | Path, field: str = "pickle"):
    """A pickle of plain containers and numpy arrays (GMR motions, OMOMO height dicts)."""
    try:
        with open(path, "rb") as f:
            return _NumpyUnpickler(f).load()
    except (OSError, EOFError, pickle.UnpicklingError, AttributeError, ValueError, TypeError) as e:
        raise InputError(path, field, f"not a readable numpy pickle ({e})") from None


def unit_scale(units: str, source: str | Path) -> float:
    """Metres per file unit for an explicit unit name (``"auto"`` is resolved by the caller)."""
    if units not in UNIT_SCALE:
        raise InputError(
            source, "units", f"unknown units {units!r}; use one of 'auto', {', '.join(map(repr, UNIT_SCALE))}"
        )
    return UNIT_SCALE[units]


def guess_units(raw_height: float) -> str:
    """The unit whose scale brings ``raw_height`` closest to a 1.7 m human (log distance)."""
    return min(UNIT_SCALE, key=lambda u: abs(np.log(max(raw_height, 1e-9) * UNIT_SCALE[u] / HUMAN_HEIGHT_M)))


def up_matrix(up: str, source: str | Path) -> np.ndarray:
    """Rotation taking the file's world frame to the z-up world."""
    if up == "z":
        return np.eye(3)
    if up == "y":
        return Y_UP_TO_Z_UP.copy()
    raise InputError(source, "up", f"unknown up axis {up!r}; use 'y' or 'z'")


def keypoints_clip(
    pos: np.ndarray,
    names,
    parents,
    fps: float,
    source: str,
    *,
    units: str = "m",
    up: str = "z",
    subject_height: float | None = None,
) -> HumanClip:
    """Validated z-up metre clip from raw ``[T, J, 3]`` positions in the file's units and axes."""
    pos = np.asarray(pos, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise InputError(source, "joint_pos", f"shape {pos.shape} is not (T, J, 3)")
    if pos.shape[0] == 0:
        raise InputError(source, "joint_pos", "has zero frames")
    bad = ~np.isfinite(pos)
    if bad.any():
        t = first_bad_frame(bad)
        j = int(np.flatnonzero(bad[t].any(axis=-1))[0])
        raise InputError(source, f"joint_pos[{names[j] if j < len(names) else j}]", "is NaN or infinite", frame=t)
    pos = pos @ up_matrix(up, source).T
    try:
        skeleton = Skeleton(tuple(str(n) for n in names), tuple(int(p) for p in parents))
    except ValueError as e:
        raise InputError(source, "joint_names", str(e)) from None
    if len(skeleton.joint_names) != pos.shape[1]:
        raise InputError(source, "joint_names", f"{len(skeleton.joint_names)} names for {pos.shape[1]} joints")
    if units == "auto":
        raw = estimate_height(pos, skeleton)
        if raw is None:
            raise InputError(
                source, "units", "cannot guess units without head/ankle joints; pass --units m (or cm, mm, inch)"
            )
        units = guess_units(raw)
    pos = pos * unit_scale(units, source)
    height = subject_height if subject_height is not None else plausible_height(estimate_height(pos, skeleton))
    return HumanClip(skeleton, pos, fps, source, subject_height=height)


# What numpy.load / NpzFile raise on an unreadable archive: empty or truncated (EOFError, BadZipFile), a damaged
# member (zlib.error, a CRC BadZipFile, a garbled .npy header: ValueError, SyntaxError, TokenError, struct.error),
# an encrypted or unsupported member (RuntimeError, NotImplementedError), or no such file (OSError).
_NPZ_ERRORS = (
    OSError,
    ValueError,
    EOFError,
    SyntaxError,
    RuntimeError,
    zipfile.BadZipFile,
    zlib.error,
    struct.error,
    tokenize.TokenError,
)


@contextmanager
def open_npz(path: str | Path) -> Iterator[np.lib.npyio.NpzFile]:
    """``np.load(path, allow_pickle=False)`` as a context manager; an empty, truncated or corrupt ``.npz`` (also one
    whose member breaks while read inside the ``with`` block) is a one-line :class:`InputError` naming the file.

    Every ``.npz`` reader opens its file through this (or :func:`load_npz`), so none ends in a traceback."""
    if Path(path).is_file() and Path(path).stat().st_size == 0:
        raise InputError(path, "file", "is empty (0 bytes), not an npz archive")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):  # a lone .npy array renamed .npz
            raise InputError(path, "file", "holds one .npy array, not an npz archive of named arrays")
        with loaded as d:
            yield d
    except InputError:
        raise
    except _NPZ_ERRORS as e:
        kind = type(e).__name__ if type(e).__module__ == "builtins" else f"{type(e).__module__}.{type(e).__name__}"
        raise InputError(path, "file", f"not a readable npz ({kind}: {e})") from None


def load_npz(path: str | Path) -> tuple[dict[str, np.ndarray], list[str]]:
    """All plain arrays of an ``.npz`` (no pickles), and the names of pickled members left out.

    An unreadable file is a one-line :class:`InputError` (see :func:`open_npz`)."""
    with open_npz(path) as d:
        out, skipped = {}, []
        for k in d.files:
            try:
                out[k] = d[k]
            except ValueError as e:  # an object array needs pickle: never loaded
                if "allow_pickle" not in str(e):
                    raise
                skipped.append(k)
        return out, skipped


def _npz_str(d: dict, key: str, default: str) -> str:
    return str(d[key].item()) if key in d else default


def read_keypoints_npz(
    path: str | Path, *, fps: float | None = None, units: str | None = None, subject_height: float | None = None
) -> HumanClip:
    """A keypoints ``.npz`` (see the module doc) as a z-up metre :class:`HumanClip`; ``fps`` and ``units`` are used
    where the file holds none (default units: metres)."""
    src = str(path)
    d, skipped = load_npz(path)
    key = "joint_pos" if "joint_pos" in d else "positions" if "positions" in d else None
    if key is None:
        raise InputError(src, "joint_pos", f"missing (keys are {', '.join(sorted(d) + skipped)})")
    if "joint_names" not in d:
        why = "stored as a pickled object array (save the names as strings)" if "joint_names" in skipped else "missing"
        raise InputError(src, "joint_names", f"{why}: a keypoints npz must name its joints")
    names = [str(n) for n in np.asarray(d["joint_names"]).reshape(-1)]
    parents = np.asarray(d["parents"]).astype(int).reshape(-1).tolist() if "parents" in d else [-1] * len(names)
    rate = float(np.asarray(d["fps"]).reshape(-1)[0]) if "fps" in d else fps
    if rate is None:
        raise InputError(src, "fps", "missing from the file; pass --fps N")
    if len(parents) != len(names):
        raise InputError(src, "parents", f"{len(parents)} parents for {len(names)} joint names")
    units, up = _npz_str(d, "units", units or "m"), _npz_str(d, "up", "z")
    return keypoints_clip(d[key], names, parents, rate, src, units=units, up=up, subject_height=subject_height)


def _csv_layout(header: list[str], src: str) -> tuple[list[str], list[int], int | None]:
    """Joint names, the column index of each ``<joint>_x``, and the ``time`` column (or None)."""
    cols = [h.strip() for h in header]
    time_col = cols.index("time") if "time" in cols else None
    data = [i for i, c in enumerate(cols) if c not in ("frame", "time")]
    if not data or len(data) % 3:
        raise InputError(src, "header", f"expected <joint>_x,<joint>_y,<joint>_z columns, got {len(data)} data columns")
    names, starts = [], []
    for k in range(0, len(data), 3):
        trio = [cols[i] for i in data[k : k + 3]]
        stem = trio[0][:-2]
        if not stem or trio != [f"{stem}_x", f"{stem}_y", f"{stem}_z"]:
            raise InputError(src, "header", f"columns {trio} are not <joint>_x,<joint>_y,<joint>_z")
        names.append(stem)
        starts.append(data[k])
    return names, starts, time_col


def read_keypoints_csv(
    path: str | Path, *, fps: float | None = None, units: str = "m", up: str = "z", subject_height: float | None = None
) -> HumanClip:
    """A keypoints ``.csv`` (see the module doc); ``fps`` is required unless a uniformly sampled ``time`` column
    exists (with a ``time`` column that is not, ``fps`` reads the rows at that rate)."""
    src = str(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise InputError(src, "header", "the file is empty")
    names, starts, time_col = _csv_layout(rows[0], src)
    body = [r for r in rows[1:] if any(c.strip() for c in r)]
    if not body:
        raise InputError(src, "joint_pos", "has zero frames")
    width = len(rows[0])
    values = np.empty((len(body), width))
    for k, r in enumerate(body):
        if len(r) != width:
            raise InputError(src, f"row {k + 2}", f"has {len(r)} columns, the header has {width}", frame=k)
        try:
            values[k] = [float(c) for c in r]
        except ValueError as e:
            raise InputError(src, f"row {k + 2}", f"not a number ({e})", frame=k) from None
    if time_col is not None:
        dt = np.diff(values[:, time_col])
        if len(dt) == 0:
            raise InputError(src, "time", "needs at least two rows to give a frame rate")
        if not np.all(dt > 0):
            k = int(np.flatnonzero(dt <= 0)[0]) + 1
            raise InputError(
                src, "time", f"is not increasing ({values[k - 1, time_col]} then {values[k, time_col]})", frame=k
            )
        uniform = np.ptp(dt) <= 0.01 * np.median(dt)
        if not uniform and fps is None:
            why = "is not uniformly sampled (resample to a fixed rate first, or pass --fps N to read the rows at N Hz)"
            raise InputError(src, "time", why)
        fps = 1.0 / float(np.median(dt)) if uniform else fps
    if fps is None:
        raise InputError(src, "fps", "no time column; pass --fps N")
    pos = np.stack([values[:, s : s + 3] for s in starts], axis=1)
    return keypoints_clip(pos, names, [-1] * len(names), fps, src, units=units, up=up, subject_height=subject_height)
