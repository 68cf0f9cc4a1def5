"""The attention explorer as one self-contained HTML file: opens offline in any current browser.

:func:`export_explorer` writes the view of :mod:`salad_viz.widgets` (pick words, layers and a range
of denoising steps; the 7-part x frame heatmap of the selected words, summed, linked to a skeleton
whose bones are coloured by their body part's attention at the current frame) as a single page that
needs no kernel, no server and no network: a small renderer of its own draws the skeleton on a
``<canvas>`` (a perspective view you turn by dragging), with play, pause, speed and a frame scrubber.
For an edit (``compare=``), the source and the edited motion stand side by side on one colour scale,
and the edit is named. The page's Content-Security-Policy forbids every request, so nothing can be
fetched.

The data travel inside the page as JSON: the joints in millimetres, and per word, per group of
denoising steps and per layer the ``(7, N')`` map averaged over the heads, as integers in units of
``scale`` (4 significant digits of the largest value). The page computes what the Jupyter explorer
computes: the mean over the selected steps (weighted by how many steps each group holds) and layers,
summed over the selected words, coloured from 0 to the map's maximum (one maximum for both motions of
an edit; a map with negative values, e.g. after a negative re-weight, gets a diverging scale
centred at 0). A full capture (every step) keeps every step when the page stays under ``max_bytes``
(8 MB), otherwise consecutive steps are averaged in groups, as few as needed.

The returned :class:`ExplorerPage` is the HTML text (a ``str``). In Jupyter it displays inline, in an
``<iframe srcdoc=...>``, so a saved (trusted) notebook keeps the interactive figure.

Tests and scripts can drive an open page through ``window.saladExplorer`` (``state``, ``panels[i].drawn``
(what the skeleton and heatmap show), ``setFrame``, ``toggleWord``, ``setWords``, ``setLayers``,
``setSteps``, ``play``, ``pause``, ``currentMap``).

Examples
--------
>>> from salad_core.attention import CaptureConfig
>>> from salad_core.pipeline import SaladPipeline
>>> from salad_viz import export_explorer
>>> pipe = SaladPipeline.from_pretrained()
>>> out = pipe("a man jumps forward and then walks", lengths=120, seed=0,
...            capture_attention=CaptureConfig(mode="full"))
>>> page = export_explorer(out.attention, None, out.joints[0], path="jumps.html")   # doctest: +SKIP
>>> page                                   # the last expression of a notebook cell shows it inline

An edit, side by side (``ed = pipe.edit(..., capture_attention=CaptureConfig(mode="full"))``):

>>> export_explorer(ed.source.attention, None, ed.source.joints[0], label="source",
...                 compare=dict(attention=ed.edited.attention, joints=ed.edited.joints[0], label="edited"),
...                 edit="word swap: walks -> runs", path="swap.html")             # doctest: +SKIP
"""
from __future__ import annotations

import difflib
import html
import json
import logging
import math
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from salad_core.skeleton import PART_NAMES, Skeleton, get_skeleton

from ._arrays import as_joints, atomic_output, to_numpy
from .attention import DIVERGING_CMAP, merge_tokens, reduce_attention
from .camera import VIEWS
from .widgets import _attention_maps_inputs, _is_attention_maps   # read as the Jupyter explorer reads them

__all__ = ["export_explorer", "ExplorerPage", "explorer_data", "MAX_BYTES", "FORMAT"]

log = logging.getLogger(__name__)

#: Largest page :func:`export_explorer` writes by default (bytes); steps are grouped to stay under it.
MAX_BYTES = 8_000_000
#: The ``format`` field of the embedded JSON.
FORMAT = "salad-explorer/1"
#: Significant digits kept of the largest attention value (the others share its unit).
DIGITS = 4
#: Joint positions are stored in units of this many metres (millimetres).
JOINT_UNIT = 0.001
_COMPARE_KEYS = {"attention", "joints", "tokens", "axes", "batch", "frames_per_latent", "prompt", "label", "words"}


# ----------------------------------------------------------------------------- inputs
def _first_content_word(words: Sequence[str]) -> int:
    from .widgets import first_content_word   # the Jupyter explorer's rule (no ipywidgets needed)

    return first_content_word(words)


def _standardise(arr: np.ndarray, axes: str, batch) -> tuple[np.ndarray, bool, bool, int | None]:
    """An array with ``axes`` letters as ``(S, L, P, N', W)`` (heads averaged, the batch element taken),
    and whether it had steps and layers."""
    reduce_attention(arr, axes, batch=batch)     # validates the letters, the shape and the batch index
    letters = list(axes)
    if "b" in letters:
        ax = letters.index("b")
        arr = np.take(arr, int(0 if batch is None else batch), axis=ax)
        letters.pop(ax)
    heads = None
    if "h" in letters:
        ax = letters.index("h")
        heads = arr.shape[ax]
        arr = arr.mean(axis=ax)
        letters.pop(ax)
    has = {c: c in letters for c in "sl"}
    for c in "ls":
        if c not in letters:
            arr = arr[None]
            letters.insert(0, c)
    return np.transpose(arr, [letters.index(c) for c in "slpnw"]), has["s"], has["l"], heads


class _Panel:
    """One motion with its maps, in the page's layout (words x steps x layers x parts x latent frames)."""

    def __init__(self, attention, tokens, joints, skeleton: Skeleton, *, axes: str, batch, frames_per_latent,
                 prompt, label, words, name: str):
        fpl = frames_per_latent
        self.step_numbers: list[int] | None = None
        self.total_steps: int | None = None
        self.layer_labels: list[str] | None = None
        if _is_attention_maps(attention):
            b, tokens, fpl, prompt = _attention_maps_inputs(attention, batch, tokens, fpl, prompt)
            self.heads = len(attention.captured_heads)
            self.layer_labels = [str(layer) for layer in attention.captured_layers]
            if attention.mode == "full":
                full = np.asarray(attention.full(b), dtype=np.float64)          # (S, L, H, N', P, W)
                arr = full.mean(axis=2).transpose(0, 1, 3, 2, 4)                # (S, L, P, N', W)
                s = arr.shape[0]
                first = 0 if s == attention.num_steps else int(round(attention.step_window[0] * attention.num_steps))
                self.step_numbers = list(range(first, first + s))
                self.total_steps = int(attention.num_steps)
            else:    # the per-layer means over the steps held, as the Jupyter explorer shows them
                arr = np.stack([attention.select(layers=[layer]).cross_map(b)
                                for layer in attention.captured_layers]).astype(np.float64)[None]
        else:
            if tokens is None:
                raise ValueError(f"{name}: tokens is required when attention is an array (pass the prompt's W tokens)")
            arr, has_s, has_l, self.heads = _standardise(to_numpy(attention, f"{name} attention"), axes, batch)
            if has_s:
                self.step_numbers = list(range(arr.shape[0]))
                self.total_steps = arr.shape[0]
            if has_l:
                self.layer_labels = [str(i) for i in range(arr.shape[1])]
        fpl = 4 if fpl is None else fpl
        if isinstance(fpl, bool) or not isinstance(fpl, (int, np.integer)) or fpl < 1:
            raise ValueError(f"{name}: frames_per_latent must be a positive int, got {frames_per_latent!r}")
        self.fpl = int(fpl)
        if arr.shape[2] != len(PART_NAMES):
            raise ValueError(f"{name}: attention has {arr.shape[2]} body parts, the explorer draws {len(PART_NAMES)} "
                             f"({', '.join(PART_NAMES)})")
        if not np.isfinite(arr).all():
            raise ValueError(f"{name}: attention contains NaN or inf")
        self.tokens = [str(t) for t in tokens]
        if arr.shape[-1] != len(self.tokens):
            raise ValueError(f"{name}: tokens has {len(self.tokens)} entries but attention has W = {arr.shape[-1]}")
        # words only: punctuation tokens ("," of "walks, while") are not offered
        self.groups = [(w, ids) for w, ids in merge_tokens(self.tokens) if any(ch.isalnum() for ch in w)]
        if not self.groups:
            raise ValueError(f"{name}: tokens contain no words")
        # (words, S, L, P, N'): each word's tokens summed, as the Jupyter explorer sums them
        self.maps = np.stack([arr[..., list(ids)].sum(axis=-1) for _, ids in self.groups])
        self.joints = as_joints(joints, skeleton, f"{name} joints")
        self.words = [w for w, _ in self.groups]
        self.prompt = str(prompt) if prompt is not None else " ".join(self.words)
        self.label = label
        self.selected = self._initial(words, name)

    def _initial(self, words, name: str) -> list[int]:
        if words is None:
            return [_first_content_word(self.words)]
        wanted = [words] if isinstance(words, str) else list(words)
        missing = [w for w in wanted if str(w).lower() not in self.words]
        if missing:
            raise ValueError(f"{name}: words {missing} are not in the prompt; its words are {self.words}")
        low = {str(w).lower() for w in wanted}
        return [i for i, w in enumerate(self.words) if w in low]


