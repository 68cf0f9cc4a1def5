"""A Jupyter explorer of cross-attention: pick words, layers and a step range, scrub the frames.

The heatmap of the selected words (summed) and the skeleton, with each joint coloured by its body
part's attention at the current frame, update together. Everything is computed from arrays; the
widget holds no model.

Example (in a notebook)::

    from salad_viz.widgets import explore_attention
    explore_attention(out.attention, out.tokens, out.joints[0], "humanml3d", axes="slhnpw")
"""
from __future__ import annotations

import io
from typing import Sequence

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import as_joints, to_numpy
from .attention import joint_attention_colors, merge_tokens, plot_word_attention, reduce_attention

__all__ = ["AttentionExplorer", "explore_attention"]


def _png(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG")
    return buf.getvalue()


class AttentionExplorer:
    """Linked heatmap + skeleton view of captured cross-attention (ipywidgets).

    Parameters
    ----------
    attention : array
        Captured maps; ``axes`` names every axis (see :func:`salad_viz.attention.reduce_attention`).
    tokens : sequence of str
        The W tokens of the prompt.
    joints : array (N, J, 3)
        The generated motion in metres.
    skeleton : str or Skeleton
    axes : str
        Axis letters of ``attention``, e.g. ``"slhnpw"``; must contain ``n``, ``p``, ``w``.
    batch : int, optional
        Batch element to show when there is a batch axis.
    frames_per_latent : int
        Motion frames per latent frame (4 in SALAD).
    size : (width, height)
        Skeleton view size in pixels.
    backend : {"auto", "pyvista", "raster"}
        Skeleton renderer.
    view : str or float
        Camera view (see :mod:`salad_viz.camera`).
    cmap : str
        Colormap shared by the heatmap and the joints.

    Attributes
    ----------
    widget : ipywidgets.VBox
        The whole explorer; displaying the explorer displays this.
    words, layers, steps, frame, play : ipywidgets controls
        ``layers`` / ``steps`` are ``None`` when ``attention`` has no such axis.
    heatmap, skeleton_view : ipywidgets.Image
        PNG views, refreshed on every change.
    """

    def __init__(self, attention, tokens: Sequence[str], joints, skeleton: str | Skeleton = "humanml3d", *,
                 axes: str = "pnw", batch: int | None = None, frames_per_latent: int = 4,
                 size: Sequence[int] = (360, 300), backend: str = "auto", view: str | float = "three_quarter",
                 cmap: str = "viridis"):
        import ipywidgets as W

        from .render import SkeletonRenderer

        self.skeleton = get_skeleton(skeleton)
        self.attention = to_numpy(attention, "attention")
        self.axes = axes
        self.batch = batch
        self.tokens = [str(t) for t in tokens]
        self.joints = as_joints(joints, self.skeleton)
        self.fpl = int(frames_per_latent)
        self.cmap = cmap
        self.view = view
        reduced = reduce_attention(self.attention, axes, batch=batch)  # validates the layout once
        if reduced.shape[2] != len(self.tokens):
            raise ValueError(f"tokens has {len(self.tokens)} entries but attention has W = {reduced.shape[2]}")
        self._renderer = SkeletonRenderer(self.skeleton, size=size, backend=backend)

        groups = [(w, ids) for w, ids in merge_tokens(self.tokens)]
        if not groups:
            raise ValueError("tokens contain no words")
        options = [(f"{ids[0]}: {w}", ids) for w, ids in groups]
        self.words = W.SelectMultiple(options=options, value=(options[0][1],), rows=min(8, len(options)),
                                      description="words")
        self.layers = None
        if "l" in axes:
            n_layers = self.attention.shape[axes.index("l")]
            self.layers = W.SelectMultiple(options=[(f"layer {i}", i) for i in range(n_layers)],
                                           value=tuple(range(n_layers)), rows=min(6, n_layers),
                                           description="layers")
        self.steps = None
        if "s" in axes:
            n_steps = self.attention.shape[axes.index("s")]
            self.steps = W.IntRangeSlider(value=(0, n_steps - 1), min=0, max=n_steps - 1, description="steps",
                                          continuous_update=False)
        n = len(self.joints)
        self.frame = W.IntSlider(value=0, min=0, max=n - 1, description="frame", continuous_update=True)
        self.play = W.Play(value=0, min=0, max=n - 1, interval=int(1000 / self.skeleton.fps))
        W.jslink((self.play, "value"), (self.frame, "value"))
        self.heatmap = W.Image(format="png")
        self.skeleton_view = W.Image(format="png")
        self.status = W.Label()

        for ctl in (self.words, self.layers, self.steps):
            if ctl is not None:
                ctl.observe(self._on_selection, names="value")
        self.frame.observe(self._on_frame, names="value")
        controls = [c for c in (self.words, self.layers, self.steps) if c is not None]
        self.widget = W.VBox([
            W.HBox(controls),
            W.HBox([self.play, self.frame, self.status]),
            W.HBox([self.heatmap, self.skeleton_view]),
        ])
        self._map = None
        self._colors = None
        self.refresh()

    # ----------------------------------------------------------------- state
    @property
    def selected_map(self) -> np.ndarray:
        """``(P, N')`` map of the selected words (summed) over the selected layers and steps."""
        return self._map.copy()

    def _compute_map(self) -> np.ndarray:
        steps = None if self.steps is None else (self.steps.value[0], self.steps.value[1] + 1)
        layers = None if self.layers is None else list(self.layers.value)
        if layers is not None and not layers:
            raise ValueError("select at least one layer")
        red = reduce_attention(self.attention, self.axes, steps=steps, layers=layers, batch=self.batch)
        ids = sorted({i for group in self.words.value for i in group})
        if not ids:
            raise ValueError("select at least one word")
        return red[:, :, ids].sum(axis=2)

    def _label(self) -> str:
        names = [label.split(": ", 1)[1] for label, ids in self.words.options if ids in self.words.value]
        return " + ".join(names)

    def refresh(self) -> None:
        """Recompute the map from the controls and redraw both views."""
        try:
            self._map = self._compute_map()
        except ValueError as exc:
            self.status.value = str(exc)
            return
        self.status.value = ""
        self._colors = joint_attention_colors(self._map, self.skeleton, len(self.joints),
                                              frames_per_latent=self.fpl, cmap=self.cmap)
        self._draw()

    def _draw(self) -> None:
        f = int(self.frame.value)
        fig = plot_word_attention(self._map, self._label(), skeleton=self.skeleton, frames_per_latent=self.fpl,
                                  cmap=self.cmap, frame=f)
        fig.set_size_inches(4.6, 2.6)
        buf = io.BytesIO()
        fig.savefig(buf, format="png", dpi=90)
        self.heatmap.value = buf.getvalue()
        img = self._renderer.render(self.joints, f, view=self.view, joint_colors=self._colors,
                                    title=f"frame {f}")
        self.skeleton_view.value = _png(img)

    def _on_selection(self, change) -> None:
        self.refresh()

    def _on_frame(self, change) -> None:
        if self._map is not None:
            self._draw()

    # ----------------------------------------------------------------- display
    def close(self) -> None:
        """Release the renderer and close the widgets."""
        self._renderer.close()
        self.widget.close()

    def _repr_mimebundle_(self, **kwargs):
        return self.widget._repr_mimebundle_(**kwargs)


def explore_attention(attention, tokens: Sequence[str], joints, skeleton: str | Skeleton = "humanml3d", *,
                      axes: str = "pnw", **kwargs) -> AttentionExplorer:
    """Build an :class:`AttentionExplorer` (display it, or return it as a notebook cell's value).

    Parameters as in :class:`AttentionExplorer`; the ``axes`` letters are listed in
    :data:`salad_viz.attention.AXES` (s step, l layer, b batch, h head, n latent frame, p body part,
    w token).
    """
    return AttentionExplorer(attention, tokens, joints, skeleton, axes=axes, **kwargs)
