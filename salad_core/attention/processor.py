"""One attention processor for capture and editing: fast attention for the output, explicit
probabilities only for the batch rows a hook asks for.

:class:`~salad_core.models.attention.EagerProcessor` computes the softmax of *every* row; its output
differs from the fast attention of plain sampling in the last bits, so a capture built on it would change the
generated motion slightly. :class:`HookedProcessor` instead

1. asks its hook which batch rows it needs (``hook.rows(site)``; ``None`` = none at this call,
   the common case for self-attention sites, which then cost nothing extra),
2. computes the output of every row exactly as sampling without hooks does
   (:func:`~salad_core.models.kernels.fast_attention`); on its explicit route (key axes shorter
   than ``SHORT_KEYS``, e.g. typical prompts) the probabilities it computes anyway are the ones
   the hook gets, so capture costs only what the hook does with them; on the SDPA route
   ``softmax(q k^T / sqrt(d))`` is computed again for the hook's rows only,
3. passes the probabilities of those rows to ``hook.process(site, batch_rows, probs)``,
4. if the hook returns ``(rows, new_probs)``, recomputes the output of those rows as
   ``new_probs @ v`` (SALAD supplement B: ``Denoise(z_t, t, c){M <- M_hat}``, values from the
   row's own prompt).

Rows the hook does not replace keep the plain-sampling output bit for bit, which is why capturing never
changes a motion and why the source branch of an edit equals plain generation.

Rows of the flat probability tensor and batch rows differ at the self-attention sites: temporal
probabilities have ``B * P`` rows ordered (batch, part), skeletal ones ``B * N'`` ordered
(batch, frame); :func:`flat_rows` converts (see :mod:`salad_core.models.attention`).
"""
from __future__ import annotations

from typing import Callable, Optional, Protocol

import torch
import torch.nn.functional as F

from salad_core.models.attention import AttentionProcessor, SiteInfo
from salad_core.models.kernels import (FoldedText, attention_probs, attention_with_probs, fast_attention,
                                       folded_cross_attention)

__all__ = ["SiteHook", "HookedProcessor", "flat_rows", "named_rows", "flat_from_named", "row_taker"]


class SiteHook(Protocol):
    """What :class:`HookedProcessor` asks of its hook at every call of a site."""

    def rows(self, site: SiteInfo) -> Optional[torch.Tensor]:
        """Batch rows ``(n,)`` (long) whose probabilities are needed now, or None."""

    def process(self, site: SiteInfo, rows: torch.Tensor, probs: torch.Tensor
                ) -> Optional[tuple[torch.Tensor, torch.Tensor]]:
        """Receive the probabilities of ``rows`` in named axes (see :func:`named_rows`); return
        None, or ``(rows2, new_probs)``: batch rows to replace and their named probabilities."""


def _rows_per_sample(site: SiteInfo) -> int:
    if site.kind == "temporal":
        return site.parts
    if site.kind == "skeletal":
        return site.frames
    return 1


def flat_rows(site: SiteInfo, rows: torch.Tensor) -> torch.Tensor:
    """Batch rows ``(n,)`` -> rows of the flat probability tensor at ``site`` ``(n * r,)``."""
    per = _rows_per_sample(site)
    if per == 1:
        return rows
    return (rows[:, None] * per + torch.arange(per, device=rows.device)[None, :]).reshape(-1)


def named_rows(site: SiteInfo, probs: torch.Tensor, n: int) -> torch.Tensor:
    """Flat probabilities of ``n`` batch rows -> named axes (as :meth:`SiteInfo.to_named`).

    temporal ``(n, P, H, N', N')``, skeletal ``(n, N', H, P, P)``, cross ``(n, H, N', P, W)``,
    sentence ``(n, H, N', P, 1 + N'P)``.
    """
    h, nf, p = site.heads, site.frames, site.parts
    if site.kind == "temporal":
        return probs.view(n, p, h, nf, nf)
    if site.kind == "skeletal":
        return probs.view(n, nf, h, p, p)
    return probs.view(n, h, nf, p, probs.shape[-1])