def _parse_compare(compare) -> dict:
    if isinstance(compare, Mapping):
        extra = set(compare) - _COMPARE_KEYS
        if extra:
            raise ValueError(f"compare has unknown keys {sorted(extra)}; it takes {sorted(_COMPARE_KEYS)}")
        if "attention" not in compare or "joints" not in compare:
            raise ValueError("compare needs at least 'attention' and 'joints' (the second motion and its maps)")
        return dict(compare)
    if isinstance(compare, (tuple, list)) and len(compare) in (2, 3):
        return dict(zip(("attention", "joints", "label"), compare))
    raise TypeError("compare must be a dict(attention=..., joints=..., tokens=..., label=...) or a tuple "
                    f"(attention, joints[, label]); got {type(compare).__name__}")


def _align(a: Sequence[str], b: Sequence[str]) -> list[int]:
    """For each word of ``a`` the index of its counterpart in ``b`` (-1: none): equal words match in order,
    and replaced words pair up by position (a word swap's "walks" with "runs")."""
    out = [-1] * len(a)
    for tag, i0, i1, j0, j1 in difflib.SequenceMatcher(a=list(a), b=list(b), autojunk=False).get_opcodes():
        if tag in ("equal", "replace"):
            for k in range(min(i1 - i0, j1 - j0)):
                out[i0 + k] = j0 + k
    return out


# ----------------------------------------------------------------------------- encoding
def _step_groups(count: int, groups: int) -> list[np.ndarray]:
    return [g for g in np.array_split(np.arange(count), max(1, min(groups, count))) if len(g)]


def _grouped(maps: np.ndarray, groups: list[np.ndarray]) -> np.ndarray:
    return np.stack([maps[:, g].mean(axis=1) for g in groups], axis=1)


def _unit(top: float) -> float:
    """The integer unit keeping :data:`DIGITS` significant digits of ``top``."""
    if not top > 0:
        return 1.0
    return float(10.0 ** (math.floor(math.log10(top)) - (DIGITS - 1)))


def _ints(arr: np.ndarray) -> str:
    return "[" + ",".join(map(str, arr.ravel().tolist())) + "]"


def _hex_table(name: str, n: int = 256) -> list[str]:
    from matplotlib import colormaps

    rgb = (np.clip(colormaps[name](np.linspace(0.0, 1.0, n))[:, :3], 0, 1) * 255).round().astype(int)
    return ["#%02x%02x%02x" % tuple(c) for c in rgb]


def _view(view) -> tuple[float, float]:
    if isinstance(view, str):
        if view not in VIEWS:
            raise ValueError(f"view {view!r} is not known; use one of {sorted(VIEWS)} or an azimuth in degrees")
        return VIEWS[view]
    if isinstance(view, bool) or not isinstance(view, (int, float, np.integer, np.floating)) or not np.isfinite(view):
        raise ValueError(f"view must be a view name or an azimuth in degrees, got {view!r}")
    return float(view), 15.0


def explorer_data(attention, tokens: Sequence[str] | None, joints, skeleton: str | Skeleton = "humanml3d",
                  **kwargs) -> dict:
    """What :func:`export_explorer` embeds, as a dict (arguments as there, except ``path`` and ``height``).

    The arrays are numpy: ``panels[i]["att"]`` holds integers ``(words, step groups, layers, 7, N')`` in
    units of ``scale`` and ``panels[i]["joints"]`` integers ``(N, J, 3)`` in units of ``jointScale`` metres.
    """
    return _build(attention, tokens, joints, skeleton, **kwargs)[0]


def _build(attention, tokens: Sequence[str] | None, joints, skeleton: str | Skeleton = "humanml3d", *,
           axes: str = "pnw", batch: int | None = None, frames_per_latent: int | None = None,
           words: str | Sequence[str] | None = None, prompt: str | None = None, model: str | None = "SALAD",
           title: str | None = None, label: str | None = None, compare=None, edit: str | None = None,
           step_bins: int | None = None, max_bytes: int = MAX_BYTES, cmap: str = "viridis",
           view: str | float = "three_quarter", fps: float | None = None) -> tuple[dict, str]:
    """The embedded data and the page."""
    skel = get_skeleton(skeleton)
    az, el = _view(view)
    if isinstance(max_bytes, bool) or not isinstance(max_bytes, (int, np.integer)) or max_bytes < 10_000:
        raise ValueError(f"max_bytes must be an int of at least 10000, got {max_bytes!r}")
    if step_bins is not None and (isinstance(step_bins, bool) or not isinstance(step_bins, (int, np.integer))
                                  or step_bins < 1):
        raise ValueError(f"step_bins must be None or a positive int, got {step_bins!r}")
    panels = [_Panel(attention, tokens, joints, skel, axes=axes, batch=batch, frames_per_latent=frames_per_latent,
                     prompt=prompt, label=label, words=words, name="attention")]
    if compare is not None:
        c = _parse_compare(compare)
        panels.append(_Panel(c["attention"], c.get("tokens"), c["joints"], skel, axes=c.get("axes", axes),
                             batch=c.get("batch"), frames_per_latent=c.get("frames_per_latent", frames_per_latent),
                             prompt=c.get("prompt"), label=c.get("label", "edited"), words=c.get("words"),
                             name="compare"))
        if panels[0].label is None:
            panels[0].label = "source"
        a, b = panels
        if ((a.step_numbers is None) != (b.step_numbers is None) or a.layer_labels != b.layer_labels
                or a.maps.shape[1:3] != b.maps.shape[1:3]):
            raise ValueError("the two motions' maps must have the same steps and layers (capture both the same way); "
                             f"got {a.maps.shape[1:3]} and {b.maps.shape[1:3]} (steps, layers)")
        if a.fpl != b.fpl:
            raise ValueError(f"the two motions have different frames_per_latent ({a.fpl} and {b.fpl})")
        if c.get("words") is None:   # open on the counterparts of the first motion's words, where there are some
            b.selected = sorted({j for j in (_align(a.words, b.words)[i] for i in a.selected) if j >= 0}) or b.selected
    first = panels[0]
    fps = float(skel.fps if fps is None else fps)
    if not fps > 0:
        raise ValueError(f"fps must be > 0, got {fps!r}")
    steps_total = first.maps.shape[1]

    def build(groups_count: int) -> tuple[dict, list[str]]:
        groups = _step_groups(steps_total, groups_count)
        grouped = [_grouped(p.maps, groups) for p in panels]
        unit = _unit(max(float(np.abs(g).max()) for g in grouped))
        data: dict[str, Any] = {
            "format": FORMAT,
            "title": title or "SALAD attention explorer",
            "prompt": first.prompt,
            "model": model,
            "edit": edit,
            "skeleton": skel.name,
            "fps": fps,
            "fpl": first.fpl,
            "parts": list(PART_NAMES),
            "parents": [int(p) for p in skel.parents],
            "jointPart": [int(p) for p in skel.joint_to_part],
            "jointNames": list(skel.joint_names),
            "view": {"azimuth": az, "elevation": el},
            "scale": unit,
            "jointScale": JOINT_UNIT,
            "heads": first.heads,
            "steps": None if first.step_numbers is None else {
                "groups": [[first.step_numbers[g[0]], first.step_numbers[g[-1]]] for g in groups],
                "weights": [len(g) for g in groups],
                "total": first.total_steps},
            "layers": first.layer_labels,
            "cmap": {"name": cmap, "colors": _hex_table(cmap)},
            "divergingCmap": {"name": DIVERGING_CMAP, "colors": _hex_table(DIVERGING_CMAP)},
            "panels": [],
        }
        for k, (p, g) in enumerate(zip(panels, grouped)):
            q = np.rint(g / unit).astype(np.int64)
            data["panels"].append({
                "label": p.label, "prompt": p.prompt, "frames": len(p.joints), "latentFrames": int(g.shape[-1]),
                "words": [{"text": w, "tokens": [int(i) for i in ids]} for w, ids in p.groups],
                "selected": p.selected,
                "align": None if len(panels) == 1 else _align(p.words, panels[1 - k].words),
                "shape": list(q.shape), "att": q,
                "joints": np.rint(p.joints / JOINT_UNIT).astype(np.int64)})
        return data, [_ints(p["att"]) for p in data["panels"]]

    count = steps_total if step_bins is None else min(int(step_bins), steps_total)
    while True:
        data, texts = build(count)
        page = _page(data, texts)
        size = len(page.encode("utf-8"))
        if size <= max_bytes or count == 1:
            break
        att = sum(len(t) for t in texts)
        # the maps grow with the number of step groups: shrink it in proportion, by at least one
        count = max(1, min(count - 1, int(count * (att - (size - max_bytes)) / att * 0.97)))
    if size > max_bytes:
        raise ValueError(f"the page would take {size / 1e6:.1f} MB even with all steps averaged, more than max_bytes = "
                         f"{max_bytes / 1e6:.1f} MB; raise max_bytes or export fewer frames or words")
    if count < steps_total and step_bins is None:
        log.info("the %d captured steps are averaged in %d groups to keep the page under %.1f MB", steps_total, count,
                 max_bytes / 1e6)
    return data, page


