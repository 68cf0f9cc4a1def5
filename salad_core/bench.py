"""``salad bench``: how fast salad runs on this machine, as one table measured in one run.

Six sections, each a function returning rows of the table (:class:`Row`), run in this order:

* ``memory``: peak memory of one generation with streaming attention capture (the default
  ``capture_attention=True``, a running mean per step bin) at 50 and at 200 DDIM steps: the peak
  resident set size (RSS) during the call minus the RSS before it. On Linux the kernel's
  high-water mark ``VmHWM`` is reset before each call (``/proc/self/clear_refs``), elsewhere the
  process peak ``ru_maxrss`` is used (a delta then only shows growth beyond earlier peaks). It runs
  first, before large batches have grown the process.
* ``overheads``: wall time of attention capture, of each edit (word swap, refinement, re-weighting,
  mirroring) and of inversion relative to a plain generation of the same prompt, every variant
  timed in the same rounds, interleaved, so that a busy machine slows all of them alike (medians).
  The full plan also times 32 prompts through the pipeline one at a time, in one batch, and in
  chunks of 8 (:func:`batching_rows`; the pipeline's default chunk is 32 with the tuned allocator).
* ``speed``: seconds per motion of the denoiser alone (random text features: the text encoder is
  excluded; VAE decoding too, which costs under 1 % of 50 steps) for 196 frames, 50 DDIM steps,
  guidance 7.5 (both branches in one batched forward), at batch 1 and 32, for the paper
  configuration and the shipped default, and for a 120-frame motion with the shipped default.
  Beside each, the *roofline* row: the denoiser's achieved GFLOP/s (FLOPs per step computed from
  the configuration by :func:`gemm_flops`) against this machine's matmul GFLOP/s at the same
  shapes, measured by running the step's own matrix products alone right after every timed step
  (:func:`step_products`, :func:`paired_step_times`); the fraction is the median over those pairs of
  products time over step time. Where sampling folds the cross-attention (fewer FLOPs than the
  configuration's count), the note gives the same fraction against the products actually run, and
  the older per-shape yardstick (:func:`matmul_rates`) for comparison.
* ``training``: optimiser steps per second of the VAE and of the denoiser on random data, with the
  shipped recipe's model configs and batch sizes (``runs.json`` beside the shipped weights, else
  the library defaults). The denoiser step is the trainer's own (:func:`_prepare`: frozen-VAE
  encoding, noising, caption dropping; then forward, backward, AdamW), with random text features.

* ``train`` (opt-in: it builds a small procedural corpus, unless ``--train-data`` names one, and a
  latent cache; a few minutes): where a denoiser training step goes, part by part (data, VAE
  latents, text features, noising, forward, backward, clipping, optimiser, logging, validation;
  :mod:`salad_core.train.profile`), for the trainer *before* the issue-19 changes (random batches,
  VAE encoder at every step) and *after* (length buckets, latent cache), steps interleaved in one
  process; ``ratio`` = before / after (a speed-up). Shipped VAE and MiniLM, the shipped recipe's
  denoiser and batch size.

* ``compile`` (opt-in, not part of the default run: compiling takes about a minute): one guided
  forward of the shipped default denoiser (196 frames, batch 1) eager against ``torch.compile``
  (inductor), the compile time and the number of 50-step generations after which compiling pays
  for itself. If compiling fails, the row says so and sampling is unaffected (salad never compiles
  by default).

``salad bench`` (:func:`main`) runs with the tuned allocator of :mod:`salad_core.allocator`, as the
``salad`` command does (``SALAD_ALLOCATOR=system`` for glibc's default); the header says which. Freed
memory then stays with the process, so the memory rows measure growth beyond what it already holds.

``--quick`` (about a minute) times fewer steps and rounds, measures batch 32 on one step and
extrapolates to 50 (every DDIM step costs the same), uses 120-frame motions for the overheads and
the memory, and says so in the notes under the table.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import gc
import json
import logging
import os
import platform
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from salad_core.models.attention import fold_pays
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.allocator import allocator_tuned
from salad_core.models.gemm import backend as gemm_backend
from salad_core.sampling import denoise, make_scheduler
from salad_core.skeleton import get_skeleton

__all__ = ["Row", "Case", "Plan", "SECTIONS", "OPTIONAL_SECTIONS", "compile_rows", "train_profile_rows", "batching_rows", "gemm_flops", "step_flops", "matmul_rates", "attended_tokens",
           "matmul_rates_by_backend", "roofline_seconds",
           "time_denoiser_steps", "speed_rows", "forward_variant_rows", "overhead_rows", "training_rows",
           "memory_rows", "peak_rss_delta", "denoiser_cases", "TrainRecipe", "train_recipe", "bench_pipeline",
           "machine_header", "run_benchmarks", "format_table", "main"]

log = logging.getLogger(__name__)

SKELETON = get_skeleton("humanml3d")
MOTION_FRAMES = SKELETON.max_length            # 196 frames = 49 latent frames
SHORT_FRAMES = 120                             # the CLI's default length (6 s at 20 fps)
SAMPLING_STEPS = 50                            # DDIM steps of the paper's sampler
GUIDANCE = 7.5                                 # classifier-free guidance (paper default)
#: Valid tokens of the random prompts (start/end tokens included), drawn uniformly: HumanML3D captions
#: are about 12 words. The rest of the padded width (CLIP: 77) is masked padding, which the denoiser
#: does not attend to (:func:`salad_core.models.attention.trim_masked_keys`).
PROMPT_TOKENS = (8, 24)
BATCHES = (1, 32)
SECTIONS = ("memory", "overheads", "speed", "training")
#: Sections run only when asked for by name.
OPTIONAL_SECTIONS = ("compile", "train")
COLUMNS = ["section", "measure", "setting", "value", "unit", "reference", "ratio", "note"]

SOURCE = "a man walks forward and waves his right hand"
SWAPPED = "a man walks forward and raises his right hand"          # same word count: word swap
REFINED = "a man slowly walks forward and waves his right hand high"


@dataclass
class Row:
    """One line of the table: ``value`` in ``unit``, optionally against a ``reference`` (``ratio``)."""

    section: str
    measure: str
    setting: str
    value: float
    unit: str
    reference: float | None = None
    ratio: float | None = None
    note: str = ""


@dataclass(frozen=True)
class Case:
    """A denoiser configuration to time, with its text length."""

    name: str               # "paper" or "default"
    config: DenoiserConfig
    tokens: int             # W, text tokens per prompt


@dataclass(frozen=True)
class Plan:
    """How much is timed; :meth:`for_mode` gives the quick and the full plans."""

    quick: bool
    b1_steps: int                    # timed DDIM steps at batch 1 (after one warm-up step)
    b32_steps: int                   # timed DDIM steps at batch 32 (extrapolated to 50 if fewer)
    b32_warmup: bool                 # a warm-up step at batch 32 too (quick: the batch-1 run warmed the model)
    matmul_time: float               # seconds of repeated timing per GEMM shape (best rate kept)
    edit_frames: int                 # motion length of the overhead and memory runs
    edit_steps: int                  # DDIM steps of the overhead runs
    edit_rounds: int                 # interleaved rounds (median)
    train_steps: int                 # timed optimiser steps (after train_warmup)
    train_warmup: int
    b1_pairs: int = 3                # roofline: steps timed side by side with their matrix products (batch 1)
    b32_pairs: int = 1               # the same at batch 32
    memory_steps: tuple[int, ...] = (50, 200)
    extras: bool = False             # full only: forward variants and the naive Algorithm 1 reference

    @classmethod
    def for_mode(cls, quick: bool) -> "Plan":
        if quick:
            return cls(True, b1_steps=5, b32_steps=1, b32_warmup=False, matmul_time=0.05, edit_frames=SHORT_FRAMES,
                       edit_steps=10, edit_rounds=1, train_steps=1, train_warmup=1)
        return cls(False, b1_steps=SAMPLING_STEPS, b32_steps=SAMPLING_STEPS, b32_warmup=True, matmul_time=0.3,
                   edit_frames=MOTION_FRAMES, edit_steps=SAMPLING_STEPS, edit_rounds=3, train_steps=5,
                   train_warmup=2, b1_pairs=20, b32_pairs=5, extras=True)


# ================================================================================ FLOPs
def gemm_flops(cfg: DenoiserConfig, rows: int, frames: int, tokens: int) -> dict[str, float]:
    """FLOPs (2 per multiply-add) of one denoiser forward over ``rows`` samples, by GEMM shape class.

    Counts every matrix product of :class:`~salad_core.models.denoiser.Denoiser` (LayerNorm,
    softmax, GELU and other element-wise work are not counted). Keys: ``proj`` (``w x w``-like
    projections: input/output processes, temporal and skeletal Q/K/V/O, cross Q/O, skip merges),
    ``ffn_up`` (``w x f``), ``ffn_down`` (``f x w``), ``attn`` (``q k^T`` and ``p v`` of the three
    attentions over ``tokens`` text keys), and the work a sampling call does once rather than per
    step: ``text_once`` (``word_emb`` and every layer's text K/V, cached on the TextContext) and
    ``timestep_once`` (the timestep MLP and all FiLMs of one timestep, for all rows: cached per
    timestep by :meth:`~salad_core.models.denoiser.Denoiser.timestep_conditioning`).
    """
    w, f, p, L, dz = cfg.width, cfg.ff_dim, cfg.num_parts, cfg.layers, cfg.latent_dim
    n = frames * p                                                  # (frame, part) tokens per sample
    half = L // 2
    proj = n * (dz * w + w * w)                                     # input process: Linear(Dz,w), Linear(w,w)
    proj += n * (w * w + w * dz)                                    # output process: Linear(w,w), Linear(w,Dz)
    proj += L * n * (4 * w * w + 4 * w * w + 2 * w * w)             # temporal QKVO, skeletal QKVO, cross Q and O
    proj += half * n * 2 * w * w                                    # skip merges Linear(2w, w)
    attn = L * (2 * n * frames * w + 2 * n * p * w + 2 * n * tokens * w)   # temporal, skeletal, cross: qk^T + pv
    ffn_up = L * n * w * f
    ffn_down = L * n * f * w
    text_once = tokens * cfg.text_dim * w + L * 2 * tokens * w * w  # word_emb + per-layer K, V
    out = {"proj": proj, "ffn_up": ffn_up, "ffn_down": ffn_down, "attn": attn, "text_once": text_once}
    out = {k: 2.0 * v * rows for k, v in out.items()}
    film = L * 4 * 2 * w * w if cfg.film else 0
    out["timestep_once"] = 2.0 * (2 * w * w + film)                 # timestep MLP + 4 FiLMs Linear(w, 2w) per layer
    return out


#: Keys of :func:`gemm_flops` that a sampling call computes once, not at every step.
ONCE_PER_CALL = ("text_once", "timestep_once")


def step_flops(cfg: DenoiserConfig, batch: int, frames: int, tokens: int, guidance: bool = True) -> float:
    """FLOPs of one sampling step for ``batch`` motions of ``frames`` latent frames (CFG: 2 rows each)."""
    fl = gemm_flops(cfg, (2 if guidance else 1) * batch, frames, tokens)
    return sum(v for k, v in fl.items() if k not in ONCE_PER_CALL)


def _best_rate(fn: Callable[[], Any], flops: float, min_time: float) -> float:
    """Best GFLOP/s of ``fn`` over repeated timings for ``min_time`` s (the best resists other load)."""
    fn()
    best, start = float("inf"), time.perf_counter()
    while True:
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
        if time.perf_counter() - start >= min_time:
            break
    return flops / best / 1e9


def matmul_rates_by_backend(cfg: DenoiserConfig, rows: int, frames: int, tokens: int,
                            min_time: float) -> dict[str, dict[str, float]]:
    """This machine's GFLOP/s of plain matrix products at the denoiser's GEMM shapes, per library.

    ``{"aten": {...}, "onednn": {...}}`` with the per-step keys of :func:`gemm_flops` (not :data:`ONCE_PER_CALL`):
    ``aten`` is ``torch.matmul`` (MKL's ``sgemm`` in PyTorch's CPU builds); ``onednn`` (only when
    :func:`salad_core.models.gemm.onednn_available`) is the oneDNN product the dense layers use,
    for the ``proj``/``ffn`` shapes (oneDNN has no batched route here, so ``attn`` is aten only:
    a batched ``q k^T`` of the temporal attention).
    """
    from salad_core.models import gemm

    w, f, p, h = cfg.width, cfg.ff_dim, cfg.num_parts, cfg.heads
    m = rows * frames * p
    dh = w // h
    g = torch.Generator().manual_seed(0)
    a_w, a_f = torch.randn(m, w, generator=g), torch.randn(m, f, generator=g)
    w_ww, w_fw, w_wf = torch.randn(w, w, generator=g), torch.randn(f, w, generator=g), torch.randn(w, f, generator=g)
    q = torch.randn(rows * p * h, frames, dh, generator=g)
    k = torch.randn(rows * p * h, dh, frames, generator=g)
    flops = {"proj": 2.0 * m * w * w, "ffn_up": 2.0 * m * w * f, "ffn_down": 2.0 * m * f * w}
    out: dict[str, dict[str, float]] = {}
    with torch.inference_mode():
        # weights stored (out, in) as in nn.Linear; aten multiplies by the transposed view, as F.linear does
        out["aten"] = {
            "proj": _best_rate(lambda: a_w @ w_ww.t(), flops["proj"], min_time),
            "ffn_up": _best_rate(lambda: a_w @ w_fw.t(), flops["ffn_up"], min_time),
            "ffn_down": _best_rate(lambda: a_f @ w_wf.t(), flops["ffn_down"], min_time),
            "attn": _best_rate(lambda: torch.bmm(q, k), 2.0 * q.shape[0] * frames * frames * dh, min_time),
        }
        if gemm.onednn_available():
            with gemm.use_backend("onednn"):
                out["onednn"] = {
                    "proj": _best_rate(lambda: gemm.linear(a_w, w_ww), flops["proj"], min_time),
                    "ffn_up": _best_rate(lambda: gemm.linear(a_w, w_fw), flops["ffn_up"], min_time),
                    "ffn_down": _best_rate(lambda: gemm.linear(a_f, w_wf), flops["ffn_down"], min_time),
                }
    return out


def matmul_rates(cfg: DenoiserConfig, rows: int, frames: int, tokens: int, min_time: float) -> dict[str, float]:
    """This machine's best GFLOP/s at the denoiser's GEMM shapes (keys of :func:`gemm_flops` except
    :data:`ONCE_PER_CALL`): for every shape the faster of the libraries of :func:`matmul_rates_by_backend`,
    so the roofline is measured against the best this CPU does, not against the library salad uses."""
    return _best_rates(matmul_rates_by_backend(cfg, rows, frames, tokens, min_time))


def step_products(cfg: DenoiserConfig, rows: int, frames: int, tokens: int,
                  libraries: dict[str, str] | None = None, seed: int = 0,
                  fold_keys: Sequence[int] | None = None) -> tuple[Callable[[], None], float]:
    """The matrix products of one denoiser forward, run back to back: the roofline's reference work.

    Every product :func:`gemm_flops` counts per step, at its shape, over ``rows`` samples of
    ``frames`` latent frames and ``tokens`` text keys: the dense layers (input and output
    processes, per layer the temporal and skeletal Q/K/V/O, cross Q/O and the FFN, the skip
    merges), each with its own weight as in the model (so weights come from memory as they do in
    a forward), on the library ``libraries[class]`` (``"aten"`` or ``"onednn"`` per class
    ``proj``/``ffn_up``/``ffn_down``; default: the dense layers' backend), and per layer the
    attention products ``q k^T`` and ``p v`` of the temporal, skeletal and cross attention at their
    shapes (``torch.matmul``: PyTorch's only fp32 batched route). No bias, activation, softmax or
    layer norm.

    ``fold_keys`` (valid keys of every row) gives instead the products sampling actually runs when
    the cross-attention is folded (:class:`~salad_core.models.attention.FoldedText`): per layer and
    row ``(N'P, w) x (w, H W_b)`` and ``(N'P, H W_b) x (H W_b, w)`` in place of the cross Q/O
    projections and the cross-attention products (fewer FLOPs than :func:`step_flops`).

    Returns
    -------
    run : callable
        Runs all products once (under ``torch.inference_mode``).
    flops : float
        Their FLOPs: :func:`step_flops` of the same sizes without guidance doubling (``rows`` rows).
    """
    from salad_core.models import gemm

    w, f, p, h, L, dz = cfg.width, cfg.ff_dim, cfg.num_parts, cfg.heads, cfg.layers, cfg.latent_dim
    dh, n = w // h, rows * frames * p
    libraries = {"proj": gemm.backend(), "ffn_up": gemm.backend(), "ffn_down": gemm.backend(), **(libraries or {})}
    if fold_keys is not None and len(fold_keys) != rows:
        raise ValueError(f"fold_keys needs one key count per row ({rows}), got {len(fold_keys)}")
    dense = [("proj", n, dz, w), ("proj", n, w, w)]                      # input process
    for _ in range(L):
        if fold_keys is None:
            dense += [("proj", n, w, w)] * 10
        else:                                                           # folded cross-attention per row
            dense += [("proj", n, w, w)] * 8
            dense += [c for keys in fold_keys for c in (("proj", frames * p, w, h * keys),
                                                        ("proj", frames * p, h * keys, w))]
        dense += [("ffn_up", n, w, f), ("ffn_down", n, f, w)]
    dense += [("proj", n, 2 * w, w)] * (L // 2) + [("proj", n, w, w), ("proj", n, w, dz)]   # skip merges, output
    g = torch.Generator().manual_seed(seed)
    inputs = {(m, k): torch.randn(m, k, generator=g) for m, k in sorted({(m, k) for _, m, k, _ in dense})}
    weights = [torch.randn(out, k, generator=g) / k ** 0.5 for _, _, k, out in dense]
    attention = []
    sites = [(rows * p, frames, frames), (rows * frames, p, p)]
    if fold_keys is None:
        sites.append((rows, frames * p, tokens))
    for r, lq, lk in sites:
        attention.append((torch.randn(r, h, lq, dh, generator=g), torch.randn(r, h, dh, lk, generator=g),
                          torch.softmax(torch.randn(r, h, lq, lk, generator=g), -1),
                          torch.randn(r, h, lk, dh, generator=g)))
    flops = sum(2.0 * m * k * out for _, m, k, out in dense)
    flops += L * sum(2.0 * q.numel() * kt.shape[-1] + 2.0 * pr.numel() * v.shape[-1] for q, kt, pr, v in attention)

    by_library: dict[str, list[tuple[torch.Tensor, torch.Tensor]]] = {}
    for (cls, m, k, _), weight in zip(dense, weights):
        by_library.setdefault(libraries[cls], []).append((inputs[(m, k)], weight))

    def run() -> None:
        with torch.inference_mode():
            for library, products in by_library.items():
                with gemm.use_backend(library):
                    for x, weight in products:
                        gemm.linear(x, weight)
            for _ in range(L):
                for q, kt, pr, v in attention:
                    torch.matmul(q, kt)
                    torch.matmul(pr, v)

    return run, flops


def paired_step_times(model: Denoiser, case: Case, batch: int, latent_frames: int, pairs: int,
                      products: Sequence[Callable[[], None]]) -> tuple[np.ndarray, np.ndarray]:
    """Seconds of ``pairs`` guided DDIM steps, and of each of ``products`` run right after every step.

    Timed side by side, step by step, so that the ratio of the two does not depend on how fast
    this machine happens to be in a given second (on a shared VM that changes by tens of percent
    within minutes). One extra step comes first and is dropped (it also prepares the text and the
    timestep table). Returns ``steps (pairs,)`` and ``products (len(products), pairs)``.
    """
    cond, null, noise, fm = _random_inputs(case, batch, latent_frames)
    for run in products:                              # warm: allocations, oneDNN primitives
        run()
    steps: list[float] = []
    refs: list[list[float]] = []
    mark = [0.0]

    def after_step(info, z) -> None:
        t0 = time.perf_counter()
        steps.append(t0 - mark[0])
        times = []
        for run in products:
            t1 = time.perf_counter()
            run()
            times.append(time.perf_counter() - t1)
        refs.append(times)
        mark[0] = time.perf_counter()

    mark[0] = time.perf_counter()
    denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=GUIDANCE, num_steps=pairs + 1,
            callback=after_step)
    return (np.asarray(steps[1:], dtype=np.float64),
            np.asarray(refs[1:], dtype=np.float64).reshape(pairs, len(products)).T)


def folded_keys(case: Case, batch: int) -> list[int] | None:
    """Valid text keys of every row of a guided step of :func:`_random_inputs`, if sampling folds
    the cross-attention for them (:meth:`~salad_core.models.attention.Attention.fold_text`:
    ``heads * keys < width`` in every row), else None."""
    (_, mask), (_, null_mask), _, _ = _random_inputs(case, batch, 1)
    keys = [int(n) for n in mask.sum(1)] + [int(null_mask.sum())] * batch
    cfg = case.config
    return keys if cfg.cross_attention and fold_pays(cfg.heads, cfg.width, keys) else None


def _best_rates(by_backend: dict[str, dict[str, float]]) -> dict[str, float]:
    """Per GEMM class, the fastest library's rate (``attn`` is measured on aten only)."""
    return {key: max(rates.get(key, 0.0) for rates in by_backend.values()) for key in by_backend["aten"]}


def roofline_seconds(flops: dict[str, float], rates: dict[str, float]) -> float:
    """Seconds one step would take if every GEMM class ran at its measured matmul rate."""
    return sum(flops[k] / (rates[k] * 1e9) for k in rates)


# ================================================================================ speed
def denoiser_cases(weights: str | Path | None = None) -> tuple[Case, Case]:
    """The paper configuration (CLIP B/32 text: 512-d, padded to 77 tokens) and the shipped default
    (its ``denoiser.json``; MiniLM text, 32 tokens as a long HumanML3D caption)."""
    from salad_core.io import config_from_dict
    from salad_core.pipeline import default_weights_dir

    path = Path(weights or default_weights_dir()) / "denoiser.json"
    try:
        shipped = config_from_dict(DenoiserConfig, json.loads(path.read_text())["config"])
    except (OSError, ValueError, KeyError) as exc:
        # the shipped recipe (configs/default_denoiser.json), when the weights are not installed
        log.warning("cannot read %s (%s); using the shipped recipe's denoiser config", path, exc)
        shipped = DenoiserConfig(width=128, heads=4, ff_dim=512, layers=5, text_dim=384)
    return Case("paper", DenoiserConfig(), 77), Case("default", shipped, 32)


def _random_inputs(case: Case, batch: int, latent_frames: int, seed: int = 0):
    """Random text features/masks, a null text, noise and a full frame mask for one batch."""
    g = torch.Generator().manual_seed(seed)
    cfg = case.config
    text = torch.randn(batch, case.tokens, cfg.text_dim, generator=g)
    lo, hi = PROMPT_TOKENS
    lengths = torch.randint(min(lo, case.tokens), min(hi, case.tokens) + 1, (batch,), generator=g)
    mask = torch.arange(case.tokens)[None] < lengths[:, None]
    null_mask = torch.zeros(1, case.tokens, dtype=torch.bool)
    null_mask[0, :2] = True  # the empty prompt: start and end tokens only
    null = (torch.randn(1, case.tokens, cfg.text_dim, generator=g), null_mask)
    noise = torch.randn(batch, latent_frames, cfg.num_parts, cfg.latent_dim, generator=g)
    frame_mask = torch.ones(batch, latent_frames, dtype=torch.bool)
    return (text, mask), null, noise, frame_mask


def attended_tokens(case: Case, batch: int) -> int:
    """Text keys the cross-attention attends at ``batch`` (the longest valid prompt of the guided
    batch, padding after it dropped): the ``tokens`` of the FLOP count of a timed step."""
    (_, mask), (_, null_mask), _, _ = _random_inputs(case, batch, 1)
    return int(torch.cat([mask, null_mask]).any(dim=0).nonzero().max()) + 1


def time_denoiser_steps(model: Denoiser, case: Case, batch: int, latent_frames: int, steps: int,
                        warmup: bool = True) -> np.ndarray:
    """Seconds of each of ``steps`` guided DDIM steps (float64), after an optional warm-up step."""
    cond, null, noise, fm = _random_inputs(case, batch, latent_frames)
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
    rates = _best_rates(by_backend)
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

    cond, _, noise, fm = _random_inputs(case, 2 * batch, MOTION_FRAMES // SKELETON.unit_length)
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


def compile_rows(case: Case, batch: int = 1, reps: int = 10) -> list[Row]:
    """Best seconds of one guided forward eager vs ``torch.compile`` (inductor, static shapes), the
    compile time, and after how many 50-step generations compiling pays off. A failure to compile
    is reported in the row's note (value NaN), not raised."""
    torch.manual_seed(0)
    model = Denoiser(case.config).eval()
    cond, _, noise, fm = _random_inputs(case, 2 * batch, MOTION_FRAMES // SKELETON.unit_length)
    ctx = model.prepare_text(*cond)
    t = torch.tensor([500])
    setting = f"{case.name}, {MOTION_FRAMES} frames, batch {batch}"

    def timed(fn) -> float:
        best = float("inf")
        with torch.inference_mode():
            for _ in range(reps):
                t0 = time.perf_counter()
                fn()
                best = min(best, time.perf_counter() - t0)
        return best

    with torch.inference_mode():
        eager_out = model(noise, t, frame_mask=fm, text_context=ctx)
    eager = timed(lambda: model(noise, t, frame_mask=fm, text_context=ctx))
    try:
        compiled = torch.compile(model, dynamic=False)
        t0 = time.perf_counter()
        with torch.inference_mode():
            out = compiled(noise, t, frame_mask=fm, text_context=ctx)
        compile_s = time.perf_counter() - t0
    except Exception as err:  # noqa: BLE001 - any backend failure is a measurement, not a crash
        return [Row("compile", "forward, torch.compile", setting, float("nan"), "s", reference=eager,
                    note=f"torch.compile failed ({type(err).__name__}: {str(err).splitlines()[0][:120]})")]
    fast = timed(lambda: compiled(noise, t, frame_mask=fm, text_context=ctx))
    diff = float((out - eager_out).abs().max())
    saved = (eager - fast) * SAMPLING_STEPS
    payoff = compile_s / saved if saved > 0 else float("inf")
    return [Row("compile", "forward, torch.compile (inductor)", setting, fast, "s", reference=eager,
                ratio=fast / eager, note=f"vs eager (best of {reps}); max |difference| {diff:.1e}"),
            Row("compile", "compile time (first call)", setting, compile_s, "s",
                note=f"pays off after {payoff:.0f} generations of {SAMPLING_STEPS} steps" if np.isfinite(payoff)
                else "never pays off: the compiled forward is not faster")]


# ================================================================================ pipeline
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


def _naive_algorithm1(pipe, source: str, target: str, edits, length: int, steps: int) -> torch.Tensor:
    """Three separate guided forwards per step (source, probe, edited; eager attention everywhere),
    the maps passed between them: the structure of the official ``Text2Motion.edit``."""
    from salad_core.attention import EditController, TokenInfo
    from salad_core.models.attention import EagerProcessor, use_processors
    from salad_core.models.denoiser import TextContext
    from salad_core.sampling import StepInfo

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
                outs.append(u + GUIDANCE * (c - u))
            z = sched.step(outs[0], t, z).prev_sample
            ze = sched.step(outs[2], t, ze).prev_sample
    pipe.decode(torch.cat([z, ze]), [length, length])
    return ze


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
            lambda s: _naive_algorithm1(pipe, SOURCE, REFINED, [Refine()], frames, s),
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


# ================================================================================ memory
def _rss_kib() -> tuple[int, int] | None:
    """``(current, peak)`` RSS in KiB from ``/proc/self/status`` (Linux), else None."""
    try:
        text = Path("/proc/self/status").read_text()
    except OSError:
        return None
    vals = {}
    for line in text.splitlines():
        key, _, rest = line.partition(":")
        if key in ("VmRSS", "VmHWM"):
            vals[key] = int(rest.split()[0])
    return (vals["VmRSS"], vals["VmHWM"]) if len(vals) == 2 else None


def _reset_peak() -> bool:
    """Reset the kernel's RSS high-water mark of this process (Linux >= 4.0)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def peak_rss_delta(fn: Callable[[], Any]) -> tuple[float, str]:
    """``(MiB, method)``: peak RSS while ``fn`` runs minus the RSS before it."""
    import resource

    gc.collect()
    if _reset_peak() and _rss_kib() is not None:
        before, _ = _rss_kib()
        fn()
        _, peak = _rss_kib()
        return max(peak - before, 0) / 1024, "resource RSS: VmHWM (reset) - VmRSS before"
    # ru_maxrss is KiB on Linux, bytes on macOS; it cannot be reset
    scale = 1 / 1024 if sys.platform != "darwin" else 1 / 2**20
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    fn()
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return (after - before) * scale, "resource RSS: ru_maxrss delta (process peak, not resettable)"


def memory_rows(pipe, frames: int, steps: Sequence[int] = (50, 200)) -> list[Row]:
    """Peak RSS growth of one generation with streaming capture, per number of steps; the ratio
    is against the first (the streaming store should not grow with the steps)."""
    pipe(SOURCE, lengths=frames, num_steps=2, capture_attention=True)  # first-call allocations out of the way
    rows, first = [], None
    for s in steps:
        mib, method = peak_rss_delta(lambda: pipe(SOURCE, lengths=frames, num_steps=s, capture_attention=True))
        first = mib if first is None else first
        rows.append(Row("memory", "peak memory, generation with streaming capture", f"{frames} frames, {s} steps",
                        mib, "MiB", reference=None if s == steps[0] else first,
                        ratio=None if s == steps[0] or first <= 0 else mib / first, note=method))
    return rows


# ================================================================================ training
@dataclass(frozen=True)
class TrainRecipe:
    """Model configs and training configs whose step rate is measured."""

    vae: Any              # VAEConfig
    vae_train: Any        # VAETrainConfig (batch_size, window, optimiser)
    denoiser: DenoiserConfig
    denoiser_train: Any   # DenoiserTrainConfig (batch_size, max_length, cond_drop_prob, optimiser)
    diffusion: Any        # DiffusionConfig
    source: str           # where the recipe came from


def train_recipe(weights: str | Path | None = None) -> TrainRecipe:
    """The recipe in ``runs.json`` of ``weights`` or of the shipped weights, else the library defaults."""
    from salad_core.io import config_from_dict
    from salad_core.models.vae import VAEConfig
    from salad_core.pipeline import default_weights_dir
    from salad_core.sampling import DiffusionConfig
    from salad_core.train.config import DenoiserTrainConfig, VAETrainConfig

    folders = ([Path(weights)] if weights is not None else []) + [default_weights_dir()]
    for path in (f / "runs.json" for f in folders):
        try:
            runs = json.loads(path.read_text())
            v, d = runs["vae"]["config"], runs["denoiser"]["config"]
            return TrainRecipe(config_from_dict(VAEConfig, v["model"]), config_from_dict(VAETrainConfig, v["train"]),
                               config_from_dict(DenoiserConfig, d["model"]),
                               config_from_dict(DenoiserTrainConfig, d["train"]),
                               config_from_dict(DiffusionConfig, d.get("task", {}).get("diffusion", {})),
                               f"recipe of {path}")
        except FileNotFoundError:
            continue
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("cannot read the training recipe %s (%s)", path, exc)
    log.warning("no readable runs.json in %s; using the library's default training configs",
                ", ".join(map(str, folders)))
    return TrainRecipe(VAEConfig(), VAETrainConfig(), DenoiserConfig(text_dim=384), DenoiserTrainConfig(),
                       DiffusionConfig(), "library defaults")


def _adamw(model: torch.nn.Module, config: Any) -> torch.optim.Optimizer:
    return torch.optim.AdamW([p for p in model.parameters() if p.requires_grad], lr=config.lr,
                             betas=tuple(config.betas), eps=config.adam_eps, weight_decay=config.weight_decay)


def _steps_per_second(step: Callable[[], None], steps: int, warmup: int) -> float:
    for _ in range(warmup):
        step()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - t0)


class _RandomText:
    """Stands in for the trainer's caption cache: random token features, ``tokens`` per caption."""

    def __init__(self, dim: int, tokens: int, seed: int = 0) -> None:
        self.dim, self.tokens = dim, tokens
        self.generator = torch.Generator().manual_seed(seed)

    def encode(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        feats = torch.randn(len(captions), self.tokens, self.dim, generator=self.generator)
        return feats, torch.ones(len(captions), self.tokens, dtype=torch.bool)


def training_rows(recipe: TrainRecipe, steps: int, warmup: int = 1, text_tokens: int = 24) -> list[Row]:
    """Optimiser steps per second of the VAE and of the denoiser on random data (one process)."""
    from salad_core.models.vae import MotionVAE
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import DenoiserObjective, _prepare
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom
    from salad_core.train.vae_trainer import VAEObjective

    g = torch.Generator().manual_seed(0)
    torch.manual_seed(0)
    # VAE: encode, reparameterise, decode, the four losses, backward, AdamW (VAEObjective)
    vc, vt = recipe.vae, recipe.vae_train
    vae = MotionVAE(vc).train()
    sk = vae.skeleton
    motion = torch.randn(vt.batch_size, vt.window, sk.feature_dim, generator=g)
    eps = torch.randn(vt.batch_size, vt.window // vae.downsample, vae.num_parts, vae.latent_dim, generator=g)
    objective, opt = VAEObjective(vae), _adamw(vae, vt)

    def vae_step() -> None:
        opt.zero_grad(set_to_none=True)
        objective(motion, eps)["loss"].backward()
        opt.step()

    vae_rate = _steps_per_second(vae_step, steps, warmup)
    del vae, objective, opt

    # denoiser: the trainer's batch preparation with a frozen (random) VAE, then forward/backward/AdamW
    dc, dt = recipe.denoiser, recipe.denoiser_train
    frozen = MotionVAE(vc).eval()
    for p in frozen.parameters():
        p.requires_grad_(False)
    den = Denoiser(dc).train()
    env = DistEnv()
    ctx = StepContext(rand=GlobalBatchRandom(torch.Generator().manual_seed(0), env), env=env, train=True, step=0)
    batch = {"motion": torch.randn(dt.batch_size, dt.max_length, sk.feature_dim, generator=g),
             "length": torch.full((dt.batch_size,), dt.max_length), "caption": [SOURCE] * dt.batch_size}
    latent_shape = (dt.max_length // frozen.downsample, frozen.num_parts, frozen.latent_dim)
    text = _RandomText(dc.text_dim, text_tokens)
    scheduler = make_scheduler(recipe.diffusion, "ddim")
    objective, opt = DenoiserObjective(den), _adamw(den, dt)

    def denoiser_step() -> None:
        inputs = _prepare(batch, ctx, vae=frozen, text=text, scheduler=scheduler, config=dt,
                          prediction_type=recipe.diffusion.prediction_type, latent_shape=latent_shape)
        opt.zero_grad(set_to_none=True)
        objective(**inputs)["loss"].backward()
        opt.step()

    den_rate = _steps_per_second(denoiser_step, steps, warmup)
    timed = f"{steps} timed step{'s' * (steps > 1)} after {warmup} warm-up; {recipe.source}"
    return [
        Row("training", "VAE steps/s", f"batch {vt.batch_size} x {vt.window} frames, latent {vc.latent_dim}",
            vae_rate, "steps/s", note=f"random motions; {timed}"),
        Row("training", "denoiser steps/s",
            f"batch {dt.batch_size} x {dt.max_length} frames, width {dc.width}, {dc.layers} layers",
            den_rate, "steps/s", note=f"random motions and text ({text_tokens} tokens), frozen random VAE; {timed}"),
    ]


def train_profile_rows(recipe: TrainRecipe, steps: int, warmup: int, data: str | Path | None = None,
                       weights: str | Path | None = None, corpus_motions: int = 60,
                       text_encoder: Any = "minilm") -> tuple[list[Row], list[str]]:
    """The ``train`` section: a denoiser step part by part, before and after (see the module docstring).

    ``data`` is a HumanML3D-layout folder (default: a procedural corpus of ``corpus_motions`` motions
    built in a temporary folder); the frozen VAE is ``weights/vae`` (default: the shipped one).
    Returns the rows and notes for the table.
    """
    import tempfile

    from salad_core.pipeline import default_weights_dir
    from salad_core.train.profile import PARTS, profile_denoiser_training

    tmp = Path(tempfile.mkdtemp(prefix="salad_bench_train_"))
    if data is None:
        from salad_core.data.procedural.corpus import build_corpus

        data = tmp / "corpus"
        try:
            build_corpus(data, size=corpus_motions, seed=0, progress=False)
        except Exception as exc:  # the generator is someone else's code: say what to do instead
            raise RuntimeError(f"building the train section's procedural corpus failed ({type(exc).__name__}: "
                               f"{exc}); pass --train-data with a HumanML3D-layout folder") from exc
    vae = Path(weights or default_weights_dir()) / "vae"
    cfg = recipe.denoiser_train.replace(progress=False)
    t0 = time.perf_counter()
    before, after = profile_denoiser_training(data, vae, recipe.denoiser, cfg, steps=steps, warmup=warmup,
                                              cache_dir=tmp / "latent_cache", diffusion_config=recipe.diffusion,
                                              text_encoder=text_encoder)
    log.info("train: profiled in %.0f s", time.perf_counter() - t0)
    setting = f"batch {cfg.batch_size}, width {recipe.denoiser.width}, {recipe.denoiser.layers} layers"
    rows = [Row("train", f"part: {p}", "ms per step", 1e3 * after.parts[p], "ms", 1e3 * before.parts[p],
                before.parts[p] / after.parts[p] if after.parts[p] > 0 else None)
            for p in PARTS]
    rows += [
        Row("train", "denoiser step", setting, 1e3 * after.step_s, "ms", 1e3 * before.step_s,
            before.step_s / after.step_s, note="sum of the parts"),
        Row("train", "denoiser steps/s", setting, after.steps_per_s, "steps/s", before.steps_per_s,
            after.steps_per_s / before.steps_per_s, note="ratio = after / before"),
        Row("train", "samples x frames/s", "valid motion frames per second", after.frames_per_s, "frames/s",
            before.frames_per_s, after.frames_per_s / before.frames_per_s, note="ratio = after / before"),
        Row("train", "padding", "latent frames computed / valid", after.padded_frames_per_step / after.frames_per_step,
            "x", before.padded_frames_per_step / before.frames_per_step, note="batch x longest item over valid frames"),
        Row("train", "start-up", "data, text prefill (+ latent cache after)", after.startup_s, "s", before.startup_s,
            note="before the first step; the cache is built once per VAE and corpus"),
    ]
    notes = [f"train: value = after (length buckets of {cfg.bucket_pool} batches, latent cache), reference = before "
             f"(random batches, VAE encoder per step), {steps} timed steps each after {warmup} warm-up, interleaved "
             f"one by one in one process; part ratio = before / after; data: {data}; VAE: {vae}; "
             f"validation amortised over val_every={cfg.val_every} steps, logging over log_every={cfg.log_every}"]
    return rows, notes


# ================================================================================ the table
def machine_header(threads: int, quick: bool) -> str:
    """One line: date, platform, CPUs, torch version and threads, and the load at the start."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    cpu = platform.processor() or platform.machine()
    return (f"salad bench{' --quick' if quick else ''}, {_dt.datetime.now().astimezone():%Y-%m-%d %H:%M %Z}: "
            f"{platform.platform()} ({cpu}), {os.cpu_count()} CPUs, Python {platform.python_version()}, "
            f"torch {torch.__version__}, {threads} torch thread{'s' * (threads != 1)}, dense layers on "
            f"{gemm_backend()}, allocator {'tuned' if allocator_tuned() else 'system default'}, load average "
            f"{load:.2f} at the start")


def run_benchmarks(quick: bool, threads: int, *, sections: Sequence[str] | None = None,
                   weights: str | Path | None = None, train_data: str | Path | None = None) -> "Any":
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


def _fmt(value: Any) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    if isinstance(value, (int, float, np.floating)):
        v = float(value)
        if v == 0:
            return "0"
        if abs(v) >= 100:
            return f"{v:,.0f}"
        if abs(v) >= 0.01:
            return f"{v:.3g}" if abs(v) < 10 else f"{v:.1f}"
        return f"{v:.2e}"
    return str(value).replace("|", "\\|")


def format_table(df: Any) -> str:
    """The table as Markdown: the machine header, one table, then the notes."""
    cols = list(df.columns)
    lines = [f"**{df.attrs.get('header', 'salad bench')}**", "",
             "| " + " | ".join(cols) + " |",
             "|" + "|".join("---:" if c in ("value", "reference", "ratio") else "---" for c in cols) + "|"]
    for rec in df.itertuples(index=False):
        lines.append("| " + " | ".join(_fmt(getattr(rec, c)) for c in cols) + " |")
    notes = df.attrs.get("notes", [])
    if notes:
        lines += ["", "Notes:"] + [f"- {n}" for n in notes]
    return "\n".join(lines) + "\n"


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="salad bench", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="measure generation speed, the denoiser's roofline fraction, the overheads of capture, "
                    "edits and inversion, training steps/s and peak memory on this machine; one table.\n\n"
                    "example:\n  salad bench --quick --threads 1 --out bench.md")
    p.add_argument("--quick", action="store_true", help="about a minute: fewer timed steps (extrapolated)")
    p.add_argument("--threads", type=int, default=None, help="torch threads (default: torch's, here %d)"
                   % torch.get_num_threads())
    p.add_argument("--out", default=None, help="also write the table to this Markdown file")
    p.add_argument("--force", action="store_true", help="overwrite --out")
    p.add_argument("--sections", default=None, help=f"comma-separated subset of {','.join(SECTIONS)} (default: "
                   f"all of them), or the opt-in {','.join(OPTIONAL_SECTIONS)}")
    p.add_argument("--weights", default=None, help="pipeline folder for memory/overheads (default: shipped)")
    p.add_argument("--train-data", default=None, help="train section: HumanML3D-layout corpus (default: a small "
                   "procedural corpus built in a temporary folder)")
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """``salad bench``: print the table (and write it to ``--out``); returns the exit code."""
    args = _parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    threads = torch.get_num_threads() if args.threads is None else args.threads
    if threads < 1:
        raise ValueError(f"--threads {threads}: use a positive number of threads")
    out = Path(args.out) if args.out else None
    if out is not None:
        if out.exists() and not args.force:
            raise FileExistsError(f"--out {out} exists; pass --force to overwrite it")
        if not out.parent.is_dir():
            raise FileNotFoundError(f"--out {out}: the folder {out.parent} does not exist")
    sections = [s.strip() for s in args.sections.split(",") if s.strip()] if args.sections else None
    from salad_core.allocator import tune_from_environment

    tune_from_environment()   # as the salad command does (also for the bench/ scripts that call this)
    df = run_benchmarks(args.quick, threads, sections=sections, weights=args.weights, train_data=args.train_data)
    text = format_table(df)
    print(text, end="")
    if out is not None:
        from salad_core.io import atomic_write_text

        atomic_write_text(out, text)
        print(f"written to {out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
