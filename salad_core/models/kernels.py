"""CPU attention kernels of the denoiser: the speed work of ``softmax(q k^T / sqrt(d)) v``.

The attention modules (:mod:`salad_core.models.attention`) say *what* is computed; the functions
here say *how*, by the faster route on a CPU for the shapes at hand (each docstring gives the
measurement behind its choice):

* :func:`softmax_last`: exp / sum for short rows, PyTorch's kernel for long ones;
* :func:`fast_attention` / :func:`attention_with_probs`: explicit matmuls for short key axes
  (with their probabilities, which capture reuses), SDPA for long ones; trailing padding keys
  dropped (:func:`trim_masked_keys`); prefix masks of a few row runs attended run by run instead
  of masked (:func:`prefix_key_runs`);
* :class:`FoldedText` / :func:`fold_text` / :func:`folded_cross_attention`: the text side of a
  cross-attention site folded into its query and output projections, once per sampling call.

Every route gives the same values as the plain formula up to float rounding (tests compare them).
"""
from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.models.gemm import linear

__all__ = [
    "VECTOR_ROW",
    "softmax_last",
    "attention_probs",
    "SHORT_KEYS",
    "explicit_route",
    "sdpa_attention_dropout",
    "trim_masked_keys",
    "MAX_KEY_RUNS",
    "prefix_key_runs",
    "prefix_lengths",
    "fast_attention",
    "attention_with_probs",
    "FoldedText",
    "fold_pays",
    "fold_text",
    "folded_cross_attention",
]

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


_SDPA_DROPOUT = contextvars.ContextVar("salad_sdpa_attention_dropout", default=False)


@contextlib.contextmanager
def sdpa_attention_dropout(enabled: bool = True) -> Iterator[None]:
    """Within the block, attention with dropout (training) goes to SDPA's own dropout on every key
    length, as before the explicit training route (``bench/bench_attention_dropout.py``'s reference
    side, or to reproduce an older run's numerics)."""
    token = _SDPA_DROPOUT.set(bool(enabled))
    try:
        yield
    finally:
        _SDPA_DROPOUT.reset(token)


def explicit_route(num_keys: int, dropout_p: float) -> bool:
    """Whether :func:`fast_attention` computes ``num_keys`` keys with explicit probabilities
    (:func:`attention_probs` then a matmul) rather than SDPA.

    With attention dropout (training) too: PyTorch's CPU SDPA with ``dropout_p > 0`` falls back to its
    unfused math path, and a denoiser training step (``configs/salad-0.3/denoiser.json``, batch 32, bf16
    autocast, one thread) took 2.00 s that way against 1.67 s with explicit probabilities dropped out by
    ``F.dropout`` (``bench/bench_attention_dropout.py``). Inside :func:`sdpa_attention_dropout` training
    attention goes to SDPA as before."""
    return num_keys < SHORT_KEYS and (dropout_p == 0.0 or not _SDPA_DROPOUT.get())


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
    plain sampling's by construction. With ``dropout_p > 0`` (training) the explicit route mixes the values
    with dropped-out probabilities and returns the probabilities before dropout."""
    if key_mask is not None:
        runs = prefix_key_runs(key_mask) if dropout_p == 0.0 else None
        if runs is not None:
            keep = max(keys for _, _, keys in runs)
            if explicit_route(keep, dropout_p):
                return _attend_runs(q, k[..., :keep, :], v[..., :keep, :], runs, need_probs)
        k, v, key_mask = trim_masked_keys(k, v, key_mask)
    if explicit_route(k.shape[-2], dropout_p):
        probs = attention_probs(q, k, key_mask)
        mixed = F.dropout(probs, p=dropout_p, training=True) if dropout_p > 0.0 else probs
        return torch.matmul(mixed, v), probs
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


def fold_text(k: torch.Tensor, v: torch.Tensor, key_mask: torch.Tensor | None, query: nn.Linear,
              output: nn.Linear, heads: int) -> FoldedText | None:
    """Fold precomputed text keys/values ``(B, H, W, dh)`` of a cross-attention site into its query
    and output projections ``query`` (``Wq``) and ``output`` (``Wo``) (see :class:`FoldedText`), or
    None where that would not pay: a key mask that is not a prefix mask per row, or ``H * W_b >= w``
    keys for some row (the folded products would be larger). Built without gradients; the caller
    keeps it as long as the keys, values and weights."""
    width = query.weight.shape[1]
    dh = width // heads
    keys = [k.shape[2]] * k.shape[0] if key_mask is None else prefix_lengths(key_mask)
    if keys is None or not fold_pays(heads, width, keys):
        return None
    scale = 1.0 / math.sqrt(dh)
    with torch.no_grad():
        wq = query.weight.view(heads, dh, width)                         # rows of head h
        bq = query.bias.view(heads, dh)
        wo = output.weight.view(width, heads, dh)                        # columns of head h
        a, c, n = [], [], []
        for b, nk in enumerate(keys):
            kb, vb = k[b, :, :nk], v[b, :, :nk]                           # (H, W_b, dh)
            a.append((torch.einsum("hjd,hdc->hjc", kb, wq) * scale).reshape(heads * nk, width))
            c.append((torch.einsum("hjd,hd->hj", kb, bq) * scale).reshape(heads * nk))
            n.append(torch.einsum("chd,hjd->chj", wo, vb).reshape(width, heads * nk).contiguous())
    return FoldedText(tuple(a), tuple(c), tuple(n), tuple(keys), k, v, output.weight, output.bias)


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
