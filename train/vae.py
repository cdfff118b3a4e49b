"""The DF-latent VAE (paper App. A, "Interaction Encoder"): one per-timestep interaction feature u -> latent z.

``u`` is the features stage's ``observation.df``: per link ``[phi, grad phi (3), v_norm (3), v_tan (3)]``, K links,
flattened to ``D = 10 K``. With ``x = normalize(u)`` (per-element statistics of the training frames, kept in the
model and its checkpoint):

    encoder:  (mu, log sigma^2) = MLP_enc(x)          MLP of ReLU layers, ``hidden`` wide, to 2 x ``latent``
    sample:   z = mu + sigma * eps,  eps ~ N(0, I)     (the reparameterisation trick)
    decoder:  x_hat = MLP_dec(z)
    loss:     mean_D (x_hat - x)^2 + beta * KL,  KL = 1/2 sum_j (mu_j^2 + sigma_j^2 - 1 - log sigma_j^2)

At inference :meth:`DFVAE.encode` returns ``mu`` (deterministic). The policy reads the sequence of per-step
latents ``{z_(t-l+1) .. z_t}`` (:mod:`train.policy`); the VAE is trained first and frozen there.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from pipeline.dataset.read import episode_ranges, read_columns, read_info
from pipeline.errors import InputError
from pipeline.stage.atomic import write_torch_atomic
from pipeline.terms.layout import DEMO_PARTS, DF, DF_PARTS
from train.normalize import Normalizer

VAE_FORMAT = "lessmimic.df_vae/1"
HOLDOUT_SEED = 0  # the held-out episodes do not depend on the training seed: the VAE and BC hold out the same ones
GROUPS = {"phi_m": ("phi",), "grad": ("grad_",), "v_norm_mps": ("v_norm_",), "v_tan_mps": ("v_tan_",)}


@dataclass(frozen=True)
class VAEConfig:
    """``latent``: z size; ``hidden``: MLP widths (decoder mirrored); ``beta``: KL weight; Adam ``lr``, ``batch``
    frames per step, ``steps``; ``min_std``: normaliser floor; ``holdout``: fraction of episodes held out."""

    latent: int = 64
    hidden: tuple[int, ...] = (256, 256)
    beta: float = 1e-3
    lr: float = 1e-3
    batch: int = 1024
    steps: int = 2000
    seed: int = 0
    min_std: float = 1e-3
    holdout: float = 0.1


# --- dataset helpers (shared with train.bc) ------------------------------------------------------------------


def require_columns(root: str | Path, columns: Sequence[str]) -> dict:
    """The dataset's ``info.json``, or a one-line :class:`InputError` naming the first missing column."""
    info = read_info(root)
    for c in columns:
        if c not in info["features"]:
            raise InputError(root, c, "missing: not a features dataset? run `lessmimic features` to write one")
    return info


def split_episodes(n_episodes: int, frac: float = 0.1, seed: int = HOLDOUT_SEED) -> tuple[list[int], list[int]]:
    """``(train, held_out)`` episode indices: ``max(1, round(frac n))`` held out when ``n >= 2``, else none."""
    if n_episodes < 2 or frac <= 0:
        return list(range(n_episodes)), []
    k = min(n_episodes - 1, max(1, round(frac * n_episodes)))
    perm = np.random.default_rng(seed).permutation(n_episodes)
    held = sorted(int(e) for e in perm[:k])
    return [e for e in range(n_episodes) if e not in held], held


def df_links(names: Sequence[str], where: str | Path | None = None) -> tuple[str, ...]:
    """The K link names of DF element names ``<link>.<part>``: the paper's parts (:data:`DF_PARTS`, 10 per link)
    or the demo contract's (:data:`DEMO_PARTS`, 4), in that order."""
    for parts in (DF_PARTS, DEMO_PARTS):
        if len(names) == 0 or len(names) % len(parts):
            continue
        links = tuple(n.rsplit(".", 1)[0] for n in names[:: len(parts)])
        if tuple(names) == tuple(f"{link}.{p}" for link in links for p in parts):
            return links
    why = f"{len(names)} element names are not <link>.<part> with parts {DF_PARTS} or {DEMO_PARTS}"
    raise InputError(where, DF, why)


