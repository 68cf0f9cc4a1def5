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

import re
from typing import Any, Sequence

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

#: Side words and their mirror images (lower case): left and right, and the turning senses seen from above
#: (clockwise is a turn to the right). Hyphenated forms ("counter-clockwise") are matched as one word.
MIRROR_SIDE_WORDS = {"left": "right", "right": "left", "leftward": "rightward", "rightward": "leftward",
                     "leftwards": "rightwards", "rightwards": "leftwards", "clockwise": "counterclockwise",
                     "counterclockwise": "clockwise", "anticlockwise": "clockwise",
                     "counter-clockwise": "clockwise", "anti-clockwise": "clockwise"}
#: Side words of the left kind (a turn counterclockwise seen from above is a turn to the left).
_LEFT_KIND = frozenset({"left", "leftward", "leftwards", "counterclockwise", "anticlockwise", "counter-clockwise",
                        "anti-clockwise"})
_SIDE_WORD = re.compile(r"[A-Za-z]+(?:-[A-Za-z]+)?")

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


def _side_words(text: str) -> list[tuple[int, int, str]]:
    """``(start, end, lower-case word)`` of the side words of ``text`` in order (a hyphenated side word such as
    "counter-clockwise" whole; in other hyphenated words, e.g. "left-handed", their side parts)."""
    out = []
    for m in _SIDE_WORD.finditer(text):
        w = m.group(0).lower()
        if w in MIRROR_SIDE_WORDS:
            out.append((m.start(), m.end(), w))
        elif "-" in w:
            for part in re.finditer(r"[A-Za-z]+", m.group(0)):
                if part.group(0).lower() in MIRROR_SIDE_WORDS:
                    out.append((m.start() + part.start(), m.start() + part.end(), part.group(0).lower()))
    return out


def _with_case(word: str, like: str) -> str:
    if like.isupper() and len(like) > 1:
        return word.upper()
    return word[0].upper() + word[1:] if like[:1].isupper() else word


def mirror_side_words(text: str) -> str:
    """The caption of the mirror image of a motion: ``text`` with every side word swapped
    (:data:`MIRROR_SIDE_WORDS`; case of the first letter kept), everything else unchanged.

    ``"Turns left, then kicks with the right foot"`` -> ``"Turns right, then kicks with the left foot"``.
    Mirroring twice gives the text back, except that "anticlockwise" and "counter-clockwise" come back as
    "counterclockwise".
    """
    if not isinstance(text, str):
        raise TypeError(f"text must be a str, got {type(text).__name__}")
    out, last = [], 0
    for start, end, w in _side_words(text):
        out.append(text[last: start])
        out.append(_with_case(MIRROR_SIDE_WORDS[w], text[start: end]))
        last = end
    out.append(text[last:])
    return "".join(out)


def names_left_first(text: str) -> bool:
    """True when the first side word of ``text`` is of the left kind ("left", "leftwards",
    "counterclockwise", ...): the prompts a side-canonical PST (``PSTConfig.side_canonical``) sees mirrored.
    Texts without side words give False."""
    if not isinstance(text, str):
        raise TypeError(f"text must be a str, got {type(text).__name__}")
    words = _side_words(text)
    return bool(words) and words[0][2] in _LEFT_KIND
