"""AdamW's three implementations (PyTorch's per-tensor CPU loop, ``foreach``, ``fused``; ``TrainConfig.adamw``)
side by side, for the shipped models' parameters.

The trainer (``salad_core.train.common.fit``) used to build ``torch.optim.AdamW`` with PyTorch's defaults, which
on CPU run the per-tensor loop (``_single_tensor_adam``); it now takes the fused one. A ``py-spy`` sample of the running KeyMotion PST
training put 11 % of its time there: its models are small (width 128), so each step's arithmetic is tiny and
the loop's per-tensor overhead is what costs. This times ``optimizer.step()`` alone (random gradients, the
trainer's ``make_adamw`` with betas 0.9/0.99) for each model, the implementations interleaved in one process,
and prints the median milliseconds per step and the ratios; it also checks that the three give the same
parameters after the timed steps (maximum absolute difference).

Example::

    python bench/bench_optimizer_step.py --threads 1 --rounds 30
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
WEIGHTS = HERE / "salad_core" / "weights"
MODELS = {"KeyMotion PST": WEIGHTS / "keymotion" / "pst", "KeyMotion MMAE": WEIGHTS / "keymotion" / "mmae",
          "KeyMotion keyframe VAE": WEIGHTS / "keymotion" / "kf_vae", "SALAD denoiser": WEIGHTS / "salad" / "denoiser",
          "SALAD VAE": WEIGHTS / "salad" / "vae"}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=30, help="timed steps of each implementation per model")
    args = p.parse_args(argv)

    import torch

    from salad_core.io import load_model
    from salad_core.train.config import ADAMW_IMPLEMENTATIONS, TrainConfig, make_adamw

    KINDS = tuple(reversed(ADAMW_IMPLEMENTATIONS))              # loop, foreach, fused
    torch.set_num_threads(args.threads)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"AdamW step alone, {args.threads} thread(s), {args.rounds} interleaved rounds, load {load:.1f}, "
          f"torch {torch.__version__}")
    print("| model | parameters (tensors) | loop (ms) | foreach (ms) | fused (ms) | loop / foreach | loop / fused | "
          "max difference after the steps |")
    print("|---|---|---|---|---|---|---|---|")
    for name, stem in MODELS.items():
        model = load_model(stem)[0].float()
        base = [q.detach().clone() for q in model.parameters() if q.requires_grad]   # what the trainer optimises
        params = {k: [torch.nn.Parameter(b.clone()) for b in base] for k in KINDS}
        opts = {k: make_adamw(params[k], TrainConfig(adamw=k, weight_decay=0.0), lr=1e-4) for k in KINDS}
        gen = torch.Generator().manual_seed(0)
        grads = [[torch.empty_like(b).normal_(generator=gen) for b in base] for _ in range(4)]   # the params' strides
        times: dict[str, list[float]] = {k: [] for k in KINDS}
        for r in range(args.rounds + 1):
            order = KINDS if r % 2 == 0 else KINDS[::-1]
            for k in order:
                for q, g in zip(params[k], grads[r % len(grads)]):
                    q.grad = g.clone()
                t0 = time.perf_counter()
                opts[k].step()
                if r:                                            # round 0 warms up
                    times[k].append(time.perf_counter() - t0)
        ms = {k: 1e3 * statistics.median(v) for k, v in times.items()}
        diff = max(float((a - b).detach().abs().max()) for k in ("foreach", "fused")
                   for a, b in zip(params["loop"], params[k]))
        n = sum(b.numel() for b in base)
        print(f"| {name} | {n:,} ({len(base)}) | {ms['loop']:.2f} | {ms['foreach']:.2f} | {ms['fused']:.2f} | "
              f"{ms['loop'] / ms['foreach']:.2f}x | {ms['loop'] / ms['fused']:.2f}x | {diff:.1e} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