def mlp(sizes: Sequence[int]) -> nn.Sequential:
    """Linear layers ``sizes[0] -> ... -> sizes[-1]`` with ReLU between them (none after the last)."""
    layers: list[nn.Module] = []
    for k, (a, b) in enumerate(zip(sizes[:-1], sizes[1:])):
        layers.append(nn.Linear(a, b))
        if k < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


# --- the model -------------------------------------------------------------------------------------------------


class DFVAE(nn.Module):
    """u (..., D) raw -> z (..., latent); the input normaliser is part of the model."""

    def __init__(self, names: Sequence[str], config: VAEConfig, normalizer: Normalizer):
        super().__init__()
        self.names, self.config = tuple(names), config
        if normalizer.dim != len(self.names):
            raise ValueError(f"normaliser has {normalizer.dim} elements, names {len(self.names)}")
        self.links = df_links(self.names)
        self.norm = normalizer
        d, h = len(self.names), tuple(config.hidden)
        self.encoder = mlp((d, *h, 2 * config.latent))
        self.decoder = mlp((config.latent, *reversed(h), d))

    @property
    def dim(self) -> int:
        return len(self.names)

    def posterior(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``(mu, log sigma^2)`` of normalised ``x``; log variance clamped to [-20, 10] for stability."""
        mu, logvar = self.encoder(x).chunk(2, dim=-1)
        return mu, logvar.clamp(-20.0, 10.0)

    def encode(self, u: torch.Tensor) -> torch.Tensor:
        """Deterministic latent ``mu`` of raw ``u (..., D)``."""
        return self.posterior(self.norm.normalize(u))[0]

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Raw ``u`` (original units) from ``z``."""
        return self.norm.denormalize(self.decoder(z))

    def loss(self, x: torch.Tensor, generator: torch.Generator | None = None) -> tuple[torch.Tensor, dict]:
        """The training loss on normalised ``x (B, D)``: ``mse + beta * kl`` and its parts (detached floats)."""
        mu, logvar = self.posterior(x)
        eps = torch.randn(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
        z = mu + torch.exp(0.5 * logvar) * eps
        mse = (self.decoder(z) - x).pow(2).mean()
        kl = 0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar).sum(-1).mean()
        total = mse + self.config.beta * kl
        return total, {"loss": total.item(), "mse": mse.item(), "kl": kl.item()}

    def to_checkpoint(self) -> dict:
        return {
            "format": VAE_FORMAT,
            "config": asdict(self.config),
            "names": list(self.names),
            "normalizer": self.norm.to_dict(),
            "state_dict": {k: v.detach().cpu() for k, v in self.state_dict().items()},
        }

    @classmethod
    def from_checkpoint(cls, ckpt: dict, where: str | Path | None = None) -> DFVAE:
        if not isinstance(ckpt, dict) or ckpt.get("format") != VAE_FORMAT:
            raise InputError(where, "format", f"not a DF-VAE checkpoint (expected format {VAE_FORMAT!r})")
        try:
            cfg = VAEConfig(**{**ckpt["config"], "hidden": tuple(ckpt["config"]["hidden"])})
            vae = cls(ckpt["names"], cfg, Normalizer.from_dict(ckpt["normalizer"]))
            vae.load_state_dict(ckpt["state_dict"])
        except (KeyError, TypeError, ValueError, RuntimeError) as exc:
            raise InputError(where, "state_dict", f"unreadable DF-VAE checkpoint: {type(exc).__name__}") from None
        return vae.eval()


def save_vae(vae: DFVAE, path: str | Path) -> Path:
    """``torch.save`` of :meth:`DFVAE.to_checkpoint`, written atomically."""
    write_torch_atomic(Path(path), vae.to_checkpoint())
    return Path(path)


def load_vae(path: str | Path, device: str | torch.device = "cpu") -> DFVAE:
    try:
        ckpt = torch.load(Path(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a one-line input error
        raise InputError(path, "format", f"not a torch checkpoint ({type(exc).__name__})") from None
    return DFVAE.from_checkpoint(ckpt, path).to(device)


# --- training and evaluation -----------------------------------------------------------------------------------


@torch.no_grad()
def evaluate_vae(vae: DFVAE, u: torch.Tensor, chunk: int = 65536) -> dict:
    """Reconstruction RMSE per feature group in original units (through ``mu``), the RMSE of predicting the
    training mean (``baseline_rmse``), the mean KL per latent dimension and the dims with KL > 0.01 nats."""
    vae.eval()
    err, kl = [], []
    for k in range(0, len(u), chunk):
        x = u[k : k + chunk]
        mu, logvar = vae.posterior(vae.norm.normalize(x))
        err.append(vae.decode(mu) - x)
        kl.append(0.5 * (mu.pow(2) + logvar.exp() - 1.0 - logvar))
    e, kl_dim = torch.cat(err), torch.cat(kl).mean(0)
    parts = [n.rsplit(".", 1)[1] for n in vae.names]
    base = u - vae.norm.mean
    out: dict = {"rmse": {}, "baseline_rmse": {}}
    for group, prefixes in GROUPS.items():
        cols = [i for i, p in enumerate(parts) if p.startswith(prefixes)]
        if not cols:  # the demo contract's DF has no velocities
            continue
        out["rmse"][group] = e[:, cols].pow(2).mean().sqrt().item()
        out["baseline_rmse"][group] = base[:, cols].pow(2).mean().sqrt().item()
    out["kl_per_dim"] = kl_dim.mean().item()
    out["active_dims"] = int((kl_dim > 0.01).sum())
    return out


def fit_vae(vae: DFVAE, x: torch.Tensor, steps: int, generator: torch.Generator, log_every: int = 0) -> list[dict]:
    """Adam on normalised frames ``x (N, D)`` (on the model's device), ``batch`` frames drawn per step."""
    opt = torch.optim.Adam(vae.parameters(), lr=vae.config.lr)
    vae.train()
    history = []
    for step in range(1, steps + 1):
        idx = torch.randint(len(x), (vae.config.batch,), generator=generator, device=x.device)
        loss, parts = vae.loss(x[idx], generator)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        if step == steps or (log_every and step % log_every == 0):
            history.append({"step": step, **parts})
    return history


def train_vae(
    features_root: str | Path,
    config: VAEConfig = VAEConfig(),
    out_path: str | Path | None = None,
    device: str | torch.device = "cpu",
    steps: int | None = None,
    column: str = DF,
) -> dict:
    """Train the VAE on every frame of ``column`` (``observation.df``; the demo contract's ``observation.df_demo``)
    of the training episodes; evaluate on the held-out
    episodes (all frames when there is one episode); save to ``out_path`` (atomically) if given.

    Returns the report: frames, held-out episodes, final loss parts, :func:`evaluate_vae`'s figures on the
    evaluation frames, the reconstruction RMSE on the training frames (``rmse_train``), seconds.
    """
    root, t0 = Path(features_root), time.perf_counter()
    names = require_columns(root, [column])["features"][column]["names"]
    df_links(names, root)
    cols = read_columns(root, [column, "episode_index"])
    train_eps, held = split_episodes(len(episode_ranges(root)[0]), config.holdout)
    ep = cols["episode_index"][:, 0]
    u_train = cols[column][np.isin(ep, train_eps)]
    u_eval = cols[column][np.isin(ep, held)] if held else cols[column]
    torch.manual_seed(config.seed)
    vae = DFVAE(names, config, Normalizer.from_array(u_train, config.min_std)).to(device)
    gen = torch.Generator(device=device).manual_seed(config.seed)
    x = vae.norm.normalize(torch.as_tensor(u_train, device=device))
    history = fit_vae(vae, x, config.steps if steps is None else steps, gen)
    report = {
        "frames_train": int(len(u_train)),
        "frames_eval": int(len(u_eval)),
        "heldout_episodes": held,
        "eval_on": "held-out episodes" if held else "all frames (one episode)",
        "steps": history[-1]["step"] if history else 0,
        "final": history[-1] if history else {},
        **evaluate_vae(vae, torch.as_tensor(u_eval, device=device)),
        "rmse_train": evaluate_vae(vae, torch.as_tensor(u_train, device=device))["rmse"],
    }
    if out_path is not None:
        report["path"] = str(save_vae(vae, out_path))
    report["seconds"] = time.perf_counter() - t0
    return report
