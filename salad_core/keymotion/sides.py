"""Side ids of prompt tokens: which tokens say "left" or "right" (the PST's optional side cue).

Why: the shipped KeyMotion PST ignores the side words. "a man waves his left hand" and "... his
right hand" give, seed for seed, the same motion (left-minus-right wrist height per seed
``[-1.12 -1.14 0.82 0.71]`` against ``[-1.13 -1.12 0.73 0.76]``; the same for kicks, punches and
raised arms), and the PST's keyframes already show it, so the side is decided by the initial noise,
not by the text. MiniLM's contextual features of "left" and "right" in otherwise identical sentences
have cosine 0.87 (every other token 0.98-0.99), and the corpus holds every motion mirrored with the
side words swapped, so the information is there; the PST just does not latch on to it. With
``PSTConfig.side_cue`` the PST adds a learned embedding of these ids to its projected text tokens
(:class:`~salad_core.keymotion.pst.ParallelSkipTransformer`), an explicit cue it cannot miss.

Ids: :data:`NO_SIDE` (0), :data:`LEFT` (1), :data:`RIGHT` (2), one per token column, aligned with a
:class:`~salad_core.text.TextBatch` (token ``j`` of prompt ``b`` is column ``j``; padding is 0).
A token's side is that of the *word* it starts: the token string lower-cased, with the WordPiece
continuation pieces (``"##..."``) that follow it appended, must be one of :data:`LEFT_WORDS` or
:data:`RIGHT_WORDS`. The continuation pieces themselves are never a side. So MiniLM's
``left ##ward ##s`` ("leftwards") gives ``1 0 0``, while ``left ##over`` ("leftover") gives ``0 0``.
A trailing ``"</w>"`` (CLIP's end-of-word mark) is ignored.
"""
from __future__ import annotations

from typing import Any, Sequence

from salad_core.side_words import MIRROR_SIDE_WORDS, mirror_side_words, names_left_first

import torch

__all__ = ["NO_SIDE", "LEFT", "RIGHT", "NUM_SIDES", "LEFT_WORDS", "RIGHT_WORDS", "word_side", "side_ids",
           "side_ids_of", "MIRROR_SIDE_WORDS", "mirror_side_words", "names_left_first"]

#: Side id of a token that names no side (and of padding).
NO_SIDE = 0
#: Side id of a token starting a left word.
LEFT = 1
#: Side id of a token starting a right word.
RIGHT = 2
#: Number of side ids (rows of ``ParallelSkipTransformer.side_embed``).
NUM_SIDES = 3
#: Words (lower case) that name the left side.
LEFT_WORDS = frozenset({"left", "leftward", "leftwards"})
#: Words (lower case) that name the right side.
RIGHT_WORDS = frozenset({"right", "rightward", "rightwards"})

_CONTINUATION = "##"
_END_OF_WORD = "</w>"


def word_side(word: str) -> int:
    """Side id of one word (case-insensitive): :data:`LEFT`, :data:`RIGHT` or :data:`NO_SIDE`."""
    w = word.lower()
    if w.endswith(_END_OF_WORD):
        w = w[: -len(_END_OF_WORD)]
    if w in LEFT_WORDS:
        return LEFT
    if w in RIGHT_WORDS:
        return RIGHT
    return NO_SIDE


def _prompt_sides(tokens: Sequence[str]) -> list[int]:
    """Side id of each token of one prompt (see the module docstring)."""
    out = [NO_SIDE] * len(tokens)
    for j, tok in enumerate(tokens):
        if tok.startswith(_CONTINUATION):
            continue
        word = tok
        for nxt in tokens[j + 1:]:
            if not nxt.startswith(_CONTINUATION):
                break
            word += nxt[len(_CONTINUATION):]
        out[j] = word_side(word)
    return out


def side_ids(tokens: Sequence[Sequence[str]], width: int) -> torch.Tensor:
    """Side ids of a batch of tokenised prompts.

    Parameters
    ----------
    tokens : list of list of str
        Per prompt, its unpadded token strings incl. special tokens (``TextBatch.tokens``, e.g.
        ``['[CLS]', 'a', 'man', 'waves', 'his', 'left', 'hand', '[SEP]']``).
    width : int
        ``W``, the padded token width of the features these ids go with (``>=`` every prompt's
        token count).

    Returns
    -------
    LongTensor ``(B, W)``: 0 no side (and padding), 1 left, 2 right.
    """
    if isinstance(tokens, str) or any(isinstance(t, str) for t in tokens):
        raise TypeError("tokens must be a list of token lists, one per prompt (TextBatch.tokens), "
                        f"got {type(tokens).__name__} of strings")
    if isinstance(width, bool) or not isinstance(width, int) or width < 0:
        raise ValueError(f"width={width!r} is invalid; use an integer >= 0 (the padded token width W)")
    out = torch.zeros((len(tokens), width), dtype=torch.long)
    for b, toks in enumerate(tokens):
        if len(toks) > width:
            raise ValueError(f"prompt {b} has {len(toks)} tokens, more than width={width}")
        if toks:
            out[b, : len(toks)] = torch.as_tensor(_prompt_sides(list(toks)), dtype=torch.long)
    return out


def side_ids_of(batch: Any) -> torch.Tensor:
    """Side ids ``(B, W)`` of a :class:`~salad_core.text.TextBatch` (``W`` = its features' width), on
    the device of its features."""
    return side_ids(batch.tokens, int(batch.features.shape[1])).to(batch.features.device)

