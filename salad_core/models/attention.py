"""Named attention sites with swappable processors (the contract capture and editing build on).

Every attention module of the denoiser is a *site* with a stable name, e.g.
``"layers.2.cross"``. The module owns the projections ``Wq, Wk, Wv, Wo`` (official key names)
and hands the core computation ``softmax(q k^T / sqrt(d)) v`` to a swappable *processor*, as in
diffusers' ``attention_processor.py``:

* :class:`SDPAProcessor` (default) computes it by the CPU kernel
  :func:`~salad_core.models.kernels.fast_attention` (explicit matmuls for short key axes, SDPA for
  long ones; see :mod:`salad_core.models.kernels`), and takes the cross-attention folded into the
  projections when sampling (:class:`~salad_core.models.kernels.FoldedText`);
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

from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Optional, Union

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.models.gemm import Linear, linear
from salad_core.models.inference import stacked_qkv
from salad_core.models.kernels import FoldedText, attention_probs, fast_attention, folded_cross_attention
from salad_core.models.kernels import fold_pays  # noqa: F401  (salad_core.bench imports it from here)

__all__ = [
    "SITE_KINDS",
    "CallDims",
    "SiteInfo",
    "Controller",
    "AttentionProcessor",
    "SDPAProcessor",
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


class SDPAProcessor(AttentionProcessor):
    """Fast default: :func:`~salad_core.models.kernels.fast_attention` (``scaled_dot_product_attention``,
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

    def attend_within(self, x: torch.Tensor, axis: int, *, key_mask: torch.Tensor | None = None,
                      dims: CallDims) -> torch.Tensor:
        """Self-attention of the tokens of ``x`` ``(B, N', P, w)`` along ``axis`` -> ``(B, N', P, w)``.

        ``axis=1``: every part is a sequence over frames (temporal; processor rows ordered
        (batch, part), ``key_mask (B*P, N')``); ``axis=2``: every frame is a sequence over parts
        (skeletal; rows ordered (batch, frame)). Same values as :meth:`forward` on the permuted
        tokens, computed without permuting the input: Q, K and V come from one product of the
        stacked weights (:func:`~salad_core.models.inference.stacked_qkv`, cached when sampling) in
        the input's layout and are rearranged into the processor's per-head layout by one copy.
        """
        if axis not in (1, 2):
            raise ValueError(f"axis must be 1 (frames) or 2 (parts), got {axis}")
        b, n, p, w = x.shape
        heads = self.heads
        weight, bias = stacked_qkv(self)
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

    def forward(self, query: torch.Tensor, context: torch.Tensor | None = None, *,
                key_mask: torch.Tensor | None = None,
                kv: tuple[torch.Tensor, torch.Tensor] | None = None,
                fold: FoldedText | None = None,
                dims: CallDims) -> torch.Tensor:
        """Attend ``query`` ``(R, Lq, w)`` to ``context`` (itself if None) -> ``(R, Lq, w)``.

        ``kv`` (precomputed :meth:`project_kv` output) replaces ``context`` when given, so the
        text keys/values can be computed once per sampling call. ``key_mask`` ``(R, Lk)`` bool,
        True = valid key. ``fold`` (:func:`~salad_core.models.kernels.fold_text` of that ``kv`` and
        mask) is used when the processor takes it (``takes_folded``) and no gradients are recorded.
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
