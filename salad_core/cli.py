"""The ``salad`` command line.

Each sub-command lives in a small function that parses nothing itself: ``main`` builds the parser,
and errors that users can fix (bad input, missing files) print one line and exit with status 2,
without a traceback unless ``--debug`` is given.
"""
from __future__ import annotations

import argparse
import logging
import os
import sys
from pathlib import Path
from typing import Callable

log = logging.getLogger("salad")

EXAMPLES: dict[str, str] = {}


class UserError(Exception):
    """An error the user can fix; printed as one line."""


def _sub(subparsers, name: str, help: str, example: str) -> argparse.ArgumentParser:
    EXAMPLES[name] = example
    return subparsers.add_parser(
        name, help=help, description=f"{help}\n\nexample:\n  {example}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def _check_out_dir(path: str | os.PathLike, force: bool) -> Path:
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} exists and is not a folder")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise UserError(f"cannot create output folder {out}: {exc.strerror}") from None
    if not os.access(out, os.W_OK):
        raise UserError(f"output folder {out} is not writable")
    return out


# ----------------------------------------------------------------------------- corpus
def cmd_corpus(args: argparse.Namespace) -> int:
    from salad_core.data.procedural import build_corpus, corpus_figures

    if args.action == "build":
        summary = build_corpus(args.out, size=args.size, seed=args.seed, overwrite=args.force,
                               progress=not args.quiet)
        print(f"corpus written to {args.out}: " + ", ".join(f"{k}={v}" for k, v in summary.items()
                                                            if isinstance(v, (int, float, str))))
    else:
        figs = corpus_figures(args.out)
        for k, v in figs.items():
            print(f"{k}: {v}")
    return 0


# ----------------------------------------------------------------------------- train
def cmd_train(args: argparse.Namespace, rest: list[str]) -> int:
    from salad_core.train import main as train_main

    return int(train_main([args.what, *rest]) or 0)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="salad", description="salad: text-driven motion generation and attention-based editing")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("-q", "--quiet", action="store_true", help="less output, no progress bars")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")

    c = _sub(sub, "corpus", "build or inspect the procedural motion-language corpus",
             "salad corpus build --out data/procedural --size default --seed 0")
    c.add_argument("action", choices=["build", "check"], help="build a corpus, or print the figures of one")
    c.add_argument("--out", required=True, help="corpus folder (HumanML3D layout)")
    c.add_argument("--size", default="default", choices=["tiny", "default"])
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--force", action="store_true", help="write into a non-empty folder")

    t = _sub(sub, "train", "train the VAE or the denoiser (torchrun-ready)",
             "salad train vae --data data/procedural --out runs/vae")
    t.add_argument("what", choices=["vae", "denoiser"])
    return p


COMMANDS: dict[str, Callable] = {"corpus": cmd_corpus}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    if rest and args.command != "train":
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    try:
        if args.command == "train":
            return cmd_train(args, rest)
        return COMMANDS[args.command](args)
    except KeyboardInterrupt:
        print("salad: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # one clear line unless --debug
        if args.debug:
            raise
        print(f"salad {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
