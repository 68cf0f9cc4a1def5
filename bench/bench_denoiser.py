"""Speed of the SALAD denoiser on this machine: seconds per generated motion and roofline fraction.

A thin wrapper of ``salad bench --sections speed`` (the measuring code lives in
:mod:`salad_core.bench`): for the paper configuration (width 256, 5 layers, FFN 1024, 8 heads,
CLIP text 512 x 77 tokens) and the shipped default (width 128, MiniLM text), seconds per motion
(196 frames, 50 DDIM steps, guidance 7.5, random text features) at batch 1 and 32 and for a
120-frame motion; FLOPs per step from the configuration against this machine's matmul GFLOP/s at
the same shapes. Without ``--quick`` it also times the text K/V cache and the eager processor.

Usage::

    python bench/bench_denoiser.py --quick --threads 1     # about 30 s
    python bench/bench_denoiser.py --threads 2 --out speed.md
"""
from __future__ import annotations

import sys

from salad_core.cli.bench import main

if __name__ == "__main__":
    sys.exit(main(["--sections", "speed", *sys.argv[1:]]))
