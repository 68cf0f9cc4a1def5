"""Record the attention of the denoiser while it samples: :class:`AttentionStore` and its result,
:class:`AttentionMaps`.

What is recorded (SALAD §4.5, Fig. 6; official ``visualize_attn.ipynb``): the post-softmax
cross-attention probabilities of the *conditional* rows of the classifier-free-guidance batch, at
every cross site ``layers.{i}.cross`` and every step. A site's probabilities have named axes
``(B, H, N', P, W)`` (query ``t * P + j`` is frame ``t``, body part ``j``; see
:mod:`salad_core.models.attention`).

Two ways to keep them (:class:`CaptureConfig`):

* ``mode="mean"`` (default): a streaming sum per (step bin, layer), summed over the chosen heads,
  in float32. Memory does not grow with the number of steps: ``step_bins x L x B x N' x P x W``.
  The default view averages everything held (steps, layers, heads), which is the official
  figure; :meth:`AttentionMaps.select` narrows it to step windows that fall on bin edges
  (multiples of ``1 / step_bins``) and to layers.
* ``mode="full"``: every (step, layer, head) as ``(S, L, H, N', P, W)`` float16 on the CPU, for
  any selection, per-head views, or animation over steps.

Self-attention (temporal ``(P, N', N')`` and skeletal ``(N', P, P)`` maps, means over the same
steps, layers and heads) is recorded only on request (``self_attention=True``) because it costs
more than the cross maps.

The store is installed by :func:`capture_cross_attention`, a context manager that puts a
:class:`~salad_core.attention.processor.HookedProcessor` on the recorded sites and restores the
previous processors on exit, also after an error. The output of every row is still computed by
the fast attention kernel, so capturing never changes the generated motion.
"""
from __future__ import annotations

import logging
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from salad_core.data.texts import split_words
from salad_core.models.attention import SiteInfo, use_processors
from salad_core.skeleton import PART_NAMES, get_skeleton

from .processor import HookedProcessor

__all__ = [
    "CaptureConfig",
    "TokenInfo",
    "AttentionStore",
    "AttentionMaps",
    "capture_cross_attention",
    "attention_store",
    "store_sites",
    "as_capture_config",
    "CAPTURE_MODES",
]

log = logging.getLogger(__name__)

#: Storage modes of :class:`CaptureConfig`.
CAPTURE_MODES: tuple[str, ...] = ("mean", "full")
_FULL_DTYPES = {"float16": torch.float16, "bfloat16": torch.bfloat16, "float32": torch.float32}
_KINDS = ("cross", "temporal", "skeletal")


def _check_window(value: Any, name: str) -> tuple[float, float]:
    try:
        start, stop = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a (start, stop) pair of step fractions in [0, 1], got {value!r}") from None
    if not (0.0 <= start < stop <= 1.0):
        raise ValueError(f"{name}={value!r} must satisfy 0 <= start < stop <= 1 (fractions i/S of the steps)")
    return start, stop