def flat_from_named(site: SiteInfo, named: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`named_rows`: ``(n, ...)`` named -> flat ``(n * r, H, Lq, Lk)``."""
    n = named.shape[0]
    h, nf, p = site.heads, site.frames, site.parts
    if site.kind == "temporal":
        return named.reshape(n * p, h, nf, nf)
    if site.kind == "skeletal":
        return named.reshape(n * nf, h, p, p)
    return named.reshape(n, h, nf * p, named.shape[-1])


def row_taker(flat: torch.Tensor) -> Callable[[torch.Tensor], torch.Tensor]:
    """A function ``x (R, ...) -> x[flat] (n, ...)`` for the rows ``flat (n,)`` (long): a slice (a
    view, no copy) when ``flat`` is a run of consecutive rows, as the conditional rows of one
    guidance branch are, else a gather (a copy)."""
    n = flat.numel()
    if n and int(flat[-1]) - int(flat[0]) == n - 1 and (n == 1 or bool((flat.diff() == 1).all())):
        start = int(flat[0])
        return lambda x: x[start:start + n]
    return lambda x: x[flat]


class HookedProcessor(AttentionProcessor):
    """Plain-sampling output for every row plus explicit probabilities for the rows a hook needs.

    Parameters
    ----------
    hook : SiteHook
        Decides per call which batch rows it needs and whether it replaces some.
    """

    def __init__(self, hook: SiteHook) -> None:
        self.hook = hook

    def __call__(self, site: SiteInfo, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor,
                 key_mask: torch.Tensor | None, dropout_p: float) -> torch.Tensor:
        rows = self.hook.rows(site)
        if rows is None or rows.numel() == 0:
            return fast_attention(q, k, v, key_mask, dropout_p)  # what plain sampling computes, bit for bit
        flat = flat_rows(site, rows)
        take = row_taker(flat)
        out, all_probs = attention_with_probs(q, k, v, key_mask, dropout_p)
        if all_probs is not None:                        # explicit route: the probabilities plain sampling used
            probs = take(all_probs)
            if probs.shape[-1] < k.shape[-2]:            # trimmed padding: probability 0 for the hook
                probs = F.pad(probs, (0, k.shape[-2] - probs.shape[-1]))
        else:
            probs = attention_probs(take(q), take(k), None if key_mask is None else take(key_mask))
        result = self.hook.process(site, rows, named_rows(site, probs, rows.numel()))
        if result is None:
            return out
        new_rows, new_named = result
        new_flat = flat_rows(site, new_rows)
        new_probs = flat_from_named(site, new_named).to(v.dtype)
        expected = (new_flat.numel(), *probs.shape[1:])
        if tuple(new_probs.shape) != expected:
            raise ValueError(f"hook returned probabilities of shape {tuple(new_probs.shape)} at site "
                             f"{site.name!r}; expected {expected}")
        if dropout_p > 0.0:
            new_probs = F.dropout(new_probs, p=dropout_p, training=True)
        out = out.clone()
        out[new_flat] = torch.matmul(new_probs, v[new_flat])
        return out

    #: Cross-attention sites may come through :meth:`folded` (the route plain sampling takes).
    takes_folded = True

    def folded(self, site: SiteInfo, x: torch.Tensor, fold: FoldedText) -> torch.Tensor:
        """The folded cross-attention of plain sampling (:class:`~salad_core.models.kernels.FoldedText`)
        for every row, with the hook served as in :meth:`__call__`: it gets the probabilities the
        folded route mixed the values with (zeros for padding keys), and rows it replaces are
        recomputed as ``Wo(new_probs @ v)`` over all keys of the row's own prompt.
        ``x (B, Lq, w)`` -> ``(B, Lq, w)`` after ``Wo``."""
        rows = self.hook.rows(site)
        if rows is None or rows.numel() == 0:
            return folded_cross_attention(x, fold)[0]          # what plain sampling computes, bit for bit
        wanted = [int(r) for r in rows]
        out, kept = folded_cross_attention(x, fold, wanted)
        heads, lq, tokens = fold.heads, x.shape[1], fold.tokens
        probs = x.new_zeros(len(wanted), heads, lq, tokens)
        for i, b in enumerate(wanted):
            probs[i, :, :, :fold.keys[b]] = kept[b].transpose(0, 1)   # (Lq, H, W_b) -> (H, Lq, W_b)
        result = self.hook.process(site, rows, named_rows(site, probs, len(wanted)))
        if result is None:
            return out
        new_rows, new_named = result
        new_probs = flat_from_named(site, new_named).to(x.dtype)
        expected = (new_rows.numel(), heads, lq, tokens)
        if tuple(new_probs.shape) != expected:
            raise ValueError(f"hook returned probabilities of shape {tuple(new_probs.shape)} at site "
                             f"{site.name!r}; expected {expected}")
        mixed = torch.matmul(new_probs, fold.v[new_rows])                    # (n, H, Lq, dh)
        merged = mixed.transpose(1, 2).reshape(new_rows.numel(), lq, -1)
        out = out.clone()
        out[new_rows] = F.linear(merged, fold.wo_weight, fold.wo_bias)
        return out

    def __repr__(self) -> str:
        return f"HookedProcessor(hook={type(self.hook).__name__})"
