"""ONNX export of an interaction policy (``lessmimic export``, ``make export``).

The graph is the policy as it acts: raw observation windows in, raw joint targets out,

    joint_targets = denormalize(backbone([normalize(proprio), normalize(root_command), mu_VAE(df)]))

with the normalisers, the frozen VAE encoder and the backbone inside (:class:`ActingGraph`; inputs
:data:`~train.export.metadata.INPUTS`, each ``(batch, history, width)``, the batch dynamic). It is exported with
torch's dynamo exporter (``torch.onnx.export(dynamo=True)``, opset :data:`OPSET`: the maintained path, the
TorchScript exporter being deprecated), and its contract (:func:`train.export.metadata.policy_metadata`) goes into
the model's ``metadata_props``. Any interaction policy checkpoint exports: BC + DAgger, post-trained, an averaged one,
and a vision student (inputs :data:`~train.export.metadata.VISION_INPUTS`, depth frames ``(batch, history, H, W)``,
its camera's intrinsics and extrinsics in the metadata).

Before anything is written the file is checked: onnxruntime and torch act on :data:`CHECK_BATCH` observations drawn
around the normalisers' statistics and must agree within :data:`CHECK_TOL` (a wrong graph, not float rounding, is
what this catches: the parity target on recorded observations is 1e-5, measured in the tests and the notes). The
file is written atomically; a bad input leaves nothing.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import onnx
import torch
from torch import nn

from pipeline.errors import InputError
from pipeline.stage.atomic import write_bytes_atomic
from train.export.metadata import OUTPUT, inputs_of, metadata_props, policy_metadata
from train.export.runtime import cpu_session
from train.policy import InteractionPolicy, load_policy

OPSET = 18
CHECK_BATCH = 64
CHECK_TOL = 1e-4


class ActingGraph(nn.Module):
    """``(proprio, root_command, df)`` raw windows -> raw joint targets: :meth:`InteractionPolicy.act` as a module
    (a vision student's: ``(proprio, root_command, depth)``, :class:`train.vision.student.VisionPolicy`)."""

    def __init__(self, policy: InteractionPolicy):
        super().__init__()
        self.policy = policy.eval()

    def forward(self, proprio: torch.Tensor, root_command: torch.Tensor, third: torch.Tensor) -> torch.Tensor:
        return self.policy.norm["action"].denormalize(self.policy(proprio, root_command, third))


@dataclass(frozen=True)
class ExportReport:
    path: Path
    bytes: int
    seconds: float
    check_max_abs: float  # onnxruntime vs torch on the check batch [rad]


def check_finite(policy: InteractionPolicy, checkpoint: str | Path) -> None:
    """A one-line :class:`InputError` naming the first weight or statistic with a NaN or an infinity."""
    for name, t in [*policy.named_parameters(), *policy.named_buffers()]:
        if not torch.isfinite(t).all():
            bad = int((~torch.isfinite(t)).sum())
            raise InputError(checkpoint, name, f"{bad} of {t.numel()} values are not finite: nothing to export")


def check_batch(policy: InteractionPolicy, n: int = CHECK_BATCH, seed: int = 0) -> tuple[torch.Tensor, ...]:
    """``n`` observation windows drawn as ``mean + std * N(0, 1)`` of each input's normaliser (the VAE's for df); a
    vision student's depth frames uniform in its camera's range."""
    g = torch.Generator().manual_seed(seed)
    lay = policy.layout
    dims = lay.observation.step_dims[:2]
    drawn = tuple(
        nm.mean.cpu() + nm.std.cpu() * torch.randn(n, lay.history, d, generator=g)
        for nm, d in zip((policy.norm["proprio"], policy.norm["root_command"]), dims)
    )
    cam = getattr(policy, "camera", None)
    if cam is not None:
        depth = cam.near + (cam.far - cam.near) * torch.rand(n, lay.history, cam.height, cam.width, generator=g)
        return (*drawn, depth)
    vae = policy.vae.norm
    return (*drawn, vae.mean.cpu() + vae.std.cpu() * torch.randn(n, lay.history, lay.df_dim, generator=g))


def load_any_policy(checkpoint: str | Path):
    """The MoCap-DF policy or the vision student saved at ``checkpoint`` (one-line errors for anything else)."""
    from train.vision.student import is_vision_checkpoint, load_vision_policy

    return load_vision_policy(checkpoint) if is_vision_checkpoint(checkpoint) else load_policy(checkpoint)


def quiet_export(graph: nn.Module, example: tuple, inputs: list[str], output: str, opset: int = OPSET):
    """``torch.onnx.export(dynamo=True)`` of ``graph`` (eval mode) with a dynamic batch axis on every input; the
    exporter's own deprecation notices silenced. Returns the ``ONNXProgram``."""
    batch = torch.export.Dim("batch")
    with warnings.catch_warnings():  # torch.export's internal deprecation notices, not the user's business
        warnings.simplefilter("ignore", FutureWarning)
        warnings.filterwarnings("ignore", message=".*axis name.*")
        return torch.onnx.export(
            graph.eval(),
            example,
            input_names=inputs,
            output_names=[output],
            dynamic_shapes=({0: batch},) * len(inputs),
            opset_version=opset,
            dynamo=True,
            external_data=False,
            verbose=False,
        )


def onnx_model(policy: InteractionPolicy) -> onnx.ModelProto:
    """The policy's acting graph as an ONNX model (no metadata yet)."""
    return quiet_export(ActingGraph(policy.cpu()), check_batch(policy, 2), list(inputs_of(policy)), OUTPUT).model_proto


def export_onnx(checkpoint: str | Path, out: str | Path | None = None, overwrite: bool = False) -> ExportReport:
    """Write the ONNX file of the policy at ``checkpoint`` to ``out`` (default: beside it, ``.onnx``); one-line
    :class:`InputError` for an existing ``out`` without ``overwrite``, a file that is not an interaction policy, or
    non-finite weights, with nothing written."""
    t0 = time.perf_counter()
    checkpoint = Path(checkpoint)
    out = Path(out) if out is not None else checkpoint.with_suffix(".onnx")
    if out.exists() and not overwrite:
        raise InputError(out, "output", "exists: pass --overwrite to replace it")
    policy = load_any_policy(checkpoint)
    check_finite(policy, checkpoint)
    model = onnx_model(policy)
    for key, value in metadata_props(policy_metadata(policy, checkpoint)).items():
        model.metadata_props.add(key=key, value=value)
    onnx.checker.check_model(model)
    x = check_batch(policy)
    with torch.no_grad():
        want = ActingGraph(policy)(*x).numpy()
    feed = {k: t.numpy() for k, t in zip(inputs_of(policy), x)}
    got = cpu_session(model.SerializeToString()).run([OUTPUT], feed)[0]
    err = float(np.abs(got - want).max())
    if not err <= CHECK_TOL:
        raise InputError(checkpoint, "export", f"onnxruntime differs from torch by {err:.2e} rad (> {CHECK_TOL:g})")
    data = model.SerializeToString()
    write_bytes_atomic(out, data)
    return ExportReport(out, len(data), time.perf_counter() - t0, err)
