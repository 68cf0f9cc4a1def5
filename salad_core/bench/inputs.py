"""The denoiser configurations ``salad bench`` times and the random inputs of a timed step.

Random text features (the text encoder is excluded from the speed rows), masks with prompts of
:data:`~salad_core.bench.plan.PROMPT_TOKENS` valid tokens, a null text of 2 tokens, noise and a full
frame mask.
"""
from __future__ import annotations

import json
import logging
from pathlib import Path

import torch

from salad_core.models.kernels import fold_pays
from salad_core.models.denoiser import DenoiserConfig

from .plan import PROMPT_TOKENS, Case

__all__ = ["denoiser_cases", "random_inputs", "attended_tokens", "folded_keys"]

log = logging.getLogger(__name__)


def denoiser_cases(weights: str | Path | None = None) -> tuple[Case, Case]:
    """The paper configuration (CLIP B/32 text: 512-d, padded to 77 tokens) and the shipped default
    (its ``denoiser.json``; MiniLM text, 32 tokens as a long HumanML3D caption)."""
    from salad_core.io import config_from_dict
    from salad_core.pipeline import default_weights_dir

    path = Path(weights or default_weights_dir()) / "denoiser.json"
    try:
        shipped = config_from_dict(DenoiserConfig, json.loads(path.read_text())["config"])
    except (OSError, ValueError, KeyError) as exc:
        # the shipped recipe (lab/configs/default_denoiser.json), when the weights are not installed
        log.warning("cannot read %s (%s); using the shipped recipe's denoiser config", path, exc)
        shipped = DenoiserConfig(width=128, heads=4, ff_dim=512, layers=5, text_dim=384)
    return Case("paper", DenoiserConfig(), 77), Case("default", shipped, 32)


def random_inputs(case: Case, batch: int, latent_frames: int, seed: int = 0):
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
    (_, mask), (_, null_mask), _, _ = random_inputs(case, batch, 1)
    return int(torch.cat([mask, null_mask]).any(dim=0).nonzero().max()) + 1


def folded_keys(case: Case, batch: int) -> list[int] | None:
    """Valid text keys of every row of a guided step of :func:`_random_inputs`, if sampling folds
    the cross-attention for them (:func:`~salad_core.models.kernels.fold_text`:
    ``heads * keys < width`` in every row), else None."""
    (_, mask), (_, null_mask), _, _ = random_inputs(case, batch, 1)
    keys = [int(n) for n in mask.sum(1)] + [int(null_mask.sum())] * batch
    cfg = case.config
    return keys if cfg.cross_attention and fold_pays(cfg.heads, cfg.width, keys) else None
