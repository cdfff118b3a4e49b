"""Depth-sensor noise (train.vision.noise): each term does what it says on synthetic images (stereo noise grows as
z^2, quantisation lands on the disparity grid, dropout at its rate, holes are rectangles, edges only at jumps,
invalid reads 0 and valid stays in [near, far]); the sensor's latency, repeated frames, per-episode extrinsics and
per-step jitter on a stub camera; all off reads the clean render exactly on a real G1 scene, and a seed fixes the
sequence; uint16 millimetres round-trip; bad settings are one-line errors."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest
from mocap_paths import expect_input_error

from pipeline.geometry import Primitive
from pipeline.robot import actuator_profile
from pipeline.scene import SceneObject, build_scene
from train.vision.camera import CameraOffset, DepthCamera
from train.vision.noise import (
    DepthNoise,
    DepthSensor,
    EpisodeDraw,
    corrupt,
    depth_edges,
    depth_to_mm,
    dropout_mask,
    edge_mask,
    hole_mask,
    mm_to_depth,
    quantise_disparity,
    stereo_noise,
)

OFF = DepthNoise.off()


def _rng(seed=0):
    return np.random.default_rng(seed)


def test_stereo_noise_grows_as_depth_squared():
    c = 0.004
    one = stereo_noise(np.full((200, 200), 1.0, np.float32), c, _rng(1))
    two = stereo_noise(np.full((200, 200), 2.0, np.float32), c, _rng(2))
    assert one.dtype == np.float32 and abs(one.std() - c) < 0.03 * c  # sigma = c z^2: 4 mm at 1 m
    assert abs(two.std() / one.std() - 4.0) < 0.15  # ... and 16 mm at 2 m
    assert abs(one.mean() - 1.0) < 1e-4 and abs(two.mean() - 2.0) < 4e-4  # unbiased
    z = np.ones((4, 4), np.float32)
    assert stereo_noise(z, 0.0, _rng()) is z


def test_quantisation_lands_on_the_disparity_grid():
    q = 0.0014
    z = np.linspace(0.3, 3.0, 5000, dtype=np.float32)
    zq = quantise_disparity(z, q)
    n = 1.0 / (q * zq.astype(np.float64))
    assert zq.dtype == np.float32 and np.all(np.abs(n - np.rint(n)) < 1e-3)  # z = 1 / (q n), n whole
    assert np.all(np.abs(zq - z) <= 0.5 * q * z.astype(np.float64) ** 2 * 1.01 + 1e-6)  # half a step, q z^2
    levels = np.unique(zq)
    levels = levels[levels > 1.0]  # every level beyond 1 m is hit (steps > 1.4 mm, samples 0.54 mm apart)
    mid = (levels[1:] + levels[:-1]) / 2
    np.testing.assert_allclose(np.diff(levels), q * mid**2, rtol=0.01)  # the step grows as q z^2: 12.6 mm at 3 m
    assert quantise_disparity(z, 0.0) is z
    assert quantise_disparity(np.zeros(3, np.float32), q).tolist() == [0.0, 0.0, 0.0]  # invalid stays 0


def test_dropout_invalidates_pixels_at_its_rate():
    mask = dropout_mask((200, 200), 0.1, _rng())
    assert mask.dtype == bool and abs(mask.mean() - 0.1) < 0.01
    assert dropout_mask((200, 200), 0.0, _rng()) is None


def test_holes_are_rectangles_of_their_size():
    rng = _rng(3)
    for _ in range(50):
        mask = hole_mask((40, 64), 1, (2, 5), rng)
        rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
        assert np.all(mask[rows[0] : rows[-1] + 1, cols[0] : cols[-1] + 1])  # one filled rectangle
        assert 1 <= len(rows) <= 5 and 1 <= len(cols) <= 5  # cut by the border at most
        assert mask.sum() == len(rows) * len(cols)
    several = hole_mask((40, 64), 3, (4, 4), rng)
    assert 0 < several.sum() <= 3 * 16
    assert hole_mask((40, 64), 0, (2, 5), rng) is None


def test_edge_pixels_are_only_beside_depth_jumps():
    z = np.tile(np.linspace(1.0, 1.5, 64, dtype=np.float32), (40, 1))  # a slope: 8 mm per pixel, no edge
    z[10:20, 30:40] = 0.6  # a box in front of it
    edges = depth_edges(z, 0.2)
    box = np.zeros_like(edges)
    box[9:21, 29:41] = True
    box[10:20, 30:40] = True
    ring = box.copy()
    ring[11:19, 31:39] = False  # the box's own border and the background pixels beside it
    ring[[9, 9, 20, 20], [29, 40, 29, 40]] = False  # diagonal corners are not 4-neighbours
    assert np.array_equal(edges, ring)
    assert np.array_equal(edge_mask(z, 0.2, 1.0, _rng()), edges)
    half = np.mean([edge_mask(z, 0.2, 0.5, _rng(s))[edges].mean() for s in range(20)])
    assert abs(half - 0.5) < 0.05
    assert not edge_mask(z, 0.2, 0.5, _rng())[~edges].any()
    assert edge_mask(z, 0.2, 0.0, _rng()) is None


def test_invalid_pixels_read_zero_and_valid_ones_stay_in_range():
    clean = np.tile(np.linspace(0.1, 3.0, 64, dtype=np.float32), (40, 1))
    noise = replace(DepthNoise(), stereo_coeff=(0.05, 0.05), dropout=(0.2, 0.2), holes=(2, 2))
    episode = EpisodeDraw(CameraOffset(), 0, 0.05, 0.2)
    z = corrupt(clean, noise, episode, 0.1, 3.0, _rng())
    valid = z != 0.0
    assert z.dtype == np.float32 and 0.1 < 1 - valid.mean() < 0.5
    assert z[valid].min() >= 0.1 and z[valid].max() <= 3.0
    assert (z[valid] == 3.0).any() and (z[valid] == np.float32(0.1)).any()  # noise pushed past both ends: clipped


def test_all_off_is_the_clean_image_exactly():
    clean = _rng().uniform(0.1, 3.0, (40, 64)).astype(np.float32)
    clean[:, 20] = 3.0
    episode = OFF.draw(_rng())
    assert episode == EpisodeDraw(CameraOffset(), 0, 0.0, 0.0)
    assert np.array_equal(corrupt(clean, OFF, episode, 0.1, 3.0, _rng()), clean)


class _Stub:
    """A camera whose k-th render is an image filled with k, recording the offsets it was given."""

    near, far = 0.1, 3.0

    def __init__(self):
        self.offsets = []

    def render(self, m, d, offset=None):
        self.offsets.append(offset)
        return np.full((4, 5), float(len(self.offsets) - 1), np.float32)


def _reads(sensor, n):
    return [float(sensor.read(None, None)[0, 0]) for _ in range(n)]


@pytest.mark.parametrize("k", [0, 1, 2])
def test_latency_returns_the_frame_k_steps_old(k):
    sensor = DepthSensor(_Stub(), replace(OFF, latency=(k, k)), _rng())
    assert sensor.episode.latency == k
    assert _reads(sensor, 6) == [max(t - k, 0) for t in range(6)]  # the first frame until one k steps old
    drawn = {DepthSensor(_Stub(), replace(OFF, latency=(0, 2)), _rng(s)).episode.latency for s in range(30)}
    assert drawn == {0, 1, 2}


def test_a_repeated_frame_is_the_previous_output():
    assert _reads(DepthSensor(_Stub(), replace(OFF, repeat_prob=1.0), _rng()), 4) == [0, 0, 0, 0]
    out = _reads(DepthSensor(_Stub(), replace(OFF, repeat_prob=0.3), _rng()), 400)
    repeated = [out[t] == out[t - 1] for t in range(1, 400)]
    assert all(r or out[t] == t for t, r in enumerate(repeated, start=1))  # the previous output, or the newest frame
    assert abs(np.mean(repeated) - 0.3) < 0.06


def test_extrinsics_are_fixed_within_an_episode_and_redrawn_at_reset():
    stub = _Stub()
    sensor = DepthSensor(stub, replace(OFF, extrinsic_pos=0.01, extrinsic_rot=0.02), _rng())
    _reads(sensor, 3)
    first = sensor.episode.offset
    assert stub.offsets == [first] * 3 and not first.is_zero
    assert max(map(abs, first.pos)) <= 0.01 and max(map(abs, first.rot)) <= 0.02
    sensor.reset()
    _reads(sensor, 3)
    assert stub.offsets[3:] == [sensor.episode.offset] * 3 and sensor.episode.offset != first


def test_jitter_differs_every_step_around_the_episode_offset():
    stub = _Stub()
    noise = replace(OFF, extrinsic_pos=0.01, extrinsic_rot=0.02, jitter_pos=0.001, jitter_rot=0.002)
    sensor = DepthSensor(stub, noise, _rng())
    _reads(sensor, 500)
    pos = np.array([o.pos for o in stub.offsets]) - sensor.episode.offset.pos
    rot = np.array([o.rot for o in stub.offsets]) - sensor.episode.offset.rot
    assert len({o.pos for o in stub.offsets}) == 500
    assert np.all(np.abs(pos.std(axis=0) - 0.001) < 0.0002) and np.all(np.abs(rot.std(axis=0) - 0.002) < 0.0003)
    assert np.all(np.abs(pos.mean(axis=0)) < 0.0002)


def _scene():
    wall = SceneObject(
        "wall", Primitive("box", (0.005, 3.0, 3.0)), pose=(1.5, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0), fixed=True
    )
    scene = build_scene([wall], actuator_profile("mjlab"))
    d = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, d)
    return scene.model, d


@pytest.fixture(scope="module")
def scene():
    return _scene()


def test_the_sensor_with_everything_off_reads_the_render_exactly(scene):
    m, d = scene
    camera = DepthCamera()
    sensor = DepthSensor(camera, OFF, _rng())
    clean = camera.render(m, d)
    assert clean.min() < 1.0 and clean.max() > 1.0  # the floor, the wall: something to corrupt
    for _ in range(3):
        assert np.array_equal(sensor.read(m, d), clean)


def test_a_seed_fixes_the_noisy_sequence(scene):
    m, d = scene
    runs = []
    for _ in range(2):
        sensor = DepthSensor(DepthCamera(), DepthNoise(), _rng(7))
        frames = [sensor.read(m, d) for _ in range(4)]
        sensor.reset()
        runs.append([*frames, sensor.read(m, d)])
    assert all(np.array_equal(a, b) for a, b in zip(*runs))
    clean = DepthCamera().render(m, d)
    assert not np.array_equal(runs[0][-1], clean) and runs[0][-1].dtype == np.float32
    with pytest.raises(ValueError):  # frames are read-only: they are also the latency buffer's
        runs[0][0][0, 0] = 1.0


def test_millimetres_round_trip():
    z = _rng().uniform(0.1, 3.0, 10_000).astype(np.float32)
    z[:10] = 0.0
    mm = depth_to_mm(z)
    assert mm.dtype == np.uint16 and np.all(mm[:10] == 0) and np.all(mm[10:] > 0)
    back = mm_to_depth(mm)
    assert back.dtype == np.float32 and np.all(np.abs(back - z) <= 0.0005 + 1e-6)
    assert np.all(back[:10] == 0.0)
    assert depth_to_mm(np.array([np.nan, 70.0])).tolist() == [0, 65535]


@pytest.mark.parametrize(
    "change, field",
    [
        ({"dropout": (0.5, 1.2)}, "dropout"),
        ({"edge_prob": 1.5}, "edge_prob"),
        ({"repeat_prob": -0.1}, "repeat_prob"),
        ({"stereo_coeff": (0.004, 0.001)}, "stereo_coeff"),
        ({"stereo_coeff": (0.001,)}, "stereo_coeff"),
        ({"latency": (0, 1.5)}, "latency"),
        ({"latency": (-1, 2)}, "latency"),
        ({"holes": (3, 1)}, "holes"),
        ({"hole_size": (0, 2)}, "hole_size"),
        ({"edge_threshold": 0.0}, "edge_threshold"),
        ({"jitter_pos": float("nan")}, "jitter_pos"),
        ({"extrinsic_rot": "0.02"}, "extrinsic_rot"),
    ],
)
def test_bad_settings_are_one_line_errors(change, field, tmp_path):
    expect_input_error(lambda: replace(DepthNoise(), **change), tmp_path, file="depth noise", field=field)