# ----------------------------------------------------------------------------- the page
def _json(data: dict, att_texts: Sequence[str]) -> str:
    payload = {k: v for k, v in data.items() if not k.startswith("_")}
    payload["panels"] = []
    for i, p in enumerate(data["panels"]):
        q = dict(p)
        q["att"] = f"@@ATT{i}@@"
        q["joints"] = f"@@JOINTS{i}@@"
        payload["panels"].append(q)
    text = json.dumps(payload, separators=(",", ":"), ensure_ascii=True, allow_nan=False)
    for i, p in enumerate(data["panels"]):
        text = text.replace(f'"@@ATT{i}@@"', att_texts[i], 1).replace(f'"@@JOINTS{i}@@"', _ints(p["joints"]), 1)
    # nothing in the JSON may end the <script> element or open a comment
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def _page(data: dict, att_texts: Sequence[str]) -> str:
    named = f"{data['edit']} of {data['prompt']}" if data.get("edit") else data["prompt"]   # a tab names the edit
    title = html.escape(f"{data['title']}: {named}")
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n"
        "<meta http-equiv=\"Content-Security-Policy\" content=\"default-src 'none'; script-src 'unsafe-inline'; "
        "style-src 'unsafe-inline'; img-src data:\">\n"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
        "<meta name=\"color-scheme\" content=\"light\">\n"
        f"<meta name=\"generator\" content=\"salad_viz.export_explorer ({FORMAT})\">\n"
        f"<title>{title}</title>\n<style>{_CSS}</style>\n</head>\n<body>\n"
        "<noscript>This attention explorer needs JavaScript.</noscript>\n<div id=\"salad-app\"></div>\n"
        f"<script id=\"salad-data\" type=\"application/json\">{_json(data, att_texts)}</script>\n"
        f"<script>{_JS}</script>\n</body></html>\n")


class ExplorerPage(str):
    """The explorer's HTML text; shown inline by Jupyter (in an ``<iframe srcdoc=...>``).

    Attributes
    ----------
    path : Path or None
        Where :func:`export_explorer` wrote it.
    height : int
        Height in pixels of the inline frame.
    """

    path: Path | None
    height: int

    def __new__(cls, text: str, path: Path | None = None, height: int = 960):
        page = super().__new__(cls, text)
        page.path = path
        page.height = int(height)
        return page

    @property
    def size_bytes(self) -> int:
        """The page's size in bytes (UTF-8)."""
        return len(self.encode("utf-8"))

    def iframe(self, height: int | None = None) -> str:
        """The page in an ``<iframe srcdoc=...>`` (scripts allowed, no access to the notebook)."""
        h = self.height if height is None else int(height)
        return (f'<iframe class="salad-explorer-html" srcdoc="{html.escape(str(self), quote=True)}" '
                f'sandbox="allow-scripts" style="width:100%;height:{h}px;border:1px solid #ddd" '
                f'title="SALAD attention explorer"></iframe>')

    def _repr_html_(self) -> str:
        saved = f" It is also saved as {html.escape(str(self.path))}." if self.path is not None else ""
        # an untrusted notebook's HTML is sanitised (JupyterLab removes the iframe): say what to do
        return (self.iframe() + '<div class="salad-explorer-note" style="font-size:12px;color:#666">If no explorer '
                "shows above, this notebook's output is not trusted: run the cell again or trust the notebook "
                f"(command palette: Trust Notebook).{saved}</div>")

    def save(self, path: str | os.PathLike) -> Path:
        """Write the page to ``path`` (atomically) and return the path."""
        path = Path(path)
        with atomic_output(path) as tmp:
            tmp.write_text(str(self), encoding="utf-8")
        self.path = path
        return path

    def __repr__(self) -> str:
        where = f", {str(self.path)!r}" if self.path is not None else ""
        return f"<ExplorerPage: {self.size_bytes / 1e6:.2f} MB of HTML{where}>"

    def _repr_pretty_(self, p, cycle) -> None:
        p.text(repr(self))


def export_explorer(attention, tokens: Sequence[str] | None, joints, skeleton: str | Skeleton = "humanml3d", *,
                    path: str | os.PathLike | None = None, axes: str = "pnw", batch: int | None = None,
                    frames_per_latent: int | None = None, words: str | Sequence[str] | None = None,
                    prompt: str | None = None, model: str | None = "SALAD", title: str | None = None,
                    label: str | None = None, compare=None, edit: str | None = None, step_bins: int | None = None,
                    max_bytes: int = MAX_BYTES, cmap: str = "viridis", view: str | float = "three_quarter",
                    fps: float | None = None, height: int | None = None) -> ExplorerPage:
    """One self-contained HTML file of the attention explorer (offline: no kernel, server or network).

    Parameters
    ----------
    attention : AttentionMaps or array
        The pipeline's captured maps (``out.attention``; sample ``batch``), or an array whose axes
        ``axes`` names (see :func:`salad_viz.attention.reduce_attention`); as in
        :func:`salad_viz.widgets.explore_attention`. A full capture (``CaptureConfig(mode="full")``)
        gives layer and step filters, a mean capture layer filters, a ``"pnw"`` array none.
    tokens : sequence of str, optional
        The W tokens of the prompt; taken from ``attention`` when it is an ``AttentionMaps``.
    joints : array (N, J, 3)
        The motion in metres.
    skeleton : str or Skeleton
        Bones (``parents``), the body part of each joint and the frame rate.
    path : path, optional
        Write the page there (atomically).
    axes, batch, frames_per_latent
        As in :class:`salad_viz.widgets.AttentionExplorer`.
    words : str or sequence of str, optional
        Words selected when the page opens (default: the first content word).
    prompt, model, title : str, optional
        Shown in the page's header (``prompt`` defaults to the maps' prompt, else the words).
    label : str, optional
        The motion's name (``"source"`` when ``compare`` is given).
    compare : dict or tuple, optional
        A second motion shown beside the first on the same colour scale, e.g. an edit's result:
        ``dict(attention=..., joints=..., tokens=None, label="edited", prompt=None, words=None, axes=...,
        batch=None)`` or ``(attention, joints[, label])``. Its maps must have the same steps and layers.
        Words of the two prompts are paired (same words in order, swapped words by position); selecting
        one selects its partner.
    edit : str, optional
        What the edit was, shown in the header (e.g. ``"word swap: walks -> runs (tau 0.8)"``).
    step_bins : int, optional
        Average the captured steps in at most this many consecutive groups (default: keep every step
        when the page fits ``max_bytes``, else as few groups as needed).
    max_bytes : int
        Largest page (bytes); :data:`MAX_BYTES` (8 MB) by default.
    cmap : str
        Colour map of the heatmap and the bones (viridis, as everywhere in salad_viz).
    view : str or float
        Initial camera azimuth: a name of :data:`salad_viz.camera.VIEWS` or degrees.
    fps : float, optional
        Frames per second of the animation (default: the skeleton's, 20 for HumanML3D).
    height : int, optional
        Height in pixels of the inline frame in Jupyter (default fits the layout).

    Returns
    -------
    ExplorerPage
        The HTML text (a ``str``); in a notebook it displays inline.
    """
    data, text = _build(attention, tokens, joints, skeleton, axes=axes, batch=batch,
                        frames_per_latent=frames_per_latent, words=words, prompt=prompt, model=model, title=title,
                        label=label, compare=compare, edit=edit, step_bins=step_bins, max_bytes=max_bytes, cmap=cmap,
                        view=view, fps=fps)
    if height is None:
        height = 1150 if len(data["panels"]) > 1 else 960
    page = ExplorerPage(text, None, height)
    if path is not None:
        page.save(path)
    return page


