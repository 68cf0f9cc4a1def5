"""Named attention sites with swappable processors (the contract capture and editing build on).

Every attention module of the denoiser is a *site* with a stable name, e.g.
``"layers.2.cross"``. The module owns the projections ``Wq, Wk, Wv, Wo`` (official key names)
and hands the core computation ``softmax(q k^T / sqrt(d)) v`` to a swappable *processor*, as in
diffusers' ``attention_processor.py``:

* :class:`SDPAProcessor` (default) computes it by :func:`fast_attention`: two matmuls and an
  explicit softmax for key axes shorter than :data:`SHORT_KEYS` (every site of a 196-frame motion
  with a typical prompt), ``torch.nn.functional.scaled_dot_product_attention`` for longer ones,
  with trailing padding keys dropped;
* :class:`EagerProcessor` computes the softmax explicitly and passes the post-softmax
  probabilities to an optional ``controller(site, probs) -> probs``. Whatever the controller
  returns is used to mix the values, so one mechanism serves capture (record and return the
  input) and editing (return modified maps; SALAD §3.3, supplement B).

A controller learns *where* it is from a :class:`SiteInfo`: the site name, its kind, the layer
index and the call's sizes, with helpers that view the flat probability tensor in named axes:

=========  ==========================  ==============================
kind       probs (flat)                :meth:`SiteInfo.to_named`
=========  ==========================  ==============================
temporal   ``(B*P, H, N', N')``        ``(B, P, H, N', N')``
skeletal   ``(B*N', H, P, P)``         ``(B, N', H, P, P)``
cross      ``(B, H, N'*P, W)``         ``(B, H, N', P, W)``
sentence   ``(B, H, N'*P, 1+N'*P)``    ``(B, H, N', P, 1+N'*P)``
=========  ==========================  ==============================

Queries of cross attention are flattened with index ``t * P + j`` (frame ``t``, part ``j``).
``sentence`` sites exist only in the "w/o CrossAttn" ablation (key 0 is the sentence token).

:func:`use_processors` installs processors for one block of code and always restores the
previous ones, also after an exception (TransformerLens-style scoped hooks).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Optional, Union

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.models.gemm import Linear, linear

__all__ = [
    "SITE_KINDS",
    "CallDims",
    "SiteInfo",
    "Controller",
    "AttentionProcessor",
    "SDPAProcessor",
    "FoldedText",
    "folded_cross_attention",
    "fold_pays",
    "fast_attention",
    "attention_with_probs",
    "attention_probs",
    "softmax_last",
    "SHORT_KEYS",
    "VECTOR_ROW",
    "trim_masked_keys",
    "prefix_key_runs",
    "prefix_lengths",
    "MAX_KEY_RUNS",
    "explicit_route",
    "EagerProcessor",
    "Attention",
    "AttnProcessorMixin",
    "use_processors",
    "site_names",
    "cross_probs_by_part",
]

#: The kinds of attention site. ``sentence`` only exists in the "w/o CrossAttn" ablation.
SITE_KINDS: tuple[str, ...] = ("temporal", "skeletal", "cross", "sentence")


def site_names(num_layers: int, cross_attention: bool = True) -> list[str]:
    """The site names of a denoiser with ``num_layers`` layers, in execution order.

    Layer ``i`` runs temporal, then skeletal, then cross (or sentence) attention; layer 0 is the
    first input block and ``num_layers - 1`` the last output block.
    """
    third = "cross" if cross_attention else "sentence"
    return [f"layers.{i}.{kind}" for i in range(num_layers) for kind in ("temporal", "skeletal", third)]


@dataclass(frozen=True)
class CallDims:
    """Sizes of one denoiser call, shared by every site of that call."""

    batch: int    # B: samples in the call (2B under batched classifier-free guidance)
    frames: int   # N': latent frames
    parts: int    # P: latent body parts
    tokens: int   # W: text tokens (cross sites); 1 + N'*P for sentence sites


@dataclass(frozen=True)
class SiteInfo:
    """Where a processor is called: site identity plus the call's sizes.

    ``probs_shape`` is the flat shape of the post-softmax probabilities at this site and
    :meth:`to_named` / :meth:`from_named` convert to and from the named-axis view (see the module
    docstring for the table).
    """

    name: str        # stable site name, e.g. "layers.3.cross"
    kind: str        # one of SITE_KINDS
    layer: int       # layer index in execution order (0 = input_blocks.0)
    num_layers: int  # L, layers of the denoiser
    heads: int       # H
    batch: int       # B
    frames: int      # N'
    parts: int       # P
    tokens: int      # key length of cross / sentence sites (W or 1 + N'*P); 0 otherwise

    @property
    def probs_shape(self) -> tuple[int, int, int, int]:
        """Flat shape of the probabilities ``(rows, H, Lq, Lk)`` at this site."""
        b, h, n, p = self.batch, self.heads, self.frames, self.parts
        if self.kind == "temporal":
            return (b * p, h, n, n)
        if self.kind == "skeletal":
            return (b * n, h, p, p)
        return (b, h, n * p, self.tokens)

    @property
    def named_axes(self) -> tuple[str, ...]:
        """Axis names of :meth:`to_named`'s output."""
        return {
            "temporal": ("batch", "part", "head", "query_frame", "key_frame"),
            "skeletal": ("batch", "frame", "head", "query_part", "key_part"),
            "cross": ("batch", "head", "frame", "part", "token"),
            "sentence": ("batch", "head", "frame", "part", "key"),
        }[self.kind]

    def to_named(self, probs: torch.Tensor) -> torch.Tensor:
        """View flat ``probs`` in named axes (no copy); see :attr:`named_axes`."""
        self._check(probs)
        b, h, n, p = self.batch, self.heads, self.frames, self.parts
        if self.kind == "temporal":
            return probs.view(b, p, h, n, n)
        if self.kind == "skeletal":
            return probs.view(b, n, h, p, p)
        return probs.view(b, h, n, p, self.tokens)

    def from_named(self, named: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`to_named`: back to :attr:`probs_shape` (a copy if needed)."""
        return named.reshape(self.probs_shape)

    def _check(self, probs: torch.Tensor) -> None:
        if tuple(probs.shape) != self.probs_shape:
            raise ValueError(
                f"probs at site {self.name!r} ({self.kind}) must have shape {self.probs_shape}, "
                f"got {tuple(probs.shape)}"
            )


def cross_probs_by_part(probs: torch.Tensor, frames: int, parts: int) -> torch.Tensor:
    """Cross-attention probabilities ``(B, H, N'*P, W)`` -> ``(B, H, N', P, W)``.

    Query index ``t * P + j`` becomes axes (frame ``t``, part ``j``).
    """
    if probs.dim() != 4 or probs.shape[2] != frames * parts:
        raise ValueError(
            f"cross probs must be (B, H, frames*parts={frames * parts}, W), got {tuple(probs.shape)}"
        )
    b, h, _, w = probs.shape
    return probs.reshape(b, h, frames, parts, w)


#: ``controller(site, probs) -> probs``: may record ``probs`` and/or return modified ones
#: (same shape). Returning ``None`` keeps the probabilities unchanged.
Controller = Callable[[SiteInfo, torch.Tensor], Optional[torch.Tensor]]


#: Rows at least this long go to PyTorch's softmax kernel, shorter ones to exp / sum (see :func:`softmax_last`).
VECTOR_ROW = 16


def softmax_last(scores: torch.Tensor) -> torch.Tensor:
    """Softmax over the last axis by the faster CPU route for the row length (the input is never
    modified).

    PyTorch's CPU softmax kernel is vectorised over rows of at least 16 values and scalar below:
    on cross-attention probabilities ``(2, 8, 343, L)`` it took 310-500 us for ``L`` = 8-14 against
    70-100 us for ``exp(x - max) / sum`` in place on a new tensor, and 43-76 us against 100-170 us
    for ``L`` = 16-24 (temporal ``(14, 8, 49, 49)``: 106 against 199 us). So rows shorter than
    :data:`VECTOR_ROW` take the exp/sum form, longer ones ``torch.softmax``. Both give the same
    values up to float rounding; rows that are all ``-inf`` give NaN either way.
    """
    if scores.shape[-1] >= VECTOR_ROW:
        return torch.softmax(scores, dim=-1)
    e = scores - scores.amax(dim=-1, keepdim=True)
    if e.requires_grad:                       # autograd needs exp's output (null-text optimisation)
        e = e.exp()
        return e / e.sum(dim=-1, keepdim=True)
    e = e.exp_()
    return e.div_(e.sum(dim=-1, keepdim=True))


class AttentionProcessor:
    """Core attention ``(q, k, v) -> out``; subclasses decide how.

    ``__call__(site, q, k, v, key_mask, dropout_p)`` receives per-head tensors
    ``q (R, H, Lq, dh)``, ``k, v (R, H, Lk, dh)``, an optional boolean ``key_mask (R, Lk)``
    (True = the key may be attended; every row has at least one True) and the attention
    dropout probability (0 in eval mode), and returns ``(R, H, Lq, dh)``.
    """

    def __call__(self, site: SiteInfo, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor,
                 key_mask: torch.Tensor | None, dropout_p: float) -> torch.Tensor:
        raise NotImplementedError

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"


def attention_probs(q: torch.Tensor, k: torch.Tensor, key_mask: torch.Tensor | None) -> torch.Tensor:
    """``softmax(q k^T / sqrt(dh))`` ``(R, H, Lq, Lk)`` with masked keys (``key_mask (R, Lk)``
    False) at probability 0; ``q (R, H, Lq, dh)``, ``k (R, H, Lk, dh)``."""
    scores = torch.matmul(q, k.transpose(-1, -2)).mul_(1.0 / math.sqrt(q.shape[-1]))
    if key_mask is not None:
        scores = scores.masked_fill_(~key_mask[:, None, None, :], float("-inf"))
    return softmax_last(scores)


#: Key lengths below this use explicit matmuls instead of SDPA (see :func:`fast_attention`): every
#: site of a 196-frame motion (49 latent frames) and prompts of up to 49 tokens.
SHORT_KEYS = 50


def explicit_route(num_keys: int, dropout_p: float) -> bool:
    """Whether :func:`fast_attention` computes ``num_keys`` keys with explicit probabilities
    (:func:`attention_probs` then a matmul) rather than SDPA."""
    return dropout_p == 0.0 and num_keys < SHORT_KEYS


def trim_masked_keys(k: torch.Tensor, v: torch.Tensor, key_mask: torch.Tensor
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
    """Drop the trailing keys that ``key_mask`` masks in every row; ``None`` mask if all that is
    left is valid. ``k, v (R, H, Lk, dh)``, ``key_mask (R, Lk)`` -> ``(R, H, Lk', dh)``, ``(R, Lk')``."""
    used = key_mask.any(dim=0)                       # (Lk,): some row may attend this key
    if bool(used[-1]):
        return k, v, (None if bool(key_mask.all()) else key_mask)
    keep = int(used.nonzero()[-1]) + 1 if bool(used.any()) else key_mask.shape[1]
    key_mask = key_mask[:, :keep]
    return k[..., :keep, :], v[..., :keep, :], (None if bool(key_mask.all()) else key_mask)


#: At most this many runs of consecutive rows with the same number of valid leading keys are
#: attended run by run instead of through a mask (see :func:`prefix_key_runs`).
MAX_KEY_RUNS = 4

_RUNS_CACHE: list = [None]          # (copy of the last mask seen, its runs): a call reuses it at every site


def prefix_key_runs(key_mask: torch.Tensor) -> tuple[tuple[int, int, int], ...] | None:
    """Runs ``(start, stop, keys)`` of consecutive rows of ``key_mask (R, Lk)`` whose valid keys
    are exactly the first ``keys`` (``keys >= 1``), or None when some row is not such a prefix mask
    or there are more than :data:`MAX_KEY_RUNS` runs.

    Text masks are prefix masks (tokens, then padding), and under classifier-free guidance a
    batch is two runs (conditional rows, then the empty prompt's) or a few more. Attending each
    run to its own keys without a mask gives the masked result (masked keys have probability 0
    either way) and skips the masking pass, which costs more than its size suggests on a CPU:
    ``exp`` of the ``-inf`` scores is a slow path (cross-attention of a 2-row batch, 8 heads,
    343 queries, 13 keys: 384 us masked, 243 us unmasked, 224 us run by run). The result for a
    mask is kept until another mask (or an in-place change) comes, so the denoiser's layers and
    steps, which share one text mask, compute it once (a copy of the mask is compared, so a mask
    changed in place is not mistaken for the cached one).
    """
    cached = _RUNS_CACHE[0]
    if cached is not None and cached[0].shape == key_mask.shape and torch.equal(cached[0], key_mask):
        return cached[1]
    runs: list[tuple[int, int, int]] | None = []
    for row, keys in enumerate(prefix_lengths(key_mask) or ()):
        if runs and runs[-1][2] == keys:
            runs[-1] = (runs[-1][0], row + 1, keys)
        else:
            runs.append((row, row + 1, keys))
    result = tuple(runs) if runs and len(runs) <= MAX_KEY_RUNS else None
    _RUNS_CACHE[0] = (key_mask.clone(), result)
    return result


def prefix_lengths(key_mask: torch.Tensor) -> list[int] | None:
    """Valid keys per row of ``key_mask (R, Lk)`` if every row is a prefix mask (its first ``n >= 1``
    keys valid, the rest not), else None."""
    lengths = []
    for valid in key_mask.tolist():
        n = valid.index(False) if not valid[-1] else len(valid)
        if n == 0 or any(valid[n:]):
            return None
        lengths.append(n)
    return lengths


def _attend_runs(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, runs: tuple[tuple[int, int, int], ...],
                 need_probs: bool) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Explicit attention of every row run to its own first ``keys`` keys (no mask); probabilities
    over all ``Lk`` keys (zeros beyond a run's keys) only if ``need_probs``."""
    r, h, lq, _ = q.shape
    differentiable = torch.is_grad_enabled() and (q.requires_grad or k.requires_grad or v.requires_grad)
    out = None if differentiable else q.new_empty(r, h, lq, v.shape[-1])
    pieces, probs = [], (q.new_zeros(r, h, lq, k.shape[-2]) if need_probs else None)
    for start, stop, keys in runs:
        p = attention_probs(q[start:stop], k[start:stop, :, :keys], None)
        if out is None:
            pieces.append(torch.matmul(p, v[start:stop, :, :keys]))
        else:                                  # straight into the output: no concatenation
            torch.matmul(p, v[start:stop, :, :keys], out=out[start:stop])
        if probs is not None:
            probs[start:stop, :, :, :keys] = p
    return (torch.cat(pieces) if out is None else out), probs


def fast_attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, key_mask: torch.Tensor | None,
                   dropout_p: float) -> torch.Tensor:
    """``softmax(q k^T / sqrt(d)) v`` by the faster CPU route for the shapes at hand.

    PyTorch's CPU ``scaled_dot_product_attention`` is slow when there are few keys: measured
    (1 thread, 4 heads of 32 channels) for the skeletal attention over 7 parts it ran at 6-7
    GFLOP/s, 2x slower than two matmuls and :func:`softmax_last`; for cross-attention with 14 text
    tokens 2.4x slower; it also has a fixed cost of about 0.4 ms per call on this machine. Up to
    49 keys (the temporal attention of a 196-frame motion, prompts of typical length) the whole
    paper denoiser ran as fast with the explicit route as with SDPA from 16 keys on (batch 1 and
    32, interleaved runs), and the explicit route hands its probabilities to capture for free
    (:class:`~salad_core.attention.processor.HookedProcessor`). So key axes shorter than
    :data:`SHORT_KEYS` take the explicit route when there is no attention dropout; longer ones call
    SDPA. Both give the same values up to float rounding.

    Keys masked in every row at the end of the key axis (the padding of the longest prompt of the
    batch, e.g. CLIP's 77-token padding) are dropped before the product: they get probability 0
    either way, so the result is the same and the work shrinks with the prompt. On the explicit
    route, a prefix mask with few row runs (:func:`prefix_key_runs`: the two guidance branches)
    is not applied as a mask at all: every run attends to its own keys.

    Shapes: ``q (R, H, Lq, dh)``, ``k, v (R, H, Lk, dh)``, ``key_mask (R, Lk)`` bool or None.
    """
    return attention_with_probs(q, k, v, key_mask, dropout_p, need_probs=False)[0]


def attention_with_probs(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, key_mask: torch.Tensor | None,
                         dropout_p: float, need_probs: bool = True) -> tuple[torch.Tensor, torch.Tensor | None]:
    """:func:`fast_attention`'s output and, on its explicit route, the probabilities it mixed the
    values with: ``(R, H, Lq, Lk')`` over the keys left after :func:`trim_masked_keys`
    (``Lk' <= Lk``, masked keys at 0); None on the SDPA route or when ``need_probs`` is False.
    The output does not depend on ``need_probs``; capture uses these probabilities, so its output is
    plain sampling's by construction."""
    if key_mask is not None:
        runs = prefix_key_runs(key_mask)
        if runs is not None:
            keep = max(keys for _, _, keys in runs)
            if explicit_route(keep, dropout_p):
                return _attend_runs(q, k[..., :keep, :], v[..., :keep, :], runs, need_probs)
        k, v, key_mask = trim_masked_keys(k, v, key_mask)
    if explicit_route(k.shape[-2], dropout_p):
        probs = attention_probs(q, k, key_mask)
        return torch.matmul(probs, v), probs
    mask = None if key_mask is None else key_mask[:, None, None, :]
    return F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=dropout_p), None


