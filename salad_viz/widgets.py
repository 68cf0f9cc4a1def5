"""A Jupyter explorer of cross-attention: pick words, layers and a step range, scrub the frames.

The heatmap of the selected words (summed) and the skeleton, with each joint coloured by its body
part's attention at the current frame, update together. Everything is computed from arrays (or
from the pipeline's :class:`~salad_core.attention.AttentionMaps`); the widget holds no model.

Threads. JupyterLab (4.4 and later) sends widget messages over kernel *subshells* by default
("Kernel Comms over subshells"), so ipykernel 7 runs the widget callbacks on ``subshell-...``
threads, one per comm or per comm target, possibly at the same time. An OpenGL context may only be
used by the thread it is current on: a pyvista plotter made on the main thread draws black or stale
frames, or noise, when a subshell thread renders with it. The explorer therefore renders every
skeleton frame on one thread of its own (:class:`RenderThread`), which creates the renderer, draws
each frame and closes it; callbacks hand it the frame and wait for the image. A lock keeps callbacks
that run at the same time on different subshells from interleaving. The explorer works the same with
the setting on ("One subshell per comm", "One subshell per comm-target") and off ("Disabled").

Examples
--------
Generate with a full capture (every step, layer and head) and explore it; the last expression of a
notebook cell displays the explorer:

>>> from salad_core.attention import CaptureConfig
>>> from salad_core.pipeline import SaladPipeline
>>> from salad_viz.widgets import explore_attention
>>> pipe = SaladPipeline.from_pretrained()
>>> out = pipe("a man jumps forward and then walks", lengths=60, num_steps=10, seed=0,
...            capture_attention=CaptureConfig(mode="full"))
>>> ex = explore_attention(out.attention, out.attention.tokens(0), out.joints[0], "humanml3d")
>>> ex.selected_words                       # opens on the first content word
['jumps']
>>> ex.selected_map.shape                   # (7 body parts, 60 / 4 latent frames)
(7, 15)
>>> (ex.steps.max, len(ex.layers.options))  # 10 steps, 5 layers to choose from
(9, 5)
>>> ex.words.value = ex.word_ids("jumps", "walks")   # what Ctrl-clicking both words does
>>> ex.frame.value = 30                     # scrub: both views follow
>>> ex.drawn                                # what the heatmap and the skeleton now show
{'words': ['jumps', 'walks'], 'layers': [0, 1, 2, 3, 4], 'steps': [0, 9], 'frame': 30}
>>> ex.close()

An ``AttentionMaps`` from the default capture (``capture_attention=True``, means over 10 step bins)
gives the layers but not the steps; a plain array needs its axis letters, e.g.
``explore_attention(out.attention.full(0), out.attention.tokens(0), out.joints[0], axes="slhnpw")``.
"""
from __future__ import annotations

import io
import queue
import threading
import weakref
from concurrent.futures import Future
from typing import Any, Callable, Sequence

import numpy as np

from salad_core.skeleton import Skeleton, get_skeleton

from ._arrays import as_joints, check_size, to_numpy
from .attention import joint_attention_colors, merge_tokens, plot_word_attention, reduce_attention

__all__ = ["AttentionExplorer", "RenderThread", "explore_attention", "first_content_word", "SKIP_WORDS",
           "SELECTION_HINT"]

#: Words the explorer does not open on: function words (articles, auxiliaries, pronouns,
#: conjunctions, prepositions) and the subject nouns nearly every caption starts with. Their maps are
#: rarely the first thing a reader wants to see.
SKIP_WORDS = frozenset("""
a an the this that these those some any each every
is are was were be been being am do does did has have had
he she it they them him her his hers its their theirs i me my we us our you your
and or but then while when as so if than after before until
of to in on at by for with from into onto over under up down off out around across through
man woman person people guy boy girl child kid someone somebody human individual figure character
""".split())

#: The help line shown beside the words list.
SELECTION_HINT = ("Ctrl-click (Cmd-click on a Mac) adds or removes a word, Shift-click selects a range; "
                  "the maps of the selected words are summed.")

_RENDER_TIMEOUT_S = 120.0


