"""The interaction policy pi_base (paper Sec. III-B, App. A "Policy Architecture").

Per time step ``s`` of the window ``t-l+1 .. t`` the policy reads one token

    o_s = [normalize(o_prop_s) (93),  normalize(c_root_s) (12),  z_s = VAE.encode(u_s) (latent)]

and maps the ``l`` tokens to the normalised joint targets of step ``t``:

    transformer:  h = TransformerEncoder(W_e o + p)   (learned positional embedding p over the l steps, ReLU)
                  a = W_out h_t                         (the last token; linear output)
    mlp ("-Trans" ablation):  a = MLP([o_(t-l+1), .., o_t])   (the l tokens flattened; ReLU hidden layers)

and :meth:`InteractionPolicy.act` returns ``denormalize(a)``: absolute joint position targets (29, mjlab order).
The policy owns the frozen VAE encoder and the normalisers, so it takes raw tensors. History steps before an
episode's start hold that episode's first step (the convention of :class:`pipeline.dataset.WindowDataset`; on
the rollout side :class:`train.envs.cpu.env.History` does the same), so no mask is needed.

A checkpoint is one ``torch.save`` dict (:func:`save_policy`, :func:`load_policy`) with a ``layout`` that names what
the policy reads and drives (links, dims, actuator profile, history); loading checks it against the caller's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import torch
from torch import nn

from pipeline.dataset.read import dataset_actuator_profile
from pipeline.errors import InputError
from pipeline.robot import DEFAULT_PROFILE
from pipeline.stage.atomic import write_torch_atomic
from pipeline.terms import layout as L
from train.normalize import MIN_STD, Normalizer
from train.vae import DFVAE, df_links, mlp, require_columns

COLUMNS = (L.PROPRIO, L.ROOT_COMMAND, L.DF, L.ACTION)
"""What a policy of the paper's contract is trained on, per window step (:mod:`pipeline.terms.layout`);
:attr:`PolicyLayout.columns` for any contract."""
POLICY_FORMAT = "lessmimic.interaction_policy/1"


@dataclass(frozen=True)
class PolicyConfig:
    """``backbone``: "transformer" or "mlp" (the paper's -Trans ablation); ``history``: l steps per window;
    transformer ``d_model``, ``layers``, ``heads``, ``ff_dim`` (feed-forward width), ``dropout``; ``mlp_hidden``;
    ``latent``: the VAE's z size; ``obs_clip``: normalised proprio / root command clipped to +-obs_clip."""

    backbone: str = "transformer"
    history: int = L.HISTORY
    d_model: int = 128
    layers: int = 2
    heads: int = 4
    ff_dim: int = 256
    mlp_hidden: tuple[int, ...] = (512, 256)
    latent: int = 64
    dropout: float = 0.0
    obs_clip: float | None = 10.0

    def __post_init__(self):
        if self.backbone not in ("transformer", "mlp"):
            raise ValueError(f"backbone must be 'transformer' or 'mlp', got {self.backbone!r}")
        if self.history < 1 or self.d_model % self.heads:
            raise ValueError(f"need history >= 1 and d_model divisible by heads, got {self.history}, {self}")

    @classmethod
    def from_dict(cls, d: Mapping) -> PolicyConfig:
        return cls(**{**d, "mlp_hidden": tuple(d["mlp_hidden"])})


@dataclass(frozen=True)
class PolicyLayout:
    """What a checkpoint reads and drives: the DF ``links`` (K, in the DF column's order), input and output
    sizes, the ``actuator_profile`` its joint targets are meant for, the ``history`` length l and the observation
    ``contract`` (:data:`pipeline.terms.layout.CONTRACTS`; checkpoints from before it are the paper's)."""

    links: tuple[str, ...]
    proprio_dim: int = L.PROPRIO_DIM
    root_command_dim: int = L.ROOT_COMMAND_DIM
    action_dim: int = L.ACTION_DIM
    actuator_profile: str = DEFAULT_PROFILE
    history: int = L.HISTORY
    contract: str = "lessmimic"

    def __post_init__(self):
        L.check_contract(self.contract)

    @property
    def demo(self) -> bool:
        return self.contract == "lessmimic_demo"

    @property
    def df_column(self) -> str:
        return L.CONTRACT_DF[self.contract][0]

    @property
    def columns(self) -> tuple[str, str, str, str]:
        """The features dataset's columns the policy is trained on: proprio, root command, its DF, the action."""
        return (L.PROPRIO, L.ROOT_COMMAND, self.df_column, L.ACTION)

    @property
    def observation(self) -> L.ObservationLayout:
        """The observation this policy reads (its windows, flat or split:
        :class:`pipeline.terms.layout.ObservationLayout`)."""
        parts = len(L.CONTRACT_DF[self.contract][1])
        return L.ObservationLayout(self.links, self.history, self.proprio_dim, self.root_command_dim, parts)

    @property
    def df_dim(self) -> int:
        return self.observation.df_dim

    def to_dict(self) -> dict:
        return {**asdict(self), "links": list(self.links)}

    @classmethod
    def from_dict(cls, d: Mapping) -> PolicyLayout:
        return cls(**{**d, "links": tuple(d["links"])})

    def mismatch(self, expected: PolicyLayout | Mapping) -> tuple[str, str] | None:
        """``(field, message)`` of the first field that differs from ``expected`` (a mapping: only its keys)."""
        want = expected.to_dict() if isinstance(expected, PolicyLayout) else dict(expected)
        have = self.to_dict()
        for f in fields(self):
            a, b = have[f.name], want.get(f.name, have[f.name])
            if (list(b) if isinstance(b, (list, tuple)) else b) != a:
                return f"layout.{f.name}", f"checkpoint has {a!r}, expected {b!r}"
        return None


def dataset_layout(root: str | Path, history: int = L.HISTORY, contract: str = "lessmimic") -> PolicyLayout:
    """The layout a policy of ``contract`` trained on the features dataset at ``root`` has (one-line error for a
    missing column); the demo contract's command is the dataset's root command plus the task condition."""
    columns = PolicyLayout((), contract=contract).columns
    info = require_columns(root, columns)
    dim = {c: int(info["features"][c]["shape"][0]) for c in columns}
    return PolicyLayout(
        links=df_links(info["features"][columns[2]]["names"], root),
        proprio_dim=dim[L.PROPRIO],
        root_command_dim=dim[L.ROOT_COMMAND] + (L.DEMO_COMMAND_DIM - L.ROOT_COMMAND_DIM) * (contract != "lessmimic"),
        action_dim=dim[L.ACTION],
        actuator_profile=dataset_actuator_profile(root),
        history=int(history),
        contract=contract,
    )


class TransformerBackbone(nn.Module):
    """tokens ``(B, l, d_in)`` -> ``(B, d_out)``: embed, add the positional embedding, encode, read the last token."""

    def __init__(self, d_in: int, d_out: int, cfg: PolicyConfig):
        super().__init__()
        self.embed = nn.Linear(d_in, cfg.d_model)
        self.pos = nn.Parameter(0.02 * torch.randn(1, cfg.history, cfg.d_model))
        layer = nn.TransformerEncoderLayer(
            cfg.d_model, cfg.heads, cfg.ff_dim, cfg.dropout, activation="relu", batch_first=True
        )
        self.encoder = nn.TransformerEncoder(layer, cfg.layers, enable_nested_tensor=False)
        self.head = nn.Linear(cfg.d_model, d_out)

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        h = self.encoder(self.embed(tokens) + self.pos)
        return self.head(h[:, -1])


class MLPBackbone(nn.Module):
    """tokens ``(B, l, d_in)`` -> ``(B, d_out)``: the l tokens flattened through a ReLU MLP."""

    def __init__(self, d_in: int, d_out: int, cfg: PolicyConfig):
        super().__init__()
        self.net = mlp((cfg.history * d_in, *cfg.mlp_hidden, d_out))

    def forward(self, tokens: torch.Tensor) -> torch.Tensor:
        return self.net(tokens.flatten(1))


class InteractionPolicy(nn.Module):
    """``(proprio (B,l,P), root_command (B,l,C), df (B,l,10K))`` raw -> joint targets; the VAE is frozen."""

    def __init__(self, config: PolicyConfig, layout: PolicyLayout, vae: DFVAE, normalizers: Mapping[str, Normalizer]):
        super().__init__()
        if layout.history != config.history or vae.config.latent != config.latent:
            raise ValueError("layout.history / vae latent must equal config.history / config.latent")
        if tuple(vae.links) != tuple(layout.links):
            raise ValueError(f"the VAE reads links {vae.links}, the layout {layout.links}")
        self.config, self.layout = config, layout
        self.vae = vae.requires_grad_(False).eval()
        self.norm = nn.ModuleDict({k: normalizers[k] for k in ("proprio", "root_command", "action")})
        want = {"proprio": layout.proprio_dim, "root_command": layout.root_command_dim, "action": layout.action_dim}
        if any(self.norm[k].dim != d for k, d in want.items()):
            raise ValueError(f"normaliser sizes {[n.dim for n in self.norm.values()]} differ from {want}")
        d_in = layout.proprio_dim + layout.root_command_dim + config.latent
        backbone = TransformerBackbone if config.backbone == "transformer" else MLPBackbone
        self.backbone = backbone(d_in, layout.action_dim, config)

    def train(self, mode: bool = True) -> InteractionPolicy:
        super().train(mode)
        self.vae.eval()  # frozen: always in inference mode
        return self

    def trainable_parameters(self) -> list[nn.Parameter]:
        return [p for p in self.parameters() if p.requires_grad]

    def _check(self, name: str, x: torch.Tensor, dim: int) -> None:
        if x.ndim != 3 or x.shape[1] != self.config.history or x.shape[2] != dim:
            raise ValueError(f"{name}: expected (B, {self.config.history}, {dim}), got {tuple(x.shape)}")

    def latents(self, df: torch.Tensor) -> torch.Tensor:
        """The VAE's ``mu`` of ``df`` (..., latent); under the demo contract unit-norm, ``mu / (|mu| + 1e-8)``, as the
        released viewer normalises its latent encoder's output."""
        with torch.no_grad():
            z = self.vae.encode(df)
        return z / (z.norm(dim=-1, keepdim=True) + 1e-8) if self.layout.demo else z

    def tokens(self, proprio: torch.Tensor, root_command: torch.Tensor, df: torch.Tensor) -> torch.Tensor:
        """``(B, l, P + C + latent)``: normalised proprio and root command with the latents of ``df``."""
        self._check("df", df, self.layout.df_dim)
        return self.tokens_from_latents(proprio, root_command, self.latents(df))

    def tokens_from_latents(self, proprio: torch.Tensor, root_command: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """:meth:`tokens` from latents ``z (B, l, latent)``. The demo contract reads the current step's command only
        (its viewer feeds one movement goal, no history): every step's token carries the last one."""
        self._check("proprio", proprio, self.layout.proprio_dim)
        self._check("root_command", root_command, self.layout.root_command_dim)
        if self.layout.demo:
            root_command = root_command[:, -1:].expand_as(root_command)
        return torch.cat(
            [self.norm["proprio"].normalize(proprio), self.norm["root_command"].normalize(root_command), z], -1
        )

    def forward(self, proprio: torch.Tensor, root_command: torch.Tensor, df: torch.Tensor) -> torch.Tensor:
        """Normalised actions ``(B, A)`` (what the BC loss compares); differentiable in the backbone."""
        return self.backbone(self.tokens(proprio, root_command, df))

    @torch.no_grad()
    def act(self, proprio: torch.Tensor, root_command: torch.Tensor, df: torch.Tensor) -> torch.Tensor:
        """Raw joint position targets ``(B, A)`` for raw windows."""
        return self.norm["action"].denormalize(self(proprio, root_command, df))

    def to_checkpoint(self) -> dict:
        return {
            "format": POLICY_FORMAT,
            "policy_config": asdict(self.config),
            "vae_config": asdict(self.vae.config),
            "layout": self.layout.to_dict(),
            "backbone": {k: v.detach().cpu() for k, v in self.backbone.state_dict().items()},
            "vae": self.vae.to_checkpoint(),
            "normalizers": {k: n.to_dict() for k, n in self.norm.items()},
        }


def make_policy(
    config: PolicyConfig, layout: PolicyLayout, vae: DFVAE, frames: Mapping[str, object]
) -> InteractionPolicy:
    """A fresh policy whose normalisers are fitted on ``frames`` (``proprio``, ``root_command``, ``action``:
    ``(N, dim)`` arrays or tensors); inputs clipped to +-``config.obs_clip`` after normalising."""
    norms = {
        "proprio": Normalizer.from_array(frames["proprio"], MIN_STD, config.obs_clip),
        "root_command": Normalizer.from_array(frames["root_command"], MIN_STD, config.obs_clip),
        "action": Normalizer.from_array(frames["action"], MIN_STD),
    }
    return InteractionPolicy(config, layout, vae, norms)


def save_policy(policy: InteractionPolicy, path: str | Path, **extra) -> Path:
    """The checkpoint dict (plus ``extra`` JSON-able entries, e.g. a training report) written atomically."""
    write_torch_atomic(Path(path), {**policy.to_checkpoint(), **extra})
    return Path(path)


def load_policy(
    path: str | Path, expect_layout: PolicyLayout | Mapping | None = None, device: str | torch.device = "cpu"
) -> InteractionPolicy:
    """The policy saved at ``path`` in eval mode on ``device``; a one-line :class:`InputError` naming the file and
    field if it is not such a checkpoint or its layout differs from ``expect_layout`` (a mapping: only its keys)."""
    try:
        ckpt = torch.load(Path(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a one-line input error
        raise InputError(path, "format", f"not a torch checkpoint ({type(exc).__name__})") from None
    return policy_from_checkpoint(ckpt, path, expect_layout).to(device).eval()


def policy_from_checkpoint(
    ckpt, path: str | Path, expect_layout: PolicyLayout | Mapping | None = None
) -> InteractionPolicy:
    """The policy of a loaded checkpoint dict (:meth:`InteractionPolicy.to_checkpoint`; another stage's checkpoint may
    nest one, as the vision student does its control head), checked as :func:`load_policy` says."""
    if not isinstance(ckpt, dict) or ckpt.get("format") != POLICY_FORMAT:
        raise InputError(path, "format", f"not an interaction policy checkpoint (expected format {POLICY_FORMAT!r})")
    try:
        layout = PolicyLayout.from_dict(ckpt["layout"])
        config = PolicyConfig.from_dict(ckpt["policy_config"])
    except (KeyError, TypeError, ValueError) as exc:
        raise InputError(path, "layout", f"unreadable policy layout or config ({type(exc).__name__})") from None
    if expect_layout is not None and (bad := layout.mismatch(expect_layout)) is not None:
        raise InputError(path, *bad)
    vae = DFVAE.from_checkpoint(ckpt.get("vae"), path)
    try:
        norms = {k: Normalizer.from_dict(d) for k, d in ckpt["normalizers"].items()}
        policy = InteractionPolicy(config, layout, vae, norms)
        policy.backbone.load_state_dict(ckpt["backbone"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise InputError(path, "backbone", f"unreadable policy weights ({type(exc).__name__})") from None
    return policy


def mean_policy(paths: list[str | Path], device: str | torch.device = "cpu") -> InteractionPolicy:
    """The policy whose backbone weights are the mean of those saved at ``paths`` (``theta = sum_j theta_j / n``,
    :class:`torch.optim.swa_utils.AveragedModel`; the frozen VAE and the normalisers are the last one's); a one-line
    :class:`InputError` if a checkpoint's layout or config differs from the last's."""
    policies = [load_policy(p, device=device) for p in paths]
    last = policies[-1]
    mean = torch.optim.swa_utils.AveragedModel(last.backbone)
    for path, policy in zip(paths, policies):
        if policy.config != last.config or policy.layout != last.layout:
            raise InputError(path, "layout", f"averaged with {paths[-1]}, whose policy layout or config differs")
        mean.update_parameters(policy.backbone)
    last.backbone.load_state_dict(mean.module.state_dict())
    return last.eval()
