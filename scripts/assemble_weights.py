"""Assemble a SaladPipeline folder from a VAE run and a denoiser run (the shipped weights).

Usage: python scripts/assemble_weights.py [--vae RUN] --denoiser RUN --out salad_core/weights/salad [--fp32]

Without --vae, the VAE the denoiser run recorded (its ``config.json``) is taken; a VAE other than the one the
denoiser trained on is refused (compared weight by weight, so an exported copy of it passes).

Takes each run's ``best`` checkpoint (else ``latest``), the VAE run's Mean/Std, the denoiser run's
text encoder and diffusion config, and writes ``pipeline.json``, ``vae.*``, ``denoiser.*`` and
``stats.safetensors`` (fp16 weights unless --fp32), plus ``runs.json`` with the runs' configs and
final log lines for the model card (:func:`salad_core.train.assemble.assemble_pipeline`).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch

from salad_core.train.assemble import assemble_pipeline


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vae", type=Path, help="the denoiser's VAE (run or exported folder; default: the one it recorded)")
    ap.add_argument("--denoiser", required=True, type=Path)
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--fp32", action="store_true", help="store float32 weights (default float16)")
    args = ap.parse_args()
    out = assemble_pipeline(args.vae, args.denoiser, args.out, dtype=None if args.fp32 else torch.float16)
    size = sum(p.stat().st_size for p in out.iterdir())
    print(f"wrote {out} ({size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
