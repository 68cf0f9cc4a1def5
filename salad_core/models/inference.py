"""Inference caches of the denoiser: work that depends only on the weights and on the text or the
timestep, done once per sampling call instead of once per step.

The architecture (:mod:`salad_core.models.denoiser`, :mod:`salad_core.models.attention`) says what
is computed; this module keeps what sampling can reuse across steps, and the CPU kernels
(:mod:`salad_core.models.kernels`) say how the products run. With gradients enabled nothing is
cached, so training back-propagates through every projection.

* :class:`TextContext`: the text conditioning of a batch, prepared once: per layer the text keys and
  values (``word_emb``, ``cross_tgt_norm``, ``Wk``, ``Wv``) and, where it pays, the cross-attention
  folded into ``Wq``/``Wo`` (:class:`~salad_core.models.kernels.FoldedText`);
* :class:`TimestepTable`: per timestep the timestep embedding and every layer's FiLM
  ``(scale, shift)``, all layers in one product of the stacked FiLM weights;
* :func:`stacked_qkv`: ``Wq``, ``Wk``, ``Wv`` of a self-attention site stacked for one product;
* :func:`weight_signature`: the one definition of "the weights a cache was built from": every
  cache is rebuilt when its weights change (optimiser steps, ``load_state_dict`` also with
  ``assign=True``, ``.to()``).

:func:`text_inputs` and :func:`timestep_inputs` are what :meth:`Denoiser.forward
<salad_core.models.denoiser.Denoiser.forward>` asks for: cached when sampling, computed afresh when
training.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Iterable, Sequence

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.models.kernels import FoldedText, fold_text

if TYPE_CHECKING:  # pragma: no cover - imports for annotations only
    from salad_core.models.attention import Attention
    from salad_core.models.denoiser import Denoiser

__all__ = [
    "weight_signature",
    "stacked_qkv",
    "TextContext",
    "TimestepTable",
    "TIMESTEP_CACHE",
    "text_inputs",
    "timestep_inputs",
]

#: Most timesteps a :class:`TimestepTable` keeps (about 40 KB each for the paper model); the table
#: starts over when a schedule would overflow it.
TIMESTEP_CACHE = 1024


def weight_signature(tensors: Iterable[torch.Tensor], owner: object = None) -> tuple:
    """What a cache built from ``tensors`` depends on: the owner's identity and, per tensor, its
    identity, storage, in-place version counter and dtype.

    In-place updates bump the version counter (PyTorch's fused optimisers do **not**: ``AdamW(fused=True)``
    writes the weights in one kernel without bumping it, so a loop stepping one must call
    ``torch.autograd.graph.increment_version`` on its parameters, as
    :func:`salad_core.train.common.optimizer_step` does), ``load_state_dict(assign=True)`` replaces the
    tensors, ``.to()`` moves their storage. The version
    counter is PyTorch's private ``Tensor._version``: no public API tells whether a tensor was changed
    in place, and comparing the weights' values at every call would cost more than the caches save.
    This is the one place salad reads it.
    """
    return (id(owner),) + tuple((id(t), t.data_ptr(), t._version, t.dtype) for t in tensors)


def _weight_and_bias(modules: Sequence[nn.Module]) -> list[torch.Tensor]:
    """``weight`` and ``bias`` (when present) of Linear / LayerNorm modules, in order.

    Read directly: walking ``.parameters()`` of 16 modules at every forward cost about 0.2 ms of
    Python per call of the paper model."""
    return [t for mod in modules for t in (mod.weight, mod.bias) if t is not None]


# ======================================================================== stacked Q, K, V
def stacked_qkv(attn: "Attention") -> tuple[torch.Tensor, torch.Tensor]:
    """``Wq, Wk, Wv`` of ``attn`` stacked: weight ``(3w, w)`` and bias ``(3w,)``, for one product
    instead of three.

    Without gradients the stack is cached on the module (a plain attribute, not a buffer: never in
    the state dict) and rebuilt when any of the six tensors changes (:func:`weight_signature`); with
    gradients it is a fresh ``torch.cat`` the gradients flow through.
    """
    params = (attn.Wq.weight, attn.Wk.weight, attn.Wv.weight, attn.Wq.bias, attn.Wk.bias, attn.Wv.bias)
    if torch.is_grad_enabled() and any(prm.requires_grad for prm in params):
        return torch.cat(params[:3]), torch.cat(params[3:])
    signature = weight_signature(params)
    cached = attn.__dict__.get("_qkv_cache")
    if cached is None or cached[0] != signature:
        # a normal tensor even under inference_mode: gradients may later flow through it to the input
        with torch.inference_mode(False), torch.no_grad():
            cached = (signature, torch.cat(params[:3]), torch.cat(params[3:]))
        attn.__dict__["_qkv_cache"] = cached
    return cached[1], cached[2]


# =========================================================================== text context
class TextContext:
    """Text conditioning of a batch, prepared once and reused for every denoising step.

    Holds the raw token features and mask; the denoiser-dependent work (``word_emb`` projection,
    each layer's ``cross_tgt_norm`` + key/value projections, :meth:`Denoiser.text_kv
    <salad_core.models.denoiser.Denoiser.text_kv>`) is cached lazily on first use when gradients are
    disabled, and recomputed if the denoiser's weights change (:func:`weight_signature`). With
    gradients enabled nothing is cached, so training back-propagates into ``word_emb``.

    Parameters
    ----------
    text : torch.Tensor
        ``(B, W, C)`` token features.
    mask : torch.Tensor
        ``(B, W)`` bool, True = valid token; every row needs at least one valid token.
    pooled : torch.Tensor, optional
        ``(B, C)`` sentence feature, used only by the "w/o CrossAttn" ablation; defaults to the
        mean of the valid token features.
    """

    def __init__(self, text: torch.Tensor, mask: torch.Tensor, pooled: torch.Tensor | None = None) -> None:
        if text.dim() != 3:
            raise ValueError(f"text must be (B, W, C) token features, got shape {tuple(text.shape)}")
        if mask.shape != text.shape[:2]:
            raise ValueError(f"text_mask must be (B, W) = {tuple(text.shape[:2])}, got {tuple(mask.shape)}")
        mask = mask.to(device=text.device, dtype=torch.bool)
        if not bool(mask.any(dim=1).all()):
            bad = (~mask.any(dim=1)).nonzero().flatten().tolist()
            raise ValueError(f"text_mask rows {bad} have no valid token; every prompt needs at least one "
                             "(the empty prompt still has its start/end tokens)")
        if pooled is None:
            m = mask.to(text.dtype)[..., None]
            pooled = (text * m).sum(1) / m.sum(1)
        elif pooled.shape != (text.shape[0], text.shape[2]):
            raise ValueError(f"pooled must be (B, C) = {(text.shape[0], text.shape[2])}, got {tuple(pooled.shape)}")
        self.text, self.mask, self.pooled = text, mask, pooled
        self._signature: tuple | None = None
        self._cache: list[tuple[torch.Tensor, torch.Tensor]] | None = None
        self._fold_signature: tuple | None = None
        self._folds: list | None = None

    @property
    def batch_size(self) -> int:
        return self.text.shape[0]

    @property
    def num_tokens(self) -> int:
        return self.text.shape[1]

    @property
    def text_dim(self) -> int:
        return self.text.shape[2]

    @classmethod
    def concat(cls, contexts: Sequence["TextContext"]) -> "TextContext":
        """Stack contexts along the batch (e.g. ``[uncond, cond]`` for batched CFG).

        Different token counts are padded with masked zero tokens. The cache is not carried over.
        """
        if not contexts:
            raise ValueError("contexts must be a non-empty sequence of TextContext")
        width = max(c.num_tokens for c in contexts)
        texts, masks = [], []
        for c in contexts:
            pad = width - c.num_tokens
            texts.append(F.pad(c.text, (0, 0, 0, pad)))
            masks.append(F.pad(c.mask, (0, pad), value=False))
        return cls(torch.cat(texts), torch.cat(masks), torch.cat([c.pooled for c in contexts]))

    def repeat(self, batch: int) -> "TextContext":
        """A batch-1 context repeated to ``batch`` rows (other sizes must already match)."""
        if self.batch_size == batch:
            return self
        if self.batch_size != 1:
            raise ValueError(f"cannot repeat a text context of batch {self.batch_size} to batch {batch}; "
                             "only batch 1 broadcasts")
        return TextContext(self.text.expand(batch, -1, -1), self.mask.expand(batch, -1),
                           self.pooled.expand(batch, -1))

    def layer_kv(self, denoiser: "Denoiser") -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Per-layer text keys and values ``(B, H, W, dh)`` (``W = 1`` for sentence tokens)."""
        if torch.is_grad_enabled():
            return denoiser.text_kv(self)
        sig = weight_signature(_text_weights(denoiser), denoiser)
        if self._cache is None or self._signature != sig:
            self._cache = denoiser.text_kv(self)
            self._signature = sig
        return self._cache

    def layer_folds(self, denoiser: "Denoiser") -> list[FoldedText | None]:
        """Per layer the cross-attention's :class:`~salad_core.models.kernels.FoldedText` of these
        text keys and values (or None where folding does not pay), cached like :meth:`layer_kv` and
        also rebuilt when the cross-attention ``Wq``/``Wo`` change. Only without gradients."""
        if torch.is_grad_enabled():
            raise RuntimeError("folded text is for sampling without gradients")
        return self._layer_folds(denoiser, self.layer_kv(denoiser))

    def _layer_folds(self, denoiser: "Denoiser", kv: list[tuple[torch.Tensor, torch.Tensor]]) -> list:
        """:meth:`layer_folds` given ``kv``, the :meth:`layer_kv` just returned (the denoiser's forward
        has it already, so the text signature is not checked twice per call)."""
        sig = (self._signature, weight_signature(_fold_weights(denoiser), denoiser))
        if self._folds is None or self._fold_signature != sig:
            mask = None if bool(self.mask.all()) else self.mask
            self._folds = [fold_text(k, v, mask, layer.cross_attn.Wq, layer.cross_attn.Wo, layer.cross_attn.heads)
                           for layer, (k, v) in zip(denoiser.transformer.layers, kv)]
            self._fold_signature = sig
        return self._folds

    def clear_cache(self) -> None:
        """Drop the cached projections (they are rebuilt on next use)."""
        self._cache, self._signature = None, None
        self._folds, self._fold_signature = None, None


def _text_weights(denoiser: "Denoiser") -> list[torch.Tensor]:
    """The weights the text keys and values depend on: ``word_emb`` and each layer's
    ``cross_tgt_norm``, ``Wk``, ``Wv``."""
    return _weight_and_bias([denoiser.word_emb] + [
        mod for layer in denoiser.transformer.layers
        for mod in (layer.cross_tgt_norm, layer.cross_attn.Wk, layer.cross_attn.Wv)
    ])


def _fold_weights(denoiser: "Denoiser") -> list[torch.Tensor]:
    """The projections the folded text is folded into: each layer's cross-attention ``Wq``, ``Wo``."""
    return _weight_and_bias([mod for layer in denoiser.transformer.layers
                             for mod in (layer.cross_attn.Wq, layer.cross_attn.Wo)])


def text_inputs(denoiser: "Denoiser", ctx: TextContext
                ) -> tuple[list[tuple[torch.Tensor, torch.Tensor]], list[FoldedText | None] | None]:
    """Per layer the text keys/values of ``ctx`` and, when sampling through processors that take
    it, the folded text (else None): what :meth:`Denoiser.forward` needs of the text."""
    kv = ctx.layer_kv(denoiser)
    if (denoiser.config.cross_attention and not torch.is_grad_enabled() and any(
            getattr(layer.cross_attn.processor, "takes_folded", False) for layer in denoiser.transformer.layers)):
        return kv, ctx._layer_folds(denoiser, kv)
    return kv, None


# ========================================================================= timestep table
class TimestepTable:
    """Timestep embedding and every layer's FiLM ``(scale, shift)`` per timestep, cached.

    The FiLMs depend on the timestep only, so with gradients disabled each distinct timestep is
    computed once (all layers' FiLMs in one product of the stacked FiLM weights, which costs the
    same as one layer's: reading the 2.6 M FiLM weights of the paper model is what takes the time)
    and kept until the FiLM weights change (:func:`weight_signature`). A denoiser keeps one table
    (:func:`timestep_table`); at most :data:`TIMESTEP_CACHE` timesteps, then it starts over.
    """

    def __init__(self) -> None:
        self._signature: tuple | None = None
        self._rows: dict[float, torch.Tensor] = {}      # timestep -> (w + L * 4 * 2w,) [temb, films]
        self._weight: torch.Tensor | None = None         # (L * 4 * 2w, w) every FiLM's Linear stacked
        self._bias: torch.Tensor | None = None           # (L * 4 * 2w,)

    def rows(self, denoiser: "Denoiser") -> dict[float, torch.Tensor]:
        """The valid table (emptied and its stacked weights rebuilt if the weights changed)."""
        films = [film.linear[1] for layer in denoiser.transformer.layers for film in layer.films]
        sig = weight_signature([*denoiser.timestep_emb.parameters()] + _weight_and_bias(films), denoiser)
        if self._signature != sig:
            self._rows = {}
            self._signature = sig
            self._weight = torch.cat([lin.weight for lin in films])
            self._bias = torch.cat([lin.bias for lin in films])
        return self._rows

    def fill(self, denoiser: "Denoiser", timesteps: torch.Tensor) -> list[float]:
        """Compute the timesteps of ``timesteps`` ``(S,)`` not in the table yet, in one product;
        returns the keys of ``timesteps`` in order."""
        table = self.rows(denoiser)
        t = timesteps.detach().reshape(-1)
        keys = [float(v) for v in t.tolist()]
        first: dict[float, int] = {}
        for i, key in enumerate(keys):
            first.setdefault(key, i)
        missing = [i for key, i in first.items() if key not in table]
        if missing and len(table) + len(missing) > TIMESTEP_CACHE:
            table.clear()                                   # start over, with all of this call's timesteps
            missing = list(first.values())
        if missing:
            t = t[missing]
            temb = denoiser.timestep_emb(t)                                        # (S, w)
            films = F.linear(F.silu(temb), self._weight, self._bias)               # FiLM: SiLU -> Linear
            for i, row in zip(missing, torch.cat([temb, films], dim=1)):
                table[keys[i]] = row
        return keys

    def conditioning(self, denoiser: "Denoiser", timesteps: torch.Tensor) -> tuple[torch.Tensor, list]:
        """``temb (R, w)`` and per layer four ``(scale, shift)``, each ``(R, 1, 1, w)``, for
        ``timesteps (R,)``, from the table."""
        w, layers = denoiser.config.width, denoiser.config.layers
        keys = self.fill(denoiser, timesteps)
        rows = torch.stack([self._rows[t] for t in keys])                                 # (R, w + L*4*2w)
        temb = rows[:, :w]
        per = rows[:, w:].view(len(keys), layers, 4, 2, w)[:, :, :, :, None, None, :]   # (R, L, 4, 2, 1, 1, w)
        films = [tuple((per[:, i, k, 0], per[:, i, k, 1]) for k in range(4)) for i in range(layers)]
        return temb, films


def timestep_table(denoiser: "Denoiser") -> TimestepTable:
    """The denoiser's :class:`TimestepTable` (a plain attribute: never in the state dict)."""
    table = denoiser.__dict__.get("_timestep_table")
    if table is None:
        table = denoiser.__dict__["_timestep_table"] = TimestepTable()
    return table


def timestep_inputs(denoiser: "Denoiser", timesteps: torch.Tensor, batch: int
                    ) -> tuple[torch.Tensor, list | None]:
    """The timestep embedding and, when sampling with FiLM, every layer's FiLMs from the table (else
    None: each layer computes its FiLMs from the embedding): what :meth:`Denoiser.forward` needs
    of the timestep. ``timesteps`` ``(1,)`` or ``(B,)``; the embedding is ``(1 or B, w)`` when
    sampling (one row broadcast over the batch), ``(B, w)`` when training."""
    if denoiser.config.film and not torch.is_grad_enabled():
        return timestep_table(denoiser).conditioning(denoiser, timesteps)
    return denoiser.timestep_emb(timesteps.expand(batch)), None