# ----------------------------------------------------------------------------- style and script
_CSS = r"""
:root { --ink:#1d1f23; --muted:#5b6068; --line:#d5d8dd; --accent:#1f5fbf; --bg:#ffffff; --chip:#eef1f5; --u: 1; }
* { box-sizing: border-box; }
html, body { margin: 0; background: var(--bg); color: var(--ink);
  font: calc(18px * var(--u))/1.35 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif; }
#salad-app { padding: 14px 18px 18px; max-width: calc(1800px * var(--u)); margin: 0 auto; }
header .kicker { font-size: calc(15px * var(--u)); color: var(--muted); letter-spacing: .02em; }
header h1 { font-size: calc(26px * var(--u)); margin: 2px 0 4px; font-weight: 650; }
header .meta { font-size: calc(15px * var(--u)); color: var(--muted); }
header .edit { font-size: calc(18px * var(--u)); margin-top: 6px; padding: 4px 10px; background: #fff4d6; border-left: 4px solid #e0a800;
  display: inline-block; }
.controls { margin: 10px 0 8px; display: flex; flex-direction: column; gap: 8px; }
.row { display: flex; flex-wrap: wrap; align-items: center; gap: 6px 8px; }
.row > .name { font-weight: 600; min-width: 4.2em; }
.hint { font-size: calc(15px * var(--u)); color: var(--muted); }
button { font: inherit; cursor: pointer; }
.chip { border: 2px solid var(--line); background: var(--chip); color: var(--ink); border-radius: 999px;
  padding: 1px 11px; font-size: calc(18px * var(--u)); }
.chip[aria-pressed="true"] { background: var(--accent); border-color: var(--accent); color: #fff; }
.chip.small { font-size: calc(16px * var(--u)); padding: 1px 10px; }
.play { min-width: 6.2em; padding: 4px 14px; border-radius: 8px; border: 2px solid var(--accent);
  background: var(--accent); color: #fff; font-weight: 600; }
select, input[type=checkbox] { font: inherit; }
input[type=checkbox] { width: calc(16px * var(--u)); height: calc(16px * var(--u)); vertical-align: middle; }
select { padding: 2px 4px; }
input[type=range].scrub { flex: 1 1 320px; min-width: 200px; accent-color: var(--accent); height: 28px; }
input[type=range].step { width: calc(150px * var(--u)); accent-color: var(--accent); }
.readout { font-variant-numeric: tabular-nums; min-width: 12em; }
.panels { display: grid; gap: 14px; }
.panels.single .panel { display: grid; grid-template-columns: minmax(260px, min(calc(460px * var(--u)), 40%)) minmax(380px, 1fr); gap: 18px;
  align-items: start; }
.row > .name.gap { margin-left: 18px; }
.panels.compare { grid-template-columns: repeat(2, minmax(0, 1fr)); column-gap: 14px; row-gap: 4px; }
.panels.compare .panel { display: grid; grid-row: span 3; grid-template-rows: subgrid; row-gap: 4px; }
.panels.compare .panel h2 { align-self: end; }
.panel h2 { font-size: calc(19px * var(--u)); margin: 0 0 4px; font-weight: 600; }
.panel h2 .label { color: var(--accent); }
.panel h2 .prompt { font-weight: 400; }
.panels.compare .panel h2 { font-size: calc(17px * var(--u)); }
canvas { display: block; width: 100%; touch-action: none; }
canvas.skel { aspect-ratio: 1 / 1; max-height: calc(460px * var(--u)); border: 1px solid var(--line); border-radius: 6px; cursor: grab; }
.panels.compare canvas.skel { aspect-ratio: 16 / 10; max-height: calc(340px * var(--u)); }
.panels.compare canvas.heat { height: calc(280px * var(--u)); }
canvas.heat { height: calc(318px * var(--u)); cursor: crosshair; }
canvas.bar { height: calc(58px * var(--u)); }
.barbox { flex: 1 1 300px; max-width: calc(560px * var(--u)); }
.hover { font-size: calc(15px * var(--u)); color: var(--muted); min-height: 1.4em; font-variant-numeric: tabular-nums; }
.scale { display: flex; flex-wrap: wrap; gap: 4px 18px; align-items: center; margin-top: 6px; }
.scale .hint { flex: 1 1 300px; max-width: calc(760px * var(--u)); }
.note { font-size: calc(15px * var(--u)); color: #9a3412; min-height: 1.2em; }
@media (max-width: 820px) {
  .panels.single .panel { grid-template-columns: 1fr; }
  .panels.compare { grid-template-columns: 1fr; }
}
"""

