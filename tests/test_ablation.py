"""Table 2's ablations as one switch of the training commands (:mod:`train.ablation`)."""

import re
from pathlib import Path

import pytest

from lessmimic.cli import main
from pipeline.errors import InputError
from train.ablation import ablated


def test_each_ablation_trains_where_it_says():
    full = ablated("corpus", "runs/bc", "", "post")
    assert (full.corpus, full.run, full.backbone, full.post_dir) == (
        "corpus",
        Path("runs/bc"),
        "transformer",
        Path("runs/bc/aip"),
    )
    assert ablated("corpus", "runs/bc", "-AIP", "post").post_dir == Path("runs/bc/aip-AIP")
    assert ablated("corpus", "runs/bc", "-Rand", "post").post == "-Rand"
    syn = ablated("corpus", "runs/bc", "-Syn", "pre")
    assert (syn.corpus, syn.run, syn.post_dir) == ("corpus-syn", Path("runs/bc-Syn"), Path("runs/bc-Syn/aip"))
    trans = ablated("corpus", "runs/bc", "-Trans", "post")
    assert (trans.corpus, trans.run, trans.backbone) == ("corpus", Path("runs/bc-Trans"), "mlp")
    assert ablated("corpus", "runs/bc", "-Syn", "pre", "mlp").backbone == "mlp"  # -Syn keeps the backbone asked for
    assert ablated("corpus", "runs/bc", "-Trans", "pre", "transformer").backbone == "mlp"


@pytest.mark.parametrize(
    "ablation, stage, why",
    [
        ("-Foo", "post", "unknown ablation '-Foo'; known: -AIP, -Syn, -Rand, -RL, -Trans"),
        ("-RL", "post", "-RL is the BC + DAgger policy as it is: score it with `make eval POLICY=runs/bc/policy.pt`"),
        ("-AIP", "pre", "-AIP is a post-training ablation: pre-train the full run"),
    ],
)
def test_an_ablation_a_stage_cannot_run_is_a_one_line_error(ablation, stage, why):
    with pytest.raises(InputError, match="ablation: " + re.escape(why)) as info:
        ablated("corpus", "runs/bc", ablation, stage)
    assert "\n" not in str(info.value)


def test_the_commands_say_which_run_an_ablation_needs(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("LESSMIMIC_DATASETS", str(tmp_path))
    assert main(["train-aip", "--run", str(tmp_path / "bc"), "--ablation=-Syn"]) == 2
    assert main(["train-bc", "--run", str(tmp_path / "bc"), "--ablation=-Rand"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2
    assert (
        f"{tmp_path}/bc-Syn/policy.pt: policy.pt: no BC + DAgger policy here: run `make train-bc ABLATION=-Syn`"
        in err[0]
    )
    assert "-Rand is a post-training ablation" in err[1]
