"""Speed of the SALAD denoiser on this machine: seconds per generated motion and FLOP efficiency.

For the paper configuration (width 256, 5 layers, FFN 1024, 8 heads, CLIP text 512 x 77 tokens)
and a small one (width 128, 5 layers, FFN 512, 4 heads, MiniLM text 384), it measures:

* seconds per generated motion: 196 frames (49 latent frames x 7 parts), 50 DDIM steps,
  classifier-free guidance 7.5 (both branches in one batched forward), random text features
  (the text encoder is excluded), at batch 1 and 32. The per-step time is measured over a few
  steps and multiplied by 50 (every DDIM step costs the same); ``--full`` runs all 50;
* FLOPs per step from the configuration (dense GEMMs + attention products; element-wise work
  such as LayerNorm, softmax and GELU is not counted);
* this machine's measured matmul GFLOP/s at the same GEMM shapes, and the achieved fraction;
* what caching the text keys/values in the TextContext saves per step, and the cost of the
  eager (capture/edit) attention processor relative to SDPA.

Usage::

    python bench/bench_denoiser.py            # about 2-3 minutes on 2 CPU cores
    python bench/bench_denoiser.py --quick    # fewer timed steps
    python bench/bench_denoiser.py --full     # all 50 steps at batch 32, batch-32 forward variants
    python bench/bench_denoiser.py --threads 1  # steadier figures on a shared machine
"""
from __future__ import annotations

import argparse
import os
import platform
import time
from dataclasses import dataclass

import torch

from salad_core.models.attention import EagerProcessor, use_processors
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import denoise, make_scheduler
from salad_core.skeleton import get_skeleton

SKELETON = get_skeleton("humanml3d")
MOTION_FRAMES = SKELETON.max_length                    # 196
LATENT_FRAMES = MOTION_FRAMES // SKELETON.unit_length  # 49
SAMPLING_STEPS = 50
GUIDANCE = 7.5


@dataclass(frozen=True)
class Case:
    name: str
    config: DenoiserConfig
    tokens: int  # W, text tokens per prompt


CASES = (
    Case("paper", DenoiserConfig(), 77),
    Case("small", DenoiserConfig(width=128, layers=5, ff_dim=512, heads=4, text_dim=384), 32),
)


def gemm_flops(cfg: DenoiserConfig, rows: int, frames: int, tokens: int) -> dict[str, float]:
    """FLOPs (2 per multiply-add) of one forward over ``rows`` samples, by GEMM shape class.

    Keys: ``proj`` (w x w projections), ``ffn_up`` (w x f), ``ffn_down`` (f x w), ``attn``
    (q k^T and p v products), ``text_once`` (word_emb + per-layer text K/V, cached per call).
    """
    w, f, p, L = cfg.width, cfg.ff_dim, cfg.num_parts, cfg.layers
    n = frames * p  # tokens per sample
    half = L // 2
    proj = n * (cfg.latent_dim * w + w * w)                        # input process
    proj += n * (w * w + w * cfg.latent_dim)                       # output process
    proj += L * n * (4 * w * w + 4 * w * w + 2 * w * w)            # temporal, skeletal QKVO; cross Q, O
    proj += half * n * 2 * w * w                                   # skip merges (2w -> w)
    proj += 2 * w * w + L * 4 * 2 * w * w                          # timestep MLP + FiLM (per sample)
    attn = L * (2 * n * frames * w + 2 * n * p * w + 2 * n * tokens * w)
    ffn_up = L * n * w * f
    ffn_down = L * n * f * w
    text_once = tokens * cfg.text_dim * w + L * 2 * tokens * w * w
    out = {"proj": proj, "ffn_up": ffn_up, "ffn_down": ffn_down, "attn": attn, "text_once": text_once}
    return {k: 2.0 * v * rows for k, v in out.items()}


def _rate(fn, flops: float, min_time: float) -> float:
    """Best GFLOP/s of ``fn`` over repeated short timings (the best is robust to other load)."""
    fn()
    best, start = float("inf"), time.perf_counter()
    while time.perf_counter() - start < min_time:
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return flops / best / 1e9


