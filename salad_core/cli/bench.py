"""``salad bench`` (and ``python -m salad_core.bench``): the command line of the benchmark table."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Sequence

import torch

from salad_core.bench.plan import OPTIONAL_SECTIONS, SECTIONS
from salad_core.bench.run import run_benchmarks
from salad_core.bench.table import format_table

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="salad bench", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="measure generation speed, the denoiser's roofline fraction, the overheads of capture, "
                    "edits and inversion, training steps/s and peak memory on this machine; one table.\n\n"
                    "example:\n  salad bench --quick --threads 1 --out bench.md")
    p.add_argument("--quick", action="store_true", help="about a minute: fewer timed steps (extrapolated)")
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's, here %d)"
                   % torch.get_num_threads())
    p.add_argument("--out", default=None, help="also write the table to this Markdown file")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.add_argument("--sections", default=None, help=f"comma-separated subset of {','.join(SECTIONS)} (default: "
                   f"all of them), or the opt-in {','.join(OPTIONAL_SECTIONS)}")
    p.add_argument("--weights", default=None, help="pipeline folder for memory/overheads (default: shipped)")
    p.add_argument("--realtime", default=None, help="realtime section: few-step weights folder (default: the shipped "
                   "salad_realtime if installed, else a stand-in of the same cost, said in the notes)")
    p.add_argument("--train-data", default=None, help="train section: HumanML3D-layout corpus (default: a small "
                   "procedural corpus built in a temporary folder)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """``salad bench``: print the table (and write it to ``--out``); returns the exit code."""
    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    threads = torch.get_num_threads() if args.threads is None else args.threads
    if threads < 1:
        raise ValueError(f"--threads {threads}: use a positive number of threads")
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.exists() and not args.force:
            raise FileExistsError(f"--out {out} exists; pass --force to overwrite it")
        if not out.parent.is_dir():
            raise FileNotFoundError(f"--out {out}: the folder {out.parent} does not exist")
    sections = [s.strip() for s in args.sections.split(",") if s.strip()] if args.sections else None
    from salad_core.allocator import tune_from_environment

    tune_from_environment()   # as the salad command does (also for the bench/ scripts that call this)
    df = run_benchmarks(args.quick, threads, sections=sections, weights=args.weights, train_data=args.train_data,
                        realtime=args.realtime)
    text = format_table(df)
    print(text, end="")
    if out is not None:
        from salad_core.io import atomic_write_text

        atomic_write_text(out, text)
        print(f"written to {out}")
    return 0
