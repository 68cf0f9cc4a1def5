"""A Jupyter explorer of cross-attention: pick words, layers and a step range, scrub the frames.

The heatmap of the selected words (summed) and the skeleton, with each joint coloured by its body
part's attention at the current frame, update together. Everything is computed from arrays (or
from the pipeline's :class:`~salad_core.attention.AttentionMaps`); the widget holds no model.

Editing. Given ``editor=pipe`` (the pipeline, or any callable with ``pipe.edit``'s arguments), the
explorer also edits: a target text box (a word swap when the target has as many words as the source,
else a refinement; or as chosen), a re-weight slider (-1 to 3, 1 = unchanged) for each selected word,
mirror toggles for the arms and the legs, and a "Run edit" button. The edit is written as ONE line of
Python (:attr:`AttentionExplorer.edit_code`), shown under the controls, and that very line is what
runs, so pasting it into a cell gives the same motion bit for bit. The result shows the source and the
edit side by side: their skeletons at the current frame and their heatmaps of the selected words (the
counterparts in the target) on one colour scale, diverging about 0 when a map is negative.
:meth:`AttentionExplorer.edit_page` exports it as the offline HTML page. ``salad_viz`` imports nothing
of ``salad_core`` but the skeleton: the edit classes the line names (``WordSwap``, ``Refine``,
``Reweight``, ``Mirror``, ``CaptureConfig``) come from the editor itself (``SaladPipeline.edit_namespace()``)
or from ``edit_names=``; without an editor nothing of this is built.

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

Editing: re-weight "jumps" to -1 and run; the line shown is the edit, as Python:

>>> ex = explore_attention(out.attention, None, out.joints[0], editor=pipe, edit_options=dict(seed=0))
>>> ex.reweight_slider("jumps").value = -1
>>> ex.run.click()                          # what the "Run edit" button does
>>> ex.last_code
'pipe.edit("a man jumps forward and then walks", edits=[Reweight(words="jumps", scale=-1)], lengths=60, seed=0, num_steps=10, capture_attention=CaptureConfig(mode="full"))'
>>> from salad_core.attention import Reweight
>>> ed = pipe.edit("a man jumps forward and then walks", edits=[Reweight(words="jumps", scale=-1)], lengths=60,
...                seed=0, num_steps=10, capture_attention=CaptureConfig(mode="full"))   # the line, pasted
>>> bool((ed.edited.features == ex.last_edit.edited.features).all())
True
>>> ex.close()

An ``AttentionMaps`` from the default capture (``capture_attention=True``, means over 10 step bins)
gives the layers but not the steps; a plain array needs its axis letters, e.g.
``explore_attention(out.attention.full(0), out.attention.tokens(0), out.joints[0], axes="slhnpw")``.
"""
from __future__ import annotations

import html as _html
import io
import queue
import re
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


def _attention_maps_inputs(maps, batch: int | None, tokens, frames_per_latent, prompt) -> tuple[int, Any, Any, Any]:
    """What an ``AttentionMaps`` gives where the caller gave nothing: ``(b, tokens, frames_per_latent,
    prompt)``, with ``b`` the sample (``batch``, default 0) and each other value the given one or the maps':
    the sample's tokens, ``unit_length``, and its prompt if the maps hold prompts."""
    b = 0 if batch is None else batch
    if tokens is None:
        tokens = maps.tokens(b)
    if frames_per_latent is None:
        frames_per_latent = maps.unit_length
    if prompt is None and hasattr(maps, "prompts"):
        prompt = maps.prompts[b]
    return b, tokens, frames_per_latent, prompt


def _from_attention_maps(maps, b: int) -> tuple[np.ndarray, str]:
    """An ``AttentionMaps`` sample as ``(array, axes)``: every step, layer and head of a full
    capture (``"slhnpw"``), or the per-layer means of a mean capture (``"lpnw"``)."""
    if maps.mode == "full":
        return np.asarray(maps.full(b), dtype=np.float32), "slhnpw"
    layers = list(maps.captured_layers)
    stack = [maps.select(layers=[layer]).cross_map(b) for layer in layers]  # each (P, N', W)
    return np.stack(stack).astype(np.float32), "lpnw"


#: pipe.edit arguments the explorer's controls set (``edit_options`` may not).
_EDIT_OWN = frozenset({"source", "target", "edits", "capture_attention", "inversion", "noise"})


