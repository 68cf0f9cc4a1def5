"""Hook points on every attention site, read or replaced for the length of one call
(TransformerLens / nnsight style, over the names the sites already have).

Every site ``layers.{i}.{kind}`` (:func:`salad_core.models.attention.site_names`) has five *hook
points*:

==========================  ==========  =====================================================
hook point                  what        axes of the tensor a hook gets (``R`` forward rows)
==========================  ==========  =====================================================
``layers.{i}.{kind}``       probs       post-softmax probabilities, the site's named axes:
                                        temporal ``(R, P, H, N', N')``, skeletal
                                        ``(R, N', H, P, P)``, cross ``(R, H, N', P, W)``
``layers.{i}.{kind}.out``   out         the site's output after ``Wo`` (what the layer adds to
                                        its residual stream through FiLM) ``(R, N', P, w)``
``layers.{i}.{kind}.q``     q           per-head queries: temporal ``(R, P, H, N', dh)``,
                                        skeletal ``(R, N', H, P, dh)``, cross ``(R, H, N', P, dh)``
``.k`` / ``.v``             k, v        per-head keys / values: temporal ``(R, P, H, N', dh)``,
                                        skeletal ``(R, N', H, P, dh)``, cross ``(R, H, W, dh)``
==========================  ==========  =====================================================

(``HookContext.axes`` names them.) ``probs`` and ``out`` may be *replaced*; ``q``, ``k`` and
``v`` are read-only. A hook is ``fn(tensor, ctx) -> None | tensor``: None reads only, a tensor of
the same shape replaces the activation (rows it leaves equal keep the plain-sampling values bit
for bit). A replaced ``probs`` changes only how that site mixes its values (SALAD supplement B's
``M <- M_hat``); a replaced ``out`` changes what the site hands on.

Rows: the plain sampler's forward batch is ``[uncond (B); cond (B)]`` under classifier-free
guidance and ``cond (B)`` without (:attr:`salad_core.sampling.StepInfo.cond_rows`). A hook gets
every row (``rows="all"``) or only the conditional ones (``rows="cond"``, what caches keep);
``ctx.cond`` and ``ctx.uncond`` are slices of the tensor's first axis either way.

How: probabilities and q/k/v come from a
:class:`~salad_core.attention.processor.HookedProcessor` on the site (fast attention for the
output, as plain sampling computes it); ``out`` from a module forward hook (cross sites: the
attention module, on the folded and the projected route alike; temporal and skeletal sites: their
``Wo``). :func:`use_hooks` installs both for one ``with`` block and always removes them.
"""
from __future__ import annotations

import fnmatch
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass
from typing import Any, Optional, Union

import numpy as np
import torch

from salad_core.models.attention import SiteInfo, use_processors
from salad_core.models.kernels import FoldedText

from .processor import HookedProcessor, SiteHook

__all__ = [
    "HOOK_POINTS",
    "WRITABLE_POINTS",
    "STORE_KINDS",
    "NameFilter",
    "HookContext",
    "HookPoint",
    "HookFn",
    "hook_point_names",
    "hook_points",
    "select_hook_points",
    "HookSession",
    "use_hooks",
    "ActivationCache",
    "CacheRecorder",
]

#: The hook points of a site, by their name suffix ("" = the probabilities).
HOOK_POINTS: dict[str, str] = {"probs": "", "out": ".out", "q": ".q", "k": ".k", "v": ".v"}
#: Hook points that a hook may replace (the others are read-only).
WRITABLE_POINTS: tuple[str, ...] = ("probs", "out")
#: ``store=`` groups of :func:`select_hook_points` (and ``run_with_cache``): which points each covers.
STORE_KINDS: dict[str, tuple[str, ...]] = {"probs": ("probs",), "inputs": ("q", "k", "v"), "outputs": ("out",)}

#: ``fn(tensor, ctx) -> None | tensor``.
HookFn = Callable[[torch.Tensor, "HookContext"], Optional[torch.Tensor]]
#: Name filters: None (all), an exact name or glob, a predicate on the name, or a sequence of these.
NameFilter = Union[None, str, Callable[[str], bool], Sequence[Union[str, Callable[[str], bool]]]]