def _png(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG")
    return buf.getvalue()


def first_content_word(words: Sequence[str]) -> int:
    """Index of the first word that is not in :data:`SKIP_WORDS` (0 when all are).

    >>> first_content_word(["a", "man", "jumps", "forward"])
    2
    """
    for i, word in enumerate(words):
        if word.lower() not in SKIP_WORDS:
            return i
    return 0


# ----------------------------------------------------------------------------- render thread
class RenderThread:
    """A thread that owns one :class:`~salad_viz.render.SkeletonRenderer` for its whole life.

    The renderer (and with it the OpenGL context of the pyvista backend) is created, used and
    closed on this thread only; other threads call :meth:`render`, which queues the frame and
    waits for the image. Frames are drawn one at a time in the order they were asked for.

    Parameters
    ----------
    skeleton, size, backend
        As in :class:`~salad_viz.render.SkeletonRenderer`; the renderer is built on the thread
        (creating it raises here, in the caller, when the arguments are bad).
    timeout : float
        Seconds :meth:`render` waits for an image before raising ``TimeoutError``.

    Attributes
    ----------
    backend : str
        The resolved backend, ``"pyvista"`` or ``"raster"``.
    thread : threading.Thread
        The daemon thread (name ``salad-render-...``).
    """

    def __init__(self, skeleton: str | Skeleton = "humanml3d", *, size: Sequence[int] = (400, 300),
                 backend: str = "auto", timeout: float = _RENDER_TIMEOUT_S):
        if not timeout > 0:
            raise ValueError(f"timeout must be > 0 seconds, got {timeout!r}")
        self.timeout = float(timeout)
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._closed = False
        started: Future = Future()
        # daemon: an explorer left open must not keep the kernel from exiting
        self.thread = threading.Thread(target=self._run, args=(skeleton, tuple(size), backend, started),
                                       name=f"salad-render-{id(self):x}", daemon=True)
        self.thread.start()
        self.backend = started.result(timeout=self.timeout)

    def _run(self, skeleton, size, backend, started: Future) -> None:
        from .render import SkeletonRenderer

        try:
            renderer = SkeletonRenderer(skeleton, size=size, backend=backend)
        except BaseException as exc:  # hand the error to the constructor's caller
            started.set_exception(exc)
            return
        started.set_result(renderer.backend)
        try:
            while True:
                job = self._jobs.get()
                if job is None:
                    return
                fn, args, kwargs, result = job
                if not result.set_running_or_notify_cancel():
                    continue
                try:
                    result.set_result(fn(renderer, *args, **kwargs))
                except BaseException as exc:
                    result.set_exception(exc)
        finally:
            renderer.close()  # releases the OpenGL context on the thread that made it

    def call(self, fn: Callable[..., Any], *args, **kwargs) -> Any:
        """Run ``fn(renderer, *args, **kwargs)`` on the render thread and return its result."""
        if self._closed:
            raise RuntimeError("this RenderThread is closed")
        result: Future = Future()
        self._jobs.put((fn, args, kwargs, result))
        return result.result(timeout=self.timeout)

    def render(self, joints, frame: int = 0, **kwargs) -> np.ndarray:
        """``SkeletonRenderer.render(joints, frame, **kwargs)`` on the render thread -> ``(H, W, 3)`` uint8."""
        return self.call(lambda r: r.render(joints, frame, **kwargs))

    def close(self, wait: bool = True) -> None:
        """Stop the thread after the frames already queued; the renderer is closed on it (safe twice)."""
        if not self._closed:
            self._closed = True
            self._jobs.put(None)
        if wait and self.thread is not threading.current_thread():
            self.thread.join(self.timeout)


# ----------------------------------------------------------------------------- inputs
def _is_attention_maps(obj) -> bool:
    # duck-typed: salad_viz depends on salad_core.skeleton only
    return all(hasattr(obj, name) for name in ("cross_map", "select", "tokens", "captured_layers", "mode"))


def _from_attention_maps(maps, b: int) -> tuple[np.ndarray, str]:
    """An ``AttentionMaps`` sample as ``(array, axes)``: every step, layer and head of a full
    capture (``"slhnpw"``), or the per-layer means of a mean capture (``"lpnw"``)."""
    if maps.mode == "full":
        return np.asarray(maps.full(b), dtype=np.float32), "slhnpw"
    layers = list(maps.captured_layers)
    stack = [maps.select(layers=[layer]).cross_map(b) for layer in layers]  # each (P, N', W)
    return np.stack(stack).astype(np.float32), "lpnw"


# ----------------------------------------------------------------------------- the explorer
class AttentionExplorer:
    """Linked heatmap + skeleton view of captured cross-attention (ipywidgets).

    Parameters
    ----------
    attention : AttentionMaps or array
        The pipeline's captured maps (``out.attention``; sample ``batch``), or an array whose
        axes ``axes`` names (see :func:`salad_viz.attention.reduce_attention`).
    tokens : sequence of str, optional
        The W tokens of the prompt (``out.attention.tokens(b)``); taken from ``attention`` when it
        is an ``AttentionMaps`` and ``tokens`` is ``None``.
    joints : array (N, J, 3)
        The generated motion in metres.
    skeleton : str or Skeleton
    axes : str
        Axis letters of an array ``attention``, e.g. ``"slhnpw"``; must contain ``n``, ``p``, ``w``
        (ignored for an ``AttentionMaps``).
    batch : int, optional
        Batch element: the sample of an ``AttentionMaps`` (default 0), or the index along an
        array's ``b`` axis.
    frames_per_latent : int, optional
        Motion frames per latent frame (default: the maps' ``unit_length``, else 4 as in SALAD).
    words : str or sequence of str, optional
        Word(s) selected at the start (default: the first content word, see
        :func:`first_content_word`).
    size : (width, height)
        Skeleton view size in pixels.
    backend : {"auto", "pyvista", "raster"}
        Skeleton renderer (it runs on the explorer's :class:`RenderThread`).
    view : str or float
        Camera view (see :mod:`salad_viz.camera`).
    cmap : str
        Colormap shared by the heatmap and the joints.

    Attributes
    ----------
    widget : ipywidgets.VBox
        The whole explorer (CSS class ``salad-explorer``); displaying the explorer displays this.
    words, layers, steps, frame, play : ipywidgets controls
        ``layers`` / ``steps`` are ``None`` when ``attention`` has no such axis. ``words`` holds
        tuples of token indices (one tuple per word).
    heatmap, skeleton_view : ipywidgets.Image
        PNG views, refreshed on every change.
    status : ipywidgets.Label
        Empty, or why the views were not updated (e.g. an empty selection).
    uid : str
        Identifies this explorer: its widget carries the CSS class ``salad-explorer-id-<uid>`` and
        :meth:`find` returns the explorer from it (tests driving a browser use this).
    """

    _live: "weakref.WeakValueDictionary[str, AttentionExplorer]" = weakref.WeakValueDictionary()

    def __init__(self, attention, tokens: Sequence[str] | None, joints, skeleton: str | Skeleton = "humanml3d", *,
                 axes: str = "pnw", batch: int | None = None, frames_per_latent: int | None = None,
                 words: str | Sequence[str] | None = None, size: Sequence[int] = (360, 300),
                 backend: str = "auto", view: str | float = "three_quarter", cmap: str = "viridis"):
        import ipywidgets as W

        self.skeleton = get_skeleton(skeleton)
        fpl = frames_per_latent
        if _is_attention_maps(attention):
            b = 0 if batch is None else batch
            if tokens is None:
                tokens = attention.tokens(b)
            if fpl is None:
                fpl = attention.unit_length
            attention, axes, batch = (*_from_attention_maps(attention, b), None)
        elif tokens is None:
            raise ValueError("tokens is required when attention is an array (pass the prompt's W tokens)")
        self.attention = to_numpy(attention, "attention")
        self.axes = axes
        self.batch = batch
        self.tokens = [str(t) for t in tokens]
        self.joints = as_joints(joints, self.skeleton)
        fpl = 4 if fpl is None else fpl
        if isinstance(fpl, bool) or not isinstance(fpl, (int, np.integer)) or fpl < 1:
            raise ValueError(f"frames_per_latent must be a positive int, got {frames_per_latent!r}")
        self.fpl = int(fpl)
        self.cmap = cmap
        self.view = view
        self.size = check_size(size)
        reduced = reduce_attention(self.attention, axes, batch=batch)  # validates the layout once
        if reduced.shape[2] != len(self.tokens):
            raise ValueError(f"tokens has {len(self.tokens)} entries but attention has W = {reduced.shape[2]}")
        groups = merge_tokens(self.tokens)
        if not groups:
            raise ValueError("tokens contain no words")
        self._groups = groups
        self._lock = threading.RLock()
        self._renderer = RenderThread(self.skeleton, size=self.size, backend=backend)
        # the render thread must stop even when nobody calls close()
        self._finalizer = weakref.finalize(self, self._renderer.close, False)

        options = [(f"{ids[0]}: {w}", ids) for w, ids in groups]
        initial = self.word_ids(*([words] if isinstance(words, str) else words)) if words is not None else \
            (groups[first_content_word([w for w, _ in groups])][1],)
        self.words = W.SelectMultiple(options=options, value=initial, rows=min(8, len(options)),
                                      description="words", tooltip=SELECTION_HINT)
        self.layers = None
        if "l" in axes:
            n_layers = self.attention.shape[axes.index("l")]
            self.layers = W.SelectMultiple(options=[(f"layer {i}", i) for i in range(n_layers)],
                                           value=tuple(range(n_layers)), rows=min(6, n_layers),
                                           description="layers", tooltip="Ctrl/Shift-click to choose several")
        self.steps = None
        if "s" in axes:
            n_steps = self.attention.shape[axes.index("s")]
            self.steps = W.IntRangeSlider(value=(0, n_steps - 1), min=0, max=n_steps - 1, description="steps",
                                          continuous_update=False,
                                          tooltip="denoising steps averaged (0 = the first, noisiest)")
        n = len(self.joints)
        self.frame = W.IntSlider(value=0, min=0, max=n - 1, description="frame", continuous_update=True)
        self.play = W.Play(value=0, min=0, max=n - 1, interval=int(1000 / self.skeleton.fps))
        W.jslink((self.play, "value"), (self.frame, "value"))
        self.heatmap = W.Image(format="png")
        self.skeleton_view = W.Image(format="png")
        self.status = W.Label()
        hint = W.HTML(f"<small>{SELECTION_HINT}</small>")

        for ctl, cls in ((self.words, "words"), (self.layers, "layers"), (self.steps, "steps"),
                         (self.frame, "frame"), (self.play, "play"), (self.heatmap, "heatmap"),
                         (self.skeleton_view, "skeleton"), (self.status, "status")):
            if ctl is not None:
                ctl.add_class(f"salad-explorer-{cls}")
        for ctl in (self.words, self.layers, self.steps):
            if ctl is not None:
                ctl.observe(self._on_selection, names="value")
        self.frame.observe(self._on_frame, names="value")
        controls = [c for c in (self.words, self.layers, self.steps) if c is not None]
        self.uid = f"{id(self):x}"
        self.widget = W.VBox([
            W.HBox(controls),
            hint,
            W.HBox([self.play, self.frame, self.status]),
            W.HBox([self.heatmap, self.skeleton_view]),
        ])
        self.widget.add_class("salad-explorer")
        self.widget.add_class(f"salad-explorer-id-{self.uid}")
        AttentionExplorer._live[self.uid] = self
        self._map = None
        self._colors = None
        self._selection: dict = {}
        self._drawn: dict | None = None
        self.refresh()

    @classmethod
    def find(cls, uid: str) -> "AttentionExplorer":
        """The live explorer whose widget carries the CSS class ``salad-explorer-id-<uid>``."""
        try:
            return cls._live[uid]
        except KeyError:
            raise KeyError(f"no live explorer with uid {uid!r} (live: {sorted(cls._live)})") from None

    # ----------------------------------------------------------------- state
    @property
    def backend(self) -> str:
        """The skeleton renderer in use, ``"pyvista"`` or ``"raster"``."""
        return self._renderer.backend

    @property
    def selected_map(self) -> np.ndarray:
        """``(P, N')`` map of the selected words (summed) over the selected layers and steps."""
        return self._map.copy()

    @property
    def drawn(self) -> dict | None:
        """What the two images show: ``{"words", "layers", "steps", "frame"}`` as the controls had
        them when they were drawn (a control's value changes before its callback redraws)."""
        return None if self._drawn is None else dict(self._drawn)

    @property
    def selected_words(self) -> list[str]:
        """The selected words, in prompt order."""
        return [w for w, ids in self._groups if ids in self.words.value]

    def word_ids(self, *words: str) -> tuple[tuple[int, ...], ...]:
        """The ``words`` control value selecting these words (every occurrence), e.g.
        ``ex.words.value = ex.word_ids("jumps", "walks")``."""
        known = [w for w, _ in self._groups]
        missing = [w for w in words if w.lower() not in known]
        if missing:
            raise ValueError(f"words {missing} are not in the prompt; its words are {known}")
        wanted = {w.lower() for w in words}
        return tuple(ids for w, ids in self._groups if w in wanted)

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
        return " + ".join(self.selected_words)

    def refresh(self) -> None:
        """Recompute the map from the controls and redraw both views."""
        with self._lock:
            try:
                self._map = self._compute_map()
            except ValueError as exc:
                self.status.value = str(exc)
                return
            self.status.value = ""
            self._selection = dict(words=self.selected_words,
                                   layers=None if self.layers is None else list(self.layers.value),
                                   steps=None if self.steps is None else list(self.steps.value))
            self._colors = joint_attention_colors(self._map, self.skeleton, len(self.joints),
                                                  frames_per_latent=self.fpl, cmap=self.cmap)
            self._draw()

    def render_frame(self, frame: int | None = None) -> np.ndarray:
        """The skeleton view of ``frame`` (default: the current one) as ``(H, W, 3)`` uint8, drawn on
        the render thread with the current selection's joint colours."""
        with self._lock:
            f = int(self.frame.value if frame is None else frame)
            return self._renderer.render(self.joints, f, view=self.view, joint_colors=self._colors,
                                         title=f"frame {f}")

    def _draw(self) -> None:
        with self._lock:
            f = int(self.frame.value)
            # matplotlib's Figure (not pyplot) is safe to draw from any thread
            fig = plot_word_attention(self._map, self._label(), skeleton=self.skeleton, frames_per_latent=self.fpl,
                                      cmap=self.cmap, frame=f)
            fig.set_size_inches(4.6, 2.6)
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=90)
            self.heatmap.value = buf.getvalue()
            self.skeleton_view.value = _png(self.render_frame(f))
            self._drawn = {**self._selection, "frame": f}

    def _on_selection(self, change) -> None:
        self.refresh()

    def _on_frame(self, change) -> None:
        with self._lock:
            if self._map is not None:
                self._draw()

    # ----------------------------------------------------------------- display
    def close(self) -> None:
        """Stop the render thread (closing its renderer there) and close the widgets."""
        self._finalizer.detach()
        self._renderer.close(wait=True)
        AttentionExplorer._live.pop(self.uid, None)
        self.widget.close()

    def _repr_mimebundle_(self, **kwargs):
        return self.widget._repr_mimebundle_(**kwargs)


def explore_attention(attention, tokens: Sequence[str] | None, joints, skeleton: str | Skeleton = "humanml3d", *,
                      axes: str = "pnw", **kwargs) -> AttentionExplorer:
    """Build an :class:`AttentionExplorer` (display it, or return it as a notebook cell's value).

    Parameters as in :class:`AttentionExplorer`: ``attention`` is the pipeline's ``out.attention``
    (then ``tokens`` may be ``None``) or an array whose ``axes`` letters are listed in
    :data:`salad_viz.attention.AXES` (s step, l layer, b batch, h head, n latent frame, p body part,
    w token). See this module's docstring for a worked example.
    """
    return AttentionExplorer(attention, tokens, joints, skeleton, axes=axes, **kwargs)
