"""The denoiser's FLOP model: matrix-product FLOPs of one forward and of one sampling step.

Counted from the configuration alone (:class:`~salad_core.models.denoiser.DenoiserConfig`); the
tests check the count against a hand count and against torch's FLOP counter on the real model.
"""
from __future__ import annotations

from salad_core.models.denoiser import DenoiserConfig

__all__ = ["gemm_flops", "ONCE_PER_CALL", "step_flops"]


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