def _is_literal(value) -> bool:
    """Whether ``repr(value)`` is Python that gives ``value`` back (the printed edit line must run as written)."""
    if value is None or isinstance(value, (bool, int, str)):
        return True
    if isinstance(value, float):
        return bool(np.isfinite(value))
    if isinstance(value, (list, tuple)):
        return all(_is_literal(v) for v in value)
    return False


def _py_str(text: str) -> str:
    """A Python string literal of ``text``, in double quotes when that needs no escape."""
    r = repr(str(text))
    if r.startswith("'") and '"' not in text and "\\" not in r:
        return '"' + r[1:-1] + '"'
    return r


def _plain_words(text: str) -> list[str]:
    """Lower-case words (letters, digits, apostrophes) of a prompt, for naming a word swap or a refinement."""
    import re

    return re.findall(r"[a-z0-9']+", text.lower())


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
    editor : pipeline or callable, optional
        Turns on editing (see the module docstring): the pipeline (``SaladPipeline``, anything with an
        ``edit`` method taking ``pipe.edit``'s arguments) or a callable with those arguments, returning
        ``pipe.edit``'s ``EditOutput``.
    prompt : str, optional
        The source prompt of an edit (read from an ``AttentionMaps``; needed with an array ``attention``).
    edit_options : dict, optional
        More arguments of the edit, plain Python literals (e.g. ``seed=3``, ``guidance_scale=4.5``,
        ``solver="ddim"``); defaults: ``lengths`` = the motion's frames, ``seed=0``, ``num_steps`` = the
        maps' steps. Pass the seed the motion was generated with to edit that motion.
    editor_name : str, optional
        The editor's name in the printed line (default ``pipe``, or a callable's ``__name__``).
    edit_names : dict, optional
        The classes the line names (default: the editor's ``edit_namespace()``, which ``SaladPipeline`` has).

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
    target, replace, reweight_box, mirror_arms, mirror_legs, run, code, result, edit_status : ipywidgets
        The edit controls and views (``None`` without an ``editor``): the target prompt, how a changed
        target edits ("auto", "swap", "refine"), the re-weight sliders (:meth:`reweight_slider`), the
        mirror toggles, the run button, the line of Python, the result figure, errors of the last run.
    uid : str
        Identifies this explorer: its widget carries the CSS class ``salad-explorer-id-<uid>`` and
        :meth:`find` returns the explorer from it (tests driving a browser use this).
    """

    _live: "weakref.WeakValueDictionary[str, AttentionExplorer]" = weakref.WeakValueDictionary()

    def __init__(self, attention, tokens: Sequence[str] | None, joints, skeleton: str | Skeleton = "humanml3d", *,
                 axes: str = "pnw", batch: int | None = None, frames_per_latent: int | None = None,
                 words: str | Sequence[str] | None = None, size: Sequence[int] = (360, 300),
                 backend: str = "auto", view: str | float = "three_quarter", cmap: str = "viridis",
                 editor=None, prompt: str | None = None, edit_options: dict | None = None,
                 editor_name: str | None = None, edit_names: dict | None = None):
        import ipywidgets as W

        self.skeleton = get_skeleton(skeleton)
        fpl = frames_per_latent
        num_steps = None
        if _is_attention_maps(attention):
            b, tokens, fpl, prompt = _attention_maps_inputs(attention, batch, tokens, fpl, prompt)
            num_steps = getattr(attention, "num_steps", None)
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
        self.prompt = None if prompt is None else str(prompt)
        self._editor = None
        self._last_edit = None
        for name in ("target", "replace", "reweight_box", "mirror_arms", "mirror_legs", "run", "code", "result",
                     "edit_status"):
            setattr(self, name, None)
        self._sliders: dict[str, Any] = {}
        if editor is not None:
            self._build_editor(W, editor, num_steps, edit_options, editor_name, edit_names)
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
        if self._editor is not None:
            self._update_sliders()
            self._draw_result()

    def _on_frame(self, change) -> None:
        with self._lock:
            if self._map is not None:
                self._draw()
            self._draw_result()

    # ----------------------------------------------------------------- editing
    def _build_editor(self, W, editor, num_steps, edit_options, editor_name, edit_names) -> None:
        """The edit controls (only with an ``editor``): target text, re-weight sliders, mirror toggles, run."""
        if not (callable(getattr(editor, "edit", None)) or callable(editor)):
            raise TypeError("editor must be a pipeline (an object with an edit(...) method, e.g. SaladPipeline) or "
                            f"a callable with pipe.edit's arguments; got {type(editor).__name__}")
        if self.prompt is None:
            raise ValueError("editing needs the source prompt: pass prompt=... (it is read from AttentionMaps)")
        self._editor = editor
        method = callable(getattr(editor, "edit", None))
        name = editor_name or ("pipe" if method else getattr(editor, "__name__", "editor"))
        if not str(name).isidentifier():
            raise ValueError(f"editor_name must be a Python name, got {name!r}")
        self.editor_name = str(name)
        self._call = f"{self.editor_name}.edit" if method else self.editor_name
        options = {"lengths": len(self.joints), "seed": 0}
        if num_steps is not None:
            options["num_steps"] = int(num_steps)
        for key, value in dict(edit_options or {}).items():
            if key in _EDIT_OWN:
                raise ValueError(f"edit_options may not set {key!r}: the explorer's controls set it")
            if not _is_literal(value):
                raise ValueError(f"edit_options[{key!r}] = {value!r} is not a plain Python literal (number, string, "
                                 "bool, None or a list/tuple of them): the printed line must run as written")
            options[key] = value
        self.edit_options = options
        self._edit_names = None if edit_names is None else dict(edit_names)
        wide = W.Layout(width="min(640px, 95%)")
        self.target = W.Text(value=self.prompt, description="target", layout=wide, continuous_update=False,
                             tooltip="change words for a word swap (same number of words) or add words to refine")
        self.replace = W.Dropdown(options=[("auto", "auto"), ("word swap", "swap"), ("refine", "refine")],
                                  value="auto", description="as", layout=W.Layout(width="190px"),
                                  tooltip="auto: a word swap when the target has as many words as the source, "
                                          "else a refinement")
        self.reweight_box = W.VBox()
        self.mirror_arms = W.ToggleButton(value=False, description="mirror arms", icon="exchange",
                                          tooltip="swap the left and right arm rows of the maps (Mirror)")
        self.mirror_legs = W.ToggleButton(value=False, description="mirror legs", icon="exchange",
                                          tooltip="swap the left and right leg rows of the maps (Mirror)")
        self.run = W.Button(description="Run edit", button_style="primary", icon="play",
                            tooltip="run the edit with the pipeline; the result appears below")
        self.edit_status = W.Label()
        self.code = W.HTML()
        self.result = W.Image(format="png")
        self.result.layout.display = "none"          # until an edit has run (an empty image shows as broken)
        self.run.on_click(self._on_run)
        # every slider is made here, on the thread that builds the explorer: the callbacks (on JupyterLab's comm
        # subshells) only choose which are shown, and never open a widget's comm themselves
        for word in self._content_words():
            self.reweight_slider(word)
        for ctl, cls in ((self.target, "target"), (self.replace, "replace"), (self.reweight_box, "reweight"),
                         (self.mirror_arms, "mirror-arms"), (self.mirror_legs, "mirror-legs"), (self.run, "run"),
                         (self.edit_status, "edit-status"), (self.code, "code"), (self.result, "result")):
            ctl.add_class(f"salad-explorer-{cls}")
        self._update_sliders()
        head = W.HTML("<b>Edit</b> <small>(zero-shot, through the cross-attention: a target prompt, re-weighted "
                      "words, mirrored limbs; 1 = a word unchanged, 0 = ignored, negative = the opposite)</small>")
        self.edit_box = W.VBox([head, W.HBox([self.target, self.replace]), self.reweight_box,
                                W.HBox([self.mirror_arms, self.mirror_legs, self.run, self.edit_status]),
                                self.code, self.result])
        self.edit_box.add_class("salad-explorer-edit")
        self.widget.children = (*self.widget.children, self.edit_box)

    def _content_words(self) -> list[str]:
        """The prompt's words that can be re-weighted (letters or digits), in order, each once."""
        return list(dict.fromkeys(w for w, _ in self._groups if any(ch.isalnum() for ch in w)))

    def reweight_slider(self, word: str):
        """The re-weight slider of ``word`` (-1 to 3; 1 leaves its attention as it is), made when first asked for
        and shown while the word is selected or its value is not 1."""
        import ipywidgets as W

        word = str(word).lower()
        if word not in self._content_words():
            raise ValueError(f"{word!r} is not a word of the prompt; its words are {self._content_words()}")
        if word not in self._sliders:
            slider = W.FloatSlider(value=1.0, min=-1.0, max=3.0, step=0.1, description=f"re-weight {word}",
                                   readout_format=".1f", continuous_update=False,
                                   style={"description_width": "initial"}, layout=W.Layout(width="420px"))
            slider.add_class("salad-explorer-reweight-slider")
            slider.add_class("salad-explorer-reweight-" + re.sub(r"[^a-z0-9_-]", "_", word))
            slider.observe(lambda change: self._update_sliders(), names="value")
            self._sliders[word] = slider
        return self._sliders[word]

    def _update_sliders(self) -> None:
        if self.reweight_box is None:
            return
        selected = set(self.selected_words)
        shown = [self.reweight_slider(w) for w in self._content_words()
                 if w in selected or (w in self._sliders and round(self._sliders[w].value, 2) != 1.0)]
        if tuple(shown) != tuple(self.reweight_box.children):
            self.reweight_box.children = tuple(shown)

    def _edit_parts(self) -> tuple[str | None, list[str], list[str]]:
        """``(target or None, the edits' source texts, their short labels)`` from the controls."""
        target = " ".join(str(self.target.value).split())
        source = " ".join(self.prompt.split())
        changed = bool(target) and target.lower() != source.lower()
        codes, labels = [], []
        if changed:
            src_words, dst_words = _plain_words(source), _plain_words(target)
            mode = self.replace.value
            if mode == "auto":
                mode = "swap" if len(src_words) == len(dst_words) else "refine"
            if mode == "swap":
                codes.append("WordSwap()")
                pairs = [f"{a}->{b}" for a, b in zip(src_words, dst_words) if a != b]
                labels.append(f"Swap({', '.join(pairs)})")
            else:
                codes.append("Refine()")
                added = [f"+{w}" for w in dst_words if w not in set(src_words)]
                labels.append(f"Refine({' '.join(added)})")
        for word in self._content_words():
            slider = self._sliders.get(word)
            if slider is None or slider not in self.reweight_box.children:
                continue
            value = round(float(slider.value), 2)
            if value != 1.0:
                codes.append(f"Reweight(words={_py_str(word)}, scale={value:g})")
                labels.append(f"Reweight({word}={value:g})")
        parts = [name for name, toggle in (("arms", self.mirror_arms), ("legs", self.mirror_legs)) if toggle.value]
        if parts:
            which = "all" if len(parts) == 2 else parts[0]
            codes.append(f"Mirror(parts={_py_str(which)})")
            labels.append(f"Mirror({which})")
        return (target if changed else None), codes, labels

    @property
    def edit_code(self) -> str:
        """The one line of Python that makes the edit the controls describe (what :meth:`run_edit` runs):
        ``pipe.edit(source, target=..., edits=[...], lengths=..., seed=..., num_steps=..., capture_attention=...)``
        with ``WordSwap``, ``Refine``, ``Reweight``, ``Mirror`` and ``CaptureConfig`` of ``salad_core.attention``.
        Raises ``ValueError`` when the controls describe no edit."""
        if self._editor is None:
            raise RuntimeError("this explorer has no editor: pass editor=pipe to explore_attention")
        target, codes, _ = self._edit_parts()
        if target is None and not codes:
            raise ValueError("nothing to edit: change the target prompt, move a re-weight slider away from 1 or "
                             "toggle a mirror")
        capture = 'CaptureConfig(mode="full")' if self.steps is not None else "True"
        args = [_py_str(" ".join(self.prompt.split()))]
        if target is not None:
            args.append(f"target={_py_str(target)}")
        args.append(f"edits=[{', '.join(codes)}]")
        args += [f"{k}={v!r}" for k, v in self.edit_options.items()]
        args.append(f"capture_attention={capture}")
        return f"{self._call}({', '.join(args)})"

    @property
    def edit_label(self) -> str:
        """A short name of the edit the controls describe, e.g. ``Swap(walks->runs) + Reweight(high=-1)``."""
        return " + ".join(self._edit_parts()[2]) or "edited"

    @property
    def last_edit(self):
        """The last edit's result (the pipeline's ``EditOutput``: ``.source`` and ``.edited``), or None."""
        return None if self._last_edit is None else self._last_edit["output"]

    @property
    def last_code(self) -> str | None:
        """The line of Python the last edit ran (shown under the controls)."""
        return None if self._last_edit is None else self._last_edit["code"]

    def _names(self) -> dict:
        if self._edit_names is not None:
            return dict(self._edit_names)
        # salad_viz imports nothing of salad_core but the skeleton (tests/test_module_layout.py): the pipeline the
        # user handed over brings the edit classes its printed line names
        names = getattr(self._editor, "edit_namespace", None)
        if not callable(names):
            raise TypeError(f"the editor {self.editor_name!r} has no edit_namespace(): pass edit_names={{'WordSwap': "
                            "..., 'Refine': ..., 'Reweight': ..., 'Mirror': ..., 'CaptureConfig': ...}} (the classes "
                            "of salad_core.attention)")
        return dict(names())

    def run_edit(self):
        """Run the edit the controls describe, exactly as the printed line (:attr:`edit_code`) does: the line is
        evaluated with the editor under its name; show the result beside the source and return it (the
        ``EditOutput``). Errors (nothing to edit, a word the target lacks) are raised."""
        code = self.edit_code
        label = self.edit_label
        namespace = {**self._names(), self.editor_name: self._editor}
        output = eval(compile(code, "<salad explorer edit>", "eval"), namespace)   # the printed line, as printed
        for branch in ("source", "edited"):
            if getattr(getattr(output, branch, None), "attention", None) is None:
                raise TypeError(f"the editor returned no {branch} attention maps: it must return pipe.edit's "
                                "EditOutput for capture_attention")
        with self._lock:
            self._last_edit = {"code": code, "label": label, "output": output}
            self.code.value = ('<div style="font-size:12px;color:#444">The same edit in Python (<code>WordSwap</code>, '
                               '<code>Refine</code>, <code>Reweight</code>, <code>Mirror</code>, <code>CaptureConfig'
                               '</code> from <code>salad_core.attention</code>):</div><pre style="white-space:pre-wrap;'
                               'margin:2px 0 6px 0;font-size:12px;background:#f4f5f7;padding:4px 6px">'
                               f"{_html.escape(code)}</pre>")
            self._draw_result()
            self.result.layout.display = None
        return output

    def _on_run(self, button=None) -> None:
        self.run.disabled = True
        self.edit_status.value = "running the edit..."
        try:
            self.run_edit()
            self.edit_status.value = ""
        except Exception as exc:    # a callback has no caller to raise to: say it beside the button
            self.edit_status.value = f"{type(exc).__name__}: {exc}"
        finally:
            self.run.disabled = False

    def _branch_map(self, maps, positions: list[int]) -> np.ndarray | None:
        """The ``(P, N')`` map of one branch of the edit: the words at ``positions`` (of its word groups) summed,
        over the explorer's chosen layers and steps where the branch has them (else all)."""
        if not positions:
            return None
        arr, axes = _from_attention_maps(maps, 0)
        steps = layers = None
        if self.steps is not None and "s" in axes and arr.shape[axes.index("s")] == self.steps.max + 1:
            steps = (self.steps.value[0], self.steps.value[1] + 1)
        if self.layers is not None and arr.shape[axes.index("l")] == len(self.layers.options):
            layers = list(self.layers.value) or None
        red = reduce_attention(arr, axes, steps=steps, layers=layers)
        groups = merge_tokens(maps.tokens(0))
        ids = sorted({i for k in positions for i in groups[k][1]})
        return red[:, :, ids].sum(axis=2)

    @property
    def result_maps(self) -> tuple[np.ndarray, np.ndarray | None] | None:
        """``(source, edited)`` ``(P, N')`` maps the result shows: the selected words of the edit's source and
        their counterparts in the edited prompt (None where the target has none), or None before an edit."""
        if self._last_edit is None:
            return None
        from .explorer_html import _align

        out = self._last_edit["output"]
        src_groups = [w for w, _ in merge_tokens(out.source.attention.tokens(0))]
        dst_groups = [w for w, _ in merge_tokens(out.edited.attention.tokens(0))]
        chosen = set(self.selected_words)
        src_pos = [k for k, w in enumerate(src_groups) if w in chosen]
        pairs = _align(src_groups, dst_groups)
        dst_pos = sorted({pairs[k] for k in src_pos if pairs[k] >= 0})
        return self._branch_map(out.source.attention, src_pos), self._branch_map(out.edited.attention, dst_pos)

    def result_figure(self, frame: int | None = None):
        """The result as a matplotlib Figure: the source (left) and the edit (right), each its skeleton at
        ``frame`` (default: the explorer's) with bones coloured by the selected words' attention and its
        7-part x frame heatmap, both on ONE colour scale (diverging, centred at 0, when a map is negative)."""
        from matplotlib import colormaps

        from .attention import DIVERGING_CMAP, _draw_map, attention_limits, joint_attention, new_figure

        if self._last_edit is None:
            raise RuntimeError("no edit has run yet")
        out, label = self._last_edit["output"], self._last_edit["label"]
        maps = self.result_maps
        src_words = self.selected_words
        branches = [(out.source, maps[0], "source", src_words)]
        dst_words = [w for w, _ in merge_tokens(out.edited.attention.tokens(0))]
        if maps[1] is not None:
            from .explorer_html import _align

            src_groups = [w for w, _ in merge_tokens(out.source.attention.tokens(0))]
            pairs = _align(src_groups, dst_words)
            picked = sorted({pairs[k] for k, w in enumerate(src_groups) if w in set(src_words) and pairs[k] >= 0})
            dst_words = [dst_words[k] for k in picked]
        else:
            dst_words = []
        branches.append((out.edited, maps[1], label, dst_words))
        limits = attention_limits(*[m for m in maps if m is not None])
        signed = limits[0] < 0
        cmap = colormaps[DIVERGING_CMAP if signed else self.cmap]
        f = int(self.frame.value if frame is None else frame)
        fig = new_figure((11.0, 6.6))
        grid = fig.add_gridspec(3, 2, height_ratios=[1.0, 0.6, 0.05])
        im = None
        for col, (motion, m, name, words) in enumerate(branches):
            joints = motion.joints[0]
            fr = min(f, len(joints) - 1)
            colors = None
            if m is not None:
                vals = joint_attention(m, self.skeleton, len(joints), frames_per_latent=self.fpl)
                top = limits[1]
                scaled = (vals / top + 1.0) / 2.0 if signed else vals / top
                colors = cmap(np.clip(scaled, 0.0, 1.0))[..., :3]
            image = self._renderer.render(joints, fr, view=self.view, joint_colors=colors)
            ax = fig.add_subplot(grid[0, col])
            ax.imshow(image)
            ax.set_axis_off()
            ax.set_title(f"{name}\n\u201c{motion.texts[0]}\u201d", fontsize=11, wrap=True)
            hax = fig.add_subplot(grid[1, col])
            if m is None:
                hax.set_axis_off()
                hax.text(0.5, 0.5, "no counterpart of the selected words\nin this prompt", ha="center",
                         va="center", transform=hax.transAxes, fontsize=10)
                continue
            im = _draw_map(hax, m, fpl=self.fpl, cmap=cmap, vmin=limits[0], vmax=limits[1],
                           title=" + ".join(words), part_labels=(col == 0))
            # the current frame, as the HTML page marks it: red on viridis, black on the diverging map
            hax.axvline(fr + 0.5, color="white", lw=4)
            hax.axvline(fr + 0.5, color="#111111" if signed else "#ff2d55", lw=2)
        if im is not None:
            cax = fig.add_subplot(grid[2, :])
            bar = fig.colorbar(im, cax=cax, orientation="horizontal")
            bar.set_label("attention of the selected words, one scale for both"
                          + (" (negative: blue, after a negative re-weight)" if signed else ""), fontsize=10)
        fig.suptitle(f"Edit: {label}    \u00b7    frame {f}", fontsize=13, fontweight="bold")
        return fig

    def _draw_result(self) -> None:
        if self._last_edit is None or self.result is None:
            return
        with self._lock:
            try:
                fig = self.result_figure()
            except ValueError as exc:     # e.g. no layer selected: the explorer's status says so
                self.edit_status.value = str(exc)
                return
            buf = io.BytesIO()
            fig.savefig(buf, format="png", dpi=80)
            self.result.value = buf.getvalue()

    def edit_page(self, path=None, **kwargs):
        """The last edit as the offline HTML explorer (:func:`salad_viz.export_explorer`): the source and the edit
        side by side on one colour scale, the edit named; ``path`` writes it."""
        from .explorer_html import export_explorer

        if self._last_edit is None:
            raise RuntimeError("no edit has run yet")
        out = self._last_edit["output"]
        kwargs.setdefault("words", [w for w in self.selected_words if any(ch.isalnum() for ch in w)] or None)
        return export_explorer(out.source.attention, None, out.source.joints[0], self.skeleton, path=path,
                               compare=dict(attention=out.edited.attention, joints=out.edited.joints[0]),
                               edit=self._last_edit["label"], **kwargs)

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
