"""An exported policy run by onnxruntime (:class:`OnnxPolicy`), with the interface the evaluation's
:class:`train.actors.PolicyActor` reads from a torch policy (``layout``, ``config.history``, ``eval()``,
``act(proprio, root_command, df)``), so ``lessmimic eval --policy file.onnx`` runs the file in the same harness.

onnxruntime runs on the CPU with one thread per session (the evaluation steps many environments per call; more
threads only contend with the physics on a small machine).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from pipeline.errors import InputError
from train.export.metadata import EXPORT_FORMAT, INPUTS, METADATA_KEY, OUTPUT, VISION_INPUTS
from train.policy import PolicyConfig, PolicyLayout


def read_metadata(path: str | Path) -> dict:
    """The :data:`~train.export.metadata.METADATA_KEY` dict of an exported file, or a one-line :class:`InputError`."""
    import onnx

    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as exc:  # noqa: BLE001 - any unreadable file is a one-line input error
        raise InputError(path, "format", f"not an ONNX model ({type(exc).__name__})") from None
    props = {p.key: p.value for p in model.metadata_props}
    try:
        meta = json.loads(props[METADATA_KEY])
    except (KeyError, ValueError):
        raise InputError(
            path, f"metadata_props.{METADATA_KEY}", "missing: not exported by `lessmimic export`"
        ) from None
    if meta.get("format") != EXPORT_FORMAT:
        raise InputError(path, "format", f"metadata format {meta.get('format')!r}, expected {EXPORT_FORMAT!r}")
    return meta


def cpu_session(model: str | Path | bytes):
    """An onnxruntime session of ``model`` (a file or its bytes) on the CPU with one thread (the module docstring;
    onnxruntime's default graph optimisation, all of them, as the released viewer's runtime sets)."""
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = options.inter_op_num_threads = 1
    return ort.InferenceSession(model if isinstance(model, bytes) else str(model), options, ["CPUExecutionProvider"])


class OnnxPolicy:
    """The exported policy at ``path``: ``act`` takes and returns what :meth:`InteractionPolicy.act` does."""

    def __init__(self, path: str | Path, expect_layout: PolicyLayout | Mapping | None = None):
        self.path = Path(path)
        self.metadata = read_metadata(path)
        self.layout = PolicyLayout.from_dict(self.metadata["policy"]["layout"])
        self.config = PolicyConfig.from_dict(self.metadata["policy"]["config"])
        if expect_layout is not None and (bad := self.layout.mismatch(expect_layout)) is not None:
            raise InputError(path, *bad)
        self.session = cpu_session(path)
        self.inputs = tuple(i.name for i in self.session.get_inputs())
        if self.inputs not in (INPUTS, VISION_INPUTS):
            raise InputError(path, "inputs", f"graph inputs {self.inputs}, expected {INPUTS} or {VISION_INPUTS}")
        self.camera = None
        if self.inputs == VISION_INPUTS:  # a vision student: the camera it was trained with
            from train.vision.camera import DepthCamera

            config = self.metadata["camera"]["config"]
            self.camera = DepthCamera.from_dict(config)

    def eval(self) -> OnnxPolicy:
        return self

    def act(self, proprio: torch.Tensor, root_command: torch.Tensor, third: torch.Tensor) -> torch.Tensor:
        """Joint targets for raw windows: ``third`` the DF windows, or a vision student's depth frames."""
        feed = {
            k: np.ascontiguousarray(x.detach().cpu().numpy(), np.float32)
            for k, x in zip(self.inputs, (proprio, root_command, third))
        }
        return torch.from_numpy(self.session.run([OUTPUT], feed)[0])

    def act_observation(self, terms: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """:meth:`act` on the environment's full observation windows: only the graph's inputs are read."""
        return self.act(*(terms[k] for k in self.inputs))
