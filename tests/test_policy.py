"""The interaction policy: shapes of both backbones, the padded-history convention, checkpoints and their layout."""

from dataclasses import replace

import numpy as np
import pytest
import torch
from test_vae import write_tiny_features

from pipeline.dataset import WindowDataset
from pipeline.errors import InputError
from train.bc import WindowTensors
from train.normalize import Normalizer
from train.policy import (
    COLUMNS,
    InteractionPolicy,
    PolicyConfig,
    PolicyLayout,
    dataset_layout,
    load_policy,
    make_policy,
    save_policy,
)
from train.vae import VAEConfig, load_vae, save_vae, train_vae

torch.set_num_threads(1)

LATENT = 16


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("policy")
    root = write_tiny_features(d / "features")
    train_vae(root, VAEConfig(latent=LATENT, hidden=(64,), batch=64), d / "vae.pt", steps=20)
    return root, load_vae(d / "vae.pt"), WindowTensors.from_dataset(root, 5)


def _policy(setup, backbone: str, seed: int = 0) -> InteractionPolicy:
    root, vae, data = setup
    torch.manual_seed(seed)
    cfg = PolicyConfig(backbone=backbone, latent=LATENT)
    return make_policy(cfg, dataset_layout(root, cfg.history), vae, data.frames()).eval()


def test_layout_from_the_dataset(setup, tmp_path):
    root = setup[0]
    layout = dataset_layout(root, 5)
    assert len(layout.links) == 14 and layout.links[0] == "pelvis" and layout.df_dim == 140
    assert (layout.proprio_dim, layout.root_command_dim, layout.action_dim) == (93, 12, 29)
    assert layout.actuator_profile == "mjlab" and layout.history == 5
    demo = write_tiny_features(tmp_path / "demo", episodes=1, frames=5, profile="lessmimic_demo")
    assert dataset_layout(demo).actuator_profile == "lessmimic_demo"


@pytest.mark.parametrize("backbone", ["transformer", "mlp"])
def test_shapes(setup, backbone):
    policy, data = _policy(setup, backbone), setup[2]
    b = data.gather(torch.arange(7))
    assert b.proprio.shape == (7, 5, 93) and b.root_command.shape == (7, 5, 12) and b.df.shape == (7, 5, 140)
    assert policy(b.proprio, b.root_command, b.df).shape == (7, 29)
    a = policy.act(b.proprio, b.root_command, b.df)
    assert a.shape == (7, 29) and torch.isfinite(a).all()
    assert not any(p.requires_grad for p in policy.vae.parameters()), "the VAE is frozen"
    with pytest.raises(ValueError, match="proprio"):
        policy.act(b.proprio[:, 1:], b.root_command, b.df)
    with pytest.raises(ValueError, match="df"):
        policy.act(b.proprio, b.root_command, b.df[..., :70])


def test_padded_history_repeats_the_first_step(setup):
    """At an episode's second frame the window is [f0, f0, f0, f0, f1] (WindowDataset's padding), and a rollout
    that fills the history the same way gets the same action."""
    root, _, data = setup
    policy = _policy(setup, "transformer")
    ds = WindowDataset(root, COLUMNS, history=5)
    i = 60 + 1  # the second frame of episode 1
    w = ds.sample([i])
    assert w["observation.proprio_is_pad"][0].tolist() == [True, True, True, False, False]
    f0, f1 = ds.data["observation.proprio"][60], ds.data["observation.proprio"][61]
    torch.testing.assert_close(w["observation.proprio"][0], torch.stack([f0, f0, f0, f0, f1]))
    b = data.gather(torch.tensor([i]))
    for key, x in zip(COLUMNS, b):
        torch.testing.assert_close(x[0], w[key][0, -1] if key == "action" else w[key][0], rtol=0, atol=0)
    rollout = [ds.data[k][[60, 60, 60, 60, 61]][None] for k in COLUMNS[:3]]
    torch.testing.assert_close(policy.act(*rollout), policy.act(b.proprio, b.root_command, b.df), rtol=0, atol=0)
    zeros = [torch.cat([torch.zeros_like(x[:, :3]), x[:, 3:]], 1) for x in rollout]
    assert not torch.allclose(policy.act(*zeros), policy.act(*rollout)), "the history steps matter"