@dataclass(frozen=True)
class FoldedText:
    """One call's text side of a cross-attention site folded into its query and output projections.

    For batch row ``b`` with ``W_b`` valid (leading) keys, ``scores_b = x_b a_b^T + c_b`` is
    ``(Lq, H * W_b)`` (index ``h * W_b + j``) and equals ``(x_b Wq^T + bq) k_b^T / sqrt(dh)`` per head;
    after the per-head softmax ``p_b``, ``p_b n_b^T + bo`` equals ``Wo`` applied to ``p_b v_b``. With
    fewer than ``w / H`` keys this is less work than projecting the queries and merging the heads
    (paper model, 13 keys: 104 instead of 256 columns), and every product is a dense one.
    ``k, v, wo_weight, wo_bias`` are kept for rows whose probabilities an editing hook replaces.
    Memory: ``2 H W_b w`` floats per row beside the text keys and values (paper model, a 24-token
    prompt: 0.4 MB per row and layer; a guided batch of 32 such prompts: 65 MB, measured).
    """

    a: tuple[torch.Tensor, ...]      # per row (H * W_b, w)
    c: tuple[torch.Tensor, ...]      # per row (H * W_b,)
    n: tuple[torch.Tensor, ...]      # per row (w, H * W_b)
    keys: tuple[int, ...]            # W_b
    k: torch.Tensor                  # (B, H, W, dh)
    v: torch.Tensor                  # (B, H, W, dh)
    wo_weight: torch.Tensor          # (w, w)
    wo_bias: torch.Tensor            # (w,)

    @property
    def heads(self) -> int:
        return self.k.shape[1]

    @property
    def tokens(self) -> int:
        """W: the (padded) key axis of the unfolded site."""
        return self.k.shape[2]


