"""The roofline yardstick: how fast this machine runs the denoiser's own matrix products.

Two measures: the older, optimistic one (one product repeated on the same operands, best rate per
GEMM shape and library: :func:`matmul_rates_by_backend`), and the reference work of one step (every
product of a forward, each with its own weight: :func:`step_products`) timed right after every
denoising step (:func:`paired_step_times`), so the ratio of the two does not depend on how fast the
shared machine happens to be in a given second.
"""
from __future__ import annotations

import time
from typing import Any, Callable, Sequence

import numpy as np
import torch

from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import denoise, make_scheduler

from .plan import GUIDANCE, Case
from .inputs import random_inputs

__all__ = ["best_rate", "matmul_rates_by_backend", "matmul_rates", "best_rates", "roofline_seconds",
           "step_products", "paired_step_times"]


def best_rate(fn: Callable[[], Any], flops: float, min_time: float) -> float:
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
            "proj": best_rate(lambda: a_w @ w_ww.t(), flops["proj"], min_time),
            "ffn_up": best_rate(lambda: a_w @ w_fw.t(), flops["ffn_up"], min_time),
            "ffn_down": best_rate(lambda: a_f @ w_wf.t(), flops["ffn_down"], min_time),
            "attn": best_rate(lambda: torch.bmm(q, k), 2.0 * q.shape[0] * frames * frames * dh, min_time),
        }
        if gemm.onednn_available():
            with gemm.use_backend("onednn"):
                out["onednn"] = {
                    "proj": best_rate(lambda: gemm.linear(a_w, w_ww), flops["proj"], min_time),
                    "ffn_up": best_rate(lambda: gemm.linear(a_w, w_fw), flops["ffn_up"], min_time),
                    "ffn_down": best_rate(lambda: gemm.linear(a_f, w_wf), flops["ffn_down"], min_time),
                }
    return out


def matmul_rates(cfg: DenoiserConfig, rows: int, frames: int, tokens: int, min_time: float) -> dict[str, float]:
    """This machine's best GFLOP/s at the denoiser's GEMM shapes (keys of :func:`gemm_flops` except
    :data:`ONCE_PER_CALL`): for every shape the faster of the libraries of :func:`matmul_rates_by_backend`,
    so the roofline is measured against the best this CPU does, not against the library salad uses."""
    return best_rates(matmul_rates_by_backend(cfg, rows, frames, tokens, min_time))


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
    the cross-attention is folded (:class:`~salad_core.models.kernels.FoldedText`): per layer and
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
    cond, null, noise, fm = random_inputs(case, batch, latent_frames)
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


def best_rates(by_backend: dict[str, dict[str, float]]) -> dict[str, float]:
    """Per GEMM class, the fastest library's rate (``attn`` is measured on aten only)."""
    return {key: max(rates.get(key, 0.0) for rates in by_backend.values()) for key in by_backend["aten"]}


def roofline_seconds(flops: dict[str, float], rates: dict[str, float]) -> float:
    """Seconds one step would take if every GEMM class ran at its measured matmul rate."""
    return sum(flops[k] / (rates[k] * 1e9) for k in rates)