def _check_indices(value: Any, name: str) -> tuple[int, ...] | None:
    if value is None:
        return None
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        value = (int(value),)
    try:
        out = tuple(int(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be None or a sequence of non-negative ints, got {value!r}") from None
    if not out or any(v < 0 for v in out) or len(set(out)) != len(out):
        raise ValueError(f"{name}={value!r} must be a non-empty sequence of distinct non-negative ints")
    return tuple(sorted(out))


@dataclass(frozen=True)
class CaptureConfig:
    """What :func:`capture_cross_attention` records and how it keeps it."""

    mode: str = "mean"                       # "mean": streaming sums per (step bin, layer); "full": all steps/layers/heads
    steps: tuple[float, float] = (0.0, 1.0)  # window [start, stop) of step fractions i/S that are recorded
    layers: tuple[int, ...] | None = None    # layers recorded (None: all)
    heads: tuple[int, ...] | None = None     # heads kept/averaged (None: all)
    step_bins: int = 10                      # "mean": sums over equal step-fraction bins (select() on their edges)
    self_attention: bool = False             # also record temporal and skeletal self-attention
    full_dtype: str = "float16"              # "full": storage dtype on the CPU

    def __post_init__(self) -> None:
        if self.mode not in CAPTURE_MODES:
            raise ValueError(f"CaptureConfig.mode must be one of {CAPTURE_MODES}, got {self.mode!r}")
        object.__setattr__(self, "steps", _check_window(self.steps, "CaptureConfig.steps"))
        object.__setattr__(self, "layers", _check_indices(self.layers, "CaptureConfig.layers"))
        object.__setattr__(self, "heads", _check_indices(self.heads, "CaptureConfig.heads"))
        if isinstance(self.step_bins, bool) or not isinstance(self.step_bins, int) or self.step_bins < 1:
            raise ValueError(f"CaptureConfig.step_bins must be a positive int, got {self.step_bins!r}")
        if not isinstance(self.self_attention, bool):
            raise TypeError(f"CaptureConfig.self_attention must be a bool, got {self.self_attention!r}")
        if self.full_dtype not in _FULL_DTYPES:
            raise ValueError(f"CaptureConfig.full_dtype must be one of {sorted(_FULL_DTYPES)}, got {self.full_dtype!r}")


def as_capture_config(config: bool | CaptureConfig | dict | None) -> CaptureConfig:
    """``True`` -> defaults; a dict -> ``CaptureConfig(**dict)``; a config passes through."""
    if config is True:
        return CaptureConfig()
    if isinstance(config, CaptureConfig):
        return config
    if isinstance(config, dict):
        return CaptureConfig(**config)
    raise TypeError(f"capture config must be True, a CaptureConfig or a dict of its fields, got {config!r}")


@dataclass(frozen=True)
class TokenInfo:
    """Tokens, words and the token -> word map of a batch of prompts (a :class:`TextBatch` without
    features; see :mod:`salad_core.text`)."""

    prompts: list[str]
    tokens: list[list[str]]
    token_to_word: list[list[int | None]]
    words: list[list[str]]

    @classmethod
    def from_batch(cls, text: Any) -> "TokenInfo":
        """From a :class:`~salad_core.text.TextBatch` (or anything with the same four lists)."""
        return cls(list(text.prompts), [list(t) for t in text.tokens], [list(t) for t in text.token_to_word],
                   [list(w) for w in text.words])

    def __len__(self) -> int:
        return len(self.prompts)

    def word_columns(self, b: int, word: str | int | tuple[int, int]) -> list[int]:
        """Token columns of a word (string or index), a phrase ("walks forward": consecutive words,
        every occurrence) or a word span ``(i0, i1)`` of prompt ``b``."""
        words = self.words[b]
        if isinstance(word, bool):
            raise TypeError(f"word must be a string, a word index or a (start, stop) word span, got {word!r}")
        if isinstance(word, (int, np.integer)):
            if not 0 <= int(word) < len(words):
                raise IndexError(f"word index {word} is out of range: prompt {b} has {len(words)} words {words}")
            wanted = {int(word)}
        elif isinstance(word, tuple):
            if len(word) != 2 or not 0 <= int(word[0]) < int(word[1]) <= len(words):
                raise ValueError(f"word span {word!r} must be (start, stop) with 0 <= start < stop <= "
                                 f"{len(words)} for prompt {b} {words}")
            wanted = set(range(int(word[0]), int(word[1])))
        elif isinstance(word, str):
            key = split_words(word)
            if not key:
                raise ValueError(f"word {word!r} has no letters; prompt {b} has the words {words}")
            starts = [i for i in range(len(words) - len(key) + 1) if words[i:i + len(key)] == key]
            if not starts:
                raise ValueError(f"word {word!r} is not in prompt {b} ({self.prompts[b]!r}); its words are {words}")
            wanted = {i + k for i in starts for k in range(len(key))}
        else:
            raise TypeError("word must be a string, a word index or a (start, stop) word span, "
                            f"got {type(word).__name__}")
        cols = [j for j, w in enumerate(self.token_to_word[b]) if w in wanted]
        if not cols:
            raise ValueError(f"word {word!r} of prompt {b} has no tokens (cut off by truncation?)")
        return cols


# =============================================================================== the store
class AttentionStore:
    """Records attention probabilities during sampling (a :class:`SiteHook` with a step hook).

    Parameters
    ----------
    text : TextBatch or TokenInfo
        Tokens of the ``B`` prompts whose maps are recorded.
    lengths : sequence of int
        Motion lengths in frames; maps are cropped to ``length // unit_length`` latent frames.
    config : CaptureConfig
    num_layers, num_heads : int
        Of the denoiser (``L``, ``H``).
    unit_length : int
        Frames per latent frame (the VAE's temporal down-sampling).
    rows : callable, optional
        ``rows(step_info) -> LongTensor (B,)``: the forward-batch rows of the ``B`` samples at this
        step; default: the conditional rows (``StepInfo.cond_rows``).
    """

    def __init__(self, text: Any, lengths: Sequence[int], config: CaptureConfig, num_layers: int,
                 num_heads: int, unit_length: int | None = None,
                 rows: Callable[[Any], torch.Tensor] | None = None) -> None:
        self.tokens = text if isinstance(text, TokenInfo) else TokenInfo.from_batch(text)
        self.config = config
        self.unit_length = unit_length or get_skeleton().unit_length
        self.lengths = [int(n) for n in lengths]
        if len(self.lengths) != len(self.tokens):
            raise ValueError(f"got {len(self.lengths)} lengths for {len(self.tokens)} prompts")
        self.num_layers, self.num_heads = int(num_layers), int(num_heads)
        layers = config.layers if config.layers is not None else tuple(range(self.num_layers))
        heads = config.heads if config.heads is not None else tuple(range(self.num_heads))
        if max(layers) >= self.num_layers:
            raise ValueError(f"CaptureConfig.layers={config.layers} has layers beyond the denoiser's {self.num_layers}")
        if max(heads) >= self.num_heads:
            raise ValueError(f"CaptureConfig.heads={config.heads} has heads beyond the denoiser's {self.num_heads}")
        self.layers, self.heads = layers, heads
        self._layer_pos = {layer: i for i, layer in enumerate(layers)}
        self._all_heads = len(heads) == self.num_heads
        self._heads_t = torch.tensor(heads)
        self.kinds = ("cross",) + (("temporal", "skeletal") if config.self_attention else ())
        self._rows_fn = rows or (lambda info: torch.arange(info.cond_rows.start, info.cond_rows.stop))
        self._rows: torch.Tensor | None = None
        self._active = False
        self._group = 0
        self.num_steps = 0
        self._mean: dict[str, torch.Tensor] = {}          # kind -> (K, L, B, ...) float32 sums
        self._counts = np.zeros(config.step_bins, dtype=np.int64)
        self._full: dict[str, dict[int, torch.Tensor]] = {k: {} for k in self.kinds}  # kind -> step -> (L, H, B, ...)
        self._steps_seen: list[int] = []

    # ------------------------------------------------------------------ hooks
    def on_step(self, info: Any) -> None:
        """Step hook (``controller_hooks`` of :func:`salad_core.sampling.denoise`)."""
        self.num_steps = int(info.num_steps)
        frac = info.index / info.num_steps
        start, stop = self.config.steps
        self._active = start <= frac < stop
        self._step = int(info.index)
        if not self._active:
            self._rows = None
            return
        self._rows = self._rows_fn(info)
        if self._rows.numel() != len(self.tokens):
            raise ValueError(f"the row selector gave {self._rows.numel()} rows for {len(self.tokens)} prompts")
        self._group = min(int(frac * self.config.step_bins + 1e-9), self.config.step_bins - 1)
        self._counts[self._group] += 1
        self._steps_seen.append(self._step)

    def wants(self, site: SiteInfo) -> bool:
        """Whether this call of ``site`` is recorded."""
        return self._active and site.kind in self.kinds and site.layer in self._layer_pos

    def rows(self, site: SiteInfo) -> torch.Tensor | None:
        return self._rows if self.wants(site) else None

    def process(self, site: SiteInfo, rows: torch.Tensor, probs: torch.Tensor) -> None:
        self.record(site, probs)
        return None

    # ---------------------------------------------------------------- storage
    def record(self, site: SiteInfo, probs: torch.Tensor) -> None:
        """Add the named probabilities of this store's ``B`` samples at ``site`` (see
        :func:`~salad_core.attention.processor.named_rows` for the axes)."""
        head_axis = {"cross": 1, "temporal": 2, "skeletal": 2}[site.kind]
        if not self._all_heads:
            probs = probs.index_select(head_axis, self._heads_t.to(probs.device))
        layer = self._layer_pos[site.layer]
        if self.config.mode == "mean":
            summed = probs.sum(head_axis, dtype=torch.float32)  # cross (B, N', P, W)
            acc = self._mean.get(site.kind)
            if acc is None or acc.shape[3:] != summed.shape[1:]:
                if acc is not None:
                    raise ValueError(f"attention at {site.name!r} changed shape from {tuple(acc.shape[2:])} to "
                                     f"{tuple(summed.shape)} during one capture")
                acc = torch.zeros((self.config.step_bins, len(self.layers), *summed.shape), dtype=torch.float32)
                self._mean[site.kind] = acc
            acc[self._group, layer] += summed.cpu()
        else:
            moved = probs.movedim(head_axis, 0)                  # (H, B, ...)
            buf = self._full[site.kind].get(self._step)
            if buf is None:
                buf = torch.zeros((len(self.layers), *moved.shape), dtype=_FULL_DTYPES[self.config.full_dtype])
                self._full[site.kind][self._step] = buf
            buf[layer] = moved.to("cpu", buf.dtype)

    # ----------------------------------------------------------------- result
    def result(self) -> "AttentionMaps":
        """The recorded maps, cropped per sample to its latent frames and tokens."""
        if not self._steps_seen:
            raise RuntimeError("no step was recorded: was the store's on_step hook passed to the sampler, "
                               f"and does CaptureConfig.steps={self.config.steps} contain any step?")
        b_count = len(self.tokens)
        n_lat = [n // self.unit_length for n in self.lengths]
        n_tok = [len(t) for t in self.tokens.tokens]
        data: dict[str, list[np.ndarray]] = {}
        for kind in self.kinds:
            per_sample = []
            if self.config.mode == "mean":
                acc = self._mean.get(kind)
                if acc is None:
                    raise RuntimeError(f"no {kind} attention was recorded (no site of that kind ran)")
                arr = acc.numpy()                                # (K, L, B, ...)
                for b in range(b_count):
                    per_sample.append(_crop(kind, arr[:, :, b], n_lat[b], n_tok[b], lead=2))
            else:
                steps = sorted(self._full[kind])
                arr = torch.stack([self._full[kind][s] for s in steps]).numpy()   # (S, L, H, B, ...)
                for b in range(b_count):
                    per_sample.append(_crop(kind, arr[:, :, :, b], n_lat[b], n_tok[b], lead=3))
            data[kind] = per_sample
        if self.config.mode == "mean":
            groups = np.arange(self.config.step_bins) / self.config.step_bins
            weights = self._counts.astype(np.float64)
        else:
            steps = np.array(sorted(set(self._steps_seen)))
            groups = steps / self.num_steps
            weights = np.ones(len(steps))
        return AttentionMaps(data=data, tokens=self.tokens, lengths=self.lengths, unit_length=self.unit_length,
                             mode=self.config.mode, group_starts=groups, group_weights=weights,
                             group_width=1.0 / self.config.step_bins if self.config.mode == "mean" else 0.0,
                             layers=self.layers, heads=self.heads, num_steps=self.num_steps,
                             num_layers=self.num_layers)


def _crop(kind: str, arr: np.ndarray, n: int, w: int, lead: int) -> np.ndarray:
    """Crop one sample's maps (``lead`` leading axes) to ``n`` latent frames and ``w`` tokens."""
    idx = (slice(None),) * lead
    if kind == "cross":        # (..., N', P, W)
        return np.ascontiguousarray(arr[idx + (slice(0, n), slice(None), slice(0, w))])
    if kind == "temporal":     # (..., P, N', N')
        return np.ascontiguousarray(arr[idx + (slice(None), slice(0, n), slice(0, n))])
    return np.ascontiguousarray(arr[idx + (slice(0, n),)])          # skeletal (..., N', P, P)


# ================================================================================ the maps
@dataclass(frozen=True)
class _Selection:
    groups: np.ndarray   # bool (G,)
    layers: tuple[int, ...]
    heads: tuple[int, ...] | None   # None = all held (the only option in mean mode)


class AttentionMaps:
    """Captured attention maps with their tokens and words (returned by the pipeline).

    Per sample ``b`` the cross-attention map is ``(P, N'_b, W_b)``: rows are the P body parts in
    the paper's order (:data:`salad_core.skeleton.PART_NAMES`), columns the sample's latent frames
    (each ``unit_length`` motion frames), the last axis its tokens (special tokens included). The
    values are means of post-softmax probabilities over the selected steps, layers and heads, so
    for every (part, frame) they sum to 1 over the tokens.

    Examples
    --------
    >>> out = pipe("a man jumps forward and then walks", capture_attention=True)   # doctest: +SKIP
    >>> out.attention.word_map(0, "jumps")            # (7, N') numpy, the word's tokens summed
    >>> early = out.attention.select(steps=(0.0, 0.5), layers=[0, 1])
    >>> salad_viz.attention.plot_attention_grid(early.cross_map(0), early.tokens(0))
    """

    def __init__(self, *, data: dict[str, list[np.ndarray]], tokens: TokenInfo, lengths: Sequence[int],
                 unit_length: int, mode: str, group_starts: np.ndarray, group_weights: np.ndarray,
                 group_width: float, layers: tuple[int, ...], heads: tuple[int, ...], num_steps: int,
                 num_layers: int, selection: _Selection | None = None) -> None:
        self._data = data
        self._tokens = tokens
        self.lengths = list(lengths)
        self.unit_length = unit_length
        self.mode = mode
        self._starts = np.asarray(group_starts, dtype=np.float64)
        self._weights = np.asarray(group_weights, dtype=np.float64)
        self._width = group_width
        self.captured_layers = tuple(layers)
        self.captured_heads = tuple(heads)
        self.num_steps = num_steps
        self.num_layers = num_layers
        self._sel = selection or _Selection(self._weights > 0, tuple(layers), None)

    # ------------------------------------------------------------- metadata
    def __len__(self) -> int:
        return len(self._tokens)

    def __repr__(self) -> str:
        return (f"AttentionMaps(B={len(self)}, mode={self.mode!r}, kinds={self.kinds}, steps={self.num_steps}, "
                f"layers={list(self._sel.layers)}, step_window={self.step_window})")

    @property
    def prompts(self) -> list[str]:
        return list(self._tokens.prompts)

    @property
    def kinds(self) -> tuple[str, ...]:
        """Recorded attention kinds: ``("cross",)`` plus temporal/skeletal on request."""
        return tuple(self._data)

    @property
    def latent_lengths(self) -> list[int]:
        return [n // self.unit_length for n in self.lengths]

    @property
    def layers(self) -> tuple[int, ...]:
        """Layers in the current selection."""
        return self._sel.layers

    @property
    def step_window(self) -> tuple[float, float]:
        """Step fractions ``[start, stop)`` covered by the current selection."""
        idx = np.flatnonzero(self._sel.groups & (self._weights > 0))
        if not len(idx):
            return (0.0, 0.0)
        width = self._width or 1.0 / max(self.num_steps, 1)
        return float(self._starts[idx[0]]), float(min(self._starts[idx[-1]] + width, 1.0))

    def tokens(self, b: int = 0) -> list[str]:
        """Token strings of prompt ``b`` (special tokens included; the W axis)."""
        return list(self._tokens.tokens[self._check_b(b)])

    def words(self, b: int = 0) -> list[str]:
        """Words of prompt ``b`` (``split_words`` convention)."""
        return list(self._tokens.words[self._check_b(b)])

    def token_to_word(self, b: int = 0) -> list[int | None]:
        """For each token of prompt ``b`` the index of its word (None for special tokens)."""
        return list(self._tokens.token_to_word[self._check_b(b)])

    def word_columns(self, b: int, word: str | int | tuple[int, int]) -> list[int]:
        """Token columns of a word, phrase or word span (see :meth:`TokenInfo.word_columns`)."""
        return self._tokens.word_columns(self._check_b(b), word)

    def _check_b(self, b: int) -> int:
        if isinstance(b, bool) or not isinstance(b, (int, np.integer)) or not 0 <= int(b) < len(self):
            raise IndexError(f"sample index b={b!r} is out of range for {len(self)} captured samples")
        return int(b)

    # ------------------------------------------------------------ selection
    def select(self, steps: tuple[float, float] | None = None, layers: Sequence[int] | int | None = None,
               heads: Sequence[int] | int | None = None) -> "AttentionMaps":
        """A view restricted to a step window, layers and (``"full"`` mode) heads.

        Parameters
        ----------
        steps : (start, stop), optional
            Step fractions ``i / S`` in ``[start, stop)``. In ``"mean"`` mode both ends must lie
            on the bin edges (multiples of ``1 / step_bins``).
        layers : int or sequence of int, optional
            Layer indices (execution order: 0 = first input block); must have been captured.
        heads : int or sequence of int, optional
            Only in ``"full"`` mode (the mean mode summed the heads while sampling).
        """
        groups = self._sel.groups.copy()
        if steps is not None:
            start, stop = _check_window(steps, "steps")
            if self.mode == "mean":
                k = round(1.0 / self._width)
                for v in (start, stop):
                    if abs(v * k - round(v * k)) > 1e-6:
                        raise ValueError(f"steps={steps!r}: a mean-mode capture holds {k} step bins, so the window "
                                         f"must lie on multiples of 1/{k}; capture with step_bins=... or mode='full'")
            groups = groups & (self._starts >= start - 1e-9) & (self._starts < stop - 1e-9)
            if not (groups & (self._weights > 0)).any():
                raise ValueError(f"steps={steps!r} contains no recorded step (recorded window {self.step_window})")
        sel_layers = self._sel.layers
        if layers is not None:
            wanted = _check_indices(layers, "layers")
            missing = [layer for layer in wanted if layer not in self.captured_layers]
            if missing:
                raise ValueError(f"layers {missing} were not captured; captured layers: {list(self.captured_layers)}")
            sel_layers = wanted
        sel_heads = self._sel.heads
        if heads is not None:
            if self.mode != "full":
                raise ValueError("heads can only be selected in a mode='full' capture (the mean mode averaged the "
                                 "heads while sampling; choose them with CaptureConfig.heads)")
            wanted = _check_indices(heads, "heads")
            missing = [h for h in wanted if h not in self.captured_heads]
            if missing:
                raise ValueError(f"heads {missing} were not captured; captured heads: {list(self.captured_heads)}")
            sel_heads = wanted
        return AttentionMaps(data=self._data, tokens=self._tokens, lengths=self.lengths, unit_length=self.unit_length,
                             mode=self.mode, group_starts=self._starts, group_weights=self._weights,
                             group_width=self._width, layers=self.captured_layers, heads=self.captured_heads,
                             num_steps=self.num_steps, num_layers=self.num_layers,
                             selection=_Selection(groups, sel_layers, sel_heads))

    def _reduce(self, kind: str, b: int) -> np.ndarray:
        if kind not in self._data:
            raise ValueError(f"{kind} attention was not captured (captured: {self.kinds}); "
                             "use CaptureConfig(self_attention=True)")
        arr = self._data[kind][self._check_b(b)]
        g = np.flatnonzero(self._sel.groups)
        lpos = [self.captured_layers.index(layer) for layer in self._sel.layers]
        weights = self._weights[g]
        if self.mode == "mean":
            sub = arr[g][:, lpos].astype(np.float64)                          # (G, L, ...)
            total = sub.sum((0, 1))
            denom = weights.sum() * len(lpos) * len(self.captured_heads)
        else:
            hpos = (list(range(len(self.captured_heads))) if self._sel.heads is None
                    else [self.captured_heads.index(h) for h in self._sel.heads])
            sub = arr[g][:, lpos][:, :, hpos].astype(np.float64)              # (G, L, H, ...)
            total = sub.sum((0, 1, 2))
            denom = len(g) * len(lpos) * len(hpos)
        if denom <= 0:
            raise ValueError("the selection holds no recorded step")
        return (total / denom).astype(np.float32)

    # ------------------------------------------------------------------ maps
    def cross_map(self, b: int = 0) -> np.ndarray:
        """``(P, N'_b, W_b)`` mean cross-attention of sample ``b`` (rows = body parts)."""
        return np.ascontiguousarray(self._reduce("cross", b).transpose(1, 0, 2))

    def token_map(self, b: int, token: int) -> np.ndarray:
        """``(P, N'_b)`` map of token column ``token`` of sample ``b``."""
        w = len(self._tokens.tokens[self._check_b(b)])
        if isinstance(token, bool) or not isinstance(token, (int, np.integer)) or not -w <= int(token) < w:
            raise IndexError(f"token index {token!r} is out of range: prompt {b} has {w} tokens {self.tokens(b)}")
        return self.cross_map(b)[:, :, int(token)]

    def word_map(self, b: int, word: str | int | tuple[int, int]) -> np.ndarray:
        """``(P, N'_b)``: the sum of the maps of a word's sub-tokens (a phrase or word span sums
        all its words' tokens, every occurrence)."""
        cols = self.word_columns(b, word)
        return self.cross_map(b)[:, :, cols].sum(-1)

    def word_maps(self, b: int = 0) -> dict[str, np.ndarray]:
        """``{word: (P, N'_b)}`` for every word of prompt ``b`` (repeated words: first occurrence
        key, maps of all occurrences summed)."""
        full = self.cross_map(b)
        out: dict[str, np.ndarray] = {}
        for i, word in enumerate(self.words(b)):
            if word in out:
                continue
            cols = self.word_columns(b, word)
            out[word] = full[:, :, cols].sum(-1)
        return out

    def temporal_map(self, b: int = 0) -> np.ndarray:
        """``(P, N'_b, N'_b)`` mean temporal self-attention (query frame x key frame per part)."""
        return self._reduce("temporal", b)

    def skeletal_map(self, b: int = 0) -> np.ndarray:
        """``(N'_b, P, P)`` mean skeletal self-attention (query part x key part per frame)."""
        return self._reduce("skeletal", b)

    def full(self, b: int = 0, kind: str = "cross") -> np.ndarray:
        """``"full"`` mode only: sample ``b``'s stored array, cross ``(S, L, H, N', P, W)``
        (temporal ``(S, L, H, P, N', N')``, skeletal ``(S, L, H, N', P, P)``), float16."""
        if self.mode != "full":
            raise ValueError("full() needs a capture with CaptureConfig(mode='full')")
        if kind not in self._data:
            raise ValueError(f"{kind} attention was not captured (captured: {self.kinds})")
        return self._data[kind][self._check_b(b)]

    @property
    def part_names(self) -> tuple[str, ...]:
        return PART_NAMES


# ============================================================================ installation
@contextmanager
def capture_cross_attention(denoiser: Any, text: Any, lengths: Sequence[int],
                            config: bool | CaptureConfig | dict = True, *, unit_length: int | None = None,
                            rows: Callable[[Any], torch.Tensor] | None = None) -> Iterator[AttentionStore]:
    """Record attention while the ``with`` block samples; the model is restored on exit.

    Parameters
    ----------
    denoiser : Denoiser
        Its cross sites (and, with ``self_attention``, temporal and skeletal sites) get a
        :class:`HookedProcessor`; the other sites are untouched.
    text : TextBatch
        The ``B`` prompts being generated (their tokens and words travel with the maps).
    lengths : sequence of int
        Motion lengths in frames.
    config : True, CaptureConfig or dict
    unit_length : int, optional
        Frames per latent frame (default: the skeletons' 4).
    rows : callable, optional
        Row selector (default: the conditional rows of the CFG batch).

    Yields
    ------
    AttentionStore
        Pass ``store.on_step`` to the sampler's ``controller_hooks``; call ``store.result()``
        after the loop.

    Examples
    --------
    >>> with capture_cross_attention(denoiser, text, [120]) as store:        # doctest: +SKIP
    ...     z = denoise(denoiser, sched, cond, uncond, noise, controller_hooks=[store.on_step])
    >>> maps = store.result()
    """
    store = attention_store(denoiser, text, lengths, config, unit_length=unit_length, rows=rows)
    processors = {name: HookedProcessor(store) for name in store_sites(denoiser, store)}
    with use_processors(denoiser, processors):
        yield store


def attention_store(denoiser: Any, text: Any, lengths: Sequence[int], config: bool | CaptureConfig | dict = True, *,
                    unit_length: int | None = None, rows: Callable[[Any], torch.Tensor] | None = None
                    ) -> AttentionStore:
    """The :class:`AttentionStore` that :func:`capture_cross_attention` installs (arguments as
    there), for callers that serve it through their own processors (``pipe(..., hooks=...)``)."""
    cfg = as_capture_config(config)
    dcfg = denoiser.config
    if not dcfg.cross_attention:
        raise ValueError("attention capture needs cross-attention sites; this denoiser is the 'w/o CrossAttn' "
                         "ablation (cross_attention=False), whose sentence attention has no word axis")
    return AttentionStore(text, lengths, cfg, dcfg.layers, dcfg.heads, unit_length, rows)


def store_sites(denoiser: Any, store: AttentionStore) -> list[str]:
    """The sites of ``denoiser`` whose attention ``store`` records (its kinds, every layer)."""
    return [name for name, mod in denoiser.attention_sites.items() if mod.kind in store.kinds]