@dataclass(frozen=True)
class HookPoint:
    """One hook point: its name, the site it belongs to and what it holds."""

    name: str     # e.g. "layers.3.cross.out"
    site: str     # e.g. "layers.3.cross"
    kind: str     # site kind: temporal, skeletal, cross (sentence in the "w/o CrossAttn" ablation)
    layer: int    # layer index in execution order
    point: str    # one of HOOK_POINTS: probs, out, q, k, v

    @property
    def writable(self) -> bool:
        return self.point in WRITABLE_POINTS


def _axes(kind: str, point: str) -> tuple[str, ...]:
    """Axis names of a hook point's tensor (first axis: the rows the hook holds)."""
    if point == "probs":
        return {"temporal": ("batch", "part", "head", "query_frame", "key_frame"),
                "skeletal": ("batch", "frame", "head", "query_part", "key_part"),
                "cross": ("batch", "head", "frame", "part", "token"),
                "sentence": ("batch", "head", "frame", "part", "key")}[kind]
    if point == "out":
        return ("batch", "frame", "part", "channel")
    if kind == "temporal":
        return ("batch", "part", "head", "frame", "channel")
    if kind == "skeletal":
        return ("batch", "frame", "head", "part", "channel")
    if point == "q":
        return ("batch", "head", "frame", "part", "channel")
    return ("batch", "head", "token" if kind == "cross" else "key", "channel")


@dataclass(frozen=True)
class HookContext:
    """Where a hook is called: the hook point, the sampler step and the row layout of its tensor."""

    name: str                  # hook point, e.g. "layers.3.cross" or "layers.3.cross.out"
    site: str                  # site name, e.g. "layers.3.cross"
    kind: str                  # site kind: temporal, skeletal, cross (sentence)
    point: str                 # probs, out, q, k or v
    layer: int                 # layer index (execution order)
    step: int                  # sampler step i (0-based)
    num_steps: int             # S
    timestep: float            # diffusion timestep of the step
    axes: tuple[str, ...]      # names of the tensor's axes
    batch_size: int            # B prompts
    cond: slice                # rows of the tensor's first axis that are the conditional branch
    uncond: slice | None       # rows of the unconditional branch (None: not held / no guidance)
    writable: bool             # whether returning a tensor replaces the activation

    @property
    def p(self) -> float:
        """Step fraction ``i / S`` (the editing windows' ``p``)."""
        return self.step / self.num_steps


def hook_points(denoiser: Any) -> list[HookPoint]:
    """Every hook point of a denoiser, site by site in execution order."""
    out = []
    for site, mod in denoiser.attention_sites.items():
        for point, suffix in HOOK_POINTS.items():
            out.append(HookPoint(site + suffix, site, mod.kind, int(mod.layer), point))
    return out


def hook_point_names(denoiser: Any) -> list[str]:
    """The names of :func:`hook_points` (the list a test pins)."""
    return [hp.name for hp in hook_points(denoiser)]


def _store_points(store: str | Sequence[str]) -> tuple[str, ...]:
    groups = (store,) if isinstance(store, str) else tuple(store)
    unknown = [g for g in groups if g not in STORE_KINDS]
    if unknown or not groups:
        raise ValueError(f"store={store!r} is unknown; allowed: one or more of {tuple(STORE_KINDS)}, e.g. "
                         "'probs' or ('probs', 'inputs', 'outputs')")
    return tuple(p for g in groups for p in STORE_KINDS[g])


