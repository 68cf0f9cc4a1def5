"""Cross-attention heatmaps: body part x time maps per word, grids, layer/step views, comparisons.

SALAD's cross-attention (paper §3.2, Fig. 6) relates each skeleto-temporal latent token (latent
frame x body part) to each text token. A *map* for one word is ``(P, N')``: rows are the P = 7
body parts in the paper's order (root, left leg, right leg, spine, left arm, right arm, head) and
columns are latent frames, each covering ``frames_per_latent`` = 4 motion frames (the VAE's
temporal down-sampling). A full *attention* array is ``(P, N', W)`` over the W text tokens.

Captured attention with more axes (steps, layers, heads, batch) is reduced with
:func:`reduce_attention`, which takes an ``axes`` string naming each axis, so it fits whatever
layout the capture produced: ``s`` step, ``l`` layer, ``b`` batch, ``h`` head, ``n`` latent frame,
``p`` body part, ``w`` token. The official visualisation averages over steps, layers and heads
and normalises each map by its maximum (viridis, rows = parts); that is the default here too.

Words are picked by token index, by text (``"walks forward"``: consecutive words, WordPiece
``##`` pieces and CLIP ``</w>`` pieces are merged) or by a list of those, whose maps are *summed*
(the official notebook's sum over word pairs).
"""
from __future__ import annotations

import re
from typing import Sequence

import numpy as np

from salad_core.skeleton import PART_MIRROR, PART_NAMES, Skeleton, get_skeleton

from ._arrays import to_numpy
from ._style import figure_text

__all__ = [
    "AXES",
    "SPECIAL_TOKENS",
    "WORD_CHARS",
    "new_figure",
    "reduce_attention",
    "merge_tokens",
    "word_token_ids",
    "select_words",
    "mirror_attention",
    "joint_attention",
    "joint_attention_colors",
    "plot_word_attention",
    "plot_attention_grid",
    "plot_attention_rows",
    "attention_limits",
    "plot_attention_by_layer",
    "plot_attention_by_steps",
    "plot_attention_comparison",
    "plot_mirror_comparison",
    "plot_joint_attention",
]

#: Axis letters understood by :func:`reduce_attention`.
AXES = {"s": "step", "l": "layer", "b": "batch", "h": "head", "n": "latent frame", "p": "body part", "w": "token"}
#: Tokens that are never words (BERT/WordPiece, CLIP, SentencePiece conventions).
SPECIAL_TOKENS = frozenset({
    "[cls]", "[sep]", "[pad]", "[mask]", "[unk]", "<|startoftext|>", "<|endoftext|>", "<s>", "</s>",
    "<pad>", "<unk>", "<bos>", "<eos>", "",
})
#: What a word is made of (lower-case letters, digits, apostrophes): tokens without any are
#: punctuation or special tokens, not words.
WORD_CHARS = re.compile(r"[a-z0-9']+")


# --------------------------------------------------------------------------- reduction
def _index(sel, size: int, name: str) -> np.ndarray:
    """Indices along an axis from None / int / (start, stop) / slice / sequence of ints."""
    if sel is None:
        return np.arange(size)
    if isinstance(sel, slice):
        idx = np.arange(size)[sel]
    elif isinstance(sel, (int, np.integer)) and not isinstance(sel, bool):
        if not -size <= sel < size:
            raise ValueError(f"{name}={sel} is out of range for {size} {name}")
        idx = np.array([int(sel) % size])
    elif isinstance(sel, tuple) and len(sel) == 2 and all(isinstance(v, (int, np.integer)) or v is None for v in sel):
        idx = np.arange(size)[slice(sel[0], sel[1])]
    else:
        try:
            idx = np.asarray(list(sel), dtype=int)
        except (TypeError, ValueError):
            raise TypeError(f"{name} must be None, an int, a (start, stop) pair, a slice or a list of ints; "
                            f"got {sel!r}") from None
        if ((idx < -size) | (idx >= size)).any():
            raise ValueError(f"{name}={list(idx)} has indices out of range for {size} {name}")
        idx = idx % size
    if len(idx) == 0:
        raise ValueError(f"{name}={sel!r} selects nothing out of {size} {name}")
    return idx


def reduce_attention(attention, axes: str = "pnw", *, steps=None, layers=None, heads=None, batch=None) -> np.ndarray:
    """Average captured cross-attention down to ``(P, N', W)``.

    Parameters
    ----------
    attention : array
        Captured maps with the axes named by ``axes`` (numpy or a CPU/GPU torch tensor).
    axes : str
        One letter per axis of ``attention``, e.g. ``"slhnpw"`` for (steps, layers, heads, N', P, W)
        or ``"bhnpw"`` for one site's ``(B, H, N', P, W)``. Must contain ``n``, ``p`` and ``w``;
        may contain ``s``, ``l``, ``b``, ``h`` (see :data:`AXES`).
    steps, layers, heads : None, int, (start, stop), slice or list of int
        Which entries to average over (``None`` = all). Step 0 is the first (noisiest) step.
    batch : int, optional
        Which batch element to take; required when the batch axis has more than one entry
        (with classifier-free guidance the conditional half is usually the second).

    Returns
    -------
    ndarray (P, N', W)
        The mean over the selected steps, layers and heads.
    """
    arr = to_numpy(attention, "attention")
    if not isinstance(axes, str) or len(set(axes)) != len(axes) or set(axes) - set(AXES):
        raise ValueError(f"axes must be distinct letters from {''.join(AXES)!r} (one per axis), got {axes!r}")
    if len(axes) != arr.ndim:
        raise ValueError(f"axes {axes!r} names {len(axes)} axes but attention has {arr.ndim} (shape {arr.shape})")
    for need in "npw":
        if need not in axes:
            raise ValueError(f"axes {axes!r} must contain {need!r} ({AXES[need]})")
    given = {"s": steps, "l": layers, "h": heads}
    for letter, sel in given.items():
        if sel is not None and letter not in axes:
            raise ValueError(f"{AXES[letter]}s were selected but attention has no {AXES[letter]} axis (axes {axes!r})")
    if "b" in axes:
        size = arr.shape[axes.index("b")]
        if batch is None and size != 1:
            raise ValueError(f"attention has a batch axis of size {size}; pass batch=<index> "
                             "(with CFG the conditional half is usually index 1)")
        arr = np.take(arr, _index(0 if batch is None else batch, size, "batch"), axis=axes.index("b"))
    elif batch is not None:
        raise ValueError(f"batch={batch} was given but attention has no batch axis (axes {axes!r})")
    for letter in "slh":
        if letter in axes:
            ax = axes.index(letter)
            arr = np.take(arr, _index(given[letter], arr.shape[ax], AXES[letter] + "s"), axis=ax)
    keep = [axes.index(c) for c in "pnw"]
    reduce = tuple(i for i in range(arr.ndim) if i not in keep)
    if reduce:
        arr = arr.mean(axis=reduce, keepdims=True)
    arr = np.transpose(arr, keep + list(reduce)).reshape(arr.shape[keep[0]], arr.shape[keep[1]], arr.shape[keep[2]])
    return arr


