"""Mocap readers: every supported file (or a folder of them) -> validated clips, z-up metres.

=========  ====================================================================================
suffix     reader
=========  ====================================================================================
``.bvh``   :func:`~pipeline.readers.bvh.read_bvh` (any skeleton; units and up axis guessed)
``.pt``    :func:`~pipeline.readers.omomo.read_omomo` (OMOMO / InterMimic 591 columns + mesh)
``.npz``   by its keys: ``poses`` -> AMASS (:func:`~pipeline.readers.amass.read_amass`, needs
           ``body_model``); ``joint_pos [T,J,3]`` / ``positions`` -> keypoints; ``joint_pos
           [T,36|29]`` -> a peer's G1 motion (:func:`read_robot_clip`, not a human clip)
``.c3d``   :func:`~pipeline.readers.c3d.read_c3d` (labelled markers)
``.mcap``  :func:`~pipeline.readers.mcap_reader.read_mcap` (transform / rigid-body streams)
``.csv``   by its content (:func:`csv_kind`): a header row -> keypoints
           (:func:`~pipeline.readers.keypoints.read_keypoints_csv`); rows of 36 numbers and no header ->
           a Unitree G1 motion (:func:`read_robot_clip`, not a human clip)
``.pkl``   GMR robot motion, through :func:`read_robot_clip` only
=========  ====================================================================================

G1 motions (peers' retargeting: BeyondMimic/mjlab ``.npz``, GMR ``.pkl``, Unitree ``.csv``, HDMI ``motion.npz`` +
``meta.json`` folders) are read by :func:`read_robot_clip` / :func:`read_robot_clips` (:mod:`pipeline.readers.peers`);
``fmt=`` (one of :data:`ROBOT_FORMATS`) names the format where the suffix or content would not (e.g. a Unitree CSV
with a header row).

A folder yields every clip inside it and in its direct sub-folders, sorted by relative path.
Files that are not human clips are skipped there: other suffixes (meshes, ``height_dict.pkl``),
peers' robot ``.npz`` and ``.csv``, ``.npz`` files with none of the keys above, and ``.mcap`` files without a
transform stream (e.g. inspection logs). Any other problem in a clip is an error, as for a file; an empty,
truncated or corrupt ``.npz`` is a one-line :class:`~pipeline.errors.InputError` naming it
(:func:`~pipeline.readers.keypoints.open_npz`, through which every ``.npz`` reader opens its file).

``fps`` is a fallback rate for files that carry none (CSV without a ``time`` column, or with one not uniformly
sampled, keypoint ``.npz`` without ``fps``) and the sampling rate of MCAP streams; files with their own rate keep it.
``units`` (``auto``, ``m``, ``cm``, ``mm``, ``inch``) are those of files that do not say: BVH (default: guessed from the
subject's height) and keypoints (default: metres, or the ``.npz``'s ``units``); the other formats carry theirs.
``mesh`` is the object mesh of an OMOMO ``.pt`` (default: found beside it by the file's name). The command line's
``lessmimic retarget --fps N --units U --object-mesh PATH`` pass them.
"""

from __future__ import annotations

import csv
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from pipeline.clip import HumanClip, RobotClip
from pipeline.errors import InputError
from pipeline.geometry import ObjectGeometry
from pipeline.readers.keypoints import open_npz
from pipeline.suspicious import SUSPICIOUS_ROOT_SPEED_MPS, check_height, suspect

HUMAN_SUFFIXES = (".bvh", ".pt", ".npz", ".c3d", ".mcap", ".csv")
ROBOT_SUFFIXES = (".npz", ".pkl", ".csv")
ROBOT_FORMATS = ("beyondmimic-npz", "gmr-pkl", "unitree-csv")  #: ``read_robot_clip(fmt=...)``
_SUFFIX_FORMAT = dict(zip(ROBOT_SUFFIXES, ROBOT_FORMATS))


class _NotHuman(InputError):
    """A readable file that is not a human clip (skipped inside folders)."""


