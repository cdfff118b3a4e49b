"""The ablations of the paper's Table 2 as one switch of the training commands (``ABLATION=`` of ``make train-bc``,
``make train-aip`` and ``make corpus``). Each removes one component of the full system:

======== ================================================== ===================================================
ablation what it removes                                     where it acts
======== ================================================== ===================================================
-AIP     the adversarial interaction prior                   post-training: ``runs/<RUN>/aip-AIP/``
-Rand    every domain randomisation                          post-training: ``runs/<RUN>/aip-Rand/``
-Syn     physicalization: trained on the retargeted motion   its own corpus ``datasets/<CORPUS>-syn/`` (physicalize
         as it is (:mod:`physicalize.kinematic`)             teacher ``kinematic``) and run ``runs/<RUN>-Syn/``
-Trans   the Transformer (an MLP backbone)                   its own run ``runs/<RUN>-Trans/``
-RL      post-training                                       nothing to train: the BC + DAgger ``runs/<RUN>/policy.pt``
======== ================================================== ===================================================

Every ablation is evaluated on the full corpus's episodes (``make eval``), so the rows compare on one test set.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pipeline.errors import InputError

ABLATIONS = ("-AIP", "-Syn", "-Rand", "-RL", "-Trans")
POST_TRAINING = ("-AIP", "-Rand")
PRE_TRAINING = ("-Syn", "-Trans")


@dataclass(frozen=True)
class Ablated:
    """Where an ablation trains: its ``corpus`` name, its pre-training ``run`` folder and ``backbone``, and the
    post-training ablation ``post`` (``""`` or one of :data:`POST_TRAINING`)."""

    corpus: str
    run: Path
    backbone: str = "transformer"
    post: str = ""

    @property
    def post_dir(self) -> Path:
        """The post-training's folder: ``<run>/aip<post>/``."""
        return self.run / f"aip{self.post}"


def ablated(corpus: str, run: str | Path, ablation: str, stage: str, backbone: str = "transformer") -> Ablated:
    """The corpus and folders of ``ablation`` (``""``: the full system) for a run named ``run`` on ``corpus`` with
    the ``backbone`` asked for (``-Trans``: the MLP, whatever was asked), as the training ``stage`` (``pre`` or
    ``post``) sees them; an unknown ablation, or one the stage has nothing to do for, is a one-line
    :class:`InputError`."""
    run = Path(run)
    if ablation and ablation not in ABLATIONS:
        raise InputError(None, "ablation", f"unknown ablation {ablation!r}; known: {', '.join(ABLATIONS)}")
    if ablation == "-RL":
        why = f"-RL is the BC + DAgger policy as it is: score it with `make eval POLICY={run}/policy.pt`"
        raise InputError(None, "ablation", why)
    if ablation in POST_TRAINING:
        if stage == "pre":
            why = f"{ablation} is a post-training ablation: pre-train the full run (`make train-bc`), then "
            raise InputError(None, "ablation", why + f"`make train-aip ABLATION={ablation}`")
        return Ablated(corpus, run, post=ablation)
    if ablation == "-Syn":
        return Ablated(f"{corpus}-syn", run.with_name(run.name + "-Syn"), backbone)
    if ablation == "-Trans":
        return Ablated(corpus, run.with_name(run.name + "-Trans"), backbone="mlp")
    return Ablated(corpus, run, backbone)
