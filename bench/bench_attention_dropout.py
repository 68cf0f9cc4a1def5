"""Denoiser training steps with attention dropout on the explicit route against SDPA's, side by side.

In training (attention dropout 0.1) the denoiser's attention used to go to PyTorch's CPU
``scaled_dot_product_attention`` with ``dropout_p > 0``, which runs its unfused math path; now short key
axes take :func:`salad_core.models.kernels.fast_attention`'s explicit route there too (probabilities,
``F.dropout`` on them, one product with the values), as they already did in sampling. This times whole
training steps (forward under bf16 autocast as ``configs/salad-0.3/denoiser.json`` trains, backward, AdamW) of
the denoiser of a config on one random batch (32 latent windows of 30 frames, 20 text tokens, half the
batch with 12-token prompts), the two routes interleaved in one process with the order flipped every
round (the reference inside :func:`~salad_core.models.kernels.sdpa_attention_dropout`), and prints the
median seconds per step and the ratio. That both routes compute the same attention in expectation is
tested (tests/test_attention_dropout.py), not here.

Example::

    python bench/bench_attention_dropout.py --threads 1 --rounds 6
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
    p.add_argument("--rounds", type=int, default=6)
    args = p.parse_args(argv)

    import torch

    from salad_core.bench.interleave import interleaved_medians
    from salad_core.io import config_from_dict
    from salad_core.models.denoiser import Denoiser, DenoiserConfig
    from salad_core.models.kernels import sdpa_attention_dropout

    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    model = Denoiser(config_from_dict(DenoiserConfig, json.loads(args.config.read_text())["model"]))
    cfg = model.config
    z = torch.randn(32, 30, 7, cfg.latent_dim)
    t = torch.randint(0, 1000, (32,))
    text = torch.randn(32, 20, cfg.text_dim)
    mask = torch.ones(32, 20, dtype=torch.bool)
    mask[16:, 12:] = False
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)

    def loss(reference: bool) -> torch.Tensor:
        with sdpa_attention_dropout(reference), torch.autocast("cpu", dtype=torch.bfloat16):
            return model(z, t, text, mask).float().pow(2).mean()

    model.train()

    def step(reference: bool) -> float:
        t0 = time.perf_counter()
        value = loss(reference)
        opt.zero_grad()
        value.backward()
        opt.step()
        return time.perf_counter() - t0

    sdpa, explicit = interleaved_medians(lambda: step(True), lambda: step(False), args.rounds)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"denoiser training step ({args.config.name}, batch 32, 30 latent frames, bf16 autocast, {args.threads} "
          f"thread(s), {args.rounds} rounds, load {load:.1f}): SDPA dropout {sdpa:.3f} s, explicit route "
          f"{explicit:.3f} s, ratio {sdpa / explicit:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
