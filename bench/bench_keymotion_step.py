"""KeyMotion's three training steps (keyframe VAE, PST, MMAE) in float32 and under bf16 autocast (or, with
``--compare adamw``, with PyTorch's per-tensor AdamW loop and the fused AdamW), side by side.

Builds each stage's real training task from a KeyMotion recipe (default ``configs/keymotion-0.2.json``) on a
corpus, twice: once as configured with ``autocast`` off and once with ``autocast="bf16"`` (float32 weights and
optimiser; only the forward under ``torch.autocast``, what ``TrainConfig.autocast`` does in the trainer). The two
start from the same weights and draw the same batches; their optimiser steps run interleaved (one of each in
turn, the order flipped every step), so both meet the same machine. Prints per stage the mean seconds per
step of each (data, preparation, forward, backward, optimiser: :class:`salad_core.train.profile.StepRunner`),
their ratio, and the two runs' losses (first step: the same weights and batch, so the difference is autocast's
alone; then the mean over the timed steps).

The PST needs a frozen keyframe VAE: the untrained one of the recipe is saved to a temporary folder (the step's
cost does not depend on what the VAE learned). Its latent cache is built at start-up and not timed.

Example::

    python bench/bench_keymotion_step.py --data /tmp/corpus --threads 1 --steps 12
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
STAGES = ("kf_vae", "pst", "mmae")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="procedural corpus folder (salad corpus build --out ...)")
    p.add_argument("--config", type=Path, default=HERE / "configs" / "keymotion-0.2.json")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--steps", type=int, default=12, help="timed steps of each setting per stage")
    p.add_argument("--warmup", type=int, default=2, help="untimed steps of each setting first")
    p.add_argument("--stages", nargs="+", default=list(STAGES), choices=STAGES)
    p.add_argument("--compare", choices=["autocast", "adamw"], default="autocast",
                   help="autocast: float32 against bf16 autocast (AdamW as configured); adamw: PyTorch's "
                        "per-tensor AdamW loop against the fused AdamW (float32)")
    args = p.parse_args(argv)

    import torch

    from salad_core.io import save_checkpoint
    from salad_core.keymotion.train import (build_kf_vae_task, build_mmae_task, build_pst_task,
                                            load_keymotion_recipe)
    from salad_core.text import load_text_encoder
    from salad_core.train.distributed import DistEnv
    from salad_core.train.profile import StepRunner

    torch.set_num_threads(args.threads)
    recipe = load_keymotion_recipe(args.config)
    encoder = load_text_encoder(recipe.text_encoder)
    tmp = Path(tempfile.mkdtemp(prefix="salad_km_bench_"))
    vae_task = build_kf_vae_task(args.data, recipe.kf_vae_model, recipe.kf_vae_train, DistEnv())
    save_checkpoint(tmp / "kf_vae" / "latest", vae_task.model, model_type=vae_task.model_type,
                    config=vae_task.model_config)
    num_keyframes = vae_task.model_config.num_keyframes
    builders = {
        "kf_vae": lambda cfg: build_kf_vae_task(args.data, recipe.kf_vae_model, cfg, DistEnv()),
        "pst": lambda cfg: build_pst_task(args.data, tmp / "kf_vae", recipe.pst_model, cfg, DistEnv(), encoder,
                                          cache_dir=tmp / "pst_cache"),
        "mmae": lambda cfg: build_mmae_task(args.data, recipe.mmae_model, cfg, DistEnv(), encoder,
                                            num_keyframes=num_keyframes),
    }
    load = []
    what = "float32 vs bf16 autocast" if args.compare == "autocast" else "AdamW loop vs fused"
    print(f"KeyMotion training steps, {what} ({args.config.name}, {args.data}, "
          f"{args.threads} thread(s), {args.steps} timed steps each after {args.warmup} untimed)")
    for stage in args.stages:
        base = getattr(recipe, f"{stage}_train")
        if args.compare == "autocast":
            configs = {name: dataclasses.replace(base, autocast=mode, progress=False)
                       for name, mode in (("float32", None), ("bf16", "bf16"))}
        else:
            configs = {name: dataclasses.replace(base, autocast=None, adamw=name, progress=False)
                       for name in ("loop", "fused")}
        runners = {name: StepRunner(name, builders[stage], cfg) for name, cfg in configs.items()}
        order = list(runners)
        for i in range(args.warmup + args.steps):
            for name in (order if i % 2 == 0 else order[::-1]):
                runners[name].step(record=i >= args.warmup)
            load.append(os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan"))
        prof = {name: r.result() for name, r in runners.items()}
        a, b = order
        pa, pb = prof[a], prof[b]
        first = {name: r.step_losses[0] for name, r in runners.items()}
        timed = {name: statistics.fmean(r.step_losses[args.warmup:]) for name, r in runners.items()}
        parts = ", ".join(f"{k} {pa.parts[k] * 1e3:.0f}/{pb.parts[k] * 1e3:.0f}"
                          for k in ("data", "noise", "forward", "backward", "optimizer") if k in pa.parts)
        print(f"{stage:7s} {a} {pa.step_s:.3f} s/step, {b} {pb.step_s:.3f} s/step: ratio "
              f"{pa.step_s / pb.step_s:.2f}x   (ms {a}/{b}: {parts})")
        print(f"        loss at step 1 (same weights and batch) {first[a]:.6f} vs {first[b]:.6f} "
              f"(relative difference {abs(first[b] - first[a]) / max(abs(first[a]), 1e-12):.1e}); "
              f"mean over the timed steps {timed[a]:.5f} vs {timed[b]:.5f}")
    print(f"load average during the rounds: median {statistics.median(load):.1f} "
          f"(min {min(load):.1f}, max {max(load):.1f}); measured {time.strftime('%Y-%m-%d %H:%M')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
