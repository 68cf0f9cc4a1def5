"""Assemble a SaladPipeline folder from a VAE run and a denoiser run (the shipped weights).

Usage: python scripts/assemble_weights.py --vae RUN --denoiser RUN --out salad_core/weights/salad [--fp32]

Takes each run's ``best`` checkpoint (else ``latest``), the VAE run's Mean/Std, the denoiser run's
text encoder and diffusion config, and writes ``pipeline.json``, ``vae.*``, ``denoiser.*`` and
``stats.safetensors`` (fp16 weights unless --fp32), plus ``runs.json`` with the runs' configs and
final log lines for the model card.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from salad_core.io import atomic_write_text, config_from_dict, load_model, load_tensors
from salad_core.pipeline import SaladPipeline
from salad_core.sampling import DiffusionConfig
from salad_core.text import load_text_encoder


def _stem(run: Path) -> Path:
    for name in ("best", "latest"):
        if (run / f"{name}.safetensors").is_file():
            return run / name
    raise SystemExit(f"{run} has no best/latest checkpoint")


def _last_log(run: Path) -> dict:
    lines = (run / "log.jsonl").read_text().splitlines() if (run / "log.jsonl").is_file() else []
    return json.loads(lines[-1]) if lines else {}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vae", required=True, type=Path)
    ap.add_argument("--denoiser", required=True, type=Path)
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--fp32", action="store_true", help="store float32 weights (default float16)")
    args = ap.parse_args()

    vae, _, _ = load_model(_stem(args.vae))
    den, _, _ = load_model(_stem(args.denoiser))
    stats = load_tensors(args.vae / "mean_std.safetensors")
    den_cfg = json.loads((args.denoiser / "config.json").read_text())
    task = den_cfg.get("task", {})
    diffusion = config_from_dict(DiffusionConfig, task.get("diffusion", {})) if task.get("diffusion") else DiffusionConfig()
    encoder = load_text_encoder(task.get("text_encoder", "minilm"))
    pipe = SaladPipeline(vae, den, encoder, stats["mean"].numpy(), stats["std"].numpy(), diffusion=diffusion)
    pipe.save_pretrained(args.out, dtype=None if args.fp32 else torch.float16)
    runs = {}
    for name, run in (("vae", args.vae), ("denoiser", args.denoiser)):
        cfg = json.loads((run / "config.json").read_text())
        runs[name] = {"checkpoint": _stem(run).name, "config": cfg, "last_log": _last_log(run)}
    atomic_write_text(args.out / "runs.json", json.dumps(runs, indent=2) + "\n")
    size = sum(p.stat().st_size for p in args.out.iterdir())
    print(f"wrote {args.out} ({size / 1e6:.1f} MB)")


if __name__ == "__main__":
    main()