def matmul_rates(cfg: DenoiserConfig, rows: int, frames: int, tokens: int, min_time: float) -> dict[str, float]:
    """Measured GFLOP/s of plain matmuls at the model's GEMM shapes."""
    w, f, p, h = cfg.width, cfg.ff_dim, cfg.num_parts, cfg.heads
    m = rows * frames * p
    dh = w // h
    a_w, a_f = torch.randn(m, w), torch.randn(m, f)
    b_ww, b_wf, b_fw = torch.randn(w, w), torch.randn(w, f), torch.randn(f, w)
    q = torch.randn(rows * p * h, frames, dh)
    k = torch.randn(rows * p * h, dh, frames)
    return {
        "proj": _rate(lambda: a_w @ b_ww, 2.0 * m * w * w, min_time),
        "ffn_up": _rate(lambda: a_w @ b_wf, 2.0 * m * w * f, min_time),
        "ffn_down": _rate(lambda: a_f @ b_fw, 2.0 * m * f * w, min_time),
        "attn": _rate(lambda: torch.bmm(q, k), 2.0 * q.shape[0] * frames * frames * dh, min_time),
    }


def _inputs(case: Case, batch: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    cfg = case.config
    text = torch.randn(batch, case.tokens, cfg.text_dim, generator=g)
    lengths = torch.randint(5, case.tokens + 1, (batch,), generator=g)
    mask = torch.arange(case.tokens)[None] < lengths[:, None]
    null_mask = torch.zeros(1, case.tokens, dtype=torch.bool)
    null_mask[0, :2] = True  # the empty prompt: start and end tokens only
    null = (torch.randn(1, case.tokens, cfg.text_dim, generator=g), null_mask)
    noise = torch.randn(batch, LATENT_FRAMES, cfg.num_parts, cfg.latent_dim, generator=g)
    frame_mask = torch.ones(batch, LATENT_FRAMES, dtype=torch.bool)
    return (text, mask), null, noise, frame_mask


def time_steps(model: Denoiser, case: Case, batch: int, steps: int) -> tuple[float, float]:
    """(median, best) seconds per DDIM step (CFG batched) at ``batch``, after one warm-up step."""
    cond, null, noise, fm = _inputs(case, batch)
    denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=GUIDANCE, num_steps=1)
    stamps = [time.perf_counter()]
    denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=GUIDANCE, num_steps=steps,
            callback=lambda info, z: stamps.append(time.perf_counter()))
    per_step = torch.tensor(stamps).diff()
    return float(per_step.median()), float(per_step.min())


