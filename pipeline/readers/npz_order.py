"""The column order of a G1 motion ``.npz`` that names none of its joints, told by its own forward kinematics.

BeyondMimic's ``csv_to_npz.py`` and mjlab's write the same keys (``joint_pos [T, 29]``, ``body_pos_w [T, 30, 3]``,
...) and no names, in two orders: Isaac Lab's breadth-first (BeyondMimic; :mod:`motion_export.isaaclab`) and
MuJoCo's depth-first (mjlab; :data:`pipeline.robot.G1_JOINT_NAMES`). Only 2 of the 29 joint columns coincide, so
reading one as the other is silently wrong. The file tells which it is: for each candidate order the joint columns
are set on the G1 model with the root at the file's first body (the pelvis in both), and the bodies' forward
kinematics positions are compared with ``body_pos_w`` read in that order's body order, on up to
:data:`CHECK_FRAMES` frames spread over the clip. The order whose largest error is under :data:`MATCH_TOL_M` is
the file's (the right one agrees to ~1e-5 m, the wrong one is off by decimetres); none, or both, is a one-line
:class:`~pipeline.errors.InputError` asking for the names: ``--joint-names`` of ``lessmimic import``, ``inspect
--robot`` and ``evaluate-retarget`` (:func:`joint_names_option`), ``joint_names=`` of the readers.
"""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np

from pipeline.errors import InputError
from pipeline.isaaclab_order import ISAACLAB_BODY_NAMES, ISAACLAB_JOINT_NAMES
from pipeline.robot import G1_JOINT_NAMES, g1_model

MATCH_TOL_M = 0.01  # m: largest body position error for an order to match
CHECK_FRAMES = 8
#: ``--joint-names``'s named orders: the two a nameless file is written in (module doc).
NAMED_ORDERS: dict[str, tuple[str, ...]] = {"mjlab": G1_JOINT_NAMES, "isaaclab": ISAACLAB_JOINT_NAMES}
#: What the errors of a file whose order cannot be told ask for.
PASS_NAMES = "pass --joint-names mjlab or isaaclab, or the file's 29 joint names (a comma list or a file of them)"


def _few(names: list[str], shown: int = 4) -> str:
    return ", ".join(names[:shown]) + (f" (and {len(names) - shown} more)" if len(names) > shown else "")


def joint_names_option(value: str) -> tuple[str, ...]:
    """``--joint-names``: a named order of :data:`NAMED_ORDERS`, else a file of names, else a comma list (names
    split by commas and white space in both), the 29 G1 joints each once, in the file's column order; anything
    else is a one-line :class:`InputError` naming it."""
    if value in NAMED_ORDERS:
        return NAMED_ORDERS[value]
    path = Path(value)
    try:
        is_file = path.is_file()
    except OSError:  # a comma list too long for a path
        is_file = False
    shown = value if len(value) <= 40 else value[:37] + "..."
    src, text = (path, path.read_text(errors="replace")) if is_file else (shown, value)
    names = tuple(n for n in re.split(r"[,\s]+", text) if n)
    unknown = [n for n in dict.fromkeys(names) if n not in G1_JOINT_NAMES]
    missing = [n for n in G1_JOINT_NAMES if n not in names]
    if unknown or missing or len(names) != len(G1_JOINT_NAMES):
        what = [f"{len(names)} names"]
        what += [f"not G1 joints: {_few(unknown)}"] if unknown else []
        what += [f"missing: {_few(missing)}"] if missing else []
        what += [] if unknown or missing else ["some twice"]
        why = f"{'; '.join(what)}: expected {' or '.join(NAMED_ORDERS)}, or the 29 G1 joints in the file's order"
        raise InputError(src, "--joint-names", why)
    return names


def _orders() -> dict[str, tuple[tuple[str, ...], tuple[str, ...]]]:
    m = g1_model()
    mjlab_bodies = tuple(m.body(i).name for i in range(1, m.nbody))
    return {
        "Isaac Lab (BeyondMimic)": (ISAACLAB_JOINT_NAMES, ISAACLAB_BODY_NAMES),
        "mjlab": (G1_JOINT_NAMES, mjlab_bodies),
    }


def _fk_error(jp: np.ndarray, pos: np.ndarray, quat: np.ndarray, joints, bodies) -> float:
    """Largest distance [m] between ``body_pos_w`` (bodies in ``bodies`` order) and the forward kinematics of the
    joint columns read in ``joints`` order."""
    m = g1_model()
    d = mujoco.MjData(m)
    to_g1 = [list(joints).index(n) for n in G1_JOINT_NAMES]
    from_file = [list(bodies).index(m.body(i).name) for i in range(1, m.nbody)]
    err = 0.0
    for t in range(jp.shape[0]):
        d.qpos[:3], d.qpos[3:7], d.qpos[7:] = pos[t, 0], quat[t, 0], jp[t, to_g1]
        mujoco.mj_kinematics(m, d)
        err = max(err, float(np.abs(d.xpos[1:] - pos[t, from_file]).max()))
    return err


def nameless_order(d, src: str) -> tuple[str, tuple[str, ...]]:
    """``(order name, joint names)`` of a nameless ``.npz``'s ``joint_pos`` columns (module doc)."""
    jp = np.asarray(d["joint_pos"], np.float64)
    pos = np.asarray(d.get("body_pos_w", np.empty(0)), np.float64)
    quat = np.asarray(d.get("body_quat_w", np.empty(0)), np.float64)
    nb = g1_model().nbody - 1
    T = jp.shape[0]
    if jp.shape != (T, 29) or pos.shape != (T, nb, 3) or quat.shape != (T, nb, 4) or T == 0:
        why = f"missing, and without [T, 29] joints and [T, {nb}, .] bodies the order cannot be told: " + PASS_NAMES
        raise InputError(src, "joint_names", why)
    frames = np.unique(np.linspace(0, T - 1, min(T, CHECK_FRAMES)).round().astype(int))
    errors = {
        name: _fk_error(jp[frames], pos[frames], quat[frames], joints, bodies)
        for name, (joints, bodies) in _orders().items()
    }
    matches = [name for name, e in errors.items() if e < MATCH_TOL_M]
    if len(matches) != 1:
        figures = ", ".join(f"{name} {e:.3g} m" for name, e in errors.items())
        why = f"missing, and the bodies' kinematics match {len(matches)} known orders ({figures}): " + PASS_NAMES
        raise InputError(src, "joint_names", why)
    return matches[0], _orders()[matches[0]][0]
