"""The denoising process step by step: decoded snapshots as strips, and where attention goes per step.

A diffusion sampler runs S steps from pure noise (step 0, the noisiest) to the final latent; the
VAE can decode any intermediate latent into joints. Two views of that process:

* :func:`denoising_strips`: key poses of the motions decoded after chosen steps, one row per step,
  so the coarse motion can be seen appearing before the details.
* :func:`word_share_by_step` / :func:`plot_word_share_by_step`: at every step, the share of the
  cross-attention that goes to each word of the prompt (averaged over layers, heads, latent frames
  and body parts), and to the special tokens. It shows which words the model listens to early (the
  steps that decide the coarse motion, which is why attention edits such as the word swap replace
  the maps during the first steps) and late.

Arrays in, images and figures out: nothing here knows about a model.
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import to_numpy
from .attention import AXES, WORD_CHARS, merge_tokens, new_figure, reduce_attention

__all__ = ["word_share_by_step", "plot_word_share_by_step", "denoising_strips", "SPECIAL_LABEL"]

#: Label of the share that goes to tokens that are not words ([CLS], [SEP], padding, punctuation).
SPECIAL_LABEL = "special tokens"


def word_share_by_step(attention, tokens: Sequence[str], *, axes: str = "slhnpw", batch: int | None = None,
                       special: bool = True) -> tuple[np.ndarray, list[str]]:
    """Share of the cross-attention on each word at every denoising step.

    Parameters
    ----------
    attention : array
        Captured cross-attention with a step axis, e.g. ``(S, L, H, N', P, W)`` for ``axes="slhnpw"``
        (what ``AttentionMaps.full(b)`` returns); numpy or torch. Every axis other than steps and
        tokens is averaged (see :func:`salad_viz.attention.reduce_attention` for the letters).
    tokens : sequence of str
        The W tokens of the prompt (special tokens included). Word pieces (``##ing``, CLIP
        ``</w>``) are merged into their word (:func:`salad_viz.attention.merge_tokens`).
    axes : str
        One letter per axis of ``attention``; must contain ``s``, ``n``, ``p`` and ``w``.
    batch : int, optional
        Batch element, when ``attention`` has a batch axis ``b``.
    special : bool
        Add a last column with the share of every token that is not part of a word (special tokens
        and punctuation).

    Returns
    -------
    shares : ndarray (S, K) float64
        Row ``s``: the mean attention probability mass on each of the K words (then, with
        ``special``, on the rest) at step ``s``. For softmax maps (each part and frame's weights
        sum to 1 over the tokens) every row sums to 1 when ``special`` is on.
    labels : list of str
        The K labels: the words in prompt order (a repeated word gets ``" (2)"``, ...), then
        :data:`SPECIAL_LABEL`.
    """
    if not isinstance(axes, str) or "s" not in axes:
        raise ValueError(f"word_share_by_step needs a step axis 's' in axes, got {axes!r} "
                         f"(letters: {', '.join(f'{k} {v}' for k, v in AXES.items())})")
    arr = to_numpy(attention, "attention")
    if arr.ndim != len(axes):
        raise ValueError(f"axes {axes!r} names {len(axes)} axes but attention has {arr.ndim} (shape {arr.shape})")
    toks = [str(t) for t in tokens]
    if len(toks) != arr.shape[axes.index("w")]:
        raise ValueError(f"tokens has {len(toks)} entries but attention has W = {arr.shape[axes.index('w')]}")
    n_steps = arr.shape[axes.index("s")]
    # one (P, N', W) map per step, averaged over the parts and frames: (S, W)
    per_token = np.stack([reduce_attention(arr, axes, steps=s, batch=batch).mean(axis=(0, 1))
                          for s in range(n_steps)])
    groups = [(w, ids) for w, ids in merge_tokens(toks) if WORD_CHARS.search(w)]   # punctuation is no word
    if not groups:
        raise ValueError(f"tokens {toks} contain no word")
    labels, columns, seen = [], [], {}
    for word, ids in groups:
        k = seen.get(word, 0) + 1
        seen[word] = k
        labels.append(word if k == 1 else f"{word} ({k})")
        columns.append(per_token[:, list(ids)].sum(axis=1))
    if special:
        in_words = sorted({i for _, ids in groups for i in ids})
        rest = [i for i in range(len(toks)) if i not in in_words]
        labels.append(SPECIAL_LABEL)
        columns.append(per_token[:, rest].sum(axis=1) if rest else np.zeros(n_steps))
    return np.stack(columns, axis=1), labels


def plot_word_share_by_step(attention, tokens: Sequence[str], *, axes: str = "slhnpw", batch: int | None = None,
                            words: Sequence[str] | None = None, special: bool = True, ax=None,
                            figsize: tuple[float, float] = (7.0, 3.0), title: str | None = None):
    """Line plot of :func:`word_share_by_step`: one line per word, the special tokens dashed grey.

    Parameters
    ----------
    attention, tokens, axes, batch, special
        As in :func:`word_share_by_step`.
    words : sequence of str, optional
        Plot only these labels (as returned by :func:`word_share_by_step`); default: every word.
    ax : matplotlib Axes, optional
        Draw into it instead of a new figure.
    figsize : (width, height)
        Inches, for a new figure.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        The x axis is the step number from 1 (pure noise) to S, the y axis the share.
    """
    shares, labels = word_share_by_step(attention, tokens, axes=axes, batch=batch, special=special)
    keep = list(range(len(labels)))
    if words is not None:
        unknown = [w for w in words if w not in labels]
        if unknown:
            raise ValueError(f"words {unknown} are not among the prompt's labels {labels}")
        keep = [i for i, label in enumerate(labels) if label in words or (special and label == SPECIAL_LABEL)]
    if ax is None:
        fig = new_figure(figsize)
        ax = fig.subplots()
    else:
        fig = ax.figure
    steps = np.arange(1, shares.shape[0] + 1)
    for i in keep:
        if labels[i] == SPECIAL_LABEL and special:
            ax.plot(steps, shares[:, i], "--", color="0.5", label=labels[i])
        else:
            ax.plot(steps, shares[:, i], marker=".", label=labels[i])
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))      # steps are whole numbers
    ax.set_xlabel("denoising step (1 = pure noise)")
    ax.set_ylabel("share of cross-attention")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)   # beside, not on, the lines
    ax.grid(alpha=0.3)
    if title:
        ax.set_title(title)
    return fig


def denoising_strips(snapshots: Mapping[int, np.ndarray], skeleton: str | Skeleton = "humanml3d", *,
                     num_steps: int | None = None, frames: int | Sequence[int] = 5, size: Sequence[int] = (160, 200),
                     view: str | float = "side", backend: str = "auto") -> np.ndarray:
    """Key poses of the motions decoded after chosen denoising steps, one row per step.

    Parameters
    ----------
    snapshots : mapping step -> joints (N, J, 3)
        The motion decoded from the latent after step ``step`` (0-based: 0 is the first, noisiest
        step), in metres. Rows are drawn in increasing step order.
    skeleton : str or Skeleton
    num_steps : int, optional
        The sampler's number of steps S, for the row titles ("after step 5/20"); every step key must
        be in ``[0, S)``. Without it the titles read "after step 5".
    frames : int or sequence of int
        Key frames per row: how many, evenly spaced, or their indices
        (:func:`salad_viz.render.keyframe_strip`).
    size : (width, height)
        One tile, pixels.
    view, backend
        As in :func:`salad_viz.render.keyframe_strip`.

    Returns
    -------
    ndarray (H, W, 3) uint8
        The rows stacked top to bottom (narrower rows padded white on the right).
    """
    from .raster import vstack_images
    from .render import keyframe_strip

    if not isinstance(snapshots, Mapping) or not snapshots:
        raise ValueError("snapshots must be a non-empty mapping {step: joints (N, J, 3)}")
    if num_steps is not None and (isinstance(num_steps, bool) or not isinstance(num_steps, (int, np.integer))
                                  or num_steps < 1):
        raise ValueError(f"num_steps must be a positive int or None, got {num_steps!r}")
    for step in snapshots:
        if isinstance(step, bool) or not isinstance(step, (int, np.integer)) or step < 0 or \
                (num_steps is not None and step >= num_steps):
            allowed = "ints >= 0" if num_steps is None else f"ints in [0, {num_steps})"
            raise ValueError(f"snapshot step {step!r} is not a valid step index; allowed: {allowed}")
    sk = get_skeleton(skeleton)
    rows = []
    for step in sorted(snapshots):
        title = f"after step {step + 1}" + ("" if num_steps is None else f"/{num_steps}")
        rows.append(keyframe_strip(snapshots[step], sk, frames, layout="row", view=view, size=size,
                                   backend=backend, title=title))
    return vstack_images(rows, gap=4)