def fold_pays(heads: int, width: int, keys: Sequence[int]) -> bool:
    """Whether folding the text into ``Wq``/``Wo`` (:class:`FoldedText`) is less work than the
    projected route: every row's ``heads * keys`` columns fewer than ``width``."""
    return bool(keys) and heads * max(keys) < width


def folded_cross_attention(x: torch.Tensor, fold: FoldedText, keep_probs: Sequence[int] = ()
                           ) -> tuple[torch.Tensor, dict[int, torch.Tensor]]:
    """Cross-attention of queries ``x (B, Lq, w)`` through ``fold`` -> ``(B, Lq, w)`` (after ``Wo``),
    and the probabilities ``(Lq, H, W_b)`` of the batch rows in ``keep_probs``."""
    heads, outs, kept = fold.heads, [], {}
    for b, keys in enumerate(fold.keys):
        scores = linear(x[b], fold.a[b], fold.c[b])                          # (Lq, H * W_b)
        probs = softmax_last(scores.view(-1, heads, keys))                    # (Lq, H, W_b)
        if b in keep_probs:
            kept[b] = probs
        outs.append(linear(probs.view(-1, heads * keys), fold.n[b], fold.wo_bias))
    return torch.stack(outs), kept


class SDPAProcessor(AttentionProcessor):
    """Fast default: :func:`fast_attention` (``torch.nn.functional.scaled_dot_product_attention``,
    or explicit matmuls for short key axes, where they are faster on a CPU)."""

    #: :meth:`Attention.forward` may hand this processor a :class:`FoldedText` (see :meth:`folded`).
    takes_folded = True

    def __call__(self, site, q, k, v, key_mask, dropout_p):
        return fast_attention(q, k, v, key_mask, dropout_p)

    def folded(self, site: SiteInfo, x: torch.Tensor, fold: FoldedText) -> torch.Tensor:
        """Cross-attention through the folded text: ``x (B, Lq, w)`` -> ``(B, Lq, w)`` after ``Wo``."""
        return folded_cross_attention(x, fold)[0]


