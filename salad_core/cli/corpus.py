"""``salad corpus build|check``: the procedural motion-language corpus."""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Callable

from ._common import UserError, _sub


def cmd_corpus(args: argparse.Namespace) -> int:
    from salad_core.data.procedural import build_corpus, corpus_figures

    if args.action == "build":
        summary = build_corpus(args.out, size=args.size, seed=args.seed, overwrite=args.force,
                               progress=not args.quiet, general=args.with_general or 0)
        print(f"corpus written to {args.out}: " + ", ".join(f"{k}={v}" for k, v in summary.items()
                                                            if isinstance(v, (int, float, str))))
    else:
        root = Path(args.out)
        missing = [n for n in ("all.txt", "new_joint_vecs", "texts") if not (root / n).exists()]
        if not root.is_dir() or missing:
            raise UserError(f"--out {root} is not a corpus folder" + (f" (no {', '.join(missing)})" if root.is_dir()
                            else " (no such folder)") + f"; build one with: salad corpus build --out {root}")
        figs = corpus_figures(args.out)
        for k, v in figs.items():
            print(f"{k}: {v}")
    return 0


def add_parsers(sub) -> None:
    """The sub-command of this module: corpus."""
    c = _sub(sub, "corpus", "build or inspect the procedural motion-language corpus",
             "salad corpus build --out data/procedural --size default --seed 0")
    c.add_argument("action", choices=["build", "check"], help="build a corpus, or print the figures of one")
    c.add_argument("--out", required=True, help="corpus folder (HumanML3D layout)")
    c.add_argument("--size", default="default", choices=["tiny", "small", "default"],
                   help="build: how many motions (default: the full corpus, 4,000 plus mirrors)")
    c.add_argument("--seed", type=int, default=0, help="build: random seed (default 0)")
    c.add_argument("--force", action="store_true", help="write into a non-empty folder")
    c.add_argument("--with-general", nargs="?", const="auto", default=None, type=_general_count, metavar="N",
                   help="build: also write N captioned general-motion clips (lying, rolls, cartwheels, handstands, "
                        "flips, kneeling, crawling, jumps, ...; G<id> and mirrors MG<id>) into the splits: corpus 2.8. "
                        "Without N: half as many as --size's motions. Off by default (corpus 2.7)")


def _general_count(value: str):
    if value == "auto":
        return "auto"
    try:
        n = int(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--with-general takes a number of motions (>= 20) or 'auto', got {value!r}")
    if n < 20:
        raise argparse.ArgumentTypeError(f"--with-general {n}: use at least 20 motions (the splits need them)")
    return n


COMMANDS: dict[str, Callable] = {"corpus": cmd_corpus}
