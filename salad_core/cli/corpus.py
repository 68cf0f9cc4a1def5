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
                               progress=not args.quiet)
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


COMMANDS: dict[str, Callable] = {"corpus": cmd_corpus}
