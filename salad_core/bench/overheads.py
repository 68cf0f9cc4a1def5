"""The ``overheads`` section and pipeline batching: full pipeline calls (text, denoising, decoding).

Every variant (capture, each edit, inversion) is timed in the same interleaved rounds as a plain
generation of the same prompt, so that a busy machine slows all of them alike (medians).
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np
import torch

from salad_core.models.denoiser import Denoiser

from .inputs import denoiser_cases
from .naive_algorithm1 import naive_algorithm1
from .plan import REFINED, SAMPLING_STEPS, SKELETON, SOURCE, SWAPPED, Row

__all__ = ["bench_pipeline", "batching_rows", "overhead_rows"]


def bench_pipeline(weights: str | Path | None = None):
    """``(pipeline, description)``: the given or shipped weights, else a random shipped-size pipeline."""
    from salad_core.models.vae import MotionVAE, VAEConfig
    from salad_core.pipeline import SaladPipeline, default_weights_dir
    from salad_core.text import load_text_encoder

    if weights is not None or (default_weights_dir() / "pipeline.json").is_file():
        pipe = SaladPipeline.from_pretrained(weights)
        return pipe, f"weights {pipe.source}"
    torch.manual_seed(0)
    _, default = denoiser_cases()
    d = SKELETON.feature_dim
    pipe = SaladPipeline(MotionVAE(VAEConfig()), Denoiser(default.config), load_text_encoder("minilm"),
                         np.zeros(d, np.float32), np.ones(d, np.float32))
    return pipe, "random weights of the shipped size (no shipped weights installed)"


def batching_rows(pipe, frames: int, steps: int, motions: int = 32, chunk: int = 8) -> list[Row]:
    """Seconds per motion of ``motions`` full pipeline generations: one prompt at a time, all in one
    batch, and in chunks of ``chunk`` (set as :attr:`SaladPipeline.max_batch`), extrapolated from ``steps``
    to :data:`SAMPLING_STEPS` denoising steps: every setting is timed at ``steps`` and ``2 * steps``,
    the difference gives the cost per step and the rest the fixed cost (text encoding, decoding),
    which is counted once."""
    prompts = [SOURCE] * motions
    kept = pipe.max_batch
    default_chunk = pipe.chunk_size()

    def run(batch: int, num_steps: int) -> float:
        t0 = time.perf_counter()
        for start in range(0, motions, batch):
            pipe(prompts[start:start + batch], lengths=frames, num_steps=num_steps, seed=start)
        return time.perf_counter() - t0

    def per_motion(max_batch: int, batch: int) -> float:
        pipe.max_batch = max_batch
        pipe(prompts[:batch], lengths=frames, num_steps=1, seed=0)             # warm-up
        # linear in the step count: the fixed part (text encoding, decoding) once, the steps x 50/steps
        short, long = run(batch, steps), run(batch, 2 * steps)
        per_step = max(long - short, 0.0) / steps
        fixed = max(short - steps * per_step, 0.0)
        return (fixed + SAMPLING_STEPS * per_step) / motions

    try:
        single = per_motion(1, 1)
        whole = per_motion(motions, motions)
        chunked = per_motion(chunk, motions)
    finally:
        pipe.max_batch = kept
    setting = f"{frames} frames, {motions} prompts"
    note = (f"timed on {steps} and {2 * steps} steps, extrapolated to {SAMPLING_STEPS} (fixed cost once); "
            "ratio vs one prompt at a time")
    return [Row("speed", "pipeline, one prompt at a time", setting, single, "s/motion", note=note),
            Row("speed", "pipeline, all prompts in one batch", setting, whole, "s/motion", reference=single,
                ratio=whole / single, note=note),
            Row("speed", f"pipeline, batches of {chunk}" + (" (the default chunk)" if chunk == default_chunk else ""),
                setting, chunked, "s/motion",
                reference=single, ratio=chunked / single, note=note)]


def overhead_rows(pipe, frames: int, steps: int, rounds: int, *, warmup_steps: int = 2,
                  naive: bool = False) -> list[Row]:
    """Median wall time of capture, each edit and inversion against a plain generation (ratio),
    all timed in the same interleaved rounds (full pipeline calls: text, denoising, decoding)."""
    from salad_core.attention import InjectSelfAttention, Mirror, Refine, Reweight, WordSwap

    kw = dict(lengths=frames, seed=0)
    plain = pipe(SOURCE, num_steps=warmup_steps, **kw)
    motion = plain.features[0, :frames]          # a motion to invert (any motion of this length would do)
    variants: dict[str, tuple[Callable[[int], Any], str]] = {
        "plain generation": (lambda s: pipe(SOURCE, num_steps=s, **kw), ""),
        "attention capture": (lambda s: pipe(SOURCE, num_steps=s, capture_attention=True, **kw),
                              "streaming mean of the cross maps"),
        "word swap": (lambda s: pipe.edit(SOURCE, SWAPPED, edits=[WordSwap(), InjectSelfAttention()], num_steps=s,
                                          **kw), "tau 0.8 + self-attention injection"),
        "refinement": (lambda s: pipe.edit(SOURCE, REFINED, edits=[Refine()], num_steps=s, **kw), ""),
        "reweight": (lambda s: pipe.edit(SOURCE, edits=[Reweight("waves", 2.0)], num_steps=s, **kw), ""),
        "mirror": (lambda s: pipe.edit(SOURCE, edits=[Mirror("all")], num_steps=s, **kw), ""),
        "inversion": (lambda s: pipe.invert(motion, SOURCE, num_steps=s, reconstruct=False),
                      "fixed_point, without the reconstruction"),
    }
    if naive:
        variants["naive Algorithm 1"] = (
            lambda s: naive_algorithm1(pipe, SOURCE, REFINED, [Refine()], frames, s),
            "reference: 3 separate guided forwards per step, as the official code")
    for fn, _ in variants.values():             # warm-up: text-encoder cache, allocator, first calls
        fn(warmup_steps)
    times: dict[str, list[float]] = {k: [] for k in variants}
    for _ in range(rounds):
        for name, (fn, _) in variants.items():
            t0 = time.perf_counter()
            fn(steps)
            times[name].append(time.perf_counter() - t0)
    base = statistics.median(times["plain generation"])
    setting = f"{frames} frames, {steps} steps, batch 1"
    return [Row("overheads", name, setting, statistics.median(times[name]), "s", reference=base,
                ratio=statistics.median(times[name]) / base, note=note)
            for name, (_, note) in variants.items()]
