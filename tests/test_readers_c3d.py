"""C3D reader: the real pyomeca recording, gap filling, axes, and bad files written with ezc3d."""

import struct
import warnings

import ezc3d
import numpy as np
import pytest
from mocap_paths import SHARED_MOCAP, expect_input_error, needs_shared

from pipeline.readers.c3d import read_c3d

REAL = SHARED_MOCAP / "c3d" / "markers_analogs.c3d"
LONG_GAPS = {"Daphnee:STERl", "Daphnee:SCAP_CP", "Daphnee:LARMl"}  # gaps of 27, 71, 45 frames at 100 Hz


@needs_shared
def test_real_markers_mm_to_m():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        c = read_c3d(REAL)
    assert c.frames == 580 and c.fps == 100.0 and len(c.skeleton.joint_names) == 51
    assert c.skeleton.joint_names[0] == "boite:gauche_ext" and set(c.skeleton.parents) == {-1}
    z = c.joint_pos[..., 2]
    assert 0.0 < z.min() and z.max() < 1.2  # millimetres -> metres (raw values reach 1084)
    assert np.isfinite(c.joint_pos).all()
    (w,) = [x for x in caught if "gaps longer" in str(x.message)]
    assert all(name in str(w.message) for name in LONG_GAPS)


@needs_shared
def test_short_gaps_are_linear_and_long_gap_policies(tmp_path):
    raw = ezc3d.c3d(str(REAL))
    pts = raw["data"]["points"][:3] / 1000.0
    labels = raw["parameters"]["POINT"]["LABELS"]["value"]
    m = labels.index("Daphnee:CLAVl")  # one missing frame: 336
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c = read_c3d(REAL)
    np.testing.assert_allclose(c.joint_pos[336, m], (pts[:, m, 335] + pts[:, m, 337]) / 2, atol=1e-9)
    np.testing.assert_allclose(c.joint_pos[300, m], pts[:, m, 300], atol=1e-9)
    with pytest.warns(UserWarning, match="dropped markers"):
        dropped = read_c3d(REAL, long_gaps="drop")
    assert len(dropped.skeleton.joint_names) == 48 and not LONG_GAPS & set(dropped.skeleton.joint_names)
    assert len(read_c3d(REAL, max_gap=1.0).skeleton.joint_names) == 51  # every gap is short now
    expect_input_error(
        lambda: read_c3d(REAL, long_gaps="error"),
        REAL.parent,
        file=REAL,
        field="marker Daphnee:STERl",
        frame=233,
        match=r"gap of 27 frames \(233-259\)",
    )


def _write(path, points, labels=("a", "b"), units="mm", y_screen=None):
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [50.0]
    c["parameters"]["POINT"]["LABELS"]["value"] = tuple(labels)
    c["parameters"]["POINT"]["UNITS"]["value"] = [units]
    if y_screen:
        c.add_parameter("POINT", "Y_SCREEN", [y_screen])
    data = np.ones((4,) + points.shape[1:])
    data[:3] = points
    c["data"]["points"] = data
    c.write(str(path))
    return path


def _walk(T=10):
    p = np.zeros((3, 2, T))
    p[0] = np.linspace(0, 900, T)  # x forward in mm
    p[1, 1], p[2] = 100.0, 1000.0
    return p


def test_y_up_lab_and_units(tmp_path):
    pts = _walk()
    z_up = read_c3d(_write(tmp_path / "z.c3d", pts))
    np.testing.assert_allclose(z_up.joint_pos[-1, 1], [0.9, 0.1, 1.0])
    y_up = read_c3d(_write(tmp_path / "y.c3d", pts, y_screen="+Y"))  # the lab's y is up: (x, y, z) -> (x, -z, y)
    np.testing.assert_allclose(y_up.joint_pos[-1, 1], [0.9, -1.0, 0.1])
    metres = read_c3d(_write(tmp_path / "m.c3d", pts / 1000, units="m"))
    np.testing.assert_allclose(metres.joint_pos, z_up.joint_pos, atol=1e-6)


def test_all_gap_marker(tmp_path):
    pts = _walk()
    pts[:, 1, :] = np.nan
    p = _write(tmp_path / "gap.c3d", pts)
    expect_input_error(lambda: read_c3d(p), tmp_path, file=p, field="marker b", match="all gap")


def test_zero_frames(tmp_path):
    p = _write(tmp_path / "zero.c3d", _walk(1))
    b = bytearray(p.read_bytes())
    first = struct.unpack("<H", bytes(b[6:8]))[0]
    b[8:10] = struct.pack("<H", first - 1)  # header: last frame before the first
    p.write_bytes(bytes(b))
    expect_input_error(lambda: read_c3d(p), tmp_path, file=p, field="frames", match="zero frames")


def test_unknown_units_and_not_c3d(tmp_path):
    p = _write(tmp_path / "furlong.c3d", _walk(), units="furlong")
    expect_input_error(lambda: read_c3d(p), tmp_path, file=p, field="POINT:UNITS", match="'furlong'")
    q = tmp_path / "text.c3d"
    q.write_text("not a c3d file at all\n" * 40)
    expect_input_error(lambda: read_c3d(q), tmp_path, file=q, field="file")
