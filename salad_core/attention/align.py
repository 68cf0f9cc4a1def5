"""Token alignment between a source and a target prompt (Prompt-to-Prompt ``seq_aligner``).

Two maps from target token columns to source token columns, both pure functions of token lists:

* :func:`global_align` (prompt refinement, SALAD supplement B): a global (Needleman-Wunsch)
  alignment with score +1 for equal tokens, -1 for different ones and 0 for a gap, as in
  Prompt-to-Prompt. With these scores a substitution (-1) never beats two gaps (0), so the result
  pairs only equal tokens: it is a longest common subsequence. ``A(k)`` is the source column of
  target token ``k``, or -1 for an inserted token. Ties prefer pairing equal tokens, then
  skipping source tokens, so that repeated words align left to right.
* :func:`word_swap_matrix` (word swap): prompts with the same number of words; word ``i`` of the
  target takes the maps of word ``i`` of the source. When the two words have different numbers of
  sub-tokens, every target token of the word receives the source word's summed map divided by
  its own token count, so the word's total attention is preserved. Special tokens map to the
  special tokens at the same end of the prompt.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["global_align", "alignment_matrix", "word_swap_matrix"]


def global_align(source: Sequence[str], target: Sequence[str]) -> list[int]:
    """For every target token, the index of the aligned equal source token, or -1 (inserted).

    Parameters
    ----------
    source, target : sequence of str
        Token strings (special tokens included, e.g. ``[CLS] a man walks [SEP]``).

    Returns
    -------
    list of int
        ``len(target)`` entries; the non-negative ones are strictly increasing.

    Examples
    --------
    >>> global_align(["[CLS]", "a", "man", "walks", "[SEP]"], ["[CLS]", "a", "man", "slowly", "walks", "[SEP]"])
    [0, 1, 2, -1, 3, 4]
    """
    n, m = len(source), len(target)
    score = np.zeros((n + 1, m + 1), dtype=np.int64)
    for i in range(1, n + 1):
        for j in range(1, m + 1):
            diag = score[i - 1, j - 1] + (1 if source[i - 1] == target[j - 1] else -1)
            score[i, j] = max(diag, score[i - 1, j], score[i, j - 1])   # gaps score 0
    mapping = [-1] * m
    i, j = n, m
    while i > 0 and j > 0:
        if source[i - 1] == target[j - 1] and score[i, j] == score[i - 1, j - 1] + 1:
            mapping[j - 1] = i - 1
            i, j = i - 1, j - 1
        elif score[i, j] == score[i - 1, j]:
            i -= 1            # source token i-1 is not in the target
        else:
            j -= 1            # target token j-1 is inserted
    return mapping


def alignment_matrix(mapping: Sequence[int], num_source: int) -> np.ndarray:
    """``(W_t, W_s)`` 0/1 matrix of a :func:`global_align` mapping (rows of inserted tokens are 0)."""
    out = np.zeros((len(mapping), num_source), dtype=np.float32)
    for k, j in enumerate(mapping):
        if j >= 0:
            out[k, j] = 1.0
    return out


def _groups(token_to_word: Sequence[int | None], num_words: int) -> tuple[list[list[int]], list[int], list[int]]:
    words: list[list[int]] = [[] for _ in range(num_words)]
    first_word = next((k for k, w in enumerate(token_to_word) if w is not None), len(token_to_word))
    head, tail = [], []
    for k, w in enumerate(token_to_word):
        if w is None:
            (head if k < first_word else tail).append(k)
        else:
            words[w].append(k)
    return words, head, tail


def _spread(rows: list[int], cols: list[int], out: np.ndarray) -> None:
    if not rows or not cols:
        return
    if len(rows) == len(cols):
        for r, c in zip(rows, cols):
            out[r, c] = 1.0
    else:
        out[np.ix_(rows, cols)] = 1.0 / len(rows)


def word_swap_matrix(source_tokens: Sequence[str], source_t2w: Sequence[int | None], source_words: Sequence[str],
                     target_tokens: Sequence[str], target_t2w: Sequence[int | None],
                     target_words: Sequence[str]) -> np.ndarray:
    """``(W_t, W_s)`` matrix ``A`` with ``M_hat[..., k] = sum_j A[k, j] M[..., j]`` for a word swap.

    Raises
    ------
    ValueError
        If the prompts have different numbers of words (use prompt refinement instead).
    """
    if len(source_words) != len(target_words):
        raise ValueError(f"word swap needs prompts with the same number of words; the source has "
                         f"{len(source_words)} {list(source_words)} and the target {len(target_words)} "
                         f"{list(target_words)}. Use Refine() for prompts that add or remove words")
    sw, sh, st = _groups(source_t2w, len(source_words))
    tw, th, tt = _groups(target_t2w, len(target_words))
    out = np.zeros((len(target_tokens), len(source_tokens)), dtype=np.float32)
    for rows, cols in zip(tw, sw):
        _spread(rows, cols, out)
    # special and punctuation tokens before the first word, and after it (in order)
    _spread_ends(th, sh, out, outer=0)
    _spread_ends(tt, st, out, outer=-1)
    return out


def _spread_ends(rows: list[int], cols: list[int], out: np.ndarray, outer: int) -> None:
    if len(rows) == len(cols):
        _spread(rows, cols, out)
    elif rows and cols:
        # different punctuation: pair only the outermost tokens ([CLS] / [SEP]); the other target
        # columns stay zero (no source attention to give them)
        out[rows[outer], cols[outer]] = 1.0
