"""One denoiser training step (forward, backward, AdamW) in float32 and under bf16 autocast, interleaved.

Times the model's own step on random inputs shaped like a training batch (no data loading, no latent
cache), alternating the two settings in one process with the order flipped every round, so both meet
the same machine. Prints the median seconds per step of each and their ratio.

Example::

    python bench/bench_denoiser_step.py --config configs/salad-0.3/denoiser.json --threads 1 --rounds 4
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", type=Path, default=HERE / "configs" / "salad-0.3" / "denoiser.json")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--batch", type=int, default=32)
    p.add_argument("--frames", type=int, default=120, help="motion frames (latent frames = frames / 4)")
    p.add_argument("--words", type=int, default=20, help="text tokens")
    p.add_argument("--rounds", type=int, default=4)
    args = p.parse_args(argv)

    import torch

    from salad_core.bench.interleave import interleaved_medians
    from salad_core.io import config_from_dict
    from salad_core.models.denoiser import Denoiser, DenoiserConfig

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    doc = json.loads(args.config.read_text())
    model = Denoiser(config_from_dict(DenoiserConfig, doc["model"])).train()
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
    cfg = model.config
    b, n = args.batch, args.frames // 4
    x = torch.randn(b, n, 7, cfg.latent_dim)
    t = torch.randint(0, 1000, (b,))
    text = torch.randn(b, args.words, cfg.text_dim)
    mask = torch.ones(b, args.words, dtype=torch.bool)

    def step(bf16: bool) -> float:
        t0 = time.perf_counter()
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            out = model(x, t, text, mask)
        loss = out.float().pow(2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        return time.perf_counter() - t0

    fp32, bf16 = interleaved_medians(lambda: step(False), lambda: step(True), args.rounds)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"denoiser step ({args.config.name}, batch {b}, {n} latent frames, {args.threads} thread(s), "
          f"{args.rounds} rounds, load {load:.1f}): float32 {fp32:.3f} s, bf16 autocast {bf16:.3f} s, "
          f"ratio {fp32 / bf16:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