def select_hook_points(denoiser: Any, names: NameFilter = None, layers: int | Sequence[int] | None = None,
                       store: str | Sequence[str] = "probs", *, expand_sites: bool = True) -> list[HookPoint]:
    """Hook points filtered by name, layer and kind of activation.

    Parameters
    ----------
    denoiser : Denoiser
    names : None, str, callable or sequence of these
        A string matches a hook point's name exactly or as a glob (``"layers.*.cross"``); a string
        that names a site (``"layers.2.cross"``) also selects that site's other points when
        ``store`` asks for them. A callable is a predicate on the hook point's name. None: all.
    layers : int or sequence of int, optional
        Layer indices (execution order).
    store : str or sequence of str
        ``"probs"``, ``"inputs"`` (q, k, v) and/or ``"outputs"`` (``.out``).
    expand_sites : bool
        Whether a string that matches a site name selects that site's other points too (else
        strings match hook point names only).

    Raises
    ------
    KeyError
        When a name or glob matches no hook point (the message lists the known names).
    """
    wanted = _store_points(store)
    points = hook_points(denoiser)
    if layers is not None:
        num_layers = len({hp.layer for hp in points})
        layer_set = {int(layers)} if isinstance(layers, int) and not isinstance(layers, bool) else set()
        if not layer_set:
            try:
                layer_set = {int(v) for v in layers}
            except (TypeError, ValueError):
                raise TypeError(f"layers must be None, an int or a sequence of ints, got {layers!r}") from None
        bad = sorted(v for v in layer_set if not 0 <= v < num_layers)
        if bad or not layer_set:
            raise ValueError(f"layers={layers!r}: the denoiser has layers 0..{num_layers - 1}")
        points = [hp for hp in points if hp.layer in layer_set]
    if names is not None:
        items = [names] if isinstance(names, str) or callable(names) else list(names)
        chosen: dict[str, HookPoint] = {}
        for item in items:
            if callable(item):
                hits = [hp for hp in points if item(hp.name)]
            elif isinstance(item, str):
                hits = [hp for hp in points if fnmatch.fnmatchcase(hp.name, item)
                        or (expand_sites and hp.point != "probs" and fnmatch.fnmatchcase(hp.site, item))]
                if not hits:
                    raise KeyError(f"no hook point matches {item!r}; known hook points: "
                                   f"{hook_point_names(denoiser)}")
            else:
                raise TypeError(f"names must be None, a name or glob string, a predicate on the name, or a list of "
                                f"these; got {item!r}")
            chosen.update((hp.name, hp) for hp in hits)
        points = [hp for hp in points if hp.name in chosen]
    return [hp for hp in points if hp.point in wanted]


def _resolve_hooks(denoiser: Any, hooks: Sequence[tuple[str, HookFn]]) -> dict[str, list[HookFn]]:
    """``[(name or glob, fn), ...]`` -> ``{hook point: [fn, ...]}`` in the order given."""
    if isinstance(hooks, tuple) and len(hooks) == 2 and isinstance(hooks[0], str):
        hooks = [hooks]                      # a single (name, fn) pair
    if not isinstance(hooks, (list, tuple)):
        raise TypeError(f"hooks must be a list of (name, fn) pairs, e.g. [('layers.0.cross', fn)], got "
                        f"{type(hooks).__name__}")
    known = {hp.name: hp for hp in hook_points(denoiser)}
    out: dict[str, list[HookFn]] = {}
    for i, item in enumerate(hooks):
        if not (isinstance(item, (tuple, list)) and len(item) == 2):
            raise TypeError(f"hooks[{i}] must be a (name, fn) pair, got {item!r}")
        name, fn = item
        if not isinstance(name, str):
            raise TypeError(f"hooks[{i}]: the hook point name must be a string, got {name!r}")
        if not callable(fn):
            raise TypeError(f"hooks[{i}] ({name!r}): fn must be callable as fn(tensor, ctx), got {fn!r}")
        hits = [n for n in known if fnmatch.fnmatchcase(n, name)]
        if not hits:
            raise KeyError(f"unknown hook point {name!r} (hooks[{i}]); known hook points: {list(known)}")
        for n in hits:
            out.setdefault(n, []).append(fn)
    return out