def time_forwards(model: Denoiser, case: Case, batch: int, reps: int) -> dict[str, float]:
    """Best seconds per batched-CFG forward for three variants, timed interleaved.

    ``cached``: text K/V from the TextContext cache (the sampling path); ``recomputed``: raw
    text every call (word_emb and K/V projections redone); ``eager``: cached, with the eager
    processor (the capture / edit path) on every site.
    """
    cond, _, noise, fm = _inputs(case, 2 * batch)
    ctx = model.prepare_text(*cond)
    t = torch.tensor([500])
    eager = EagerProcessor()

    def cached():
        model(noise, t, frame_mask=fm, text_context=ctx)

    def recomputed():
        model(noise, t, cond[0], cond[1], fm)

    def eager_run():
        with use_processors(model, eager):
            model(noise, t, frame_mask=fm, text_context=ctx)

    runs = {"cached": cached, "recomputed": recomputed, "eager": eager_run}
    best = {k: float("inf") for k in runs}
    with torch.inference_mode():
        for fn in runs.values():
            fn()
        for _ in range(reps):
            for name, fn in runs.items():
                t0 = time.perf_counter()
                fn()
                best[name] = min(best[name], time.perf_counter() - t0)
    return best


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="time fewer steps (rougher figures)")
    ap.add_argument("--full", action="store_true", help="run all 50 steps at batch 32 too")
    ap.add_argument("--threads", type=int, default=None, help="torch intra-op threads (default: torch's)")
    args = ap.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    steps_b1 = 10 if args.quick else SAMPLING_STEPS
    steps_b32 = SAMPLING_STEPS if args.full else (2 if args.quick else 3)
    min_time = 0.2 if args.quick else 0.5
    torch.manual_seed(0)

    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, {platform.processor() or platform.machine()}, "
          f"load average {os.getloadavg()[0]:.2f} (other processes skew CPU timings)")
    if os.getloadavg()[0] > (os.cpu_count() or 1):
        print(f"WARNING: load average above the {os.cpu_count()} CPUs: other processes compete, so timings "
              "(and multi-threaded matmul rates most of all) are unreliable; try --threads 1 or a quiet machine")
    print(f"motion: {MOTION_FRAMES} frames = {LATENT_FRAMES} latent frames; {SAMPLING_STEPS} DDIM steps; "
          f"guidance {GUIDANCE} (uncond+cond in one forward); text encoder excluded\n")
    rows = []
    for case in CASES:
        cfg = case.config
        model = Denoiser(cfg).eval()
        params = sum(p.numel() for p in model.parameters())
        print(f"[{case.name}] width {cfg.width}, layers {cfg.layers}, ff {cfg.ff_dim}, heads {cfg.heads}, "
              f"text {cfg.text_dim} x {case.tokens} tokens, {params:,} parameters")
        for batch, steps in ((1, steps_b1), (32, steps_b32)):
            fl = gemm_flops(cfg, 2 * batch, LATENT_FRAMES, case.tokens)
            step_flops = sum(v for k, v in fl.items() if k != "text_once")
            before = matmul_rates(cfg, 2 * batch, LATENT_FRAMES, case.tokens, min_time)
            sec_step, best_step = time_steps(model, case, batch, steps)
            after = matmul_rates(cfg, 2 * batch, LATENT_FRAMES, case.tokens, min_time)
            rates = {k: max(before[k], after[k]) for k in before}  # best of two windows (shared CPUs)
            ideal = sum(fl[k] / (rates[k] * 1e9) for k in rates)  # seconds if every GEMM ran at its rate
            per_motion = sec_step * SAMPLING_STEPS / batch
            achieved = step_flops / best_step / 1e9
            extrap = "" if steps == SAMPLING_STEPS else f" (median of {steps} timed steps x {SAMPLING_STEPS})"
            print(f"  batch {batch:>2}: {per_motion:8.3f} s/motion{extrap}; step median {sec_step * 1e3:.1f} ms, "
                  f"best {best_step * 1e3:.1f} ms; {step_flops / 1e9:.2f} GFLOP/step "
                  f"(text projections {fl['text_once'] / 1e9:.3f} GFLOP = {fl['text_once'] / step_flops:.1%} of a step, "
                  "done once per call thanks to the TextContext cache)")
            print(f"            matmul GFLOP/s at these shapes: "
                  + ", ".join(f"{k} {v:.1f}" for k, v in rates.items())
                  + f"; best step achieves {achieved:.1f} GFLOP/s = {ideal / best_step:.0%} of the matmul-bound time")
            rows.append((case.name, batch, per_motion, sec_step, step_flops, achieved, ideal / best_step))
        for batch in (1, 32) if args.full else (1,):
            best = time_forwards(model, case, batch, reps=4 if batch == 1 else 2)
            print(f"  batch {batch:>2} forward (best): cached text K/V {best['cached'] * 1e3:.1f} ms, "
                  f"recomputed {best['recomputed'] * 1e3:.1f} ms "
                  f"({(best['recomputed'] - best['cached']) / best['recomputed']:+.1%} saved by the cache); "
                  f"eager processor {best['eager'] * 1e3:.1f} ms ({best['eager'] / best['cached']:.2f}x SDPA)")
        print()

    print("summary: config, batch, s/motion, median s/step, GFLOP/step, best-step GFLOP/s, fraction of matmul bound")
    for name, batch, pm, ss, fl, ach, frac in rows:
        print(f"  {name:6s} {batch:3d} {pm:9.3f} {ss:8.3f} {fl / 1e9:9.2f} {ach:8.1f} {frac:6.0%}")


if __name__ == "__main__":
    main()