# --------------------------------------------------------------------------- tokens and words
def _clean(tok: str) -> str:
    t = tok.lower().strip()
    if t.startswith("▁"):  # SentencePiece word start
        t = t[1:]
    return t


def merge_tokens(tokens: Sequence[str]) -> list[tuple[str, tuple[int, ...]]]:
    """Group tokens into words: ``[(word, token_indices), ...]``, special tokens left out.

    WordPiece continuation pieces (``##ing``) join the previous token; CLIP BPE pieces join until a
    piece ending in ``</w>``. Tokens that are plain words pass through one per word.
    """
    toks = [str(t) for t in tokens]
    clip_style = any(t.endswith("</w>") for t in toks)
    words: list[tuple[str, tuple[int, ...]]] = []
    cur_text, cur_idx = "", []
    for i, tok in enumerate(toks):
        low = _clean(tok)
        if low in SPECIAL_TOKENS:
            if cur_idx:
                words.append((cur_text, tuple(cur_idx)))
                cur_text, cur_idx = "", []
            continue
        if low.startswith("##") and words and not cur_idx:
            text, idx = words.pop()
            words.append((text + low[2:], idx + (i,)))
            continue
        if clip_style:
            cur_text += low.removesuffix("</w>")
            cur_idx.append(i)
            if low.endswith("</w>"):
                words.append((cur_text, tuple(cur_idx)))
                cur_text, cur_idx = "", []
        else:
            words.append((low, (i,)))
    if cur_idx:
        words.append((cur_text, tuple(cur_idx)))
    return words


def word_token_ids(tokens: Sequence[str], word) -> tuple[int, ...]:
    """Token indices of a word query.

    Parameters
    ----------
    tokens : sequence of str
        The W tokens (or words) labelling the attention's last axis.
    word : int, str or sequence of int/str
        A token index; a text of one or more consecutive words (``"walks forward"``), matched
        case-insensitively against the merged words; or a list of those (indices are united).

    Returns
    -------
    tuple of int
        Sorted token indices.
    """
    n = len(tokens)
    if isinstance(word, (int, np.integer)) and not isinstance(word, bool):
        if not -n <= word < n:
            raise ValueError(f"token index {word} is out of range for {n} tokens")
        return (int(word) % n,)
    if isinstance(word, str):
        query = WORD_CHARS.findall(word.lower())
        if not query:
            raise ValueError(f"word {word!r} contains no letters")
        merged = merge_tokens(tokens)
        texts = [w for w, _ in merged]
        hits = [i for i in range(len(texts) - len(query) + 1) if texts[i:i + len(query)] == query]
        if not hits:
            raise ValueError(f"word {word!r} is not in the tokens; words are: {' '.join(texts)}")
        if len(hits) > 1:
            where = ", ".join(str([t for k in range(h, h + len(query)) for t in merged[k][1]]) for h in hits)
            raise ValueError(f"word {word!r} occurs {len(hits)} times (token indices {where}); "
                             "pass the token indices or a longer phrase")
        h = hits[0]
        return tuple(t for k in range(h, h + len(query)) for t in merged[k][1])
    if isinstance(word, Sequence) or isinstance(word, np.ndarray):
        out: set[int] = set()
        for item in word:
            out.update(word_token_ids(tokens, item))
        if not out:
            raise ValueError("an empty list selects no tokens")
        return tuple(sorted(out))
    raise TypeError(f"word must be an int, a str or a list of those, got {type(word).__name__}")


def _label(tokens: Sequence[str], ids: Sequence[int]) -> str:
    """Readable label of a token group (sub-word pieces joined, special tokens kept verbatim)."""
    text = " ".join(w for w, _ in merge_tokens([tokens[i] for i in ids]))
    return text or " ".join(str(tokens[i]) for i in ids)


