"""Cost of attention capture, of the zero-shot edits and of inversion relative to one plain
generation, measured side by side in interleaved rounds.

A thin wrapper of ``salad bench --sections overheads`` (the measuring code lives in
:mod:`salad_core.bench`): plain generation, capture (streaming mean), word swap, refinement,
re-weighting, mirroring and fixed-point inversion with the shipped weights (or ``--weights``);
without ``--quick`` also the naive Algorithm 1 reference (three separate guided forwards per step,
the official code's structure).

Usage::

    python bench/bench_editing.py --quick --threads 1      # 120 frames, 10 steps, 1 round
    python bench/bench_editing.py --weights DIR --threads 1
"""
from __future__ import annotations

import sys

from salad_core.cli.bench import main

if __name__ == "__main__":
    sys.exit(main(["--sections", "overheads", *sys.argv[1:]]))
