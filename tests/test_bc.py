"""Behaviour cloning: window sources, the loss falling on a learnable mapping, determinism, the end-to-end run and its
errors."""

import json

import pytest
import torch
from test_vae import write_tiny_features

from pipeline.dataset import WindowDataset
from pipeline.errors import InputError
from train.bc import BCConfig, WindowTensors, bc_speed, evaluate, fit, train_bc
from train.policy import COLUMNS, PolicyConfig, dataset_layout, load_policy, make_policy
from train.vae import VAEConfig, load_vae, train_vae

torch.set_num_threads(1)

VAE = VAEConfig(latent=16, hidden=(64,), batch=64)
SMALL = PolicyConfig(latent=16, d_model=32, layers=1, heads=2, ff_dim=64, mlp_hidden=(64,))


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("bc")
    root = write_tiny_features(d / "features")
    train_vae(root, VAE, d / "vae.pt", steps=20)
    return root, load_vae(d / "vae.pt")


def test_window_tensors_equal_window_dataset(setup):
    root = setup[0]
    ds = WindowDataset(root, COLUMNS, history=5)
    data = WindowTensors.from_window_dataset(ds)
    assert len(data) == 180 and data.history == 5 and data.proprio.shape == (180, 93)
    w, b = ds.sample(torch.arange(180)), data.gather(torch.arange(180))
    for key, x in zip(COLUMNS, b):
        assert torch.equal(x, w[key][:, -1] if key == "action" else w[key]), key
    part = WindowTensors.from_window_dataset(ds, [1])
    assert len(part) == 60 and part.proprio.shape[0] == 60  # only the episode's frames are kept
    assert torch.equal(part.gather(torch.arange(60)).df, w["observation.df"][60:120])
    rollout = WindowTensors.from_windows(*b[:3], b.action)  # materialised windows, e.g. from DAgger
    both = WindowTensors.concat([part, rollout])
    assert len(both) == 240
    for x, y in zip(both.gather(torch.arange(60, 240)), b):
        assert torch.equal(x, y)
    g = torch.Generator().manual_seed(0)
    assert both.sample(8, g).df.shape == (8, 5, 140)


@pytest.mark.parametrize("backbone", ["transformer", "mlp"])
def test_loss_falls_on_a_learnable_mapping(setup, backbone):
    """``action`` is a linear function of the last frame's proprio and root command: BC (default architecture and
    optimiser) learns it."""
    root, vae = setup
    data = WindowTensors.from_dataset(root, 5)
    torch.manual_seed(0)
    policy = make_policy(PolicyConfig(backbone=backbone, latent=16), dataset_layout(root), vae, data.frames())
    before = evaluate(policy, data)
    history = fit(policy, data, BCConfig(steps=150, batch=64, log_every=50), heldout=data)
    after = evaluate(policy, data)
    assert after < 0.5 * before, (before, after, history)
    assert [h["step"] for h in history] == [50, 100, 150] and history[-1]["heldout_loss"] == pytest.approx(after)
    assert all(h["samples_per_s"] > 0 for h in history)


def test_train_bc_is_deterministic_and_logs(setup, tmp_path):
    root = setup[0]
    cfg = BCConfig(steps=20, batch=32, log_every=10)
    reports = [train_bc(root, tmp_path / run, cfg, SMALL, VAE, vae_steps=10) for run in ("a", "b")]
    losses = [{k: r["final"][k] for k in ("train_loss", "heldout_loss")} for r in reports]
    assert losses[0] == losses[1]
    a, b = (load_policy(tmp_path / run / "policy.pt", dataset_layout(root)) for run in ("a", "b"))
    sa, sb = a.state_dict(), b.state_dict()
    assert sa.keys() == sb.keys() and all(torch.equal(sa[k], sb[k]) for k in sa), "identical weights"
    rows = [json.loads(line) for line in (tmp_path / "a" / "bc_log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [10, 20] and all(r["heldout_loss"] is not None for r in rows)
    r = reports[0]
    assert r["heldout_episodes"] and r["windows_train"] + r["windows_heldout"] == 180 and r["samples_per_s"] > 0
    assert "rmse" in r["vae"] and (tmp_path / "a" / "bc_report.json").is_file()
    again = train_bc(root, tmp_path / "a", cfg, SMALL, VAE, vae_steps=10)  # reuses run_dir/vae.pt
    assert again["vae"] == {"loaded": str(tmp_path / "a" / "vae.pt")}
    assert again["final"]["heldout_loss"] == r["final"]["heldout_loss"]


def test_a_dataset_missing_action_is_one_line_and_writes_nothing(tmp_path):
    root = write_tiny_features(tmp_path / "noaction", episodes=1, frames=10, drop=("action",))
    with pytest.raises(InputError) as e:
        train_bc(root, tmp_path / "run", BCConfig(steps=2), SMALL, VAE, vae_steps=2)
    msg = str(e.value)
    assert "\n" not in msg and ": action: missing" in msg and "lessmimic features" in msg, msg
    assert not (tmp_path / "run").exists()


def test_bc_speed_measures_samples_per_second(setup):
    threads = torch.get_num_threads()
    assert bc_speed(setup[0], "mlp", steps=3, batch=16) > 0
    assert torch.get_num_threads() == threads, "the thread count is restored"
