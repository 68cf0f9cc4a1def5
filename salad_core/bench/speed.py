"""The ``speed`` section: seconds per motion of the denoiser alone, its roofline row, and the cost of
the forward variants (text K/V recomputed, the eager capture/edit processor)."""
from __future__ import annotations

import time

import numpy as np
import torch

from salad_core.models.denoiser import Denoiser
from salad_core.models.gemm import backend as gemm_backend
from salad_core.sampling import denoise, make_scheduler

from .flops import gemm_flops, step_flops
from .inputs import attended_tokens, folded_keys, random_inputs
from .plan import GUIDANCE, MOTION_FRAMES, SAMPLING_STEPS, SKELETON, Case, Row
from .roofline import best_rates, matmul_rates_by_backend, paired_step_times, roofline_seconds, step_products

__all__ = ["time_denoiser_steps", "speed_rows", "forward_variant_rows"]


def time_denoiser_steps(model: Denoiser, case: Case, batch: int, latent_frames: int, steps: int,
                        warmup: bool = True) -> np.ndarray:
    """Seconds of each of ``steps`` guided DDIM steps (float64), after an optional warm-up step."""
    cond, null, noise, fm = random_inputs(case, batch, latent_frames)
    if warmup:
        denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=GUIDANCE, num_steps=1)
    stamps = [time.perf_counter()]
    denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=GUIDANCE, num_steps=steps,
            callback=lambda info, z: stamps.append(time.perf_counter()))
    return np.diff(np.asarray(stamps, dtype=np.float64))


def speed_rows(model: Denoiser, case: Case, frames: int, batch: int, steps: int, *, warmup: bool = True,
               matmul_time: float = 0.3, rates_twice: bool = False, pairs: int = 3) -> list[Row]:
    """Seconds per motion, and the roofline row, of one (configuration, length, batch) setting.

    The roofline row compares ``pairs`` steps with the same step's matrix products run alone right
    after each (:func:`step_products`, :func:`paired_step_times`): value = FLOPs / median step time,
    reference = FLOPs / median product time, ratio = median over the pairs of product time / step
    time. The note also gives the older, optimistic yardstick: per-shape best rates of one product
    repeated on the same operands (:func:`matmul_rates_by_backend`, the temporal attention's rate
    for every attention product) and the best step's fraction of it.
    """
    unit = SKELETON.unit_length
    latent_frames = frames // unit
    per_step = time_denoiser_steps(model, case, batch, latent_frames, steps, warmup=warmup)
    tokens = attended_tokens(case, batch)
    fl = gemm_flops(case.config, 2 * batch, latent_frames, tokens)
    flops = step_flops(case.config, batch, latent_frames, tokens)
    by_backend = matmul_rates_by_backend(case.config, 2 * batch, latent_frames, tokens, matmul_time)
    if rates_twice:  # best of two windows: other processes share the CPUs
        again = matmul_rates_by_backend(case.config, 2 * batch, latent_frames, tokens, matmul_time)
        by_backend = {lib: {k: max(v, again[lib][k]) for k, v in rates.items()} for lib, rates in by_backend.items()}
    rates = best_rates(by_backend)
    if len(per_step) >= SAMPLING_STEPS:
        total, how = float(per_step[:SAMPLING_STEPS].sum()), f"all {SAMPLING_STEPS} steps timed"
    else:
        total = float(np.median(per_step)) * SAMPLING_STEPS
        how = (f"median of {len(per_step)} timed step{'s' * (len(per_step) > 1)} x {SAMPLING_STEPS} "
               "(extrapolated)")
    hot_ratio = roofline_seconds(fl, rates) / float(per_step.min())
    libraries = {k: max(by_backend, key=lambda lib: by_backend[lib].get(k, 0.0)) for k in ("proj", "ffn_up", "ffn_down")}
    products, product_flops = step_products(case.config, 2 * batch, latent_frames, tokens, libraries)
    runs = [products]
    fold = folded_keys(case, batch)
    if fold is not None:            # also the products sampling runs with the folded cross-attention
        done, done_flops = step_products(case.config, 2 * batch, latent_frames, tokens, libraries, fold_keys=fold)
        runs.append(done)
    step_s, product_s = paired_step_times(model, case, batch, latent_frames, max(1, pairs), runs)
    setting = f"{case.name}, {frames} frames, batch {batch}"
    folded = "" if fold is None else (
        f"; cross-attention folded, so the step runs {done_flops / 1e9:.2f} GFLOP of products: the same "
        f"comparison against those products gives {float(np.median(product_s[1] / step_s)):.2f}")
    return [
        Row("speed", "seconds per motion", setting, total / batch, "s", note=how),
        Row("roofline", "denoiser GFLOP/s (step)", setting, flops / float(np.median(step_s)) / 1e9, "GFLOP/s",
            reference=product_flops / float(np.median(product_s[0])) / 1e9,
            ratio=float(np.median(product_s[0] / step_s)),
            note=f"{flops / 1e9:.2f} GFLOP/step ({tokens} text keys attended); median of {len(step_s)} step(s), "
                 f"each followed by its matrix products alone ({', '.join(f'{k} on {v}' for k, v in libraries.items())}"
                 f"; attention products on aten){folded}; older yardstick, one product repeated per shape, GFLOP/s: "
                 + "; ".join(f"{lib} " + ", ".join(f"{k} {v:.1f}" for k, v in r.items())
                             for lib, r in by_backend.items())
                 + f" -> best step at {hot_ratio:.2f} of it; dense layers ran on {gemm_backend()}"),
    ]


def forward_variant_rows(model: Denoiser, case: Case, batch: int = 1, reps: int = 4) -> list[Row]:
    """Best seconds per guided forward with the text K/V recomputed every call, and with the eager
    (capture / edit) attention processor, against the cached SDPA forward of sampling."""
    from salad_core.models.attention import EagerProcessor, use_processors

    cond, _, noise, fm = random_inputs(case, 2 * batch, MOTION_FRAMES // SKELETON.unit_length)
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
    setting = f"{case.name}, {MOTION_FRAMES} frames, batch {batch}"
    return [Row("speed", "forward, text K/V recomputed per call", setting, best["recomputed"], "s",
                reference=best["cached"], ratio=best["recomputed"] / best["cached"],
                note="vs the TextContext cache of sampling (best of %d)" % reps),
            Row("speed", "forward, eager attention processor", setting, best["eager"], "s",
                reference=best["cached"], ratio=best["eager"] / best["cached"],
                note="the capture/edit processor vs SDPA (best of %d)" % reps)]