def npz_kind(path: str | Path) -> str | None:
    """``"amass"``, ``"keypoints"``, ``"robot"`` or ``None`` from an ``.npz``'s keys."""
    with open_npz(path) as d:  # an empty or corrupt file: a one-line InputError
        keys = set(d.files)
        if "poses" in keys:
            return "amass"
        if "positions" in keys:
            return "keypoints"
        if "joint_pos" in keys:
            return "keypoints" if d["joint_pos"].ndim == 3 else "robot"
    return None


def csv_kind(path: str | Path) -> str:
    """``"robot"`` when a ``.csv``'s first non-empty row is 36 numbers (Unitree's G1 layout: no header), else
    ``"keypoints"`` (a header row of names); an unreadable file is a one-line :class:`InputError`."""
    from pipeline.readers.peers import UNITREE_CSV_COLUMNS, csv_numbers

    try:
        with open(path, newline="") as f:
            first = next((r for r in csv.reader(f) if any(c.strip() for c in r)), [])
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InputError(path, "file", f"not a readable CSV file ({exc})") from None
    robot = len(first) == UNITREE_CSV_COLUMNS and csv_numbers(first) is not None
    return "robot" if robot else "keypoints"


#: Faster than this between two frames, a clip's root (the skeleton's first joint without a parent) is a broken file
#: or a unit error (a sprinter peaks near 12 m/s), never a person.
MAX_ROOT_SPEED_MPS = 15.0


def check_root_speed(clip: HumanClip, path: str | Path) -> HumanClip:
    """``clip``, or an :class:`InputError` naming the first frame whose root moved faster than
    :data:`MAX_ROOT_SPEED_MPS` since the frame before; faster than
    :data:`~pipeline.suspicious.SUSPICIOUS_ROOT_SPEED_MPS` is a warning (:func:`pipeline.suspicious.suspect`)."""
    root = int(np.flatnonzero(np.asarray(clip.skeleton.parents) < 0)[0])
    speed = np.linalg.norm(np.diff(clip.joint_pos[:, root], axis=0), axis=1) * clip.fps
    name = clip.skeleton.joint_names[root]
    if (speed > MAX_ROOT_SPEED_MPS).any():
        k = int(np.flatnonzero(speed > MAX_ROOT_SPEED_MPS)[0])
        why = (
            f"moves {speed[k]:.4g} m/s since the frame before (above {MAX_ROOT_SPEED_MPS:g} m/s): a jump or a wrong "
            "unit (--units), not motion"
        )
        raise InputError(path, f"{name} position", why, frame=k + 1)
    if (fast := speed > SUSPICIOUS_ROOT_SPEED_MPS).any():
        k = int(np.flatnonzero(fast)[0])
        why = (
            f"moves {speed[k]:.4g} m/s since the frame before ({int(fast.sum())} frame(s) above "
            f"{SUSPICIOUS_ROOT_SPEED_MPS:g} m/s, a run); read as it is"
        )
        suspect(path, f"{name} position", why, frame=k + 1)
    return clip


def read_clip(
    path: str | Path,
    *,
    body_model: str | Path | None = None,
    fps: float | None = None,
    mesh: str | Path | None = None,
    units: str | None = None,
) -> HumanClip:
    """One human clip file, dispatched by suffix (see the module doc); its root's speed checked
    (:func:`check_root_speed`), its stated height against its joints' (:func:`pipeline.suspicious.check_height`)."""
    clip = check_root_speed(_read_clip(Path(path), body_model, fps, mesh, units), path)
    check_height(clip, path)
    return clip


