"""The DF-latent VAE: reconstruction, deterministic encoding, checkpoints; and the tiny features dataset the training
tests share (:func:`write_tiny_features`: real LeRobot datasets from the project's writer, shaped like the features
stage's output)."""

from pathlib import Path

import numpy as np
import pytest
import torch

from pipeline.dataset import Episode, Feature, write_dataset
from pipeline.dataset.card import DatasetCard
from pipeline.errors import InputError
from pipeline.robot import G1_JOINT_NAMES, G1_LINK_NAMES
from pipeline.terms.interaction import interaction_features
from pipeline.terms.layout import DF_PARTS, PROPRIO_NAMES, ROOT_COMMAND_NAMES, feature_names
from train.vae import DFVAE, VAEConfig, evaluate_vae, load_vae, split_episodes, train_vae

torch.set_num_threads(1)

FPS = 50
LINKS = G1_LINK_NAMES  # K = 14
RADIUS = 0.3  # the object: a sphere of this radius at the origin


def _smooth(rng: np.random.Generator, t: np.ndarray, dim: int, scale: float = 1.0) -> np.ndarray:
    """``dim`` smooth signals over ``t``: offset + two sines of random frequency and phase."""
    c, a = rng.normal(0, scale, dim), rng.uniform(0.2, 1.0, (2, dim)) * scale
    w, ph = rng.uniform(0.5, 4.0, (2, dim)), rng.uniform(0, 2 * np.pi, (2, dim))
    return (c + (a[:, None] * np.sin(w[:, None] * t[None, :, None] + ph[:, None])).sum(0)).astype(np.float32)


def _df(rng: np.random.Generator, offsets: np.ndarray, t: np.ndarray) -> np.ndarray:
    """u_t of the links of a body moving past the sphere: link = root(t) + fixed offset; exact phi, grad, v."""
    r0, v = rng.uniform(-0.8, 0.8, 3) + [0, 0, 0.9], rng.uniform(-0.5, 0.5, 3)
    w, amp = rng.uniform(1.0, 3.0), rng.uniform(0.05, 0.2)
    root = r0 + v * t[:, None] + amp * np.sin(w * t)[:, None]
    root_vel = v + amp * w * np.cos(w * t)[:, None]
    x = root[:, None] + offsets[None]  # (T, K, 3)
    vel = np.broadcast_to(root_vel[:, None], x.shape)
    dist = np.linalg.norm(x, axis=-1)
    u = interaction_features(np.maximum(dist - RADIUS, 0.0), x / dist[..., None], vel)
    return u.reshape(len(t), -1).astype(np.float32)


def tiny_features(episodes: int = 3, frames: int = 60, seed: int = 0, drop: tuple[str, ...] = ()):
    """``(features, episodes)`` like the features stage writes: ``observation.df`` (K = 14 links x 10), proprio (93),
    root command (12) and ``action`` (29), the action a fixed linear function of the same frame's proprio and root
    command (learnable from the window's last step)."""
    rng = np.random.default_rng(seed)
    offsets = np.random.default_rng(123).uniform(-0.4, 0.4, (len(LINKS), 3))
    W = np.random.default_rng(7).normal(0, 0.15, (len(PROPRIO_NAMES) + len(ROOT_COMMAND_NAMES), 29))
    feats = [
        Feature("observation.df", "float32", feature_names(LINKS, DF_PARTS), "u_t per link", "m, 1, m/s"),
        Feature("observation.root_command", "float32", ROOT_COMMAND_NAMES, "root command"),
        Feature("observation.proprio", "float32", PROPRIO_NAMES, "proprioception"),
        Feature("action", "float32", G1_JOINT_NAMES, "joint position targets", "rad"),
    ]
    eps = []
    for k in range(episodes):
        t = np.arange(frames) / FPS
        proprio, cmd = _smooth(rng, t, len(PROPRIO_NAMES)), _smooth(rng, t, len(ROOT_COMMAND_NAMES), 0.5)
        action = (np.concatenate([proprio, cmd], 1) @ W).astype(np.float32)
        data = {"observation.df": _df(rng, offsets, t), "observation.root_command": cmd}
        data |= {"observation.proprio": proprio, "action": action}
        eps.append(Episode(f"task{k % 2}", data, {"k": k}))
    feats = [f for f in feats if f.name not in drop]
    for e in eps:
        e.data = {f.name: e.data[f.name] for f in feats}
    return feats, eps