class _PointProcessor(HookedProcessor):
    """A :class:`HookedProcessor` that also reports the site's q, k and v to the session."""

    def __init__(self, session: "HookSession", module: Any) -> None:
        super().__init__(session)
        self.session, self.module = session, module

    def __call__(self, site, q, k, v, key_mask, dropout_p):
        if self.session.wants_inputs(site):
            self.session.inputs(site, q, k, v)
        return super().__call__(site, q, k, v, key_mask, dropout_p)

    def folded(self, site: SiteInfo, x: torch.Tensor, fold: FoldedText) -> torch.Tensor:
        if self.session.wants_inputs(site):
            # the folded route never forms the queries: project them as the projected route does
            r, lq, w = x.shape
            q = self.module.Wq(x).view(r, lq, fold.heads, w // fold.heads).transpose(1, 2)
            self.session.inputs(site, q, fold.k, fold.v)
        return super().folded(site, x, fold)

    def __repr__(self) -> str:
        return f"_PointProcessor(site={self.module.site_name!r})"


class HookSession:
    """The hooks of one call: a :class:`~salad_core.attention.processor.SiteHook` for the
    probabilities, the q/k/v reports of its processors and the forward hooks of the outputs.

    Made and installed by :func:`use_hooks`; pass :meth:`on_step` to the sampler's
    ``controller_hooks``.

    Parameters
    ----------
    denoiser : Denoiser
    hooks : sequence of (name, fn)
        Hook point names or globs (see :func:`hook_point_names`) and ``fn(tensor, ctx)``.
    rows : "all" or "cond"
        Rows of the forward batch the hooks get (see the module docstring).
    observer : SiteHook, optional
        A read-only hook (e.g. an :class:`~salad_core.attention.capture.AttentionStore`) that
        also sees the probabilities of its sites after the hooks replaced them; its own step
        hook must be passed to the sampler too.
    observer_sites : iterable of str
        The sites ``observer`` watches.
    """

    def __init__(self, denoiser: Any, hooks: Sequence[tuple[str, HookFn]], *, rows: str = "all",
                 observer: SiteHook | None = None, observer_sites: Sequence[str] = ()) -> None:
        if rows not in ("all", "cond"):
            raise ValueError(f"rows must be 'all' (every forward row) or 'cond' (the conditional branch), got {rows!r}")
        self.denoiser = denoiser
        self.rows_mode = rows
        self.fns = _resolve_hooks(denoiser, hooks)
        self.points = {hp.name: hp for hp in hook_points(denoiser)}
        self.observer = observer
        self.observer_sites = set(observer_sites)
        self._info: Any = None
        self._sites_probs = {self.points[n].site for n in self.fns if self.points[n].point == "probs"}
        self._sites_inputs = {self.points[n].site for n in self.fns if self.points[n].point in ("q", "k", "v")}
        self._sites_out = {self.points[n].site for n in self.fns if self.points[n].point == "out"}

    # ----------------------------------------------------------------- steps
    def on_step(self, info: Any) -> None:
        """Step hook (``controller_hooks`` of :func:`salad_core.sampling.denoise`)."""
        self._info = info

    def _held(self, total: int) -> tuple[torch.Tensor, slice, slice | None]:
        """Forward rows the hooks hold at this call, and the cond / uncond slices of them."""
        info = self._info
        if info is None:
            raise RuntimeError("a hook point was reached before any sampler step: pass the session's on_step to "
                               "denoise(..., controller_hooks=[session.on_step])")
        b = int(info.batch_size)
        expected = 2 * b if info.cfg else b
        if total != expected:
            raise RuntimeError(f"the forward batch has {total} rows; hooks serve the plain sampler's layout "
                               f"[uncond (B); cond (B)] = {expected} rows")
        cond = info.cond_rows
        if self.rows_mode == "cond":
            return torch.arange(cond.start, cond.stop), slice(0, b), None
        return torch.arange(total), cond, (slice(0, b) if info.cfg else None)

    def _context(self, name: str, shape_rows: tuple[slice, slice | None]) -> HookContext:
        hp, info = self.points[name], self._info
        return HookContext(name=name, site=hp.site, kind=hp.kind, point=hp.point, layer=hp.layer,
                           step=int(info.index), num_steps=int(info.num_steps), timestep=float(info.timestep),
                           axes=_axes(hp.kind, hp.point), batch_size=int(info.batch_size), cond=shape_rows[0],
                           uncond=shape_rows[1], writable=hp.writable)

    def _apply(self, name: str, tensor: torch.Tensor, rows: tuple[slice, slice | None]) -> torch.Tensor | None:
        """Run the hooks of ``name`` in order; the last replacement (checked), or None."""
        fns = self.fns.get(name)
        if not fns:
            return None
        ctx = self._context(name, rows)
        current, replaced = tensor, False
        for fn in fns:
            new = fn(current, ctx)
            if new is None:
                continue
            where = f"hook {getattr(fn, '__name__', fn)!r} at {name!r} (step {ctx.step})"
            if not ctx.writable:
                raise ValueError(f"{where} returned a tensor, but {ctx.point} is read-only; only the "
                                 f"probabilities ('{ctx.site}') and the output ('{ctx.site}.out') can be replaced")
            if not isinstance(new, torch.Tensor):
                raise TypeError(f"{where} must return None or a tensor, got {type(new).__name__}")
            if tuple(new.shape) != tuple(current.shape):
                raise ValueError(f"{where} returned shape {tuple(new.shape)}; expected {tuple(current.shape)} "
                                 f"with axes {ctx.axes}")
            if not bool(torch.isfinite(new).all()):
                raise ValueError(f"{where} returned NaN or infinite values")
            current, replaced = new.to(device=tensor.device, dtype=tensor.dtype), True
        return current if replaced else None

    # --------------------------------------------------------- probabilities
    def rows(self, site: SiteInfo) -> torch.Tensor | None:
        if site.name in self._sites_probs:
            return self._held(site.batch)[0]
        if self.observer is not None and site.name in self.observer_sites:
            return self.observer.rows(site)
        return None

    def process(self, site: SiteInfo, rows: torch.Tensor, probs: torch.Tensor):
        result = None
        if site.name in self._sites_probs:
            _, cond, uncond = self._held(site.batch)
            new = self._apply(site.name, probs, (cond, uncond))
            if new is not None:
                # only rows the hooks changed are recomputed, so the others keep plain sampling's values
                changed = [i for i in range(new.shape[0]) if not torch.equal(new[i], probs[i])]
                if changed:
                    idx = torch.tensor(changed)
                    result = (rows[idx], new[idx])
                probs = new
        if self.observer is not None and site.name in self.observer_sites:
            wanted = self.observer.rows(site)
            if wanted is not None and wanted.numel():
                pos = {int(r): i for i, r in enumerate(rows)}
                self.observer.process(site, wanted, probs[torch.tensor([pos[int(r)] for r in wanted])])
        return result

    # ----------------------------------------------------------------- q, k, v
    def wants_inputs(self, site: SiteInfo) -> bool:
        return site.name in self._sites_inputs

    def inputs(self, site: SiteInfo, q: torch.Tensor, k: torch.Tensor, v: torch.Tensor) -> None:
        held, cond, uncond = self._held(site.batch)
        take_all = self.rows_mode == "all"
        for point, t in (("q", q), ("k", k), ("v", v)):
            name = f"{site.name}.{point}"
            if name not in self.fns:
                continue
            named = _named_inputs(site, point, t)
            if not take_all:
                named = named[int(held[0]):int(held[-1]) + 1]
            self._apply(name, named, (cond, uncond))

    # ----------------------------------------------------------------- outputs
    def _out_hook(self, site: str, parts: int, flat: bool):
        name = site + ".out"

        def hook(module, args, output):
            total = output.shape[0]
            held, cond, uncond = self._held(total)
            named = output.view(total, -1, parts, output.shape[-1]) if flat else output
            view = named if self.rows_mode == "all" else named[int(held[0]):int(held[-1]) + 1]
            new = self._apply(name, view, (cond, uncond))
            if new is None:
                return None
            if self.rows_mode == "all":
                return new.reshape(output.shape)
            full = named.clone()
            full[int(held[0]):int(held[-1]) + 1] = new
            return full.reshape(output.shape)
        return hook

    # ------------------------------------------------------------ installation
    @contextmanager
    def installed(self) -> Iterator["HookSession"]:
        """Processors and forward hooks for the ``with`` block; all removed on exit, also after an error."""
        sites = self.denoiser.attention_sites
        parts = int(self.denoiser.config.num_parts)
        wanted = self._sites_probs | self._sites_inputs | self.observer_sites
        processors = {name: _PointProcessor(self, sites[name]) for name in sites if name in wanted}
        with ExitStack() as stack:
            for name in self._sites_out:
                mod = sites[name]
                if mod.kind in ("cross", "sentence"):      # called through forward() on either route
                    handle = mod.register_forward_hook(self._out_hook(name, parts, flat=True))
                else:                                      # attend_within: its Wo gives (B, N', P, w)
                    handle = mod.Wo.register_forward_hook(self._out_hook(name, parts, flat=False))
                stack.callback(handle.remove)
            stack.enter_context(use_processors(self.denoiser, processors))
            yield self


def _named_inputs(site: SiteInfo, point: str, t: torch.Tensor) -> torch.Tensor:
    """Flat per-head q/k/v ``(rows, H, L, dh)`` of a site -> the axes of :func:`_axes`."""
    r, h, n, p = site.batch, site.heads, site.frames, site.parts
    if site.kind == "temporal":
        return t.view(r, p, h, n, t.shape[-1])
    if site.kind == "skeletal":
        return t.view(r, n, h, p, t.shape[-1])
    if point == "q":
        return t.view(r, h, n, p, t.shape[-1])
    return t


@contextmanager
def use_hooks(denoiser: Any, hooks: Sequence[tuple[str, HookFn]], *, rows: str = "all",
              observer: SiteHook | None = None, observer_sites: Sequence[str] = ()) -> Iterator[HookSession]:
    """Install ``hooks`` on ``denoiser`` for the ``with`` block; nothing stays installed afterwards.

    Parameters
    ----------
    denoiser : Denoiser
    hooks : sequence of (name, fn)
        Hook point names or globs and ``fn(tensor, ctx) -> None | tensor`` (see the module
        docstring). Unknown names raise ``KeyError`` listing the known ones.
    rows : "all" or "cond"
    observer, observer_sites
        See :class:`HookSession`.

    Yields
    ------
    HookSession
        Pass ``session.on_step`` to the sampler's ``controller_hooks``.

    Examples
    --------
    >>> def flat(probs, ctx):                                    # doctest: +SKIP
    ...     return torch.full_like(probs, 1 / probs.shape[-1])
    >>> with use_hooks(denoiser, [("layers.0.skeletal", flat)]) as session:
    ...     z = denoise(denoiser, sched, cond, uncond, noise, controller_hooks=[session.on_step])
    """
    session = HookSession(denoiser, hooks, rows=rows, observer=observer, observer_sites=observer_sites)
    with session.installed():
        yield session



# ================================================================================ the cache
class CacheRecorder:
    """Read-only hooks that keep the conditional rows of chosen hook points in a step window.

    Parameters
    ----------
    points : sequence of HookPoint
        From :func:`select_hook_points`.
    steps : (start, stop)
        Step fractions ``i / S`` in ``[start, stop)`` that are kept.
    """

    def __init__(self, points: Sequence[HookPoint], steps: tuple[float, float] = (0.0, 1.0)) -> None:
        from .capture import _check_window

        self.points = {hp.name: hp for hp in points}
        self.window = _check_window(steps, "steps")
        self._data: dict[str, dict[int, torch.Tensor]] = {name: {} for name in self.points}
        self.num_steps = 0

    @property
    def hooks(self) -> list[tuple[str, HookFn]]:
        """``(name, fn)`` pairs for :func:`use_hooks` (or ``pipe(..., hooks=...)``)."""
        return [(name, self._record) for name in self.points]

    def _record(self, tensor: torch.Tensor, ctx: HookContext) -> None:
        self.num_steps = ctx.num_steps
        if self.window[0] <= ctx.p < self.window[1]:
            self._data[ctx.name][ctx.step] = tensor[ctx.cond].detach().to("cpu", copy=True)

    def result(self, tokens: Any = None, lengths: Sequence[int] | None = None,
               unit_length: int | None = None, num_layers: int | None = None) -> "ActivationCache":
        """The recorded activations, stacked over the steps (see :class:`ActivationCache`)."""
        steps = sorted({s for per in self._data.values() for s in per})
        if not steps:
            raise RuntimeError(f"nothing was recorded: does steps={self.window} contain a step of the "
                               f"{self.num_steps}-step sampler, and were the hooks installed?")
        data = {}
        for name, per in self._data.items():
            if sorted(per) != steps:
                raise RuntimeError(f"{name!r} was recorded at steps {sorted(per)}, the others at {steps}")
            data[name] = torch.stack([per[s] for s in steps])
        return ActivationCache(data, self.points, tuple(steps), self.num_steps, tokens=tokens, lengths=lengths,
                               unit_length=unit_length, num_layers=num_layers)


class ActivationCache(Mapping):
    """Activations of one sampling call by hook point name (a read-only mapping).

    ``cache[name]`` is a CPU tensor ``(S, B, ...)``: the kept steps (:meth:`steps`), the ``B``
    prompts (the conditional rows of the guided batch), then the hook point's own axes
    (:meth:`axes`; see :mod:`salad_core.attention.hooks`). Sizes are the batch's: ``N'`` latent
    frames of the longest motion and ``W`` tokens of the longest prompt; shorter prompts have
    probability 0 on the padding tokens, shorter motions carry padded frames (crop them with
    :attr:`lengths`, or use :meth:`to_attention_maps`, which does). The mapping is read-only; the
    tensors are the cache's own, so clone one before changing it in place. Memory: every kept step
    of every chosen point in float32 (by arithmetic: the paper model's 5 cross sites' probabilities
    over 50 steps for one 24-token prompt of 196 frames are 5 x 50 x 8 x 49 x 7 x 24 floats, 66 MB;
    choose ``names``, ``layers`` and ``steps`` accordingly).

    Examples
    --------
    >>> out, cache = pipe.run_with_cache("a man jumps", names="layers.*.cross", steps=(0.0, 0.5))  # doctest: +SKIP
    >>> cache["layers.0.cross"].shape          # (S, B, H, N', P, W)
    >>> cache.axes("layers.0.cross")           # ('step', 'batch', 'head', 'frame', 'part', 'token')
    """

    def __init__(self, data: dict[str, torch.Tensor], points: dict[str, HookPoint], steps: tuple[int, ...],
                 num_steps: int, *, tokens: Any = None, lengths: Sequence[int] | None = None,
                 unit_length: int | None = None, num_layers: int | None = None) -> None:
        self._data = dict(data)
        self._points = dict(points)
        self._steps = tuple(int(s) for s in steps)
        self.num_steps = int(num_steps)
        self.tokens = tokens
        self.lengths = None if lengths is None else [int(n) for n in lengths]
        self.unit_length = unit_length
        self.num_layers = num_layers if num_layers is not None else max(hp.layer for hp in points.values()) + 1

    def __getitem__(self, name: str) -> torch.Tensor:
        if name not in self._data:
            raise KeyError(f"{name!r} is not in this cache; it holds {self.names()}")
        return self._data[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __repr__(self) -> str:
        return f"ActivationCache({len(self)} hook points, steps {list(self._steps)} of {self.num_steps})"

    def names(self) -> list[str]:
        """The hook points held, in execution order."""
        return list(self._data)

    def steps(self) -> tuple[int, ...]:
        """The sampler step indices ``i`` held (the first axis of every entry)."""
        return self._steps

    def fractions(self) -> tuple[float, ...]:
        """``i / S`` of :meth:`steps`."""
        return tuple(s / self.num_steps for s in self._steps)

    def point(self, name: str) -> HookPoint:
        """The :class:`HookPoint` of an entry (site, kind, layer, point)."""
        self[name]
        return self._points[name]

    def axes(self, name: str) -> tuple[str, ...]:
        """Axis names of ``cache[name]``: ``("step", "batch", ...)``."""
        hp = self.point(name)
        return ("step",) + _axes(hp.kind, hp.point)

    def to_attention_maps(self) -> Any:
        """The cached cross-attention probabilities as :class:`~salad_core.attention.AttentionMaps`
        (``mode="full"``, every cached step, layer and head; temporal and skeletal maps too when
        they were cached at the same layers), cropped per prompt to its frames and tokens, kept in
        float32 (a full capture keeps float16)."""
        from .capture import AttentionMaps, _crop

        if self.tokens is None or self.lengths is None or self.unit_length is None:
            raise ValueError("to_attention_maps needs the prompts' tokens and lengths (caches made by "
                             "pipe.run_with_cache have them)")
        by_kind: dict[str, dict[int, torch.Tensor]] = {}
        for name, t in self._data.items():
            hp = self._points[name]
            if hp.point == "probs":
                by_kind.setdefault(hp.kind, {})[hp.layer] = t
        if "cross" not in by_kind:
            raise ValueError(f"no cross-attention probabilities are cached (it holds {self.names()}); cache "
                             "names='layers.*.cross' with store='probs'")
        layers = tuple(sorted(by_kind["cross"]))
        head_axis = {"cross": 1, "temporal": 2, "skeletal": 2}     # in one prompt's probabilities
        n_lat = [n // self.unit_length for n in self.lengths]
        n_tok = [len(t) for t in self.tokens.tokens]
        data: dict[str, list[np.ndarray]] = {}
        for kind in ("cross", "temporal", "skeletal"):
            per_layer = by_kind.get(kind)
            if per_layer is None or tuple(sorted(per_layer)) != layers:
                continue
            stacked = torch.stack([per_layer[layer] for layer in layers], 1)    # (S, L, B, ...)
            data[kind] = []
            for b in range(len(self.lengths)):
                one = stacked[:, :, b].movedim(2 + head_axis[kind] - 1, 2)      # (S, L, H, ...)
                data[kind].append(_crop(kind, one.float().numpy(), n_lat[b], n_tok[b], lead=3))
        heads = data["cross"][0].shape[2]
        return AttentionMaps(data=data, tokens=self.tokens, lengths=self.lengths, unit_length=self.unit_length,
                             mode="full", group_starts=np.array(self.fractions()),
                             group_weights=np.ones(len(self._steps)), group_width=0.0, layers=layers,
                             heads=tuple(range(heads)), num_steps=self.num_steps,
                             num_layers=self.num_layers)