class EagerProcessor(AttentionProcessor):
    """Explicit softmax; exposes the probabilities to an optional controller.

    Parameters
    ----------
    controller : callable, optional
        ``controller(site, probs) -> probs | None`` called with the post-softmax probabilities
        (flat shape :attr:`SiteInfo.probs_shape`). A returned tensor of the same shape replaces
        them (SALAD supplement B: ``Denoise(z_t, t, c){M <- M_hat}``, values still computed from
        the current prompt); ``None`` keeps them. Attention dropout, if any, is applied after the
        controller, so recorded maps are the clean ones.
    """

    def __init__(self, controller: Controller | None = None) -> None:
        self.controller = controller

    def __call__(self, site, q, k, v, key_mask, dropout_p):
        probs = attention_probs(q, k, key_mask)
        if self.controller is not None:
            new = self.controller(site, probs)
            if new is not None:
                if tuple(new.shape) != tuple(probs.shape):
                    raise ValueError(
                        f"controller returned probs of shape {tuple(new.shape)} at site {site.name!r}; "
                        f"expected {tuple(probs.shape)}"
                    )
                probs = new.to(v.dtype)
        if dropout_p > 0.0:
            probs = F.dropout(probs, p=dropout_p, training=True)
        return torch.matmul(probs, v)

    def __repr__(self) -> str:
        return f"EagerProcessor(controller={self.controller!r})"


