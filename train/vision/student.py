"""The vision student pi_vis (paper Sec. III-D): the MoCap policy's control head on latents from egocentric depth.

The student reads ``o_vis = [o_prop, c_root, S_t]``: the same proprioception and root command windows as the MoCap
policy pi_full (:class:`train.policy.InteractionPolicy`) and ``S_t``, the last ``l`` depth frames of its camera
(:class:`train.vision.camera.DepthCamera`). A depth encoder ``E_phi`` maps every frame to a latent, in place of the
VAE latent of that step's DF features, and the teacher's control head reads the tokens as before:

    z_s = E_phi(D_s)                      (one CNN, shared over the l frames of the window)
    a   = head([normalize(o_prop_s), normalize(c_root_s), z_s]_{s = t-l+1 .. t})

``E_phi``: the frame ``D / far`` (invalid pixels read 0, as a RealSense reports them; valid ones lie in
``[near / far, 1]``) through a 4 x 4 patch embedding (16 channels, stride 4: 64 x 40 -> 16 x 10), a 3 x 3 stride-2
convolution (32 channels: 8 x 5), ReLUs, and a two-layer MLP (128) to the latent width. The paper gives no encoder; a
small per-frame CNN shared over the history is what depth students of this size use (the CNN encoders of legged
parkour students, mjlab's own depth CNN). Measured (one CPU thread, forward and backward of 1,280 frames, one batch of
256 windows): 89 ms, against 525 ms for three stride-2 convolutions (16, 32, 32; 5 x 5 first) and 255 ms for
(8, 16, 32): the patch embedding makes a refit of ~10^3 steps a matter of minutes on a laptop.

The head (backbone, normalisers) is a copy of pi_full's, fine-tuned with the encoder; the copy carries pi_full's
frozen VAE (the head's class holds one) but never applies it to the student's input (the alignment loss's targets,
:func:`train.vision.distill.distill_loss`, are pi_full's latents recorded during the rollouts).
:meth:`VisionPolicy.act_observation` takes the full observation the environment gives the MoCap policy and reads only
``proprio``, ``root_command`` and ``depth`` from it: the MoCap DF cannot leak in.

A checkpoint (:func:`save_vision_policy`, :func:`load_vision_policy`) nests pi_full's own checkpoint (the head) with
the encoder's weights and the camera, and names the teacher it was distilled from (path and SHA-256).
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from torch import nn

from pipeline.errors import InputError
from pipeline.stage.atomic import write_torch_atomic
from train.policy import InteractionPolicy, policy_from_checkpoint
from train.vision.camera import DepthCamera

VISION_FORMAT = "lessmimic.vision_policy/1"


@dataclass(frozen=True)
class EncoderConfig:
    """The depth CNN's strided ReLU convolutions ``(channels, kernel, stride)`` (a kernel equal to its stride: no
    padding, a patch embedding; else ``kernel // 2``) and its MLP's ``hidden`` width."""

    convs: tuple[tuple[int, int, int], ...] = ((16, 4, 4), (32, 3, 2))
    hidden: int = 128

    @classmethod
    def from_dict(cls, d: Mapping) -> EncoderConfig:
        return cls(convs=tuple(tuple(int(x) for x in c) for c in d["convs"]), hidden=int(d["hidden"]))


class DepthEncoder(nn.Module):
    """``(B, l, H, W)`` depth [m] -> ``(B, l, latent)``, one CNN per frame (module docstring)."""

    def __init__(self, camera: DepthCamera, latent: int, config: EncoderConfig = EncoderConfig()):
        super().__init__()
        self.camera, self.config, self.latent = camera, config, latent
        layers, c_in, h, w = [], 1, camera.height, camera.width
        for c, k, stride in config.convs:
            pad = 0 if k == stride else k // 2
            layers += [nn.Conv2d(c_in, c, k, stride=stride, padding=pad), nn.ReLU()]
            c_in, h, w = c, (h + 2 * pad - k) // stride + 1, (w + 2 * pad - k) // stride + 1
        if h < 1 or w < 1:
            raise ValueError(f"the encoder's convolutions leave no pixel of a {camera.width} x {camera.height} frame")
        self.conv = nn.Sequential(*layers, nn.Flatten())
        self.mlp = nn.Sequential(nn.Linear(c_in * h * w, config.hidden), nn.ReLU(), nn.Linear(config.hidden, latent))

    def forward(self, depth: torch.Tensor) -> torch.Tensor:
        b, steps, h, w = depth.shape
        if (h, w) != (self.camera.height, self.camera.width):
            raise ValueError(
                f"depth: expected (B, l, {self.camera.height}, {self.camera.width}), got {tuple(depth.shape)}"
            )
        x = (depth.float() / self.camera.far).reshape(b * steps, 1, h, w)
        return self.mlp(self.conv(x)).view(b, steps, self.latent)