@pytest.mark.parametrize("backbone", ["transformer", "mlp"])
def test_save_load_gives_identical_actions(setup, tmp_path, backbone):
    policy, data = _policy(setup, backbone, seed=3), setup[2]
    path = save_policy(policy, tmp_path / "policy.pt")
    back = load_policy(path, expect_layout=dataset_layout(setup[0], 5))
    assert not back.training and back.config == policy.config and back.layout == policy.layout
    b = data.gather(torch.arange(0, 180, 7))
    assert torch.equal(back.act(b.proprio, b.root_command, b.df), policy.act(b.proprio, b.root_command, b.df))
    ckpt = torch.load(path, weights_only=True)
    assert ckpt["layout"]["links"][0] == "pelvis" and ckpt["layout"]["actuator_profile"] == "mjlab"
    assert set(ckpt["normalizers"]) == {"proprio", "root_command", "action"} and "normalizer" in ckpt["vae"]
    assert isinstance(ckpt["normalizers"]["proprio"]["mean"], list)


def test_layout_mismatch_is_one_line_naming_file_and_field(setup, tmp_path):
    path = save_policy(_policy(setup, "mlp"), tmp_path / "policy.pt")
    layout = dataset_layout(setup[0], 5)
    cases = {
        "layout.links": replace(layout, links=layout.links[::-1]),
        "layout.actuator_profile": replace(layout, actuator_profile="lessmimic_demo"),
        "layout.proprio_dim": replace(layout, proprio_dim=90),
        "layout.history": {"history": 3},
    }
    for field, expected in cases.items():
        with pytest.raises(InputError) as e:
            load_policy(path, expect_layout=expected)
        msg = str(e.value)
        assert "\n" not in msg and str(path) in msg and field in msg, msg
    load_policy(path, expect_layout={"actuator_profile": "mjlab", "links": list(layout.links)})  # a subset: fine
    assert PolicyLayout.from_dict(layout.to_dict()) == layout


def test_a_file_that_is_not_a_policy_checkpoint(setup, tmp_path):
    cases = {"garbage.pt": None, "dict.pt": {"weights": torch.zeros(3)}, "vae.pt": "vae"}
    for name, content in cases.items():
        path = tmp_path / name
        if content is None:
            path.write_bytes(b"\x00not a checkpoint")
        elif content == "vae":
            save_vae(setup[1], path)
        else:
            torch.save(content, path)
        with pytest.raises(InputError) as e:
            load_policy(path)
        msg = str(e.value)
        assert "\n" not in msg and str(path) in msg and "format" in msg, msg
    with pytest.raises(InputError, match="format"):
        load_policy(tmp_path / "missing.pt")
    assert np.isfinite(setup[2].proprio.numpy()).all()


def test_normalizer_floors_clips_and_round_trips():
    x = np.stack([np.linspace(-1, 1, 50), np.full(50, 2.0)], 1)  # the second element is constant
    n = Normalizer.from_array(x, min_std=1e-3)
    assert n.std[1].item() == pytest.approx(1e-3) and n.mean[1].item() == pytest.approx(2.0)
    t = torch.from_numpy(x).float()
    torch.testing.assert_close(n.denormalize(n.normalize(t)), t)
    assert n.normalize(t)[:, 0].std(unbiased=False).item() == pytest.approx(1.0, abs=1e-5)
    clipped = Normalizer.from_dict({**n.to_dict(), "clip": 10.0})
    assert clipped.normalize(torch.tensor([[0.0, 3.0]]))[0, 1].item() == 10.0
    assert isinstance(n.to_dict()["mean"], list) and Normalizer.from_dict(n.to_dict()).std.tolist() == n.std.tolist()