_DEFAULT_PROCESSOR = SDPAProcessor()


class Attention(nn.Module):
    """Multi-head attention site with official parameter names ``Wq, Wk, Wv, Wo`` (all with bias).

    Parameters
    ----------
    width : int
        Model width ``w`` (queries, keys and values all have ``w`` channels).
    heads : int
        Number of heads ``H`` (``w`` divisible by ``H``).
    dropout : float
        Dropout on the attention probabilities during training (official: 0.1).
    kind : str
        One of :data:`SITE_KINDS`.
    """

    def __init__(self, width: int, heads: int, dropout: float, kind: str) -> None:
        super().__init__()
        if kind not in SITE_KINDS:
            raise ValueError(f"kind must be one of {SITE_KINDS}, got {kind!r}")
        if width % heads:
            raise ValueError(f"width ({width}) must be divisible by heads ({heads})")
        self.width, self.heads, self.dropout, self.kind = width, heads, dropout, kind
        self.Wq = Linear(width, width)
        self.Wk = Linear(width, width)
        self.Wv = Linear(width, width)
        self.Wo = Linear(width, width)
        self.processor: AttentionProcessor = _DEFAULT_PROCESSOR
        # set by the owning model (bind_site) so that the name travels with the module
        self.site_name = kind
        self.layer = 0
        self.num_layers = 1

    def bind_site(self, name: str, layer: int, num_layers: int) -> None:
        """Record this module's stable site name and layer index (called by the owner)."""
        self.site_name, self.layer, self.num_layers = name, layer, num_layers

    def set_processor(self, processor: AttentionProcessor) -> None:
        if not callable(processor):
            raise TypeError(f"processor for site {self.site_name!r} must be callable, got {processor!r}")
        self.processor = processor

    def qkv_parameters(self) -> tuple[torch.Tensor, torch.Tensor]:
        """``Wq, Wk, Wv`` stacked: weight ``(3w, w)`` and bias ``(3w,)``, for one product instead of three.

        Without gradients the stack is cached and rebuilt when any of the six tensors changes
        (identity, storage or in-place version: optimiser steps, ``load_state_dict``, ``.to()``);
        with gradients it is a fresh ``torch.cat`` the gradients flow through.
        """
        params = (self.Wq.weight, self.Wk.weight, self.Wv.weight, self.Wq.bias, self.Wk.bias, self.Wv.bias)
        if torch.is_grad_enabled() and any(prm.requires_grad for prm in params):
            return torch.cat(params[:3]), torch.cat(params[3:])
        signature = tuple((id(prm), prm.data_ptr(), prm._version, prm.dtype) for prm in params)
        cached = self.__dict__.get("_qkv_cache")
        if cached is None or cached[0] != signature:
            # a normal tensor even under inference_mode: gradients may later flow through it to the input
            with torch.inference_mode(False), torch.no_grad():
                cached = (signature, torch.cat(params[:3]), torch.cat(params[3:]))
            self.__dict__["_qkv_cache"] = cached           # plain attribute: not a buffer, not in state_dict
        return cached[1], cached[2]

    def attend_within(self, x: torch.Tensor, axis: int, *, key_mask: torch.Tensor | None = None,
                      dims: CallDims) -> torch.Tensor:
        """Self-attention of the tokens of ``x`` ``(B, N', P, w)`` along ``axis`` -> ``(B, N', P, w)``.

        ``axis=1``: every part is a sequence over frames (temporal; processor rows ordered
        (batch, part), ``key_mask (B*P, N')``); ``axis=2``: every frame is a sequence over parts
        (skeletal; rows ordered (batch, frame)). Same values as :meth:`forward` on the permuted
        tokens, computed without permuting the input: Q, K and V come from one product of the
        stacked weights (:meth:`qkv_parameters`) in the input's layout and are rearranged into the
        processor's per-head layout by one copy.
        """
        if axis not in (1, 2):
            raise ValueError(f"axis must be 1 (frames) or 2 (parts), got {axis}")
        b, n, p, w = x.shape
        heads = self.heads
        weight, bias = self.qkv_parameters()
        qkv = linear(x, weight, bias).view(b, n, p, 3, heads, w // heads)
        if axis == 1:      # (3, B, P, H, N', dh) -> rows (batch, part)
            qkv = qkv.permute(3, 0, 2, 4, 1, 5).reshape(3, b * p, heads, n, w // heads)
        else:              # (3, B, N', H, P, dh) -> rows (batch, frame)
            qkv = qkv.permute(3, 0, 1, 4, 2, 5).reshape(3, b * n, heads, p, w // heads)
        q, k, v = qkv.unbind(0)
        out = self.processor(self._site(dims, 0), q, k, v, key_mask, self.dropout if self.training else 0.0)
        if axis == 1:      # (B*P, H, N', dh) -> (B, N', P, H, dh)
            out = out.view(b, p, heads, n, -1).permute(0, 3, 1, 2, 4)
        else:              # (B*N', H, P, dh) -> (B, N', P, H, dh)
            out = out.view(b, n, heads, p, -1).permute(0, 1, 3, 2, 4)
        return self.Wo(out.reshape(b, n, p, w))

    def _site(self, dims: CallDims, tokens: int) -> SiteInfo:
        """This site's :class:`SiteInfo` for one call (``tokens``: key length of cross/sentence sites)."""
        return SiteInfo(self.site_name, self.kind, self.layer, self.num_layers, self.heads,
                        dims.batch, dims.frames, dims.parts, tokens)

    def _split(self, x: torch.Tensor) -> torch.Tensor:
        # (R, L, w) -> (R, H, L, dh)
        r, length, _ = x.shape
        return x.view(r, length, self.heads, self.width // self.heads).transpose(1, 2)

    def project_kv(self, context: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-head keys and values ``(R, H, Lk, dh)`` of ``context`` ``(R, Lk, w)``."""
        return self._split(self.Wk(context)), self._split(self.Wv(context))

    def fold_text(self, k: torch.Tensor, v: torch.Tensor, key_mask: torch.Tensor | None) -> FoldedText | None:
        """Fold precomputed text keys/values ``(B, H, W, dh)`` into ``Wq`` and ``Wo`` (see
        :class:`FoldedText`), or None where that would not pay: a key mask that is not a prefix
        mask per row, or ``H * W_b >= w`` keys for some row (the folded products would be larger).
        Built without gradients; the caller keeps it as long as the keys, values and weights."""
        heads, width = self.heads, self.width
        dh = width // heads
        keys = [k.shape[2]] * k.shape[0] if key_mask is None else prefix_lengths(key_mask)
        if keys is None or not fold_pays(heads, width, keys):
            return None
        scale = 1.0 / math.sqrt(dh)
        with torch.no_grad():
            wq = self.Wq.weight.view(heads, dh, width)                       # rows of head h
            bq = self.Wq.bias.view(heads, dh)
            wo = self.Wo.weight.view(width, heads, dh)                       # columns of head h
            a, c, n = [], [], []
            for b, nk in enumerate(keys):
                kb, vb = k[b, :, :nk], v[b, :, :nk]                           # (H, W_b, dh)
                a.append((torch.einsum("hjd,hdc->hjc", kb, wq) * scale).reshape(heads * nk, width))
                c.append((torch.einsum("hjd,hd->hj", kb, bq) * scale).reshape(heads * nk))
                n.append(torch.einsum("chd,hjd->chj", wo, vb).reshape(width, heads * nk).contiguous())
        return FoldedText(tuple(a), tuple(c), tuple(n), tuple(keys), k, v, self.Wo.weight, self.Wo.bias)

    def forward(self, query: torch.Tensor, context: torch.Tensor | None = None, *,
                key_mask: torch.Tensor | None = None,
                kv: tuple[torch.Tensor, torch.Tensor] | None = None,
                fold: FoldedText | None = None,
                dims: CallDims) -> torch.Tensor:
        """Attend ``query`` ``(R, Lq, w)`` to ``context`` (itself if None) -> ``(R, Lq, w)``.

        ``kv`` (precomputed :meth:`project_kv` output) replaces ``context`` when given, so the
        text keys/values can be computed once per sampling call. ``key_mask`` ``(R, Lk)`` bool,
        True = valid key. ``fold`` (:meth:`fold_text` of that ``kv`` and mask) is used when the
        processor takes it (``takes_folded``) and no gradients are recorded.
        """
        if (fold is not None and getattr(self.processor, "takes_folded", False) and not self.training
                and not torch.is_grad_enabled()):
            return self.processor.folded(self._site(dims, fold.tokens), query, fold)
        q = self._split(self.Wq(query))
        if kv is None:
            k, v = self.project_kv(query if context is None else context)
        else:
            k, v = kv
        site = self._site(dims, k.shape[2] if self.kind in ("cross", "sentence") else 0)
        out = self.processor(site, q, k, v, key_mask, self.dropout if self.training else 0.0)
        r, _, lq, _ = out.shape
        return self.Wo(out.transpose(1, 2).reshape(r, lq, self.width))


ProcessorSpec = Union[AttentionProcessor, Mapping[str, AttentionProcessor]]


class AttnProcessorMixin:
    """diffusers-style processor management for a module exposing ``attention_sites``.

    The owner implements ``attention_sites -> dict[name, Attention]`` in execution order.
    """

    @property
    def attention_sites(self) -> dict[str, Attention]:  # pragma: no cover - provided by the owner
        raise NotImplementedError

    @property
    def attn_processors(self) -> dict[str, AttentionProcessor]:
        """The processor of every site, by site name (execution order)."""
        return {name: mod.processor for name, mod in self.attention_sites.items()}

    def set_attn_processor(self, processor: ProcessorSpec) -> None:
        """Install one processor on every site, or a ``{site name: processor}`` dict.

        A dict may name a subset of the sites; the others keep their processor. Unknown names
        raise ``KeyError`` listing the valid ones.
        """
        sites = self.attention_sites
        if isinstance(processor, Mapping):
            unknown = sorted(set(processor) - set(sites))
            if unknown:
                raise KeyError(f"unknown attention site(s) {unknown}; valid sites: {list(sites)}")
            for name, proc in processor.items():
                sites[name].set_processor(proc)
        else:
            for mod in sites.values():
                mod.set_processor(processor)


@contextmanager
def use_processors(model: AttnProcessorMixin, processors: ProcessorSpec) -> Iterator[AttnProcessorMixin]:
    """Install ``processors`` on ``model`` for the ``with`` block; restore the previous ones on exit.

    The previous processors are restored even if the block raises.

    Examples
    --------
    >>> with use_processors(denoiser, EagerProcessor(recorder)):   # doctest: +SKIP
    ...     latents = denoise(denoiser, scheduler, cond, uncond, noise, mask)
    """
    saved = model.attn_processors
    try:
        model.set_attn_processor(processors)
        yield model
    finally:
        model.set_attn_processor(saved)