class VisionPolicy(nn.Module):
    """``(proprio (B,l,P), root_command (B,l,C), depth (B,l,H,W))`` raw -> joint targets (module docstring)."""

    def __init__(self, control: InteractionPolicy, encoder: DepthEncoder, teacher: Mapping | None = None):
        super().__init__()
        if encoder.latent != control.config.latent:
            raise ValueError(
                f"the encoder's latent width {encoder.latent} differs from the head's {control.config.latent}"
            )
        self.control, self.encoder = control, encoder
        self.control.vae.requires_grad_(False)
        self.teacher = dict(teacher or {})  # {"path", "sha256"} of pi_full

    @property
    def layout(self):
        return self.control.layout

    @property
    def config(self):
        return self.control.config

    @property
    def camera(self) -> DepthCamera:
        return self.encoder.camera

    @property
    def norm(self) -> nn.ModuleDict:
        """The head's normalisers (proprio, root command, action)."""
        return self.control.norm

    def train(self, mode: bool = True) -> VisionPolicy:
        super().train(mode)
        self.control.vae.eval()
        return self

    def trainable_parameters(self) -> list[nn.Parameter]:
        return [p for n, p in self.named_parameters() if p.requires_grad and not n.startswith("control.vae.")]

    def latents(self, depth: torch.Tensor) -> torch.Tensor:
        """``E_phi(depth)`` ``(B, l, latent)``; unit-norm under the demo contract, as the head was trained."""
        z = self.encoder(depth)
        return z / (z.norm(dim=-1, keepdim=True) + 1e-8) if self.layout.demo else z

    def head(self, proprio: torch.Tensor, root_command: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """Normalised actions ``(B, A)`` of the control head on latents ``z (B, l, latent)``."""
        return self.control.backbone(self.control.tokens_from_latents(proprio, root_command, z))

    def forward(self, proprio: torch.Tensor, root_command: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        """Normalised actions ``(B, A)`` (what the distillation loss compares)."""
        return self.head(proprio, root_command, self.latents(depth))

    @torch.no_grad()
    def act(self, proprio: torch.Tensor, root_command: torch.Tensor, depth: torch.Tensor) -> torch.Tensor:
        """Raw joint position targets ``(B, A)`` for raw windows."""
        return self.norm["action"].denormalize(self(proprio, root_command, depth))

    @torch.no_grad()
    def act_observation(self, terms: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """:meth:`act` on the environment's full observation windows (``proprio``, ``root_command``, ``df``,
        ``depth``, ...): only ``proprio``, ``root_command`` and ``depth`` are read."""
        return self.act(terms["proprio"], terms["root_command"], terms["depth"])

    def to_checkpoint(self) -> dict:
        return {
            "format": VISION_FORMAT,
            "control": self.control.to_checkpoint(),
            "camera": asdict(self.camera),
            "encoder_config": asdict(self.encoder.config),
            "encoder": {k: v.detach().cpu() for k, v in self.encoder.state_dict().items()},
            "teacher": self.teacher,
        }


def vision_student(
    teacher: InteractionPolicy,
    camera: DepthCamera,
    config: EncoderConfig = EncoderConfig(),
    source: Mapping | None = None,
) -> VisionPolicy:
    """A fresh student of ``teacher`` (pi_full): a copy of its head, a new encoder (torch's default initialisation,
    under the caller's seed); ``source``: the teacher's ``{"path", "sha256"}``."""
    control = copy.deepcopy(teacher).cpu()
    return VisionPolicy(control, DepthEncoder(camera, teacher.config.latent, config), source)


def save_vision_policy(policy: VisionPolicy, path: str | Path, **extra) -> Path:
    """The checkpoint dict (plus JSON-able ``extra``, e.g. the distillation's settings) written atomically."""
    write_torch_atomic(Path(path), {**policy.to_checkpoint(), **extra})
    return Path(path)


def is_vision_checkpoint(path: str | Path) -> bool:
    """Whether ``path`` is a vision student's checkpoint (an unreadable file is not)."""
    try:
        return torch.load(Path(path), map_location="cpu", weights_only=True).get("format") == VISION_FORMAT
    except Exception:  # noqa: BLE001 - whatever it is, it is not a vision checkpoint
        return False


def load_vision_policy(path: str | Path, device: str | torch.device = "cpu") -> VisionPolicy:
    """The student saved at ``path`` in eval mode; a one-line :class:`InputError` naming the file and field if it is
    not one."""
    try:
        ckpt = torch.load(Path(path), map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a one-line input error
        raise InputError(path, "format", f"not a torch checkpoint ({type(exc).__name__})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != VISION_FORMAT:
        raise InputError(path, "format", f"not a vision policy checkpoint (expected format {VISION_FORMAT!r})")
    control = policy_from_checkpoint(ckpt.get("control"), path)
    try:
        camera = DepthCamera.from_dict(ckpt["camera"])
        encoder = DepthEncoder(camera, control.config.latent, EncoderConfig.from_dict(ckpt["encoder_config"]))
        encoder.load_state_dict(ckpt["encoder"])
    except (KeyError, TypeError, ValueError, RuntimeError) as exc:
        raise InputError(path, "encoder", f"unreadable depth encoder ({type(exc).__name__})") from None
    return VisionPolicy(control, encoder, ckpt.get("teacher")).to(device).eval()