def _read_clip(path: Path, body_model, fps, mesh, units) -> HumanClip:
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        from pipeline.readers.bvh import read_bvh

        return read_bvh(path, units=units or "auto")
    if suffix == ".pt":
        from pipeline.readers.omomo import read_omomo

        return read_omomo(path, mesh=mesh)
    if suffix == ".c3d":
        from pipeline.readers.c3d import read_c3d

        return read_c3d(path)
    if suffix == ".mcap":
        from pipeline.readers.mcap_reader import read_mcap

        return read_mcap(path, fps=fps)
    if suffix == ".csv":
        from pipeline.readers.keypoints import read_keypoints_csv

        if csv_kind(path) == "robot":
            raise _NotHuman(
                path,
                "columns",
                "36 numbers a row and no header: a G1 robot motion (Unitree CSV), not a human clip: read it with "
                "read_robot_clip",
            )
        return read_keypoints_csv(path, fps=fps, units=units or "m")
    if suffix == ".npz":
        return _read_npz(path, body_model, fps, units)
    raise InputError(
        path, "suffix", f"unknown clip format {path.suffix or '(none)'!r}; expected one of {', '.join(HUMAN_SUFFIXES)}"
    )


def _read_npz(path: Path, body_model, fps, units) -> HumanClip:
    kind = npz_kind(path)
    if kind == "amass":
        from pipeline.readers.amass import read_amass

        return read_amass(path, body_model)
    if kind == "keypoints":
        from pipeline.readers.keypoints import read_keypoints_npz

        return read_keypoints_npz(path, fps=fps, units=units)
    if kind == "robot":
        raise _NotHuman(
            path,
            "joint_pos",
            "is a G1 robot motion (BeyondMimic/mjlab npz), not a human clip: read it with read_robot_clip / --robot",
        )
    raise _NotHuman(path, "keys", "none of 'poses' (AMASS), 'joint_pos'/'positions' (keypoints or robot motion)")


def _candidates(folder: Path) -> list[Path]:
    files = [p for p in folder.iterdir() if p.is_file()]
    for sub in (p for p in folder.iterdir() if p.is_dir() and not p.name.startswith(".")):
        files += [p for p in sub.iterdir() if p.is_file()]
    return sorted(
        (p for p in files if p.suffix.lower() in HUMAN_SUFFIXES), key=lambda p: p.relative_to(folder).as_posix()
    )


def read_clips(
    path: str | Path,
    *,
    body_model: str | Path | None = None,
    fps: float | None = None,
    mesh: str | Path | None = None,
    units: str | None = None,
) -> list[HumanClip]:
    """Every human clip in ``path`` (a file, or a folder searched one level deep)."""
    path = Path(path)
    options = {"body_model": body_model, "fps": fps, "mesh": mesh, "units": units}
    if not path.exists():
        raise InputError(path, "input", "does not exist")
    if path.is_file():
        return [read_clip(path, **options)]
    if not path.is_dir():
        raise InputError(path, "input", "is neither a file nor a folder (a FIFO or a device?)")
    clips = []
    for p in _candidates(path):
        try:
            clips.append(read_clip(p, **options))
        except _NotHuman:
            continue
        except InputError as e:
            if p.suffix.lower() == ".mcap" and e.field == "topics":  # an MCAP without transform streams
                continue
            raise
    if not clips:
        raise InputError(
            path, "input", f"no readable human clips ({', '.join(HUMAN_SUFFIXES)}) in this folder or its sub-folders"
        )
    return clips