def _check_attention(attention, name: str = "attention") -> np.ndarray:
    arr = to_numpy(attention, name)
    if arr.ndim != 3:
        raise ValueError(f"{name} must be (P, N', W) (use reduce_attention for captured maps with more axes), "
                         f"got shape {arr.shape}")
    if arr.shape[0] != len(PART_NAMES):
        raise ValueError(f"{name} must have P = {len(PART_NAMES)} body-part rows on axis 0, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def select_words(attention, tokens: Sequence[str], word_ids=None) -> tuple[np.ndarray, list[str]]:
    """Maps of chosen words.

    Parameters
    ----------
    attention : array (P, N', W)
    tokens : sequence of str, length W
    word_ids : sequence, optional
        One entry per map: an int, a str or a list of those (their token maps are summed).
        ``None``: every word of ``tokens`` (special tokens skipped, sub-word pieces summed).

    Returns
    -------
    maps : ndarray (K, P, N')
    labels : list of str, length K
    """
    arr = _check_attention(attention)
    if len(tokens) != arr.shape[2]:
        raise ValueError(f"tokens has {len(tokens)} entries but attention has W = {arr.shape[2]} tokens")
    if word_ids is None:
        # every word; pure punctuation tokens ("," ".") are left out
        groups = [(w, ids) for w, ids in merge_tokens(tokens) if WORD_CHARS.search(w)]
        if not groups:
            raise ValueError("tokens contain no words (only special tokens and punctuation)")
        labels = [w for w, _ in groups]
        ids_list = [ids for _, ids in groups]
    else:
        if isinstance(word_ids, (str, int, np.integer)):
            word_ids = [word_ids]
        ids_list = [word_token_ids(tokens, w) for w in word_ids]
        labels = [w if isinstance(w, str) else _label(tokens, ids) for w, ids in zip(word_ids, ids_list)]
    maps = np.stack([arr[:, :, list(ids)].sum(axis=2) for ids in ids_list])
    return maps, labels


def mirror_attention(maps, skeleton: str | Skeleton | None = None, axis: int = 0) -> np.ndarray:
    """Swap the left/right body-part rows (left leg <-> right leg, left arm <-> right arm).

    Parameters
    ----------
    maps : array with P = 7 entries along ``axis`` (e.g. ``(P, N')`` or ``(P, N', W)``)
    skeleton : ignored except for validation; the part mirror is the same for every skeleton.
    axis : int
        The body-part axis.

    Returns
    -------
    ndarray
        A new array; mirroring twice gives the input back.
    """
    if skeleton is not None:
        get_skeleton(skeleton)
    arr = to_numpy(maps, "maps")
    if arr.shape[axis] != len(PART_MIRROR):
        raise ValueError(f"maps must have {len(PART_MIRROR)} body parts along axis {axis}, got shape {arr.shape}")
    return np.take(arr, list(PART_MIRROR), axis=axis)


# --------------------------------------------------------------------------- joints <- parts
def _check_map(maps, name: str = "maps") -> np.ndarray:
    arr = to_numpy(maps, name)
    if arr.ndim != 2 or arr.shape[0] != len(PART_NAMES):
        raise ValueError(f"{name} must be one word's map (P, N') with P = {len(PART_NAMES)}, got shape {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"{name} contains NaN or inf")
    return arr


def joint_attention(maps, skeleton: str | Skeleton = "humanml3d", n_frames: int | None = None, *,
                    frames_per_latent: int = 4) -> np.ndarray:
    """Per-frame, per-joint attention: each joint takes its body part's value at its latent frame.

    Parameters
    ----------
    maps : array (P, N')
        One word's map.
    skeleton : str or Skeleton
        Supplies ``joint_to_part``.
    n_frames : int, optional
        Motion length N; default ``N' * frames_per_latent``. Frames past the last latent frame
        take the last column.
    frames_per_latent : int
        Motion frames per latent frame (4 in SALAD).

    Returns
    -------
    ndarray (N, J)
    """
    skel = get_skeleton(skeleton)
    arr = _check_map(maps)
    fpl = _check_fpl(frames_per_latent)
    n = arr.shape[1] * fpl if n_frames is None else int(n_frames)
    if n < 1:
        raise ValueError(f"n_frames must be >= 1, got {n_frames}")
    cols = np.minimum(np.arange(n) // fpl, arr.shape[1] - 1)
    return arr[np.asarray(skel.joint_to_part)][:, cols].T.copy()


def joint_attention_colors(maps, skeleton: str | Skeleton = "humanml3d", n_frames: int | None = None, *,
                           frames_per_latent: int = 4, cmap: str = "viridis", normalize: bool = True,
                           vmax: float | None = None) -> np.ndarray:
    """Joint colours ``(N, J, 3)`` from a word's map, for ``joint_colors=`` of the renderers.

    Values are divided by the map's maximum (``normalize``, as the heatmaps do) or by ``vmax``,
    then coloured with ``cmap`` (viridis by default, so joints match the heatmap).
    """
    from matplotlib import colormaps

    vals = joint_attention(maps, skeleton, n_frames, frames_per_latent=frames_per_latent)
    top = vmax if vmax is not None else (float(np.abs(_check_map(maps)).max()) if normalize else 1.0)
    scaled = np.clip(vals / top, 0.0, 1.0) if top > 0 else np.zeros_like(vals)
    return colormaps[cmap](scaled)[..., :3].astype(np.float64)


def _check_fpl(frames_per_latent) -> int:
    if isinstance(frames_per_latent, bool) or not isinstance(frames_per_latent, (int, np.integer)) or frames_per_latent < 1:
        raise ValueError(f"frames_per_latent must be a positive int, got {frames_per_latent!r}")
    return int(frames_per_latent)


# --------------------------------------------------------------------------- plotting
def _figure_png(fig) -> bytes:
    import io

    buf = io.BytesIO()
    fig.savefig(buf, format="png", bbox_inches="tight")
    return buf.getvalue()


def _ensure_notebook_display() -> None:
    """Let IPython show a returned ``Figure`` as PNG even when no inline backend is active."""
    try:
        from IPython import get_ipython
    except ImportError:
        return
    ip = get_ipython()
    if ip is None:
        return
    from matplotlib.figure import Figure

    png = ip.display_formatter.formatters["image/png"]
    try:
        png.lookup_by_type(Figure)  # the inline backend already formats figures
    except KeyError:
        png.for_type(Figure, _figure_png)


def new_figure(figsize: tuple[float, float]):
    """A ``matplotlib.figure.Figure`` of ``figsize`` (inches) outside pyplot's global state: no
    leaks, no double display in notebooks.

    A notebook shows it when it is a cell's value (or through ``display(fig)``).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    _ensure_notebook_display()
    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _new_axes(ax, figsize):
    if ax is not None:
        return ax.figure, ax
    fig = new_figure(figsize)
    return fig, fig.subplots()


#: Colour map of signed maps (an edit's re-weighted maps can be negative): blue < 0 < red, white at 0.
DIVERGING_CMAP = "RdBu_r"
#: ``normalize`` values: one scale for all panels ("global", alias "shared"), per panel ("each", True), raw.
NORMALIZE = ("global", "shared", "each", "none")
#: Title colour of a panel whose word the model never saw in training.
UNKNOWN_COLOR = "#b2182b"


def attention_limits(*maps) -> tuple[float, float]:
    """One colour scale ``(vmin, vmax)``, in attention units, for several sets of heatmaps (e.g. the
    source's and the edit's word maps, so that their figures compare cell by cell).

    Parameters
    ----------
    *maps : arrays of any shape
        E.g. ``(K, P, N')`` word maps of each figure; NaN entries (absent words) are ignored.

    Returns
    -------
    (vmin, vmax)
        ``(0, m)`` when no value is negative, else ``(-m, m)``: symmetric about 0, the centre of the
        diverging colour map (:data:`DIVERGING_CMAP`); ``m`` is the largest ``|value|`` (1 when all are 0).
    """
    if not maps:
        raise ValueError("attention_limits needs at least one array of maps")
    arrays = [np.asarray(to_numpy(m, "maps"), dtype=np.float64) for m in maps]
    values = np.concatenate([a[np.isfinite(a)] for a in arrays])
    top = float(np.abs(values).max()) if values.size else 0.0
    top = top if top > 0 else 1.0
    return (-top if (values < 0).any() else 0.0), top


def _check_limits(limits) -> tuple[float, float]:
    """``(vmin, vmax)`` as :func:`attention_limits` returns them: ``(0, m)`` or ``(-m, m)``, ``m > 0``."""
    try:
        vmin, vmax = (float(v) for v in limits)
    except (TypeError, ValueError):
        raise TypeError(f"limits must be a (vmin, vmax) pair of numbers, got {limits!r}") from None
    if not (np.isfinite(vmin) and np.isfinite(vmax) and vmax > 0 and (vmin == 0 or np.isclose(vmin, -vmax))):
        raise ValueError(f"limits={limits!r} must be (0, m) or (-m, m) with m > 0 (see attention_limits)")
    return vmin, vmax


def _normalise(maps: np.ndarray, normalize, limits=None) -> tuple[np.ndarray, float, float]:
    """Scale ``(K, P, N')`` maps for display: "each" (per map max), "global"/"shared" (common max) or none.

    Returns ``(shown, vmin, vmax)``. Maps with negative values (signed, e.g. an edit's negative
    re-weight) keep their sign and get symmetric limits ``vmin = -vmax``, drawn with a diverging
    colour map centred at 0 (:func:`_draw_map`); others are clipped at 0 as the official plots do.
    ``limits`` (from :func:`attention_limits`, e.g. over two figures) fixes the common maximum and
    whether the scale is signed, instead of these maps' own.
    """
    if limits is not None:
        lo, hi = _check_limits(limits)
        signed, common = lo < 0, hi
    else:
        signed = bool((maps < 0).any())
        common = float(np.abs(maps).max()) if maps.size else 0.0
    low = (lambda x: x) if signed else (lambda x: np.clip(x, 0, None))
    if normalize in (True, "each"):
        top = np.abs(maps).reshape(len(maps), -1).max(axis=1)
        out = np.where(top[:, None, None] > 0, low(maps) / np.where(top > 0, top, 1)[:, None, None], 0.0)
        return out, (-1.0 if signed else 0.0), 1.0
    if normalize in ("global", "shared"):
        return (low(maps) / common if common > 0 else np.zeros_like(maps)), (-1.0 if signed else 0.0), 1.0
    if normalize in (False, None, "none"):
        if limits is not None:
            return maps, lo, hi
        if signed:
            return maps, -common, common
        return maps, float(min(0.0, maps.min())), float(maps.max()) if maps.max() > 0 else 1.0
    raise ValueError(f"normalize must be 'global' ('shared'), 'each' (True) or 'none' (False), got {normalize!r}")


def _draw_map(ax, m: np.ndarray, *, fpl: int, cmap, vmin, vmax, title, part_labels: bool, fps=None,
              frame=None, xlabel=True, part_names=PART_NAMES):
    p, n_lat = m.shape
    n_frames = n_lat * fpl
    scale = 1.0 / fps if fps else 1.0
    if vmin is not None and vmax is not None and vmin < 0 < vmax and np.isclose(-vmin, vmax):
        from matplotlib.colors import CenteredNorm   # signed: 0 is the centre of the colour map

        limits = dict(norm=CenteredNorm(vcenter=0.0, halfrange=float(vmax)))
    else:
        limits = dict(vmin=vmin, vmax=vmax)
    im = ax.imshow(m, aspect="auto", cmap=cmap, interpolation="nearest",
                   extent=(0, n_frames * scale, p - 0.5, -0.5), **limits)
    ax.set_yticks(np.arange(p))
    ax.set_yticklabels(part_names if part_labels else [])
    if not part_labels:
        ax.tick_params(axis="y", length=0)
    if xlabel:
        ax.set_xlabel("time (s)" if fps else "motion frame")
    if title is not None:
        ax.set_title(title)
    if frame is not None:
        ax.axvline((frame + 0.5) * scale, color="white", lw=1.5)
        ax.axvline((frame + 0.5) * scale, color="black", lw=0.6, ls="--")
    ax.set_xlim(0, n_frames * scale)  # cursors past the last latent frame must not widen the axis
    return im


def plot_word_attention(maps, word: str | None = None, *, ax=None, skeleton: str | Skeleton = "humanml3d",
                        frames_per_latent: int = 4, normalize="each", cmap: str = "viridis",
                        colorbar: bool = True, part_labels: bool = True, fps: float | None = None,
                        frame: int | None = None, diverging_cmap: str = DIVERGING_CMAP):
    """Heatmap of one word: 7 body-part rows (paper order, labelled) x motion time.

    Parameters
    ----------
    maps : array (P, N')
        One word's attention (see :func:`select_words`).
    word : str, optional
        Title.
    ax : matplotlib Axes, optional
        Draw into this axes; a new figure is made otherwise.
    skeleton : str or Skeleton
        Checked for consistency; the part names are the paper's 7 parts.
    frames_per_latent : int
        Motion frames per latent column (4 in SALAD); the x axis is in motion frames.
    normalize : {"each", "global", "shared", "none"} or bool
        "each"/True divides by the map's maximum (the official plots do), "none" shows raw values.
    cmap : str
        Colormap (viridis, as in the official code).
    diverging_cmap : str
        Colormap of a signed map (negative values, e.g. after a negative re-weight), centred at 0.
    colorbar, part_labels : bool
    fps : float, optional
        Label the x axis in seconds instead of frames.
    frame : int, optional
        Draw a cursor at this motion frame.

    Returns
    -------
    matplotlib.figure.Figure
    """
    get_skeleton(skeleton)
    m = _check_map(maps)
    fpl = _check_fpl(frames_per_latent)
    shown, vmin, vmax = _normalise(m[None], normalize)
    fig, ax = _new_axes(ax, (max(3.5, 0.12 * m.shape[1] * fpl / 4 + 2.0), 2.4))
    im = _draw_map(ax, shown[0], fpl=fpl, cmap=diverging_cmap if vmin < 0 else cmap, vmin=vmin, vmax=vmax,
                   title=word, part_labels=part_labels, fps=fps, frame=frame)
    if colorbar:
        cb = fig.colorbar(im, ax=ax, fraction=0.05, pad=0.02)
        cb.set_label(colorbar_label(normalize, signed=vmin < 0))
    return fig


def _grid(maps: np.ndarray, titles: Sequence[str], *, ncols, fpl, cmap, normalize, suptitle, panel_size,
          colorbar, fps=None, row_titles=None, diverging_cols=(), ncols_fixed=None,
          diverging_cmap: str = DIVERGING_CMAP, marked: Sequence[int] = (), limits=None):
    k = len(maps)
    ncols = ncols_fixed or (min(k, 4) if ncols is None else int(ncols))
    if ncols < 1:
        raise ValueError(f"ncols must be >= 1, got {ncols}")
    nrows = int(np.ceil(k / ncols))
    fig = new_figure((panel_size[0] * ncols + 1.2, panel_size[1] * nrows + 0.6))
    axs = fig.subplots(nrows, ncols, squeeze=False)
    shown, vmin, vmax = _normalise(maps, normalize, limits)
    signed = vmin < 0
    im = None
    for i in range(nrows * ncols):
        ax = axs[i // ncols][i % ncols]
        if i >= k:
            ax.axis("off")
            continue
        im = _draw_map(ax, shown[i], fpl=fpl, cmap=diverging_cmap if signed else cmap, vmin=vmin, vmax=vmax,
                       title=titles[i], part_labels=(i % ncols == 0), fps=fps, xlabel=(i + ncols >= k))
        if i in marked:
            ax.title.set_color(UNKNOWN_COLOR)
    if suptitle:
        # a prompt in another script: an installed font that has it, else "?" (said), never boxes
        text, family = figure_text(str(suptitle))
        fig.suptitle(_wrap_title(text, panel_size[0] * ncols + 1.2), **({"fontfamily": family} if family else {}))
    if colorbar and im is not None:
        cb = fig.colorbar(im, ax=axs, fraction=0.03, pad=0.01, shrink=0.9)
        cb.set_label(colorbar_label(normalize, signed=signed))
    return fig


def colorbar_label(normalize, signed: bool = False) -> str:
    """What the colours of a heatmap mean under ``normalize`` (the colour bar's label); ``signed``: the
    maps have negative values (scaled by their largest magnitude, 0 at the centre)."""
    top = "largest |value|" if signed else "maximum"
    if normalize in (True, "each"):
        return f"attention / its panel's {top}"
    if normalize in ("shared", "global"):
        return f"attention / {top} over all panels"
    return "attention (signed, after the edit)" if signed else "attention weight (softmax probability)"


def _wrap_title(text: str, width_inches: float, points: float = 12.0) -> str:
    """Wrap a figure title to about ``width_inches`` (a character is about 0.55 em wide)."""
    import textwrap

    chars = max(20, int(width_inches * 72 / (0.55 * points)))
    return "\n".join(textwrap.wrap(str(text), chars)) or str(text)


def _distinct_labels(labels: Sequence[str], index: Sequence[str]) -> list[str]:
    """Labels that occur more than once get their word index, e.g. ``forward [3]`` and ``forward [7]``."""
    counts: dict[str, int] = {}
    for lab in labels:
        counts[lab] = counts.get(lab, 0) + 1
    return [f"{lab} [{i}]" if counts[lab] > 1 else lab for lab, i in zip(labels, index)]


def plot_attention_grid(attention, tokens: Sequence[str], word_ids=None, *, ncols: int | None = None,
                        prompt: str | None = None, skeleton: str | Skeleton = "humanml3d",
                        frames_per_latent: int = 4, normalize="global", cmap: str = "viridis",
                        panel_size: tuple[float, float] = (3.4, 2.0), colorbar: bool = True,
                        fps: float | None = None, unknown_words: Sequence[str] = (),
                        diverging_cmap: str = DIVERGING_CMAP, limits: tuple[float, float] | None = None):
    """Heatmaps of several words in the layout of the paper's Fig. 6.

    One panel per entry of ``word_ids`` (a row of up to 4, wrapping), part labels on the left
    column, the prompt as the figure title. By default every panel shares one colour scale
    (``normalize="global"``), so a word that draws little attention looks dim; ``"each"`` scales
    each panel to its own maximum (the official plots), which shows every map's shape but makes a
    word the model ignores look as bright as the one it follows.

    Parameters
    ----------
    attention : array (P, N', W)
    tokens : sequence of str, length W
    word_ids : sequence, optional
        Per panel an int, a str (``"walks forward"``) or a list of those, summed; ``None`` = every
        word. E.g. Fig. 6: ``["jumps forward", "walks forward", ["waving", "arms"]]``.
    ncols : int, optional
        Panels per row (default ``min(K, 4)``).
    prompt : str, optional
        Figure title.
    normalize : {"global", "each", "none"} or bool
        "global" (default; alias "shared"): every panel divided by the largest value of all panels;
        "each"/True: by its own maximum; "none": raw values.
    skeleton, frames_per_latent, cmap, fps
        As in :func:`plot_word_attention`.
    panel_size : (width, height)
        Inches per panel.
    colorbar : bool
        One shared colorbar, labelled with what the colours mean (with ``"each"``: every panel is
        divided by its own maximum, so colours compare within a panel, not across panels).
    unknown_words : sequence of str
        Words the model never saw in training (e.g. ``out.unknown_words[b]``): their panels are
        titled ``"cartwheel (unknown)"`` in red, since their maps say nothing the model learned.
    diverging_cmap : str
        Colour map used instead of ``cmap`` when a map has negative values (an edit's negative
        re-weight): centred at 0 (white), negative blue, positive red; the scale is symmetric.
    limits : (vmin, vmax), optional
        A colour scale shared with other figures (:func:`attention_limits` over all their maps): the
        common maximum of "global" and whether the scale is signed come from it, not from these maps
        alone, so a source's figure and its edit's read on one scale.

    Panels of a word that occurs more than once are labelled with its index (``forward [3]``: the
    word index for ``word_ids=None`` and for integer ids, else the panel's position).

    Returns
    -------
    matplotlib.figure.Figure
    """
    get_skeleton(skeleton)
    maps, labels = select_words(attention, tokens, word_ids)
    if word_ids is None:
        index = [str(k) for k in range(len(labels))]
    else:
        ids = [word_ids] if isinstance(word_ids, (str, int, np.integer)) else list(word_ids)
        index = [str(w) if isinstance(w, (int, np.integer)) else str(k) for k, w in enumerate(ids)]
    labels = _distinct_labels(labels, index)
    unknown = {w.lower() for w in (unknown_words or ())}
    marked = [k for k, lab in enumerate(labels) if unknown & set(WORD_CHARS.findall(lab.lower()))]
    labels = [f"{lab} (unknown)" if k in marked else lab for k, lab in enumerate(labels)]
    return _grid(maps, labels, ncols=ncols, fpl=_check_fpl(frames_per_latent), cmap=cmap, normalize=normalize,
                 suptitle=prompt, panel_size=panel_size, colorbar=colorbar, fps=fps,
                 diverging_cmap=diverging_cmap, marked=marked, limits=limits)


def _block_labels(words: Sequence[str], unknown: Sequence[str]) -> tuple[list[str], list[int]]:
    """Panel titles of one block (repeated words indexed, unknown words marked) and the marked panels."""
    labels = _distinct_labels([str(w) for w in words], [str(k) for k in range(len(words))])
    unknown_set = {w.lower() for w in unknown}
    marked = [k for k, lab in enumerate(labels) if unknown_set & set(WORD_CHARS.findall(lab.lower()))]
    return [f"{lab} (unknown)" if k in marked else lab for k, lab in enumerate(labels)], marked


def _balanced_columns(k: int, most: int = 6) -> int:
    """Panels per line for ``k`` panels: as few lines as ``most`` per line allows, filled evenly."""
    lines = int(np.ceil(k / most))
    return int(np.ceil(k / lines))


def _check_rows(maps, words, titles) -> list[np.ndarray]:
    """The blocks of :func:`plot_attention_rows` as ``(K_r, P, N'_r)`` float arrays, checked against
    their words and titles."""
    if isinstance(titles, str) or len(maps) != len(words) or len(maps) != len(titles) or not len(maps):
        raise ValueError(f"maps, words and titles need one entry per block; got {len(maps)}, {len(words)} and "
                         f"{len(titles) if not isinstance(titles, str) else 'a string'}")
    out = []
    for r, (m, w) in enumerate(zip(maps, words)):
        arr = np.asarray(to_numpy(m, f"maps[{r}]"), dtype=np.float64)
        if arr.ndim != 3 or arr.shape[1] != len(PART_NAMES) or not len(arr):
            raise ValueError(f"maps[{r}] must be (K, P, N') word maps with K >= 1 and P = {len(PART_NAMES)}, "
                             f"got shape {arr.shape}")
        if len(w) != len(arr):
            raise ValueError(f"words[{r}] has {len(w)} labels for {len(arr)} maps")
        if not np.isfinite(arr).all():
            raise ValueError(f"maps[{r}] contains NaN or inf")
        out.append(arr)
    return out


def plot_attention_rows(maps: Sequence, words: Sequence[Sequence[str]], titles: Sequence[str], *,
                        normalize="global", limits: tuple[float, float] | None = None, ncols: int | None = None,
                        frames_per_latent: int = 4, cmap: str = "viridis", diverging_cmap: str = DIVERGING_CMAP,
                        panel_size: tuple[float, float] = (3.0, 1.8), fps: float | None = None,
                        unknown_words: Sequence[Sequence[str]] = (), suptitle: str | None = None):
    """Word heatmaps of several motions, one titled block of panels per motion, on ONE colour scale:
    the figure that compares a source's attention with its edit's.

    Parameters
    ----------
    maps : sequence of arrays ``(K_r, P, N'_r)``
        Per block (motion) the maps of its ``K_r`` words (e.g. ``AttentionMaps.word_map`` stacked).
    words : sequence of sequences of str
        Per block the ``K_r`` panel titles (repeated words get their index, ``forward [3]``).
    titles : sequence of str
        Per block its title, e.g. ``"source: a man raises his right hand high"`` and
        ``"Reweight(high=-1): a man raises his right hand high"``; long titles wrap.
    normalize : {"global", "each", "none"}
        As in :func:`plot_attention_grid`; "global" (default) divides every panel of every block by one
        maximum, so a cell's colour compares across blocks.
    limits : (vmin, vmax), optional
        The colour scale (:func:`attention_limits`); default: the one of all the blocks' maps, a
        diverging map centred at 0 when any value is negative (a negative re-weight).
    ncols : int, optional
        Panels per line of a block (default: the most words of a block on one line up to 6, else as few
        lines as that allows, evenly filled: 7 words are 4 + 3, not 6 + 1).
    unknown_words : sequence of sequences of str, optional
        Per block the words the model never saw in training (titled in red, "(unknown)").
    frames_per_latent, cmap, diverging_cmap, panel_size, fps
        As in :func:`plot_attention_grid`.
    suptitle : str, optional
        A title above all blocks.

    Returns
    -------
    matplotlib.figure.Figure
        Blocks top to bottom (``fig.subfigs[0].subfigs``), one colour bar on the right for all.
    """
    arrays = _check_rows(maps, words, titles)
    fpl = _check_fpl(frames_per_latent)
    limits = attention_limits(*arrays) if limits is None else _check_limits(limits)
    ncols = _balanced_columns(max(len(a) for a in arrays)) if ncols is None else int(ncols)
    if ncols < 1:
        raise ValueError(f"ncols must be >= 1, got {ncols}")
    lines = [int(np.ceil(len(a) / ncols)) for a in arrays]
    title_h = 0.5
    width = panel_size[0] * ncols + 0.9
    fig = new_figure((width + 1.0, sum(panel_size[1] * n + title_h for n in lines) + (0.4 if suptitle else 0.0)))
    body, bar = fig.subfigures(1, 2, width_ratios=[width, 1.0])
    blocks = body.subfigures(len(arrays), 1, height_ratios=[panel_size[1] * n + title_h for n in lines],
                             squeeze=False)[:, 0]
    unknown = list(unknown_words) + [()] * (len(arrays) - len(unknown_words))
    im = None
    for block, arr, labels, title, n_lines, unk in zip(blocks, arrays, words, titles, lines, unknown):
        shown, vmin, vmax = _normalise(arr, normalize, limits)
        axs = block.subplots(n_lines, ncols, squeeze=False)
        panel_titles, marked = _block_labels(labels, unk)
        for i in range(n_lines * ncols):
            ax = axs[i // ncols][i % ncols]
            if i >= len(arr):
                ax.axis("off")
                continue
            im = _draw_map(ax, shown[i], fpl=fpl, cmap=diverging_cmap if vmin < 0 else cmap, vmin=vmin, vmax=vmax,
                           title=panel_titles[i], part_labels=(i % ncols == 0), fps=fps,
                           xlabel=(i + ncols >= len(arr)))
            if i in marked:
                ax.title.set_color(UNKNOWN_COLOR)
        text, family = figure_text(str(title))
        block.suptitle(_wrap_title(text, width, 13.0), x=0.01, ha="left", fontsize=13, fontweight="bold",
                       **({"fontfamily": family} if family else {}))
    cax = bar.add_axes((0.15, 0.08, 0.22, 0.84))
    cb = fig.colorbar(im, cax=cax)
    cb.set_label(colorbar_label(normalize, signed=limits[0] < 0))
    if suptitle:
        text, family = figure_text(str(suptitle))
        fig.suptitle(_wrap_title(text, width + 1.0), **({"fontfamily": family} if family else {}))
    return fig


def plot_attention_by_layer(attention, tokens: Sequence[str], word, *, axes: str = "slhnpw", steps=None,
                            heads=None, batch=None, include_mean: bool = True, frames_per_latent: int = 4,
                            normalize="shared", cmap: str = "viridis", ncols: int | None = None,
                            panel_size: tuple[float, float] = (3.2, 2.0)):
    """One word's map per transformer layer (and their mean), on a shared colour scale.

    Parameters
    ----------
    attention : array
        Captured maps with a layer axis; ``axes`` names every axis (see :func:`reduce_attention`).
    tokens : sequence of str, length W
    word : int, str or list
        The word (see :func:`word_token_ids`); lists are summed.
    axes : str
        Must contain ``l``.
    steps, heads, batch
        Passed to :func:`reduce_attention` for every panel.
    include_mean : bool
        Add a last panel with the mean over all layers.
    normalize : {"shared", "each", "none"}
        "shared" (default) keeps layers comparable.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if "l" not in axes:
        raise ValueError(f"plot_attention_by_layer needs a layer axis 'l' in axes, got {axes!r}")
    arr = to_numpy(attention, "attention")
    n_layers = arr.shape[axes.index("l")] if arr.ndim == len(axes) else 0
    panels, titles = [], []
    ids = None
    for layer in range(n_layers):
        red = reduce_attention(arr, axes, steps=steps, layers=layer, heads=heads, batch=batch)
        ids = word_token_ids(tokens, word) if ids is None else ids
        panels.append(red[:, :, list(ids)].sum(axis=2))
        titles.append(f"layer {layer}")
    if not panels:
        reduce_attention(arr, axes)  # raises the shape error
    if include_mean:
        red = reduce_attention(arr, axes, steps=steps, heads=heads, batch=batch)
        panels.append(red[:, :, list(ids)].sum(axis=2))
        titles.append("mean of layers")
    label = word if isinstance(word, str) else _label(tokens, ids)
    return _grid(np.stack(panels), titles, ncols=ncols, fpl=_check_fpl(frames_per_latent), cmap=cmap,
                 normalize=normalize, suptitle=f"{label!r} by layer", panel_size=panel_size, colorbar=True)


def _step_ranges(step_ranges, n_steps: int) -> list[tuple[int, int]]:
    if isinstance(step_ranges, (int, np.integer)):
        k = int(step_ranges)
        if not 1 <= k <= n_steps:
            raise ValueError(f"step_ranges={k} must be between 1 and the number of steps ({n_steps})")
        edges = np.round(np.linspace(0, n_steps, k + 1)).astype(int)
        return [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:])]
    out = []
    for r in step_ranges:
        a, b = (int(v) for v in r)
        if not 0 <= a < b <= n_steps:
            raise ValueError(f"step range {r!r} must satisfy 0 <= start < stop <= {n_steps}")
        out.append((a, b))
    if not out:
        raise ValueError("step_ranges is empty")
    return out


def plot_attention_by_steps(attention, tokens: Sequence[str], word, *, axes: str = "slhnpw", step_ranges=4,
                            layers=None, heads=None, batch=None, frames_per_latent: int = 4,
                            normalize="shared", cmap: str = "viridis", ncols: int | None = None,
                            panel_size: tuple[float, float] = (3.2, 2.0)):
    """One word's map averaged over consecutive ranges of denoising steps.

    Parameters
    ----------
    attention : array
        Captured maps with a step axis ``s`` (step 0 = the first, noisiest step).
    tokens, word, axes, layers, heads, batch
        As in :func:`plot_attention_by_layer`.
    step_ranges : int or sequence of (start, stop)
        Number of equal ranges, or explicit half-open ranges.

    Returns
    -------
    matplotlib.figure.Figure
    """
    if "s" not in axes:
        raise ValueError(f"plot_attention_by_steps needs a step axis 's' in axes, got {axes!r}")
    arr = to_numpy(attention, "attention")
    if arr.ndim != len(axes):
        reduce_attention(arr, axes)  # raises the shape error
    ranges = _step_ranges(step_ranges, arr.shape[axes.index("s")])
    ids = word_token_ids(tokens, word)
    panels = [reduce_attention(arr, axes, steps=r, layers=layers, heads=heads, batch=batch)[:, :, list(ids)].sum(axis=2)
              for r in ranges]
    titles = [f"steps {a}-{b - 1}" for a, b in ranges]
    label = word if isinstance(word, str) else _label(tokens, ids)
    return _grid(np.stack(panels), titles, ncols=ncols, fpl=_check_fpl(frames_per_latent), cmap=cmap,
                 normalize=normalize, suptitle=f"{label!r} by denoising step", panel_size=panel_size,
                 colorbar=True)


def _pairs(a, b, tokens_a, tokens_b, word_ids):
    """Maps of the same words in two attention arrays (a word missing from one gives a NaN map).

    With ``word_ids=None`` every word of ``tokens_a`` is used; the k-th occurrence of a repeated
    word is matched with the k-th occurrence in ``tokens_b``.
    """
    arr_a = _check_attention(a, "source")
    arr_b = _check_attention(b, "edited")
    if arr_a.shape[:2] != arr_b.shape[:2]:
        raise ValueError(f"both maps must share (P, N'); got {arr_a.shape[:2]} and {arr_b.shape[:2]}")
    for arr, toks, name in ((arr_a, tokens_a, "tokens"), (arr_b, tokens_b, "edited tokens")):
        if len(toks) != arr.shape[2]:
            raise ValueError(f"{name} have {len(toks)} entries but the attention has W = {arr.shape[2]}")
    absent = np.full(arr_a.shape[:2], np.nan)
    rows = []
    if word_ids is None:
        words_b = merge_tokens(tokens_b)
        seen: dict[str, int] = {}
        for text, ids in merge_tokens(tokens_a):
            if not WORD_CHARS.search(text):
                continue
            k = seen.get(text, 0)
            seen[text] = k + 1
            match = [i for t, i in words_b if t == text]
            map_b = arr_b[:, :, list(match[k])].sum(axis=2) if k < len(match) else absent
            rows.append((text if k == 0 else f"{text} ({k + 1})", arr_a[:, :, list(ids)].sum(axis=2), map_b))
        return rows
    if isinstance(word_ids, (str, int, np.integer)):
        word_ids = [word_ids]
    for w in word_ids:
        maps = []
        for arr, toks in ((arr_a, tokens_a), (arr_b, tokens_b)):
            try:
                maps.append(arr[:, :, list(word_token_ids(toks, w))].sum(axis=2))
            except ValueError as exc:
                if not (isinstance(w, str) and "is not in the tokens" in str(exc)):
                    raise
                maps.append(absent)
        if np.isnan(maps[0]).all() and np.isnan(maps[1]).all():
            raise ValueError(f"word {w!r} is in neither token list")
        label = w if isinstance(w, str) else _label(tokens_a, word_token_ids(tokens_a, w))
        rows.append((label, maps[0], maps[1]))
    return rows


def _comparison_figure(rows, labels, diff_label, *, fpl, cmap, diff_cmap, normalize, suptitle, panel_size):
    """Rows of [A | B | B - A']: A, B on a per-row shared scale, the difference symmetric about 0."""
    n = len(rows)
    fig = new_figure((panel_size[0] * 3 + 1.6, panel_size[1] * n + 0.6))
    axs = fig.subplots(n, 3, squeeze=False)
    for r, (word, a, b, diff) in enumerate(rows):
        both = np.stack([np.nan_to_num(a), np.nan_to_num(b)])
        signed = bool((both < 0).any())       # an edit's negative re-weight: centred diverging scale
        if normalize in (True, "each", "shared", "global"):
            top = float(np.abs(both).max()) or 1.0
            a_s, b_s, d_s, vmax = a / top, b / top, diff / top, 1.0
        elif normalize in (False, None, "none"):
            a_s, b_s, d_s, vmax = a, b, diff, float(np.abs(both).max()) or 1.0
        else:
            raise ValueError(f"normalize must be 'shared' or 'none', got {normalize!r}")
        last = r == n - 1
        im = None
        for c, (m, title) in enumerate(((a_s, labels[0]), (b_s, labels[1]))):
            ax = axs[r][c]
            if np.isnan(m).all():
                ax.text(0.5, 0.5, f"{word!r} absent", ha="center", va="center", transform=ax.transAxes)
                ax.set_xticks([]), ax.set_yticks([])
                continue
            im = _draw_map(ax, m, fpl=fpl, cmap=diff_cmap if signed else cmap, vmin=-vmax if signed else 0.0,
                           vmax=vmax, title=f"{title}: {word}", part_labels=(c == 0), xlabel=last)
        if im is not None:
            cb = fig.colorbar(im, ax=axs[r][:2], fraction=0.03, pad=0.01)
            cb.set_label(("attention / row max" if normalize in (True, "each", "shared", "global") else
                          "attention weight") + (" (signed)" if signed else ""))
        ax = axs[r][2]
        if np.isnan(d_s).all():
            ax.text(0.5, 0.5, "no difference (word absent)", ha="center", va="center", transform=ax.transAxes)
            ax.set_xticks([]), ax.set_yticks([])
            continue
        lim = float(np.nanmax(np.abs(d_s))) or 1.0
        imd = _draw_map(ax, d_s, fpl=fpl, cmap=diff_cmap, vmin=-lim, vmax=lim, title=diff_label,
                        part_labels=False, xlabel=last)
        fig.colorbar(imd, ax=ax, fraction=0.05, pad=0.01).set_label("difference")
    if suptitle:
        fig.suptitle(suptitle)
    return fig


def plot_attention_comparison(source, edited, tokens: Sequence[str], word_ids=None, *,
                              edited_tokens: Sequence[str] | None = None,
                              labels: tuple[str, str] = ("source", "edited"), frames_per_latent: int = 4,
                              normalize="shared", cmap: str = "viridis", diff_cmap: str = "RdBu_r",
                              title: str | None = None, panel_size: tuple[float, float] = (3.2, 2.0)):
    """Source vs edited maps and their difference, one row per word.

    Parameters
    ----------
    source, edited : array (P, N', W) and (P, N', W')
        Reduced attention of the source and the edited generation (same P and N').
    tokens : sequence of str
        Tokens of ``source``.
    word_ids : sequence, optional
        Words to compare (see :func:`select_words`); ``None`` = every word of the source. A word
        absent from one prompt (e.g. added by a refinement edit) shows as "absent" there.
    edited_tokens : sequence of str, optional
        Tokens of ``edited`` (default: the same as ``tokens``).
    labels : (str, str)
        Column titles.
    normalize : {"shared", "none"}
        "shared" divides both maps of a row by their common maximum, so they stay comparable.
    diff_cmap : str
        Diverging colormap of ``edited - source`` (symmetric limits).

    Returns
    -------
    matplotlib.figure.Figure
    """
    rows = _pairs(source, edited, tokens, tokens if edited_tokens is None else edited_tokens, word_ids)
    rows = [(w, a, b, b - a) for w, a, b in rows]
    return _comparison_figure(rows, labels, f"{labels[1]} - {labels[0]}", fpl=_check_fpl(frames_per_latent),
                              cmap=cmap, diff_cmap=diff_cmap, normalize=normalize, suptitle=title,
                              panel_size=panel_size)


def plot_mirror_comparison(original, mirrored, tokens: Sequence[str], word_ids=None, *,
                           mirrored_tokens: Sequence[str] | None = None,
                           labels: tuple[str, str] = ("original", "mirrored"), frames_per_latent: int = 4,
                           normalize="shared", cmap: str = "viridis", diff_cmap: str = "RdBu_r",
                           title: str | None = None, panel_size: tuple[float, float] = (3.2, 2.0)):
    """Original vs mirrored maps, and how far the mirrored maps are from a perfect left/right swap.

    The third column is ``mirrored - mirror_attention(original)``: zero everywhere when the mirrored
    generation attends exactly like the original with left and right exchanged.

    Parameters
    ----------
    original, mirrored : array (P, N', W)
    tokens, word_ids, mirrored_tokens, labels, frames_per_latent, normalize, cmap, diff_cmap, title
        As in :func:`plot_attention_comparison`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    rows = _pairs(original, mirrored, tokens, tokens if mirrored_tokens is None else mirrored_tokens, word_ids)
    rows = [(w, a, b, b - mirror_attention(a)) for w, a, b in rows]
    return _comparison_figure(rows, labels, f"{labels[1]} - mirror({labels[0]})",
                              fpl=_check_fpl(frames_per_latent), cmap=cmap, diff_cmap=diff_cmap,
                              normalize=normalize, suptitle=title, panel_size=panel_size)


def plot_joint_attention(joints, skeleton: str | Skeleton, maps, word: str | None = None, *, frames=6,
                         frames_per_latent: int = 4, cmap: str = "viridis", view: str | float = "side",
                         tile_size: tuple[int, int] = (180, 240), backend: str = "auto"):
    """A motion's key poses with joints coloured by their part's attention to a word, over the heatmap.

    Top: key poses (each joint and the bone ending at it take the colour of its body part's
    attention at that frame). Bottom: the word's heatmap with the key frames marked.

    Parameters
    ----------
    joints : array (N, J, 3)
        Joint positions in metres.
    skeleton : str or Skeleton
    maps : array (P, N')
        The word's map.
    word : str, optional
        Title.
    frames : int or sequence of int
        Key frames (or how many, evenly spaced).
    frames_per_latent, cmap
        As in :func:`plot_word_attention`.
    view, tile_size, backend
        Passed to :func:`salad_viz.render.keyframe_strip` (``layout="row"``).

    Returns
    -------
    matplotlib.figure.Figure
    """
    from ._arrays import as_joints
    from .render import keyframe_strip, select_keyframes

    skel = get_skeleton(skeleton)
    motion = as_joints(joints, skel)
    m = _check_map(maps)
    fpl = _check_fpl(frames_per_latent)
    n = len(motion)
    idx = select_keyframes(n, frames) if isinstance(frames, (int, np.integer)) else np.asarray(list(frames), int)
    colors = joint_attention_colors(m, skel, n, frames_per_latent=fpl, cmap=cmap)
    strip = keyframe_strip(motion, skel, [int(i) for i in idx], layout="row", view=view, size=tile_size,
                           joint_colors=colors, backend=backend)
    aspect = strip.shape[0] / strip.shape[1]
    width = 9.0
    fig = new_figure((width, width * aspect + 2.6))
    ax_img, ax_map = fig.subplots(2, 1, gridspec_kw={"height_ratios": [width * aspect, 2.2]})
    ax_img.imshow(strip)
    ax_img.axis("off")
    shown, vmin, vmax = _normalise(m[None], "each")
    im = _draw_map(ax_map, shown[0], fpl=fpl, cmap=cmap, vmin=vmin, vmax=vmax, title=None, part_labels=True)
    for i in idx:
        ax_map.axvline(int(i) + 0.5, color="white", lw=1.2)
    fig.colorbar(im, ax=ax_map, fraction=0.04, pad=0.01).set_label(colorbar_label("each"))
    if word:
        fig.suptitle(f"attention to {word!r}")
    return fig
