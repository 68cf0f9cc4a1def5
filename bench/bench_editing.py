"""Cost of attention capture and of zero-shot edits relative to one plain generation, side by side.

Every variant runs in the same process, interleaved round by round (plain, capture, edits, plain,
...) so that a busy machine slows all of them alike; the table prints the median wall time of each
variant over the rounds and its ratio to the median plain generation (the full pipeline call:
text encoding, denoising, decoding and joint recovery):

* ``capture``: ``pipe(..., capture_attention=True)`` (streaming mean of the cross maps); the
  target is at most +10 %;
* ``capture-full``: every step, layer and head kept (float16);
* ``mirror``, ``reweight``, ``word swap`` (+ self-attention injection), ``refine``: ``pipe.edit``
  (one batched forward per step, 4 rows: source and edited, both guidance branches); the target
  is at most 2x;
* ``refine (probe)``: Algorithm 1's separate probe row (5 rows per step);
* ``naive Alg. 1``: three separate CFG forwards per step (source, probe, edited; eager attention
  everywhere), i.e. the official code's structure with batched guidance: about 3x.

Usage::

    python bench/bench_editing.py                      # shipped weights if present, else a random
                                                       # paper-size denoiser; 196 frames, 50 steps
    python bench/bench_editing.py --quick              # 10 steps, 2 rounds
    python bench/bench_editing.py --weights DIR --threads 1 --rounds 5
"""
from __future__ import annotations

import argparse
import os
import statistics
import time
from pathlib import Path

import numpy as np
import torch

from salad_core.attention import (CaptureConfig, EditController, InjectSelfAttention, Mirror, Refine, Reweight,
                                  TokenInfo, WordSwap)
from salad_core.models.attention import EagerProcessor, use_processors
from salad_core.models.denoiser import Denoiser, DenoiserConfig, TextContext
from salad_core.models.vae import MotionVAE, VAEConfig
from salad_core.pipeline import SaladPipeline, default_weights_dir
from salad_core.sampling import StepInfo, make_scheduler
from salad_core.text import load_text_encoder

SOURCE = "a man walks forward and waves his right hand"
REFINED = "a man slowly walks forward and waves his right hand high"
SWAPPED = "a man walks forward and raises his right hand"


def build_pipeline(weights: Path | None) -> tuple[SaladPipeline, str]:
    if weights is not None or (default_weights_dir() / "pipeline.json").is_file():
        pipe = SaladPipeline.from_pretrained(weights)
        return pipe, f"trained weights {pipe.source}"
    torch.manual_seed(0)
    stats = Path(__file__).resolve().parents[1] / "tests" / "data" / "humanml3d_sample"
    pipe = SaladPipeline(MotionVAE(VAEConfig()), Denoiser(DenoiserConfig(text_dim=384)), load_text_encoder("minilm"),
                         np.load(stats / "Mean.npy"), np.load(stats / "Std.npy"))
    return pipe, "random paper-size denoiser (width 256, 5 layers, 8 heads; no shipped weights found)"


