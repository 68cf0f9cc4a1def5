"""Activation patching between two prompts: which site, at which steps, carries what a word does?

Three runs from the same noise (same seed, lengths and sampler):

1. the *clean* prompt, keeping the activations of the chosen hook points over a step window
   (:meth:`SaladPipeline.run_with_cache`);
2. the *corrupt* prompt, plain (the baseline);
3. the corrupt prompt again, with the clean run's activations written into its conditional rows
   at those hook points and steps (``pipe(..., hooks=...)``).

The effect is measured on the motion, per body part: the mean speed of each of the 7 parts
(:func:`salad_core.part_activity.part_activity`, m/s), its change against the corrupt baseline and
the fraction of the clean-corrupt gap the patch recovers.

Patching the *outputs* of every cross site at every step reproduces the clean run exactly: up to
the first cross site the two runs compute the same thing from the same noise, and from there on the
corrupt run is handed the clean run's values (tests check it). Probabilities (``layers.{i}.cross``)
can only be patched between prompts with the same number of tokens (their last axis); outputs
(``layers.{i}.cross.out``) between any two prompts.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from salad_core.part_activity import part_activity
from salad_core.skeleton import PART_NAMES

from .hooks import HookContext, select_hook_points

__all__ = ["PatchingResult", "patch_activations", "MIN_GAP"]

#: Smallest clean-corrupt difference of a part's activity (m/s) whose recovered fraction is reported
#: (NaN below it, where the ratio is noise: with the shipped weights, "waves his left hand" against
#: "... right hand" differed by 0.55 and 0.48 m/s in the arms and by 0.001-0.006 m/s in root, legs
#: and spine, whose "recovered" fractions then ranged from -7 to 1.1).
MIN_GAP = 0.01


@dataclass(frozen=True)
class PatchingResult:
    """What :func:`patch_activations` measured; activities are ``(P,)`` mean part speeds (m/s),
    parts in the order of :data:`salad_core.skeleton.PART_NAMES`."""

    points: tuple[str, ...]       # hook points patched
    steps: tuple[int, ...]        # sampler steps patched
    clean: np.ndarray             # (P,) activity of the clean run
    corrupt: np.ndarray           # (P,) activity of the corrupt run (the baseline)
    patched: np.ndarray           # (P,) activity of the patched corrupt run
    part_names: tuple[str, ...] = PART_NAMES
    outputs: dict[str, Any] = field(default_factory=dict, repr=False)   # "clean", "corrupt", "patched" MotionOutput

    @property
    def change(self) -> np.ndarray:
        """``(P,)`` patched minus corrupt activity (m/s)."""
        return self.patched - self.corrupt

    @property
    def gap(self) -> np.ndarray:
        """``(P,)`` clean minus corrupt activity (m/s)."""
        return self.clean - self.corrupt

    @property
    def recovered(self) -> np.ndarray:
        """``(P,)`` fraction of each part's clean-corrupt gap the patch recovers (1: the clean
        activity, 0: the corrupt one); NaN where ``|gap| < MIN_GAP``."""
        gap = self.gap
        out = np.full(gap.shape, np.nan)
        ok = np.abs(gap) >= MIN_GAP
        out[ok] = self.change[ok] / gap[ok]
        return out

    @property
    def recovered_total(self) -> float:
        """The patched activity projected on the clean-corrupt direction over all parts:
        ``<patched - corrupt, clean - corrupt> / |clean - corrupt|^2`` (NaN if the runs agree)."""
        gap = self.gap
        norm = float(gap @ gap)
        return float(self.change @ gap / norm) if norm >= MIN_GAP ** 2 else float("nan")

    def table(self) -> list[dict[str, Any]]:
        """One row per part: name, clean, corrupt, patched, change, recovered."""
        return [dict(part=name, clean=float(self.clean[p]), corrupt=float(self.corrupt[p]),
                     patched=float(self.patched[p]), change=float(self.change[p]),
                     recovered=float(self.recovered[p])) for p, name in enumerate(self.part_names)]


def patch_activations(pipe: Any, clean_prompt: str, corrupt_prompt: str, site: Any = "layers.*.cross.out",
                      steps: tuple[float, float] = (0.0, 1.0), seed: int = 0, *, lengths: int | None = None,
                      num_steps: int = 50, guidance_scale: Any = None, solver: str | None = None,
                      progress: bool = False) -> PatchingResult:
    """Run ``corrupt_prompt`` with the clean run's activations at ``site`` over ``steps``.

    Parameters
    ----------
    pipe : SaladPipeline
    clean_prompt, corrupt_prompt : str
        One prompt each; both runs start from the same noise (``seed``) at the same length.
    site : str, callable or sequence of these
        Hook points (exact names or globs, see :func:`salad_core.attention.hooks.hook_point_names`):
        ``"layers.2.cross.out"`` a site's output, ``"layers.2.cross"`` its probabilities (same token
        count needed), ``"layers.*.cross.out"`` (default) every cross site's output. An empty
        sequence patches nothing (the patched run is the corrupt run).
    steps : (start, stop)
        Step fractions ``i / S`` in ``[start, stop)`` that are patched.
    seed : int
        Noise seed of all three runs.
    lengths, num_steps, guidance_scale, solver, progress
        As :meth:`SaladPipeline.__call__` (``lengths`` one int: one motion per run).

    Returns
    -------
    PatchingResult
    """
    for name, prompt in (("clean_prompt", clean_prompt), ("corrupt_prompt", corrupt_prompt)):
        if not isinstance(prompt, str):
            raise TypeError(f"{name} must be one prompt (a string), got {type(prompt).__name__} {prompt!r}")
    empty = isinstance(site, (list, tuple)) and len(site) == 0
    points = [] if empty else select_hook_points(pipe.denoiser, site, store=("probs", "outputs"), expand_sites=False)
    if not empty and not points:
        raise ValueError(f"site={site!r} names no probabilities or outputs to patch (q, k and v are read-only)")
    common = dict(lengths=lengths, seed=seed, num_steps=num_steps, guidance_scale=guidance_scale, solver=solver,
                  progress=progress)
    if points:
        wanted = {hp.name for hp in points}
        clean, cache = pipe.run_with_cache(clean_prompt, names=lambda name: name in wanted,
                                           store=("probs", "outputs"), steps=steps, **common)
        patched_steps = cache.steps()
    else:
        clean, cache, patched_steps = pipe(clean_prompt, **common), None, ()
    corrupt = pipe(corrupt_prompt, **common)
    if cache is None:
        patched = pipe(corrupt_prompt, **common)
    else:
        position = {s: i for i, s in enumerate(patched_steps)}

        def patch(tensor: torch.Tensor, ctx: HookContext) -> torch.Tensor | None:
            i = position.get(ctx.step)
            if i is None:
                return None
            value = cache[ctx.name][i]                                   # (B, ...) the clean cond rows
            if tuple(value.shape) != tuple(tensor[ctx.cond].shape):
                raise ValueError(f"cannot patch {ctx.name!r}: the clean run's activation has shape "
                                 f"{tuple(value.shape)}, the corrupt run's {tuple(tensor[ctx.cond].shape)} (axes "
                                 f"{ctx.axes}); probabilities need prompts with the same token count, outputs "
                                 f"('{ctx.site}.out') do not")
            new = tensor.clone()
            new[ctx.cond] = value.to(tensor)
            return new

        patched = pipe(corrupt_prompt, hooks=[(hp.name, patch) for hp in points], **common)
    sk = pipe.skeleton
    activity = [part_activity(out.joints[0], skeleton=sk) for out in (clean, corrupt, patched)]
    return PatchingResult(points=tuple(hp.name for hp in points), steps=tuple(patched_steps), clean=activity[0],
                          corrupt=activity[1], patched=activity[2], part_names=tuple(PART_NAMES),
                          outputs={"clean": clean, "corrupt": corrupt, "patched": patched})
