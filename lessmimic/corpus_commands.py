"""Commands on whole corpora (``lessmimic subset``), kept apart from the per-stage commands of :mod:`lessmimic.cli`."""

from __future__ import annotations

import argparse


def _cmd_subset(a: argparse.Namespace) -> int:
    from pipeline.dataset.subset import subset_corpus

    variants = [v.strip() for v in a.variants.split(",") if v.strip()]
    summary = subset_corpus(a.name, a.out, variants, overwrite=a.overwrite)
    counts = ", ".join(f"{stage} {n}" for stage, n in summary["episodes"].items())
    print(f"datasets/{a.out}/: {', '.join(summary['variants'])} of datasets/{a.name}/ ({counts} episodes)")
    print(f"  held out: {', '.join(summary['held_out'])}")
    return 0


def add_corpus(sub) -> None:
    p = sub.add_parser(
        "subset",
        help="a training corpus of some geometry variants of an augmented corpus (the others held out for the "
        "evaluation): datasets/<OUT>/{retargeted,physicalized,features}/ and subset.json",
    )
    p.add_argument("--name", required=True, help="the augmented corpus (datasets/<NAME>/)")
    p.add_argument("--out", required=True, help="the subset's corpus name (datasets/<OUT>/)")
    p.add_argument(
        "--variants", required=True, help="comma list of the variant labels kept, e.g. x0.6,x0.8,x1,x1.2,x1.4"
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing datasets/<OUT>/")
    p.set_defaults(func=_cmd_subset, writes="out")