def naive_algorithm1(pipe: SaladPipeline, source: str, target: str, edits, length: int, steps: int) -> torch.Tensor:
    """Three separate CFG forwards per step (source, probe, edited) with eager attention, the maps
    passed between them: the structure of the official ``Text2Motion.edit``."""
    den = pipe.denoiser
    ts, null = pipe.encode_text([source])
    tt = pipe.text_encoder.encode([target])
    width = max(ts.features.shape[1], tt.features.shape[1], null.features.shape[1])
    ctrl = EditController(edits, TokenInfo.from_batch(ts), TokenInfo.from_batch(tt), width, cfg=True, probe=True)

    def both(ctx):
        return TextContext.concat([den.prepare_text(null.features, null.mask), ctx])

    cs, ct = both(den.prepare_text(ts.features, ts.mask)), both(den.prepare_text(tt.features, tt.mask))
    noise = pipe.make_noise([0], length // pipe.skeleton.unit_length)
    sched = make_scheduler(pipe.diffusion, "ddim")
    sched.set_timesteps(steps)
    z, ze = noise.clone(), noise.clone()
    pad = lambda p: torch.nn.functional.pad(p, (0, width - p.shape[-1]))  # noqa: E731
    with torch.inference_mode():
        for i, t in enumerate(sched.timesteps):
            ctrl.on_step(StepInfo(i, steps, float(t), True, 1))
            src, own = {}, {}

            def record(store):
                def fn(site, probs):
                    store[site.name] = probs[1:].clone()
                return fn

            def edit(site, probs):
                if site.kind != "cross":
                    return None
                m = pad(src[site.name].view(1, site.heads, site.frames, site.parts, -1))
                o = pad(own[site.name].view(1, site.heads, site.frames, site.parts, -1))
                new = ctrl.edit_cross(m, o)[..., :site.tokens]
                out = probs.clone()
                out[1:] = new.reshape(1, site.heads, -1, site.tokens)
                return out

            outs = []
            for x, ctx, ctl in ((z, cs, record(src)), (ze, ct, record(own)), (ze, ct, edit)):
                with use_processors(den, EagerProcessor(ctl)):
                    u, c = den(torch.cat([x, x]), t.reshape(1), text_context=ctx).chunk(2)
                outs.append(u + 7.5 * (c - u))
            z = sched.step(outs[0], t, z).prev_sample
            ze = sched.step(outs[2], t, ze).prev_sample
    pipe.decode(torch.cat([z, ze]), [length, length])
    return ze


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description="cost of capture and edits relative to one generation")
    ap.add_argument("--weights", type=Path, default=None)
    ap.add_argument("--length", type=int, default=196, help="motion frames")
    ap.add_argument("--steps", type=int, default=50)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--quick", action="store_true", help="10 steps, 2 rounds")
    ap.add_argument("--no-naive", action="store_true", help="skip the naive Algorithm 1 reference")
    args = ap.parse_args(argv)
    if args.quick:
        args.steps, args.rounds = 10, 2
    if args.threads:
        torch.set_num_threads(args.threads)
    pipe, what = build_pipeline(args.weights)
    kw = dict(lengths=args.length, num_steps=args.steps, seed=0)
    variants = {
        "plain": lambda: pipe(SOURCE, **kw),
        "capture": lambda: pipe(SOURCE, capture_attention=True, **kw),
        "capture-full": lambda: pipe(SOURCE, capture_attention=CaptureConfig(mode="full"), **kw),
        "mirror": lambda: pipe.edit(SOURCE, edits=[Mirror("all")], **kw),
        "reweight": lambda: pipe.edit(SOURCE, edits=[Reweight("waves", 2.0)], **kw),
        "word swap": lambda: pipe.edit(SOURCE, SWAPPED, edits=[WordSwap(), InjectSelfAttention()], **kw),
        "refine": lambda: pipe.edit(SOURCE, REFINED, edits=[Refine(), Reweight("high", 2.0)], **kw),
        "refine (probe)": lambda: pipe.edit(SOURCE, REFINED, edits=[Refine(), Reweight("high", 2.0)], probe=True, **kw),
    }
    if not args.no_naive:
        variants["naive Alg. 1"] = lambda: naive_algorithm1(pipe, SOURCE, REFINED, [Refine(), Reweight("high", 2.0)],
                                                            args.length, args.steps)
    rows = {}
    for name, fn in variants.items():           # warm-up (text encoder cache, allocator)
        out = fn()
        rows[name] = out.settings.get("cost_vs_generation") if hasattr(out, "settings") else None
    times: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(args.rounds):
        for name, fn in variants.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    base = statistics.median(times["plain"])
    print(f"salad editing bench: {what}")
    print(f"{args.length} frames, {args.steps} DDIM steps, w = 7.5, batch 1, {torch.get_num_threads()} torch "
          f"thread(s), {os.cpu_count()} CPUs, {args.rounds} interleaved rounds (median)")
    print(f"{'variant':16s} {'seconds':>9s} {'x plain':>8s} {'rows x':>7s}  target")
    result = {}
    for name in variants:
        med = statistics.median(times[name])
        target = "<= 1.10" if name.startswith("capture") else ("<= 2.00" if name not in ("plain", "naive Alg. 1",
                                                                                          "refine (probe)") else "")
        rows_ratio = rows.get(name)
        rr = f"{rows_ratio:7.2f}" if rows_ratio else ("   3.00" if name == "naive Alg. 1" else "   1.00")
        print(f"{name:16s} {med:9.3f} {med / base:8.2f} {rr}  {target}")
        result[name] = {"seconds": med, "ratio": med / base, "all": times[name]}
    return result


if __name__ == "__main__":
    main()
