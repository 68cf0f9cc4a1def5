"""The ``salad`` command line, at the top of the toolkit: the only part of ``salad_core`` that draws figures (with
``salad_viz``) and tunes the process (OpenMP wait policy, allocator).

Each sub-command lives in a small function that parses nothing itself: ``main`` builds the parser,
and errors that users can fix (bad input, missing files) print one line and exit with status 2,
without a traceback unless ``--debug`` is given. One module per command group:

``generate``  ``salad demo``, ``generate``, ``edit``, ``invert``
``files``     ``salad import``, ``render``, ``export`` (and the motion-file readers ``invert`` shares)
``corpus``    ``salad corpus``
``eval``      ``salad eval`` (its own parser)
``train``     ``salad train`` (its own parser; also ``python -m salad_core.train`` and ``torchrun -m``)
``bench``     ``salad bench`` (its own parser; also ``python -m salad_core.bench``)
``_common``   the user errors, output checks and files, :func:`run_reporting_errors`, :func:`tune_process`

Importing this package loads neither torch nor salad_viz: :func:`main` first chooses the OpenMP wait policy
(:func:`salad_core.openmp.configure`), then each command imports what it needs. ``import salad_core`` alone
changes nothing in the process.
"""
from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path
from typing import Callable

from . import corpus as _corpus
from . import files as _files
from . import generate as _generate
from ._common import EXAMPLES, UserError, _quiet_libraries, _sub, run_reporting_errors, tune_process

__all__ = ["main", "build_parser", "run_reporting_errors", "tune_process", "UserError", "COMMANDS", "PASS_THROUGH",
           "EXAMPLES"]

log = logging.getLogger("salad")


# ----------------------------------------------------------------------------- the commands with their own parser
def cmd_eval(args: argparse.Namespace, rest: list[str]) -> int:
    from salad_core.cli.eval import main as eval_main

    return int(eval_main(rest) or 0)


def _option_value(rest: list[str], flag: str) -> str | None:
    """The value of ``flag`` (``--flag V`` or ``--flag=V``) among pass-through arguments."""
    for i, item in enumerate(rest):
        if item == flag and i + 1 < len(rest):
            return rest[i + 1]
        if item.startswith(flag + "="):
            return item.split("=", 1)[1]
    return None


def cmd_train(args: argparse.Namespace, rest: list[str]) -> int:
    import json

    from salad_core.cli.train import main as train_main

    try:
        return int(train_main(([args.what] if args.what else []) + rest) or 0)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        # the trainers' parser reads --config without naming it in the error: say which file and why
        config = _option_value(rest, "--config")
        try:
            if config is None:
                raise ValueError
            json.loads(Path(config).read_text(encoding="utf-8"))
        except (OSError, ValueError):        # the --config file is the culprit (JSONDecodeError is a ValueError)
            what = (f"{exc.msg} at line {exc.lineno}, column {exc.colno}" if isinstance(exc, json.JSONDecodeError)
                    else "it is not UTF-8 text")
            if config is not None:
                raise UserError(f"--config {config} is not a JSON document ({what}); see "
                                "configs/salad-0.3/vae.json for the format") from None
        raise


def cmd_bench(args: argparse.Namespace, rest: list[str]) -> int:
    from salad_core.cli.bench import main as bench_main

    return int(bench_main(rest) or 0)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="salad", description="salad: text-driven motion generation and attention-based editing")
    p.add_argument("--debug", action="store_true", help="show full tracebacks")
    p.add_argument("-q", "--quiet", action="store_true", help="less output, no progress bars")
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    _generate.add_parsers(sub)      # demo, generate, edit, invert
    _files.add_parsers(sub)         # import, render, export
    _corpus.add_parsers(sub)        # corpus

    t = _sub(sub, "train", "train the SALAD VAE or denoiser, or the three KeyMotion models (torchrun-ready)",
             "salad train vae --data data/procedural --out runs/vae", add_help=False)
    # --help and the choices go to salad_core.cli.train (TRAIN_TARGETS), which owns them; importing
    # them here would load torch for every command
    t.add_argument("what", nargs="?", help="vae, denoiser or keymotion")

    _sub(sub, "eval", "evaluate generators with the T2M protocol (R-precision, FID, MM-Dist, Diversity, "
         "MultiModality), CFG sweeps", "salad eval --data data/procedural --quick --out eval_out",
         add_help=False)  # --help goes to the evaluation's own parser (salad_core.cli.eval)
    _sub(sub, "bench", "measure speed, roofline fraction, edit overheads, training rate and memory on this "
         "machine; one table", "salad bench --quick --threads 1 --out bench.md",
         add_help=False)  # --help goes to the benchmark's own parser (salad_core.cli.bench)
    return p


COMMANDS: dict[str, Callable] = {**_corpus.COMMANDS, **_generate.COMMANDS, **_files.COMMANDS}
#: Commands whose remaining arguments go to another module's parser.
PASS_THROUGH: dict[str, Callable] = {"train": cmd_train, "eval": cmd_eval, "bench": cmd_bench}


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    args, rest = parser.parse_known_args(argv)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO,
                        format="%(levelname)s %(name)s: %(message)s")
    if args.command is None:
        parser.print_help()
        return 2
    if args.quiet:
        _quiet_libraries()
    tune_process(parser)     # the OpenMP wait policy (before any command loads torch) and the allocator
    if rest and args.command not in PASS_THROUGH:
        parser.error(f"unrecognized arguments: {' '.join(rest)}")
    if hasattr(args, "preset"):
        _generate._resolve_sampler(args, parser)
    if args.command in PASS_THROUGH:
        return run_reporting_errors(f"salad {args.command}", args.debug, lambda: PASS_THROUGH[args.command](args, rest))
    return run_reporting_errors(f"salad {args.command}", args.debug, lambda: COMMANDS[args.command](args))
