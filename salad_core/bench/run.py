"""Run the sections of ``salad bench`` in one process and gather their rows into one table."""
from __future__ import annotations

import gc
import logging
import os
from pathlib import Path
from typing import Any, Sequence

import torch

from salad_core.models.denoiser import Denoiser

from .compile_trial import compile_rows
from .inputs import denoiser_cases
from .memory import memory_rows
from .overheads import batching_rows, bench_pipeline, overhead_rows
from .plan import (BATCHES, COLUMNS, GUIDANCE, MOTION_FRAMES, OPTIONAL_SECTIONS, PROMPT_TOKENS, SAMPLING_STEPS,
                   SECTIONS, SHORT_FRAMES, Plan, Row)
from .realtime import realtime_rows
from .speed import forward_variant_rows, speed_rows
from .table import machine_header
from .training import train_profile_rows, train_recipe, training_rows

__all__ = ["run_benchmarks"]

log = logging.getLogger(__name__)


def run_benchmarks(quick: bool, threads: int, *, sections: Sequence[str] | None = None,
                   weights: str | Path | None = None, train_data: str | Path | None = None,
                   realtime: str | Path | None = None) -> "Any":
    """Measure everything (or ``sections``) in this process and return the table.

    Parameters
    ----------
    quick : bool
        The quick plan (about a minute; see :class:`Plan`) instead of the full one.
    threads : int
        Torch intra-op threads for the run (restored afterwards).
    sections : sequence of str, optional
        Subset of :data:`SECTIONS` and :data:`OPTIONAL_SECTIONS` (default: all of :data:`SECTIONS`,
        in that order).
    weights : path, optional
        Pipeline folder for the memory and overhead sections (default: the shipped weights).
    train_data : path, optional
        HumanML3D-layout folder of the ``train`` section (default: a small procedural corpus).
    realtime : path, optional
        Few-step weights folder of the ``realtime`` section (default: the shipped ``salad_realtime`` if present,
        else a stand-in, said in the notes; :mod:`salad_core.bench.realtime`).

    Returns
    -------
    pandas.DataFrame
        Columns :data:`COLUMNS`; ``df.attrs["header"]`` states the machine and the date,
        ``df.attrs["notes"]`` how the figures were measured.
    """
    import pandas as pd

    sections = list(SECTIONS if sections is None else sections)
    unknown = [s for s in sections if s not in SECTIONS + OPTIONAL_SECTIONS]
    if unknown:
        raise ValueError(f"unknown bench sections {unknown}; allowed: {', '.join(SECTIONS + OPTIONAL_SECTIONS)}")
    if isinstance(threads, bool) or not isinstance(threads, int) or threads < 1:
        raise ValueError(f"threads={threads!r} must be a positive integer")
    plan = Plan.for_mode(quick)
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    header = machine_header(threads, quick)
    notes: list[str] = []
    rows: list[Row] = []
    try:
        if "memory" in sections or "overheads" in sections:
            pipe, what = bench_pipeline(weights)
            notes.append(f"memory and overheads: the full pipeline with {what}; guidance {GUIDANCE}, DDIM")
            if "memory" in sections:
                log.info("memory: streaming capture at %s steps", plan.memory_steps)
                rows += memory_rows(pipe, plan.edit_frames, plan.memory_steps)
            if "overheads" in sections:
                log.info("overheads: %d rounds of %d variants", plan.edit_rounds, 8 if plan.extras else 7)
                rows += overhead_rows(pipe, plan.edit_frames, plan.edit_steps, plan.edit_rounds, naive=plan.extras)
                notes.append(f"overheads: median of {plan.edit_rounds} interleaved round(s) after a 2-step warm-up "
                             "of every variant; ratio = variant / plain generation")
                if plan.extras:
                    log.info("speed: pipeline batching, 32 prompts")
                    rows += batching_rows(pipe, plan.edit_frames, 5)
            del pipe
            gc.collect()
        if "speed" in sections:
            for case in denoiser_cases(weights):
                torch.manual_seed(0)
                model = Denoiser(case.config).eval()
                lengths = (MOTION_FRAMES, SHORT_FRAMES) if case.name == "default" else (MOTION_FRAMES,)
                for frames in lengths:
                    for batch in BATCHES:
                        log.info("speed: %s, %d frames, batch %d", case.name, frames, batch)
                        big = batch > 1
                        rows += speed_rows(model, case, frames, batch, plan.b32_steps if big else plan.b1_steps,
                                           warmup=plan.b32_warmup or not big, matmul_time=plan.matmul_time,
                                           rates_twice=not plan.quick, pairs=plan.b32_pairs if big else plan.b1_pairs)
                if plan.extras:
                    rows += forward_variant_rows(model, case)
                del model
                gc.collect()
            paper, default = denoiser_cases(weights)
            notes.append(f"speed: denoiser only (random weights), {SAMPLING_STEPS} DDIM steps, guidance {GUIDANCE} "
                         "(both branches in one batched forward), random text features: text encoder and VAE "
                         f"decoding excluded; paper = width {paper.config.width}, {paper.config.layers} layers, "
                         f"ffn {paper.config.ff_dim}, {paper.config.heads} heads, CLIP text {paper.config.text_dim}-d "
                         f"x {paper.tokens} tokens; default = width {default.config.width}, {default.config.layers} "
                         f"layers, ffn {default.config.ff_dim}, {default.config.heads} heads, MiniLM "
                         f"{default.config.text_dim}-d x {default.tokens} tokens; prompts of {PROMPT_TOKENS[0]}-"
                         f"{PROMPT_TOKENS[1]} valid tokens, the rest masked padding (not attended)")
            if plan.quick:
                notes.append(f"quick: batch 1 timed on {plan.b1_steps} steps, batch 32 on {plan.b32_steps} step, "
                             f"both extrapolated to {SAMPLING_STEPS} (every DDIM step costs the same)")
            notes.append("roofline: FLOPs per step = dense GEMMs + attention products over the attended keys "
                         "(element-wise work not counted); every timed step is followed by the same step's matrix "
                         "products alone (each dense layer with its own weight, on the faster of aten/MKL and oneDNN "
                         "for its shape class; attention products at their shapes); value = FLOPs / median step "
                         "time, reference = FLOPs / median products time, ratio = median of products time / step "
                         "time (side by side, so the machine's speed swings cancel); the note adds the older, "
                         "optimistic yardstick (one product repeated on the same operands, best time per shape)")
        if "training" in sections:
            recipe = train_recipe(weights)
            log.info("training: %d timed steps each", plan.train_steps)
            rows += training_rows(recipe, plan.train_steps, plan.train_warmup)
        if "train" in sections:
            log.info("train: denoiser step profile, before and after")
            train_rows, train_notes = train_profile_rows(train_recipe(weights), 3 if plan.quick else 12,
                                                         1 if plan.quick else 2, data=train_data, weights=weights)
            rows += train_rows
            notes += train_notes
        if "realtime" in sections:
            pipe, _ = bench_pipeline(weights)
            log.info("realtime: the default and the few-step pipeline, %d rounds", 2 if plan.quick else 5)
            rt_rows, rt_note = realtime_rows(pipe, realtime, rounds=2 if plan.quick else 5)
            rows += rt_rows
            notes.append(rt_note)
            del pipe
            gc.collect()
        if "compile" in sections:
            log.info("compile: torch.compile of the default denoiser")
            rows += compile_rows(denoiser_cases(weights)[1], reps=3 if plan.quick else 10)
    finally:
        torch.set_num_threads(before)
    if plan.quick:
        notes.append(f"quick: overheads and memory on {plan.edit_frames}-frame motions, overheads with "
                     f"{plan.edit_steps} steps; training rates from {plan.train_steps} step(s)")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    notes.append(f"load average {load:.2f} at the end: other processes on the {os.cpu_count()} CPUs slow every "
                 "figure (ratios measured side by side suffer least)")
    df = pd.DataFrame([r.__dict__ for r in rows], columns=COLUMNS)
    df.attrs["header"] = header
    df.attrs["notes"] = notes
    return df