def read_robot_clip(
    path: str | Path,
    *,
    object_geometry: ObjectGeometry | None = None,
    object_scale: float = 1.0,
    object_name: str | None = None,
    joint_names: Sequence[str] | None = None,
    fmt: str | None = None,
    fps: float | None = None,
) -> RobotClip:
    """A peer's G1 motion: BeyondMimic/mjlab ``.npz``, GMR ``.pkl`` or Unitree ``.csv`` (see
    :mod:`pipeline.readers.peers`), by suffix (and a CSV's content), or by ``fmt`` (:data:`ROBOT_FORMATS`);
    ``fps`` is the rate of a CSV (default 30 Hz: it carries none)."""
    from pipeline.readers.peers import UNITREE_CSV_FPS, read_beyondmimic_npz, read_gmr_pkl, read_unitree_csv

    path = Path(path)
    if not path.is_file():
        raise InputError(path, "input", "does not exist or is not a file")
    if fmt is not None and fmt not in ROBOT_FORMATS:
        raise InputError(path, "format", f"unknown robot motion format {fmt!r}; expected one of {ROBOT_FORMATS}")
    kind = fmt or _SUFFIX_FORMAT.get(path.suffix.lower())
    obj = {"object_geometry": object_geometry, "object_scale": object_scale, "object_name": object_name}
    if kind == "gmr-pkl":
        return read_gmr_pkl(path, **obj)
    if kind == "unitree-csv":
        if fmt is None and csv_kind(path) != "robot":
            raise InputError(path, "columns", "is not a Unitree G1 CSV (expected 36 numbers a row, no header)")
        return read_unitree_csv(path, fps=fps or UNITREE_CSV_FPS)
    if kind == "beyondmimic-npz":
        if npz_kind(path) != "robot":
            raise InputError(path, "joint_pos", "is not a G1 motion npz (expected joint_pos [T, 36] or [T, 29])")
        return read_beyondmimic_npz(path, **obj, joint_names=joint_names)
    raise InputError(
        path, "suffix", f"unknown robot motion format {path.suffix or '(none)'!r}; expected .npz, .pkl or .csv"
    )


def _robot_candidates(folder: Path) -> list[Path]:
    """G1 motion files and HDMI motion folders at or below ``folder``, sorted by relative path."""
    out = []
    for p in sorted(folder.rglob("*"), key=lambda p: p.relative_to(folder).as_posix()):
        if p.is_dir() and (p / "motion.npz").is_file() and (p / "meta.json").is_file():
            out.append(p)
        elif p.is_file() and p.parent not in out and p.suffix.lower() == ".pkl" and p.name != "height_dict.pkl":
            out.append(p)
        elif p.is_file() and p.suffix.lower() == ".npz" and p.name != "motion.npz" and npz_kind(p) == "robot":
            out.append(p)
        elif p.is_file() and p.suffix.lower() == ".csv" and csv_kind(p) == "robot":
            out.append(p)
    return out


def read_robot_clips(
    path: str | Path, *, object_geometry: ObjectGeometry | None = None, joint_names: Sequence[str] | None = None
) -> list[RobotClip]:
    """Every G1 motion in ``path``: a BeyondMimic/mjlab ``.npz``, a GMR ``.pkl``, a Unitree ``.csv`` (30 Hz), an HDMI
    motion folder, or a folder of them (searched recursively). An object a file carries must have a geometry
    (``object_geometry``, else ``<name>.obj`` beside the file): a one-line :class:`InputError` otherwise, as for any
    unreadable file. ``joint_names``: the column order of the ``.npz`` files that name none of their joints
    (``--joint-names``; :func:`pipeline.readers.peers.read_beyondmimic_npz`)."""
    from pipeline.readers.peers import object_mesh_beside, read_hdmi_motion

    path = Path(path)
    if not path.exists():
        raise InputError(path, "input", "does not exist")
    if path.is_dir() and (path / "motion.npz").is_file():
        items = [path]
    elif path.is_dir():
        items = _robot_candidates(path)
    else:
        items = [path]
    clips = []
    for item in items:
        if item.is_dir():
            clips.append(read_hdmi_motion(item, object_geometry=object_geometry))
            continue
        with warnings.catch_warnings():  # an object left out for want of geometry is looked for beside the file
            warnings.simplefilter("ignore", UserWarning)
            clip = read_robot_clip(item, object_geometry=object_geometry, joint_names=joint_names)
        left_out = clip.provenance.get("object_left_out")
        if left_out is not None:
            geometry = object_mesh_beside(item, left_out)
            if geometry is None:
                raise InputError(
                    item, f"object {left_out}", "has no geometry: pass --object-mesh or put <name>.obj beside it"
                )
            clip = read_robot_clip(item, object_geometry=geometry, object_name=left_out, joint_names=joint_names)
        clips.append(clip)
    if not clips:
        raise InputError(path, "input", "no G1 motions (.npz, .pkl, .csv, HDMI motion folders) in this folder")
    return clips