def write_tiny_features(root: Path, episodes: int = 3, frames: int = 60, seed: int = 0, drop=(), profile="mjlab"):
    feats, eps = tiny_features(episodes, frames, seed, drop)
    card = DatasetCard(title="tiny features", actuator_profile=f"{profile}: test gains", stage="features")
    return write_dataset(root, "tester/tiny-features", FPS, feats, eps, card=card)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    return write_tiny_features(tmp_path_factory.mktemp("vae") / "features", episodes=40, frames=20)


CFG = VAEConfig(latent=16, hidden=(128, 128), batch=256, lr=2e-3)


def test_split_holds_out_a_tenth_of_the_episodes_at_least_one():
    assert split_episodes(1) == ([0], [])
    train, held = split_episodes(20)
    assert len(held) == 2 and sorted(train + held) == list(range(20))
    assert split_episodes(4) == split_episodes(4) and len(split_episodes(4)[1]) == 1


def test_reconstruction_falls_below_the_data_std_and_reloads(tiny, tmp_path):
    out = tmp_path / "vae.pt"
    report = train_vae(tiny, CFG, out, steps=600)
    assert len(report["heldout_episodes"]) == 4 and report["frames_train"] == 36 * 20 and report["frames_eval"] == 80
    base = report["baseline_rmse"]  # predicting the training mean: about the data's std
    for group, rmse in report["rmse_train"].items():  # in original units
        assert rmse < 0.1 * base[group], (group, report)
    for group, rmse in report["rmse"].items():  # the 4 held-out episodes
        assert rmse < 0.7 * base[group], (group, report)
    assert 0 < report["kl_per_dim"] and report["final"]["mse"] < 0.05
    vae = load_vae(out)
    u = torch.from_numpy(np.concatenate([np.asarray(e.data["observation.df"]) for e in tiny_features(40, 20)[1]]))
    assert evaluate_vae(vae, u)["rmse"]["phi_m"] < 0.5 * u[:, 0::10].std().item()
    z = vae.encode(u)
    assert z.shape == (len(u), CFG.latent)
    assert torch.equal(z, vae.encode(u)), "encode uses mu: deterministic"
    assert torch.equal(z, load_vae(out).encode(u)), "a reload gives the same z"
    assert torch.allclose(vae.encode(u[None, :5]), z[None, :5], atol=1e-6), "any leading shape"


def test_training_is_deterministic_for_a_seed(tiny, tmp_path):
    a = train_vae(tiny, CFG, tmp_path / "a.pt", steps=30)
    b = train_vae(tiny, CFG, tmp_path / "b.pt", steps=30)
    assert a["final"] == b["final"]
    sa, sb = load_vae(tmp_path / "a.pt").state_dict(), load_vae(tmp_path / "b.pt").state_dict()
    assert all(torch.equal(sa[k], sb[k]) for k in sa)


def test_a_dataset_without_df_is_one_line_and_writes_nothing(tmp_path):
    root = write_tiny_features(tmp_path / "nodf", drop=("observation.df",))
    with pytest.raises(InputError) as e:
        train_vae(root, CFG, tmp_path / "run" / "vae.pt", steps=5)
    msg = str(e.value)
    assert "\n" not in msg and "observation.df" in msg and "lessmimic features" in msg
    assert not (tmp_path / "run").exists()


def test_a_file_that_is_not_a_vae_checkpoint(tmp_path):
    bad = tmp_path / "x.pt"
    bad.write_bytes(b"not torch")
    with pytest.raises(InputError, match="format"):
        load_vae(bad)
    torch.save({"format": "something else"}, bad)
    with pytest.raises(InputError, match="not a DF-VAE checkpoint"):
        load_vae(bad)
    with pytest.raises(InputError, match="not a DF-VAE checkpoint"):
        DFVAE.from_checkpoint([1, 2], bad)