_JS = r"""
(function () {
"use strict";
const D = JSON.parse(document.getElementById("salad-data").textContent);
const NP = D.parts.length, FPS = D.fps, FPL = D.fpl, J = D.parents.length;
const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
const FOV = 30 * Math.PI / 180;
// the interface grows on large screens (a projector): U scales the text and the views
let U = 1;
function updateScale() {
  U = clamp(Math.min(window.innerWidth / 1400, window.innerHeight / (D.panels.length === 2 ? 1150 : 820)), 1, 1.6);
  document.documentElement.style.setProperty("--u", String(U));
}
const font = (size, weight) => (weight ? weight + " " : "") + (size * U).toFixed(1) + "px system-ui, sans-serif";
const HEAD = D.jointNames.indexOf("head");

function h(tag, props, ...kids) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(props || {})) {
    if (k === "class") e.className = v;
    else if (k === "text") e.textContent = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else e.setAttribute(k, v);
  }
  for (const kid of kids) if (kid !== null && kid !== undefined) e.append(kid);
  return e;
}
function fmt(v) {
  if (v === 0) return "0";
  if (Math.abs(v) >= 1) return v.toFixed(2);
  return v.toPrecision(3);
}
function fmtTime(f) { return (f / FPS).toFixed(2) + " s"; }

// ----------------------------------------------------------------- data
const edges = [];
for (let c = 0; c < J; c++) if (D.parents[c] >= 0) edges.push([D.parents[c], c]);

const panels = D.panels.map((p, index) => {
  const [W, S, L, P, N] = p.shape;
  const att = new Float64Array(p.att.length);
  for (let k = 0; k < att.length; k++) att[k] = p.att[k] * D.scale;
  const joints = new Float64Array(p.joints.length);
  for (let k = 0; k < joints.length; k++) joints[k] = p.joints[k] * D.jointScale;
  return {index, label: p.label, prompt: p.prompt, words: p.words, align: p.align, W, S, L, N, F: p.frames,
          att, joints, sel: new Set(p.selected), map: null, drawn: null, els: {}};
});
const NF = Math.max(...panels.map(p => p.F));
const S = panels[0].S, L = panels[0].L;
const sameWords = panels.length === 2 &&
  panels[0].words.map(w => w.text).join(" ") === panels[1].words.map(w => w.text).join(" ");

const state = {frame: 0, playing: false, speed: 1, layers: new Set([...Array(L).keys()]), steps: [0, S - 1],
               azimuth: D.view.azimuth, elevation: D.view.elevation, zoom: 1, follow: true, hoverPart: -1,
               scale: null};

// ----------------------------------------------------------------- maps
function computeMap(p) {
  if (p.sel.size === 0 || state.layers.size === 0) return null;
  const span = NP * p.N, m = new Float64Array(span);
  let weights = 0;
  for (let k = state.steps[0]; k <= state.steps[1]; k++) {
    const wk = D.steps ? D.steps.weights[k] : 1;
    weights += wk;
    for (const w of p.sel) for (const l of state.layers) {
      const base = ((w * S + k) * L + l) * span;
      for (let q = 0; q < span; q++) m[q] += wk * p.att[base + q];
    }
  }
  const denom = weights * state.layers.size;
  for (let q = 0; q < span; q++) m[q] /= denom;
  return m;
}
function colourScale() {
  let top = 0, signed = false;
  for (const p of panels) if (p.map) for (const v of p.map) { top = Math.max(top, Math.abs(v)); if (v < 0) signed = true; }
  if (!(top > 0)) top = 1;
  return {signed, lo: signed ? -top : 0, hi: top};
}
function colour(v, sc) {
  const t = (v - sc.lo) / (sc.hi - sc.lo);
  const table = sc.signed ? D.divergingCmap.colors : D.cmap.colors;
  return table[clamp(Math.round(t * (table.length - 1)), 0, table.length - 1)];
}
const frameOf = p => Math.min(state.frame, p.F - 1);
const columnOf = (p, f) => Math.min(Math.floor(f / FPL), p.N - 1);
function selectedText(p) {
  return p.words.filter((w, i) => p.sel.has(i)).map(w => w.text).join(" + ");
}

// ----------------------------------------------------------------- camera
function prepare(p) {
  const X = p.joints, F = p.F;
  let minY = Infinity, maxY = -Infinity, minX = Infinity, maxX = -Infinity, minZ = Infinity, maxZ = -Infinity;
  for (let k = 0; k < F * J; k++) {
    const x = X[3 * k], y = X[3 * k + 1], z = X[3 * k + 2];
    minX = Math.min(minX, x); maxX = Math.max(maxX, x); minY = Math.min(minY, y); maxY = Math.max(maxY, y);
    minZ = Math.min(minZ, z); maxZ = Math.max(maxZ, z);
  }
  p.floorY = minY;
  const midY = (minY + maxY) / 2, half = Math.max(1, Math.round(FPS / 8));
  p.followAt = new Float64Array(3 * F);
  for (let f = 0; f < F; f++) {
    let sx = 0, sz = 0, n = 0;
    for (let g = Math.max(0, f - half); g <= Math.min(F - 1, f + half); g++) { sx += X[3 * g * J]; sz += X[3 * g * J + 2]; n++; }
    p.followAt[3 * f] = sx / n; p.followAt[3 * f + 1] = midY; p.followAt[3 * f + 2] = sz / n;
  }
  p.fixedAt = [(minX + maxX) / 2, midY, (minZ + maxZ) / 2];
}
panels.forEach(prepare);
function basis() {
  const a = state.azimuth * Math.PI / 180, e = state.elevation * Math.PI / 180;
  const dir = [Math.cos(e) * Math.sin(a), Math.sin(e), Math.cos(e) * Math.cos(a)];   // focal point -> camera
  const fwd = [-dir[0], -dir[1], -dir[2]];
  let right = [-fwd[2], 0, fwd[0]];                                                  // fwd x (0, 1, 0)
  const n = Math.hypot(right[0], right[2]) || 1;
  right = [right[0] / n, 0, right[2] / n];
  const up = [right[1] * fwd[2] - right[2] * fwd[1], right[2] * fwd[0] - right[0] * fwd[2],
              right[0] * fwd[1] - right[1] * fwd[0]];
  return {dir, fwd, right, up};
}
function focalOf(q, f) {
  f = Math.min(f, q.F - 1);
  return state.follow ? [q.followAt[3 * f], q.followAt[3 * f + 1], q.followAt[3 * f + 2]] : q.fixedAt;
}
let fitCache = {key: null};
function viewFit(B, aspect) {
  // every joint of every frame (of both motions) relative to its frame's focal point, in camera axes
  const key = [state.azimuth, state.elevation, state.follow, aspect].join(",");
  if (fitCache.key === key) return fitCache;
  let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
  const rel = [];
  for (const q of panels) {
    const X = q.joints;
    for (let f = 0; f < q.F; f++) {
      const c = focalOf(q, f);
      for (let j = 0; j < J; j++) {
        const k = 3 * (f * J + j), r = [X[k] - c[0], X[k + 1] - c[1], X[k + 2] - c[2]];
        const x = r[0] * B.right[0] + r[2] * B.right[2];
        const y = r[0] * B.up[0] + r[1] * B.up[1] + r[2] * B.up[2];
        const z = r[0] * B.fwd[0] + r[1] * B.fwd[1] + r[2] * B.fwd[2];
        rel.push(x, y, z);
        x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y);
      }
    }
  }
  const cx = (x0 + x1) / 2, cy = (y0 + y1) / 2, t = Math.tan(FOV / 2), margin = 0.9;
  // the distance at which the widest point fills `margin` of the half-width (perspective: nearer is larger)
  let dist = 0.5;
  for (let k = 0; k < rel.length; k += 3) {
    dist = Math.max(dist, Math.abs(rel[k] - cx) / (t * aspect * margin) - rel[k + 2],
                    Math.abs(rel[k + 1] - cy) / (t * margin) - rel[k + 2]);
  }
  fitCache = {key, cx, cy, dist};
  return fitCache;
}
function camera(p, width, height) {
  const f = frameOf(p), B = basis(), fitted = viewFit(B, width / height);
  const c = focalOf(p, f);
  const focal = [c[0] + fitted.cx * B.right[0] + fitted.cy * B.up[0], c[1] + fitted.cy * B.up[1],
                 c[2] + fitted.cx * B.right[2] + fitted.cy * B.up[2]];
  const dist = fitted.dist * state.zoom;
  const eye = [focal[0] + B.dir[0] * dist, focal[1] + B.dir[1] * dist, focal[2] + B.dir[2] * dist];
  const fl = (height / 2) / Math.tan(FOV / 2);
  const toCam = (x, y, z) => {
    const r = [x - eye[0], y - eye[1], z - eye[2]];
    return [r[0] * B.right[0] + r[1] * B.right[1] + r[2] * B.right[2],
            r[0] * B.up[0] + r[1] * B.up[1] + r[2] * B.up[2],
            r[0] * B.fwd[0] + r[1] * B.fwd[1] + r[2] * B.fwd[2]];
  };
  const screen = q => [width / 2 + fl * q[0] / q[2], height / 2 - fl * q[1] / q[2], q[2]];
  return {toCam, screen, focal: c, fl, project: (x, y, z) => screen(toCam(x, y, z))};
}

// ----------------------------------------------------------------- drawing
function fit(canvas) {
  const dpr = window.devicePixelRatio || 1, w = canvas.clientWidth, hgt = canvas.clientHeight;
  if (canvas.width !== Math.round(w * dpr) || canvas.height !== Math.round(hgt * dpr)) {
    canvas.width = Math.round(w * dpr); canvas.height = Math.round(hgt * dpr);
  }
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return [ctx, w, hgt];
}
function segment(ctx, cam, a, b) {
  const near = 0.05;
  let pa = cam.toCam(...a), pb = cam.toCam(...b);
  if (pa[2] < near && pb[2] < near) return;
  const cut = (u, v) => {
    const t = (near - u[2]) / (v[2] - u[2]);
    return [u[0] + t * (v[0] - u[0]), u[1] + t * (v[1] - u[1]), near];
  };
  if (pa[2] < near) pa = cut(pa, pb);
  if (pb[2] < near) pb = cut(pb, pa);
  const sa = cam.screen(pa), sb = cam.screen(pb);
  ctx.moveTo(sa[0], sa[1]); ctx.lineTo(sb[0], sb[1]);
}
function drawSkeleton(p, sc) {
  const [ctx, w, hgt] = fit(p.els.skel);
  if (!(w > 0 && hgt > 0)) return;
  ctx.fillStyle = "#f4f5f2"; ctx.fillRect(0, 0, w, hgt);
  const f = frameOf(p), cam = camera(p, w, hgt), X = p.joints, y0 = p.floorY;
  // floor grid (0.5 m), fixed in the world so that travel shows
  const g0x = Math.round(cam.focal[0] / 0.5) * 0.5, g0z = Math.round(cam.focal[2] / 0.5) * 0.5, ext = 4;
  ctx.beginPath();
  for (let k = -ext; k <= ext; k += 0.5) {
    segment(ctx, cam, [g0x + k, y0, g0z - ext], [g0x + k, y0, g0z + ext]);
    segment(ctx, cam, [g0x - ext, y0, g0z + k], [g0x + ext, y0, g0z + k]);
  }
  ctx.strokeStyle = "#d2d5d0"; ctx.lineWidth = 1; ctx.stroke();
  // the root's path on the floor
  ctx.beginPath();
  for (let g = 0; g + 1 < p.F; g++) {
    segment(ctx, cam, [X[3 * g * J], y0, X[3 * g * J + 2]], [X[3 * (g + 1) * J], y0, X[3 * (g + 1) * J + 2]]);
  }
  ctx.strokeStyle = "rgba(40,90,200,0.45)"; ctx.lineWidth = 2; ctx.stroke();
  // bones, far ones first, each in its body part's attention colour (child joint's part)
  const pts = [];
  for (let j = 0; j < J; j++) { const k = 3 * (f * J + j); pts.push(cam.project(X[k], X[k + 1], X[k + 2])); }
  const col = columnOf(p, f);
  const values = D.parts.map((_, r) => p.map ? p.map[r * p.N + col] : null);
  const partColour = values.map(v => v === null ? "#9aa0a6" : colour(v, sc));
  const boneColours = edges.map(([a, c]) => partColour[D.jointPart[c]]);
  const lw = Math.max(3, Math.min(w, hgt) / 64);
  const depth = i => pts[edges[i][0]][2] + pts[edges[i][1]][2];
  const order = edges.map((e, i) => i).sort((i, k) => depth(k) - depth(i));
  ctx.lineCap = "round";
  for (const i of order) {
    const [a, c] = edges[i], hot = D.jointPart[c] === state.hoverPart;
    ctx.beginPath(); ctx.moveTo(pts[a][0], pts[a][1]); ctx.lineTo(pts[c][0], pts[c][1]);
    ctx.strokeStyle = hot ? "#ff2d55" : "#50545b"; ctx.lineWidth = lw + (hot ? 7 : 2.5); ctx.stroke();
    ctx.beginPath(); ctx.moveTo(pts[a][0], pts[a][1]); ctx.lineTo(pts[c][0], pts[c][1]);
    ctx.strokeStyle = boneColours[i]; ctx.lineWidth = lw; ctx.stroke();
  }
  for (let j = 0; j < J; j++) {
    let r = lw * 0.62;
    if (j === HEAD) r = Math.max(lw * 1.2, cam.fl * 0.075 / pts[j][2]);
    ctx.beginPath(); ctx.arc(pts[j][0], pts[j][1], r, 0, 2 * Math.PI);
    ctx.fillStyle = partColour[D.jointPart[j]]; ctx.fill();
    ctx.lineWidth = 1.5; ctx.strokeStyle = "#1d1f23"; ctx.stroke();
  }
  ctx.fillStyle = "#5b6068"; ctx.font = font(14); ctx.textAlign = "right"; ctx.textBaseline = "bottom";
  ctx.fillText("drag: turn · wheel: zoom · double-click: reset", w - 8, hgt - 6);
  p.drawn = {frame: f, column: col, joints2d: pts.map(q => [Math.round(q[0] * 100) / 100, Math.round(q[1] * 100) / 100]),
             boneColors: boneColours, jointColors: D.jointPart.map(r => partColour[r]), partValues: values,
             scale: {lo: sc.lo, hi: sc.hi, signed: sc.signed}, words: p.words.filter((x, i) => p.sel.has(i)).map(x => x.text)};
}
function heatLayout(p, w, hgt) {
  const left = 104 * U, right = 92 * U, top = 30 * U, bottom = 52 * U;
  return {left, right, top, bottom, gw: w - left - right, gh: hgt - top - bottom, rowH: (hgt - top - bottom) / NP,
          frames: p.N * FPL};
}
function drawHeat(p, sc) {
  const [ctx, w, hgt] = fit(p.els.heat);
  if (!(w > 0 && hgt > 0)) return;
  ctx.clearRect(0, 0, w, hgt);
  const Lh = heatLayout(p, w, hgt), xOf = fr => Lh.left + Lh.gw * fr / Lh.frames;
  ctx.textBaseline = "middle";
  ctx.font = font(17, 600); ctx.fillStyle = "#1d1f23"; ctx.textAlign = "left";
  ctx.fillText(p.map ? selectedText(p) : "no word selected", Lh.left, Lh.top / 2);
  ctx.font = font(15); ctx.fillStyle = "#5b6068"; ctx.textAlign = "center";
  ctx.fillText("now", w - Lh.right / 2, Lh.top / 2);
  const f = frameOf(p), col = columnOf(p, f);
  for (let r = 0; r < NP; r++) {
    const y = Lh.top + r * Lh.rowH;
    if (p.map) {
      for (let n = 0; n < p.N; n++) {
        ctx.fillStyle = colour(p.map[r * p.N + n], sc);
        const x0 = xOf(n * FPL), x1 = xOf((n + 1) * FPL);
        ctx.fillRect(Math.floor(x0), Math.floor(y), Math.ceil(x1) - Math.floor(x0), Math.ceil(Lh.rowH));
      }
    } else {
      ctx.fillStyle = "#e6e8eb"; ctx.fillRect(Lh.left, y, Lh.gw, Lh.rowH);
    }
    const hot = r === state.hoverPart;
    ctx.font = font(17, hot ? 700 : 0); ctx.fillStyle = hot ? "#c81e4a" : "#1d1f23";
    ctx.textAlign = "right"; ctx.fillText(D.parts[r], Lh.left - 8, y + Lh.rowH / 2);
    if (p.map) {
      const v = p.map[r * p.N + col];
      ctx.fillStyle = colour(v, sc); ctx.fillRect(w - Lh.right + 8 * U, y + 5, 14 * U, Lh.rowH - 10);
      ctx.strokeStyle = "#1d1f23"; ctx.lineWidth = 1; ctx.strokeRect(w - Lh.right + 8 * U, y + 5, 14 * U, Lh.rowH - 10);
      ctx.fillStyle = "#1d1f23"; ctx.textAlign = "left"; ctx.font = font(16);
      ctx.fillText(fmt(v), w - Lh.right + 27 * U, y + Lh.rowH / 2);
    }
  }
  ctx.strokeStyle = "rgba(255,255,255,0.55)"; ctx.lineWidth = 1;
  for (let r = 1; r < NP; r++) {
    ctx.beginPath(); ctx.moveTo(Lh.left, Lh.top + r * Lh.rowH); ctx.lineTo(Lh.left + Lh.gw, Lh.top + r * Lh.rowH); ctx.stroke();
  }
  // time axis in seconds
  const seconds = Lh.frames / FPS, tick = seconds > 16 ? 4 : seconds > 8 ? 2 : seconds > 3 ? 1 : 0.5;
  ctx.fillStyle = "#1d1f23"; ctx.strokeStyle = "#1d1f23"; ctx.font = font(15); ctx.textAlign = "center";
  ctx.textBaseline = "top";
  for (let s = 0; s <= seconds + 1e-9; s += tick) {
    const x = xOf(s * FPS);
    ctx.beginPath(); ctx.moveTo(x, Lh.top + Lh.gh); ctx.lineTo(x, Lh.top + Lh.gh + 6 * U); ctx.stroke();
    ctx.fillText((tick < 1 ? s.toFixed(1) : String(Math.round(s))), x, Lh.top + Lh.gh + 8 * U);
  }
  ctx.fillText("time (s)  ·  one column = " + FPL + " frames", Lh.left + Lh.gw / 2, Lh.top + Lh.gh + 29 * U);
  // the current frame
  const fx = xOf(f + 0.5);
  ctx.beginPath(); ctx.moveTo(fx, Lh.top - 4); ctx.lineTo(fx, Lh.top + Lh.gh + 4);
  ctx.strokeStyle = "#ffffff"; ctx.lineWidth = 5; ctx.setLineDash([]); ctx.stroke();
  ctx.beginPath(); ctx.moveTo(fx, Lh.top - 4); ctx.lineTo(fx, Lh.top + Lh.gh + 4);
  ctx.strokeStyle = sc.signed ? "#111111" : "#ff2d55"; ctx.lineWidth = 2.5; ctx.stroke();   // red vanishes on RdBu
  p.heatDrawn = {cursorX: fx, column: col};
}
function drawBar(sc) {
  const [ctx, w, hgt] = fit(els.bar);
  if (!(w > 0)) return;
  ctx.clearRect(0, 0, w, hgt);
  const x0 = 14, x1 = w - 14, y0 = 6, bh = 22 * U;
  for (let x = x0; x < x1; x++) {
    ctx.fillStyle = colour(sc.lo + (sc.hi - sc.lo) * (x - x0) / (x1 - x0 - 1), sc); ctx.fillRect(x, y0, 1.5, bh);
  }
  ctx.strokeStyle = "#1d1f23"; ctx.lineWidth = 1; ctx.strokeRect(x0, y0, x1 - x0, bh);
  ctx.fillStyle = "#1d1f23"; ctx.font = font(16); ctx.textBaseline = "top";
  const ticks = sc.signed ? [sc.lo, 0, sc.hi] : [0, sc.hi / 2, sc.hi];
  ticks.forEach((v, i) => {
    const x = x0 + (x1 - x0) * (v - sc.lo) / (sc.hi - sc.lo);
    ctx.textAlign = i === 0 ? "left" : i === ticks.length - 1 ? "right" : "center";
    ctx.beginPath(); ctx.moveTo(x, y0 + bh); ctx.lineTo(x, y0 + bh + 5 * U); ctx.stroke();
    ctx.fillText(fmt(v), x, y0 + bh + 8 * U);
  });
}
function draw() {
  const key = [state.layers.size ? [...state.layers].sort().join(".") : "-", state.steps.join("-")].join("|");
  for (const p of panels) {       // the map changes with the selection only, not with the frame
    const k = key + "|" + [...p.sel].sort((a, b) => a - b).join(".");
    if (p.mapKey !== k) { p.map = computeMap(p); p.mapKey = k; }
  }
  const sc = colourScale();
  state.scale = sc;
  for (const p of panels) { drawSkeleton(p, sc); drawHeat(p, sc); }
  drawBar(sc);
  els.barText.textContent = scaleText(sc);
  els.scrub.value = String(state.frame);
  els.readout.textContent = "frame " + state.frame + " / " + (NF - 1) + "  ·  " + fmtTime(state.frame);
  els.play.textContent = state.playing ? "❚❚ Pause" : "▶ Play";
  for (const b of els.wordButtons) b.setAttribute("aria-pressed", String(panels[b._panel].sel.has(b._word)));
  for (const b of els.layerButtons) b.setAttribute("aria-pressed", String(state.layers.has(b._layer)));
  if (D.steps) {
    els.stepFrom.value = String(state.steps[0]); els.stepTo.value = String(state.steps[1]);
    const g = D.steps.groups;
    els.stepText.textContent = "steps " + g[state.steps[0]][0] + "–" + g[state.steps[1]][1] + " of " + D.steps.total +
      " (0 = noisiest)";
  }
}

// ----------------------------------------------------------------- actions
function note(text) { els.note.textContent = text || ""; }
function setFrame(f) { state.frame = clamp(Math.round(Number(f)) || 0, 0, NF - 1); draw(); return state.frame; }
function toggleWord(pi, wi) {
  const p = panels[pi], on = !p.sel.has(wi);
  const other = panels.length === 2 ? panels[1 - pi] : null;
  const partner = other ? p.align[wi] : -1;
  const next = new Set(p.sel), nextOther = other ? new Set(other.sel) : null;
  if (on) next.add(wi); else next.delete(wi);
  if (other && partner >= 0) { if (on) nextOther.add(partner); else nextOther.delete(partner); }
  if (next.size === 0 && (!other || nextOther.size === 0)) {
    note("At least one word stays selected: select another word first."); draw(); return;
  }
  note("");
  p.sel = next;
  if (other) other.sel = nextOther;
  draw();
}
function setWords(pi, indices) {
  const p = panels[pi];
  p.sel = new Set(indices);
  if (panels.length === 2) {
    const other = panels[1 - pi];
    other.sel = new Set(indices.map(i => p.align[i]).filter(j => j >= 0));
  }
  draw();
}
function toggleLayer(l) {
  if (state.layers.has(l) && state.layers.size === 1) { note("At least one layer stays selected."); draw(); return; }
  note("");
  if (state.layers.has(l)) state.layers.delete(l); else state.layers.add(l);
  draw();
}
function setLayers(list) { if (list.length) { state.layers = new Set(list); } draw(); }
function setSteps(a, b) {
  a = clamp(Math.round(a), 0, S - 1); b = clamp(Math.round(b), 0, S - 1);
  state.steps = [Math.min(a, b), Math.max(a, b)]; draw();
}
let last = null, carry = 0;
function tick(t) {
  if (state.playing) {
    if (last !== null) {
      carry += (t - last) / 1000 * FPS * state.speed;
      const n = Math.floor(carry);
      if (n > 0) { carry -= n; state.frame = (state.frame + n) % NF; draw(); }
    }
    last = t;
    requestAnimationFrame(tick);
  } else last = null;
}
function play() { if (!state.playing) { state.playing = true; carry = 0; last = null; requestAnimationFrame(tick); } draw(); }
function pause() { state.playing = false; draw(); }

// ----------------------------------------------------------------- the page
const els = {wordButtons: [], layerButtons: []};
updateScale();
const app = document.getElementById("salad-app");
const steps = D.steps, heads = D.heads;
const secs = (NF / FPS).toFixed(1);
const capture = [];
if (steps) capture.push(steps.total + " denoising steps" +
                        (steps.groups.length !== steps.total ? " in " + steps.groups.length + " groups" : ""));
if (D.layers) capture.push(D.layers.length + " layers");
if (heads) capture.push("mean over " + heads + " heads");
const compare = panels.length === 2;
const header = h("header", {},
  h("div", {class: "kicker", text: D.title}),
  h("h1", {text: compare ? (D.edit ? "Edit: " + D.edit : (panels[0].label || "source") + " and " + (panels[1].label || "edited"))
                         : "“" + D.prompt + "”"}),
  h("div", {class: "meta", text: [D.model ? "model: " + D.model : null, "skeleton: " + D.skeleton,
                                   NF + " frames (" + secs + " s at " + FPS + " fps)",
                                   capture.length ? "attention: " + capture.join(", ") : null].filter(Boolean).join("  ·  ")}));

function wordRow(pi, name) {
  const p = panels[pi];
  const row = h("div", {class: "row words"}, h("span", {class: "name", text: name}));
  p.words.forEach((wd, wi) => {
    const b = h("button", {class: "chip", "aria-pressed": "false", title: "tokens " + wd.tokens.join(", "),
                           onclick: () => toggleWord(pi, wi), text: wd.text});
    b._panel = pi; b._word = wi; b.dataset.panel = pi; b.dataset.word = wi;
    els.wordButtons.push(b); row.append(b);
  });
  return row;
}
const controls = h("section", {class: "controls"});
if (panels.length === 1 || sameWords) controls.append(wordRow(0, "Words"));
else panels.forEach((p, i) => controls.append(wordRow(i, p.label || ("motion " + (i + 1)))));
controls.append(h("div", {class: "hint", text: "Click words to add or remove them: the maps of the selected words are summed" +
  (compare ? " (a word's counterpart in the other prompt follows)." : ".")}));
const filters = h("div", {class: "row filters"});
if (D.layers) {
  filters.append(h("span", {class: "name", text: "Layers"}));
  D.layers.forEach((lab, l) => {
    const b = h("button", {class: "chip small", "aria-pressed": "true", onclick: () => toggleLayer(l), text: lab});
    b._layer = l; b.dataset.layer = l; els.layerButtons.push(b); filters.append(b);
  });
}
if (steps) {
  els.stepFrom = h("input", {type: "range", class: "step", min: "0", max: String(S - 1), step: "1", value: "0",
                             "aria-label": "first step group"});
  els.stepTo = h("input", {type: "range", class: "step", min: "0", max: String(S - 1), step: "1", value: String(S - 1),
                           "aria-label": "last step group"});
  els.stepFrom.addEventListener("input", () => setSteps(Number(els.stepFrom.value), Math.max(Number(els.stepFrom.value), state.steps[1])));
  els.stepTo.addEventListener("input", () => setSteps(Math.min(Number(els.stepTo.value), state.steps[0]), Number(els.stepTo.value)));
  els.stepText = h("span", {class: "readout"});
  filters.append(h("span", {class: "name gap", text: "Steps"}), h("span", {class: "hint", text: "from"}), els.stepFrom,
                 h("span", {class: "hint", text: "to"}), els.stepTo, els.stepText);
}
if (filters.childNodes.length) controls.append(filters);
els.play = h("button", {class: "play", onclick: () => (state.playing ? pause() : play())});
els.speed = h("select", {"aria-label": "speed"});
for (const s of [0.25, 0.5, 1, 2]) els.speed.append(h("option", {value: String(s), text: s + "×"}));
els.speed.value = "1";
els.speed.addEventListener("change", () => { state.speed = Number(els.speed.value); });
els.scrub = h("input", {type: "range", class: "scrub", min: "0", max: String(NF - 1), step: "1", value: "0", "aria-label": "frame"});
els.scrub.addEventListener("input", () => setFrame(els.scrub.value));
els.readout = h("span", {class: "readout"});
els.follow = h("input", {type: "checkbox", checked: ""});
els.follow.addEventListener("change", () => { state.follow = els.follow.checked; draw(); });
controls.append(h("div", {class: "row player"}, els.play, h("label", {}, "speed ", els.speed), els.scrub, els.readout,
  h("label", {class: "hint"}, els.follow, " camera follows")));
els.note = h("div", {class: "note"});
controls.append(els.note);

const main = h("main", {class: "panels " + (compare ? "compare" : "single")});
els.bar = h("canvas", {class: "bar", "aria-label": "colour scale"});
els.barText = h("div", {class: "hint"});
const scale = h("div", {class: "scale"}, h("div", {class: "barbox"}, els.bar), els.barText);
function scaleText(sc) {
  return "Colour: attention of the selected words (post-softmax probability summed over their tokens, " +
    "mean over the chosen steps, layers and heads), " +
    (sc.signed ? "from minus to plus the largest magnitude shown (negative after a negative re-weight)"
               : "from 0 to the largest value shown") +
    (compare ? " in either motion: one scale for both." : ".") +
    " Each bone takes its body part's value at the current frame; point at a heatmap row to outline its bones.";
}
for (const p of panels) {
  p.els.skel = h("canvas", {class: "skel", "aria-label": "skeleton of " + (p.label || "the motion")});
  p.els.heat = h("canvas", {class: "heat", "aria-label": "attention heatmap"});
  p.els.hover = h("div", {class: "hover"});
  const title = compare ? h("h2", {}, h("span", {class: "label", text: (p.label || "motion " + (p.index + 1)) + ": "}),
                                    h("span", {class: "prompt", text: "“" + p.prompt + "”"})) : null;
  main.append(h("div", {class: "panel", "data-panel": String(p.index)}, title, p.els.skel,
                h("div", {class: "side"}, p.els.heat, p.els.hover, compare ? null : scale)));
}
app.append(header, controls, main);
if (compare) app.append(scale);

// ----------------------------------------------------------------- interaction
for (const p of panels) {
  let drag = null;
  const c = p.els.skel;
  c.addEventListener("pointerdown", e => { drag = [e.clientX, e.clientY]; c.setPointerCapture(e.pointerId); });
  c.addEventListener("pointermove", e => {
    if (!drag) return;
    state.azimuth -= (e.clientX - drag[0]) * 0.5;
    state.elevation = clamp(state.elevation + (e.clientY - drag[1]) * 0.4, -10, 85);
    drag = [e.clientX, e.clientY]; draw();
  });
  c.addEventListener("pointerup", () => { drag = null; });
  c.addEventListener("wheel", e => { e.preventDefault(); state.zoom = clamp(state.zoom * Math.exp(e.deltaY * 0.001), 0.3, 4); draw(); },
                     {passive: false});
  c.addEventListener("dblclick", () => { state.azimuth = D.view.azimuth; state.elevation = D.view.elevation; state.zoom = 1; draw(); });
  const hc = p.els.heat;
  let scrubbing = false;
  const at = e => {
    const r = hc.getBoundingClientRect(), Lh = heatLayout(p, r.width, r.height);
    const x = e.clientX - r.left, y = e.clientY - r.top;
    return {fr: (x - Lh.left) / Lh.gw * Lh.frames, part: Math.floor((y - Lh.top) / Lh.rowH), inside: x >= Lh.left && x <= Lh.left + Lh.gw};
  };
  hc.addEventListener("pointerdown", e => {
    const q = at(e);
    if (q.inside) { scrubbing = true; hc.setPointerCapture(e.pointerId); setFrame(Math.floor(q.fr)); }
  });
  hc.addEventListener("pointerup", () => { scrubbing = false; });
  hc.addEventListener("pointermove", e => {
    const q = at(e);
    if (scrubbing) setFrame(Math.floor(clamp(q.fr, 0, NF - 1)));
    const part = q.part >= 0 && q.part < NP ? q.part : -1;
    if (part !== state.hoverPart) { state.hoverPart = part; draw(); }
    if (part >= 0 && q.inside && p.map) {
      const n = clamp(Math.floor(q.fr / FPL), 0, p.N - 1);
      p.els.hover.textContent = D.parts[part] + "  ·  frames " + n * FPL + "–" + ((n + 1) * FPL - 1) + "  ·  " + fmt(p.map[part * p.N + n]);
    } else p.els.hover.textContent = part >= 0 ? D.parts[part] + ": its bones are outlined in the skeleton" : "";
  });
  hc.addEventListener("pointerleave", () => { state.hoverPart = -1; p.els.hover.textContent = ""; draw(); });
}
document.addEventListener("keydown", e => {
  if (e.target && (e.target.tagName === "INPUT" || e.target.tagName === "SELECT" || e.target.tagName === "BUTTON")) return;
  if (e.key === " ") { e.preventDefault(); state.playing ? pause() : play(); }
  else if (e.key === "ArrowRight") setFrame(state.frame + 1);
  else if (e.key === "ArrowLeft") setFrame(state.frame - 1);
});
if (window.ResizeObserver) new ResizeObserver(() => draw()).observe(main);
window.addEventListener("resize", () => { updateScale(); draw(); });

window.saladExplorer = {
  data: D, state, panels, edges, setFrame, toggleWord, setWords, setLayers, setSteps, play, pause, draw,
  currentMap: pi => { const p = panels[pi]; if (!p.map) return null;
    return D.parts.map((_, r) => Array.from(p.map.slice(r * p.N, (r + 1) * p.N))); },
};
draw();
})();
"""
