"""In-painting in the latent space: regenerate chosen body parts and/or a frame span of a motion from
the edit's target prompt, keep the rest.

The latents are ``(B, N', P, Dz)``: ``N' = frames / unit_length`` latent frames of the 7 body parts of
:data:`salad_core.skeleton.PART_NAMES`. :class:`Inpaint` names a *region* of them, the chosen parts
(all if none) over the chosen frames (all if none); :func:`~salad_core.attention.editing.edit_latents`
then runs the edited branch as usual (the target prompt, any attention edits) and after every
sampler step (inside the edit's ``steps`` window) replaces the edited latent outside the region by
the *source branch's* latent of the same step::

    z*_{t-1} <- m * z*_{t-1} + (1 - m) * z_{t-1}

The source branch is the generated source motion, or, for ``pipe.edit(inversion=inv, ...)``, the
inverted motion's own reconstruction (its inversion trajectory, with the exact corrections): both
sit at the same noise level as the edited latent, so the regenerated region is denoised in the
context of the kept one (the "replacement" of RePaint / blended latent diffusion; RePaint's resampling jumps
with ``resample``). ``m`` is 1 in the region and 0 outside it; with ``blend = k`` the ``k`` latent
frames of the region next to a kept frame ramp up, ``d / (k + 1)`` at distance ``d`` from it, so
those frames start from the source and the seam is denoised softly; the kept frames themselves are
always the source's. Body parts have no seam (``m`` is 0 or 1 along the part axis).

More levers, chosen on procedural validation clips (``measure_inpaint.py --tuning 8``) and on by
default: editing an inversion, the region starts from fresh white noise (``noise="auto"``: the inverted noise is
not white and holds the take's own motion there, so the region tended to regenerate the take: a real take's arms
waved in 2 of 8 cases); after decoding, the kept parts / frames are taken from the source's decoded features and
the seams cross-faded over ``fade`` frames in feature space, with the root of a span corrected so that the frames
after it keep their global place and facing, unless the span turned on its own (``root="auto"``: a middle span asked
to turn keeps its turn and the rest of the take follows it) (``composite=True``,
:mod:`salad_core.attention.composite`: the VAE decoder's convolutions mix neighbouring parts and frames, and the
features integrate the root's velocities); the span's frames next to each seam are then smoothed by a small
least-squares jerk penalty (``smooth``); a frame span's edited branch is guided with :data:`SPAN_GUIDANCE`
(``guidance="auto"``: a short span otherwise tended not to do what the prompt says); body parts alone of an inverted
take were sampled with RePaint's resampling (``resample``: each ``jump`` of 5 steps denoised 3 times, re-noising the
region in between, so that the region harmonises with the kept parts; now only with ``prior="none"``, the pasted
prior below having replaced it).

The region is pasted, then harmonised (``prior="auto"``, :meth:`Inpaint.prior_for`) for every edit of an inverted take
and for a frame span of a generated source: the target prompt is first sampled alone (over the span, or the whole
motion) and, for the first half of the steps (the first 30 % for a span of a take), the region's latents are that
sample's, noised to each step's level, so that the region enters the free steps already doing what the prompt says
(on 24 validation clips: an inverted take's arms passed the prompt's check in 22 against 18 with RePaint's
resampling, which it replaces there, at 0.56 times the time; a generated source's span in 20 against 16).

A frame span of an inverted take is regenerated :data:`SPAN_CANDIDATES` times, from that many seeds (each with its
own pasted sample), and among the candidates whose seams are smooth (``seam_bound="auto"``: seam jerk within
:data:`SEAM_BOUND` times the source's own 95th percentile) the one whose pelvis and feet heights follow its pasted
sample most closely is kept (``score="auto"`` -> ``"prior"``, :func:`~salad_core.attention.ranking.prior_height_cm`:
what reads flight and foot contacts); when no candidate's seams are smooth, 8 candidates without the prior are run
and the one the T2M evaluator finds closest to the prompt is kept (:mod:`salad_core.attention.ranking`). On 24 new
validation clips this passed the span's check in 23 against 21 for the previous default (8 candidates without the
prior ranked by the evaluator, which had raised it from 11 of 24 with one candidate), every seam smooth in both, at
1.5 times its time; the evaluator's own ranking of the pasted candidates had chosen worse (16 of 24), as had their
closeness in pose (12). Body parts alone are sampled once: ranking their resampled edits lowered the check, 18 -> 12
of 24, and scoring the regenerated parts alone, the kept ones held still (``score="parts"``), ranked them no better:
10 of 24.

:func:`parse_inpaint` reads the command line's ``PARTS[@START:END]`` notation.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Optional, Sequence, Union

import torch

from salad_core.skeleton import PART_NAMES

from .edits import EditKernel, EditSpec, _window, seeded_noise

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

__all__ = ["Inpaint", "INPAINT_GROUPS", "MATCHED_MAX_RHO", "NOISE_MODES", "PARTS_RESAMPLE", "PRIOR_MODES",
           "PRIOR_STRENGTH", "SCORE_MODES", "SEAM_BOUND", "SPAN_CANDIDATES", "SPAN_GUIDANCE", "SPAN_PRIOR_STRENGTH",
           "ar1_noise", "inpaint_parts", "matched_noise", "noise_statistics", "parse_inpaint"]

#: What :class:`Inpaint`'s regenerated region starts from (see :attr:`Inpaint.noise`).
NOISE_MODES = ("auto", "fresh", "source", "matched")

#: What :class:`Inpaint`'s regenerated region is drawn towards in the first steps (see :attr:`Inpaint.prior`).
PRIOR_MODES = ("auto", "none", "prompt")

#: The share of the steps in which the pasted prior's region is free (``Inpaint(prior_strength="auto")``).
PRIOR_STRENGTH = 0.5

#: ``prior_strength="auto"`` for a frame span of an inverted motion: its candidates are ranked by how closely they
#: follow the pasted motion (``score="prior"``), and a longer-held prior gave more candidates that do what it does.
SPAN_PRIOR_STRENGTH = 0.7

#: The largest lag-1 frame correlation :func:`matched_noise` gives the region's noise.
MATCHED_MAX_RHO = 0.95

#: The edited branch's guidance weight of ``Inpaint(guidance="auto")`` when a frame span is regenerated.
SPAN_GUIDANCE = 7.5

#: The resampling passes of ``Inpaint(resample="auto")`` when body parts alone of an inverted motion are regenerated.
PARTS_RESAMPLE = 3

#: The candidates of ``Inpaint(candidates="auto")`` when a frame span of an inverted motion is regenerated.
SPAN_CANDIDATES = 8

#: How :class:`Inpaint`'s candidates are scored (see :attr:`Inpaint.score`).
SCORE_MODES = ("auto", "whole", "parts", "prior", "first_smooth")

#: The seam bound of ``Inpaint(seam_bound="auto")`` when a frame span of an inverted motion is regenerated: a seam's
#: jerk at most 1.5 times the source's own 95th percentile (:func:`~salad_core.attention.composite.seam_jerk_ratio`).
SEAM_BOUND = 1.5

#: Group names :class:`Inpaint` accepts besides the part names. "legs" / "arms" as :class:`Mirror`;
#: "upper" / "lower" are the upper body (spine, arms, head) and the lower body (root, legs) -- the
#: same limbs Mirror's "upper" / "lower" swap (mirroring leaves root, spine and head as they are).
INPAINT_GROUPS: dict[str, tuple[str, ...]] = {
    "legs": ("left leg", "right leg"),
    "arms": ("left arm", "right arm"),
    "upper": ("spine", "left arm", "right arm", "head"),
    "lower": ("root", "left leg", "right leg"),
    "all": PART_NAMES,
}


def _norm(name: str) -> str:
    return " ".join(name.strip().lower().replace("_", " ").replace("-", " ").split())


def inpaint_parts(value: Union[str, Sequence[str]]) -> tuple[str, ...]:
    """Part names and group names (a string, ``"arms,head"`` or ``"arms+head"`` too, or a sequence)
    -> the distinct parts of :data:`PART_NAMES` they name, in that order.

    Raises
    ------
    ValueError
        An unknown name (the message lists the part and group names) or nothing named.
    """
    if isinstance(value, str):
        items = [v for v in value.replace("+", ",").split(",")]
    else:
        try:
            items = list(value)
        except TypeError:
            raise TypeError(f"Inpaint.parts must be a part or group name or a sequence of them, got {value!r}") from None
    chosen: set[str] = set()
    for item in items:
        if not isinstance(item, str):
            raise TypeError(f"Inpaint.parts={value!r}: {item!r} is not a name")
        name = _norm(item)
        if name in PART_NAMES:
            chosen.add(name)
        elif name in INPAINT_GROUPS:
            chosen.update(INPAINT_GROUPS[name])
        else:
            raise ValueError(f"Inpaint.parts={value!r}: unknown body part {item!r}; the parts are "
                             f"{', '.join(PART_NAMES)} (or left_arm, ...) and the groups {', '.join(INPAINT_GROUPS)}")
    if not chosen:
        raise ValueError(f"Inpaint.parts={value!r} names no body part")
    return tuple(p for p in PART_NAMES if p in chosen)


def _check_noise(noise: torch.Tensor, frame_mask: torch.Tensor) -> None:
    if noise.dim() != 4:
        raise ValueError(f"the noise must be (B, N', P, Dz), got shape {tuple(noise.shape)}")
    if tuple(frame_mask.shape) != tuple(noise.shape[:2]):
        raise ValueError(f"frame_mask must be (B, N') = {tuple(noise.shape[:2])}, got {tuple(frame_mask.shape)}")


def _correlation(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Pearson correlation of two flat tensors of the same length (0 when either is constant or too short)."""
    if a.numel() < 2:
        return a.new_zeros(())
    a, b = a - a.mean(), b - b.mean()
    den = torch.sqrt((a * a).sum() * (b * b).sum())
    return (a * b).sum() / den if den > 0 else a.new_zeros(())


def noise_statistics(noise: torch.Tensor, frame_mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Per motion, over its valid latent frames only: the std of ``noise`` ``(B, N', P, Dz)`` (pooled over frames,
    parts and channels) and the lag-1 correlation of neighbouring valid latent frames (pooled over parts and
    channels; 0 with fewer than two valid frames).

    Parameters
    ----------
    noise : torch.Tensor
        ``(B, N', P, Dz)``, e.g. an inverted motion's noise.
    frame_mask : torch.Tensor
        ``(B, N')`` bool, True = valid latent frame (frames past a motion's length do not count).

    Returns
    -------
    std, rho : torch.Tensor
        ``(B,)`` float64 each.

    Raises
    ------
    ValueError
        Wrong shapes, or a motion without a valid frame.
    """
    _check_noise(noise, frame_mask)
    stds, rhos = [], []
    for i, (z, valid) in enumerate(zip(noise.detach().double(), frame_mask.bool())):
        if not valid.any():
            raise ValueError(f"motion {i} of the batch has no valid latent frame: no noise statistics")
        stds.append(z[valid].std(unbiased=False))
        pair = valid[1:] & valid[:-1]
        rhos.append(_correlation(z[1:][pair].flatten(), z[:-1][pair].flatten()))
    return torch.stack(stds), torch.stack(rhos)


def ar1_noise(white: torch.Tensor, rho: torch.Tensor) -> torch.Tensor:
    """White noise ``(B, N', P, Dz)`` -> the stationary AR(1) process along the latent-frame axis with lag-1
    correlation ``rho`` ``(B,)`` (one per motion, in ``(-1, 1)``): ``x_0 = e_0``, ``x_t = rho x_{t-1} +
    sqrt(1 - rho^2) e_t``, so every frame keeps the white noise's variance. ``rho = 0`` returns ``white``."""
    rho = torch.as_tensor(rho, dtype=white.dtype, device=white.device).reshape(-1, 1, 1)
    if rho.shape[0] != white.shape[0]:
        raise ValueError(f"rho must have one value per motion ({white.shape[0]}), got {rho.shape[0]}")
    gain = torch.sqrt(1.0 - rho * rho)
    frames = [white[:, 0]]
    for t in range(1, white.shape[1]):
        frames.append(rho * frames[-1] + gain * white[:, t])
    return torch.stack(frames, 1)


def matched_noise(white: torch.Tensor, reference: torch.Tensor, frame_mask: torch.Tensor) -> torch.Tensor:
    """White noise ``(B, N', P, Dz)`` shaped to the statistics of ``reference`` (same shape; the source's noise) over
    each motion's valid latent frames (:func:`noise_statistics`): :func:`ar1_noise` with the reference's lag-1
    correlation clipped to ``[0, MATCHED_MAX_RHO]``, scaled to the reference's std. A white reference gives about
    ``white`` itself. ``frame_mask`` ``(B, N')`` bool marks the valid frames. Returns ``white``'s shape and dtype."""
    if tuple(white.shape) != tuple(reference.shape):
        raise ValueError(f"the white noise {tuple(white.shape)} and the reference noise {tuple(reference.shape)} "
                         "must have the same shape")
    std, rho = noise_statistics(reference, frame_mask)
    shaped = ar1_noise(white.double(), rho.clamp(0.0, MATCHED_MAX_RHO).to(white.device))
    return (shaped * std.to(white.device)[:, None, None, None]).to(white.dtype)


def _frame_bound(v, name: str) -> Optional[int]:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, int):
        raise TypeError(f"Inpaint.frames: {name} must be an int number of motion frames or None, got {v!r}")
    if v < 0:
        raise ValueError(f"Inpaint.frames: {name}={v} is negative; frames count from 0 (motion frames)")
    return int(v)


@dataclass(frozen=True)
class Inpaint(EditSpec):
    """Regenerate ``parts`` over ``frames`` from the target prompt; keep the rest of the source.

    Parameters
    ----------
    parts : str or sequence of str, optional
        Body parts to regenerate: names of :data:`PART_NAMES` (``"left arm"``, ``"left_arm"``), groups
        of :data:`INPAINT_GROUPS` (``"arms"``, ``"legs"``, ``"upper"``, ``"lower"``, ``"all"``), or a
        sequence / comma-separated string of those. None: all parts (give ``frames``).
    frames : (start, end), optional
        Motion frames ``[start, end)`` to regenerate; ``None`` for an open end (``(None, 40)``: a
        prefix, ``(80, None)``: a suffix). Mapped to latent frames ``start // unit_length`` to
        ``ceil(end / unit_length)`` (rounded outward). None: all frames (give ``parts``). The span
        must lie inside every motion of the batch (checked when the edit runs).
    unit_length : int
        Motion frames per latent frame (4).
    blend : int
        Latent frames of the region next to a kept frame over which the mask ramps up (0: hard seam).
        Default 1, a compromise measured by ``lab/scripts/editing/measure_inpaint.py`` (shipped weights,
        50 steps, 120 frames; 12 generated and 8 inverted real frame-span cases): seam jerk over the
        source's 95th percentile 1.45 / 1.65 / 1.09 (generated) and 2.46 / 1.94 / 1.33 (real) for blend
        0 / 1 / 2, but the prompt's checks passed 67 / 67 / 58 % and 75 / 62 / 38 %: a wider ramp
        smooths the seam and weakens the edit of a short span. Kept frames stay within 0.2-0.7 cm
        (heading-aligned) with any blend.
    steps : (start, stop)
        Window of step fractions in which the kept region is replaced (default all steps, the last
        included, so the kept latents end exactly as the source's).
    noise : ``"auto"``, ``"fresh"``, ``"source"`` or ``"matched"``
        What the regenerated region starts from. ``"source"``: the source's noise (for an inverted take its
        inverted noise, which is not white and holds the take's own motion of that region: the region then tends
        to regenerate the take); ``"fresh"``: white noise drawn from ``seed`` (the exact inversion's corrections
        are dropped there); ``"matched"``: the same white noise shaped to the source noise's own statistics over
        each motion's valid frames, its lag-1 frame correlation (an AR(1) filter along the latent frames) and its
        std (:func:`matched_noise`; corrections dropped as with ``"fresh"``; for a generated source, whose noise
        is white, about ``"fresh"``; only the starting noise is shaped: :attr:`resample`'s re-noising between
        passes is white, so with resampling the region largely forgets it); ``"auto"`` (default): fresh when
        editing an inversion, the source's otherwise (on 24 generated validation spans the source's noise passed
        the prompt's check in 16, fresh noise in 13, the best of 4 fresh seeds in 15).
    seed : int
        Seed of the fresh (or matched) noise.
    composite : bool
        After decoding, take the kept parts / frames from the source's decoded features, hang regenerated limbs
        from the source's kept joints and cross-fade a frame span's seams over ``fade`` frames in feature space
        (:mod:`salad_core.attention.composite`). Default on.
    fade : int
        Motion frames of a regenerated span, next to each kept frame, over which the composite cross-fades.
    guidance : float, ``"auto"`` or None
        Classifier-free guidance weight of the edited branch (the regenerated region follows the target prompt more
        strongly with a larger one); None: the motion's (the inversion's); ``"auto"`` (default): :data:`SPAN_GUIDANCE`
        when a frame span is regenerated, the motion's for body parts alone (:attr:`edited_guidance`). The kept region
        is the source's anyway.
    root : ``"source"``, ``"edit"`` or ``"auto"``
        With ``composite``: ``"source"`` corrects a regenerated span's root velocities so that the kept frames
        after it keep their global position and facing; ``"edit"`` lets them follow the span's turn and travel;
        ``"auto"`` (default) lets them follow a span that turned on its own, more than
        :data:`~salad_core.attention.composite.TURN_FOLLOW_DEG` and that much beyond the source over the same frames
        (a middle span asked to turn keeps its turn), and keeps them in place after any other
        (:func:`~salad_core.attention.composite.followed_turns`; on 24 validation spans of generated motions the
        span's check rose from 20 to 23, the three middle "turns left" spans that ``"source"`` turned back now
        turning, every other edit unchanged; on 24 validation jump spans of inverted takes it changed nothing).
    smooth : float
        With ``composite``: weight of the jerk penalty of the least-squares seam smoothing
        (:func:`~salad_core.attention.composite.smooth_seam_features`) of a frame span (default 100; 0: off). It is
        kept only where it lowers the seams' jerk of the recovered joints
        (:func:`~salad_core.attention.composite.composite_output`).
    smooth_window : int
        Motion frames of a regenerated span, next to each kept frame, that the seam smoothing may move (default 8;
        a wider window smooths the seams more and damps more of the span's own motion).
    resample : int or ``"auto"``
        RePaint's resampling (Lugmayr et al., CVPR 2022): each ``jump`` of sampler steps is denoised ``resample``
        times; between the passes the merged latents are noised back by the forward process (the kept region
        from the source's trajectory, the region with fresh noise), so that the region is denoised again in
        the context of the kept one it has already met. 1: off (one pass); ``"auto"`` (default):
        :data:`PARTS_RESAMPLE` passes when body parts alone of an inverted motion are regenerated without a prior
        (``prior="none"``), off for a frame span, for a generated source and with a prior (:meth:`passes_for`).
        Costs about ``resample`` times the forward passes; needs the DDIM sampler (``"auto"`` resamples with DDIM
        only, a number refuses other solvers).
    jump : int
        Sampler steps per resampling jump (default 5).
    candidates : int or ``"auto"``
        Edits to run and rank (1: one edit from ``seed``). ``K`` > 1: the edit runs ``K`` times, the region's
        noise drawn from ``seed``, ``seed + 1``, ..., ``seed + K - 1``, and the candidate whose edited motion is
        closest to the target prompt by the T2M evaluator's text-motion distance is kept
        (:mod:`salad_core.attention.ranking`; over the regenerated frames); ``K`` times the cost. Needs a region
        that starts from the seed's noise (:meth:`fresh_noise`) and one motion per edit. ``"auto"`` (default):
        :data:`SPAN_CANDIDATES` when a frame span of one inverted motion is regenerated from fresh noise, where it
        was chosen; 1 otherwise (:meth:`candidates_for`).
    score : ``"auto"``, ``"whole"``, ``"parts"``, ``"prior"`` or ``"first_smooth"``
        What the evaluator scores of each candidate (with ``candidates`` > 1). ``"whole"``: the edited motion as it
        is (over the regenerated frames, see :func:`~salad_core.attention.ranking.scoring_window`); ``"parts"``: the
        edited motion with the kept body parts held still, so that only the regenerated :attr:`parts` move
        (:func:`~salad_core.attention.ranking.isolate_parts`; needs ``parts`` that keep some part); ``"prior"``:
        not the evaluator but the distance between the heights above the floor of the pelvis and the feet over the
        region and those of the pasted prior (:func:`~salad_core.attention.ranking.prior_height_cm`: the candidate
        whose flight and foot contacts follow the prompt sampled alone most closely; needs a pasted prior,
        :attr:`prior`), and when no candidate's seams are within :attr:`seam_bound` the candidates are drawn again
        without the prior and ranked by the evaluator (:func:`~salad_core.attention.ranking.ranked_edit`);
        ``"first_smooth"``: no score at all; the candidates are run one at a time in seed order and the first whose
        seam ratio is within :attr:`seam_bound` (:data:`SEAM_BOUND` for ``"auto"``) is kept, the others not run
        (none within it: the smoothest of all; needs ``frames``). Smoother seams cost the prompt's check: on 48
        validation spans of generated sources, seams within 1.5x 45 against the default's 39, the span's check 42
        against 45 (lab/docs/editing.md), so it is an option, not a default.
        ``"auto"`` (default): ``"prior"`` for a frame span of an inverted motion with a pasted prior, ``"whole"`` for
        every other edit (:meth:`score_for`; on procedural validation clips the parts alone did not rank an arms edit's
        candidates better than the whole motion).
    seam_bound : float, ``"auto"`` or None
        With ``candidates`` > 1 and a frame span: rank by the evaluator's distance only the candidates whose seams
        are smooth, those whose :func:`~salad_core.attention.composite.seam_jerk_ratio` (the largest jerk of the
        edit's joints within 4 frames of an inner seam over the source's own 95th percentile of jerk) is at most
        ``seam_bound``; when none is, keep the one with the smallest ratio
        (:func:`~salad_core.attention.ranking.pick_candidate`). None: by distance alone. Body parts alone have no
        seam: their ranking is by distance whatever the bound. ``"auto"`` (default): :data:`SEAM_BOUND` (1.5) when a
        frame span of an inverted motion is regenerated, where it was chosen; None otherwise (:meth:`seam_bound_for`).
    prior : ``"auto"``, ``"none"`` or ``"prompt"``
        ``"prompt"``: paste, then harmonise (SDEdit, Meng et al., ICLR 2022, in the region only). Before the edit, the
        target prompt alone is sampled (a motion of the span's length for a frame span, at least the skeleton's
        shortest clip and then its middle latent frames; the motion's whole length for body parts alone; the edited
        branch's guidance, the edit's solver and steps, noise :func:`~salad_core.attention.edits.seeded_noise` of
        :attr:`seed`). For the first ``1 - prior_strength`` of the steps the region's latents are that motion's
        latents noised by the forward process to each step's level (with the region's own noise), so the region
        enters the free steps already doing what the prompt says and the rest of the loop fits it to the kept
        context; ``settings["inpaint_prior"]`` records it and the edit's ``prior`` holds the pasted motion.
        ``"none"``: the region is denoised from noise alone. ``"auto"`` (default): ``"prompt"`` for an inverted
        motion (body parts alone, where it replaces :attr:`resample`'s passes, and frame spans, whose candidates are
        then ranked by ``score="prior"``) and for a frame span of a generated source, where it was chosen;
        ``"none"`` for body parts alone of a generated source (:meth:`prior_for`).
    prior_strength : float or ``"auto"``
        With a prior: the share of the steps, ending at the last, in which the region is free (in ``(0, 1]``; 1 frees
        it from the first step, when the pasted motion would be only noise, so nothing is sampled). Smaller keeps
        more of the pasted motion, larger fits it more to the kept context. ``"auto"`` (default):
        :data:`SPAN_PRIOR_STRENGTH` (0.7) for a frame span of an inverted motion, :data:`PRIOR_STRENGTH` (0.5)
        otherwise (:meth:`prior_strength_for`; both were measured on each).
    """

    role: ClassVar[str] = "latent"

    parts: Union[str, Sequence[str], None] = None
    frames: Optional[tuple] = None
    unit_length: int = 4
    blend: int = 1
    steps: tuple[float, float] = (0.0, 1.0)
    noise: str = "auto"
    seed: int = 0
    composite: bool = True
    fade: int = 8
    root: str = "auto"
    guidance: Union[float, str, None] = "auto"
    smooth: float = 100.0
    smooth_window: int = 8
    resample: Union[int, str] = "auto"
    jump: int = 5
    candidates: Union[int, str] = "auto"
    score: str = "auto"
    seam_bound: Union[float, str, None] = "auto"
    prior: str = "auto"
    prior_strength: Union[float, str] = "auto"

    def __post_init__(self) -> None:
        if self.noise not in NOISE_MODES:
            raise ValueError(f"Inpaint.noise={self.noise!r}; allowed: {NOISE_MODES}")
        from .composite import ROOT_MODES

        if self.root not in ROOT_MODES:
            raise ValueError(f"Inpaint.root={self.root!r}; allowed: {ROOT_MODES}")
        if self.guidance is not None and self.guidance != "auto":
            if isinstance(self.guidance, bool) or not isinstance(self.guidance, (int, float)) or not self.guidance >= 1:
                raise ValueError(f"Inpaint.guidance={self.guidance!r} must be a number >= 1, 'auto' or None")
            object.__setattr__(self, "guidance", float(self.guidance))
        for name in ("fade", "seed", "smooth_window"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"Inpaint.{name}={v!r} must be an int >= 0")
        if self.candidates != "auto" and (isinstance(self.candidates, bool) or not isinstance(self.candidates, int)
                                          or self.candidates < 1):
            raise ValueError(f"Inpaint.candidates={self.candidates!r} must be an int >= 1 (edits to run and rank; 1: one "
                             "edit) or 'auto'")
        if not isinstance(self.prior, str) or self.prior not in PRIOR_MODES:
            raise ValueError(f"Inpaint.prior={self.prior!r}; allowed: {PRIOR_MODES}")
        ps = self.prior_strength
        if ps != "auto":
            if isinstance(ps, bool) or not isinstance(ps, (int, float)) or not 0 < ps <= 1:
                raise ValueError(f"Inpaint.prior_strength={ps!r} must be a number in (0, 1] (the share of the steps "
                                 "in which the region is free of the prompt's pasted motion) or 'auto'")
            object.__setattr__(self, "prior_strength", float(ps))
        if not isinstance(self.score, str) or self.score not in SCORE_MODES:
            raise ValueError(f"Inpaint.score={self.score!r}; allowed: {SCORE_MODES}")
        if self.seam_bound is not None and self.seam_bound != "auto":
            b = self.seam_bound
            if isinstance(b, bool) or not isinstance(b, (int, float)) or not math.isfinite(b) or b <= 0:
                raise ValueError(f"Inpaint.seam_bound={b!r} must be a finite number > 0 (the largest seam jerk over "
                                 "the source's 95th percentile a candidate may have to be ranked by distance), "
                                 "'auto' or None")
            object.__setattr__(self, "seam_bound", float(b))
        for name in ("resample", "jump"):
            v = getattr(self, name)
            if name == "resample" and v == "auto":
                continue
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"Inpaint.{name}={v!r} must be an int >= 1" + (" or 'auto'" if name == "resample"
                                                                                else ""))
        if (isinstance(self.smooth, bool) or not isinstance(self.smooth, (int, float)) or not math.isfinite(self.smooth)
                or self.smooth < 0):
            raise ValueError(f"Inpaint.smooth={self.smooth!r} must be a finite number >= 0 (the seams' jerk penalty)")
        object.__setattr__(self, "smooth", float(self.smooth))
        if self.parts is None and self.frames is None:
            raise ValueError("Inpaint needs parts=... (body parts to regenerate) and/or frames=(start, end) "
                             "(a motion-frame span to regenerate)")
        if self.parts is not None:
            object.__setattr__(self, "parts", inpaint_parts(self.parts))
        if isinstance(self.unit_length, bool) or not isinstance(self.unit_length, int) or self.unit_length < 1:
            raise ValueError(f"Inpaint.unit_length={self.unit_length!r} must be a positive int (motion frames per "
                             "latent frame)")
        if self.frames is not None:
            try:
                start, end = self.frames
            except (TypeError, ValueError):
                raise ValueError(f"Inpaint.frames={self.frames!r} must be a (start, end) pair of motion frames "
                                 "(None for an open end)") from None
            start, end = _frame_bound(start, "start"), _frame_bound(end, "end")
            if end is not None and end <= (start or 0):
                raise ValueError(f"Inpaint.frames={self.frames!r} is an empty span: end must be after start")
            if start in (None, 0) and end is None:
                raise ValueError(f"Inpaint.frames={self.frames!r} spans the whole motion; give frames=None to "
                                 "regenerate all frames of the chosen parts")
            object.__setattr__(self, "frames", (start, end))
        if self.parts == PART_NAMES and self.frames is None:
            raise ValueError("Inpaint(parts='all') without frames keeps nothing: that is a plain generation of the "
                             "target; name fewer parts or a frame span")
        if self.score == "prior" and self.prior == "none":
            raise ValueError("Inpaint(score='prior') ranks the candidates by how closely they follow the pasted "
                             "prior's heights, but prior='none' pastes none; give prior='prompt' (or 'auto')")
        if self.score == "first_smooth" and (self.frames is None or self.seam_bound is None):
            raise ValueError("Inpaint(score='first_smooth') keeps the first candidate whose seams are within seam_bound, "
                             + ("but a body-part edit without frames has no seam; give frames=(start, end) or "
                                "score='whole'" if self.frames is None else
                                "but seam_bound=None sets no bound; give a number or 'auto'"))
        if self.score == "parts" and self.parts in (None, PART_NAMES):
            raise ValueError("Inpaint(score='parts') scores the regenerated body parts with the kept ones held still, "
                             "but this Inpaint regenerates every part; name the parts (e.g. parts='arms') or give "
                             "score='whole'")
        if isinstance(self.blend, bool) or not isinstance(self.blend, int) or self.blend < 0:
            raise ValueError(f"Inpaint.blend={self.blend!r} must be an int >= 0 (latent frames of the soft seam)")
        object.__setattr__(self, "steps", _window(self.steps, "Inpaint.steps"))

    @property
    def site_kinds(self) -> tuple[str, ...]:
        return ()

    def bind(self, source, target, width: int, *, maps_of) -> EditKernel:
        """No attention kernel: in-painting acts on the latents (:meth:`mask`)."""
        return lambda maps, own: maps

    def latent_span(self, num_frames: int) -> tuple[int, int]:
        """The regenerated latent frames ``[s, e)`` of a motion of ``num_frames`` motion frames.

        Raises
        ------
        ValueError
            The span reaches past the motion (the message names the span and the length).
        """
        if self.frames is None:
            return 0, num_frames // self.unit_length
        start, end = self.frames
        start = start or 0
        if start >= num_frames or (end is not None and end > num_frames):
            raise ValueError(f"Inpaint.frames={self.frames!r} lies outside the motion of {num_frames} frames "
                             f"(valid frames 0..{num_frames})")
        n = num_frames // self.unit_length
        s = start // self.unit_length
        e = n if end is None else min(n, math.ceil(end / self.unit_length))
        if s == 0 and e == n and self.parts in (None, PART_NAMES):
            raise ValueError(f"Inpaint.frames={self.frames!r} covers every latent frame of the motion of {num_frames} "
                             "frames: nothing is kept")
        return s, e

    def mask(self, frame_mask: torch.Tensor, num_parts: int = len(PART_NAMES)) -> torch.Tensor:
        """``m`` ``(B, N', P, 1)`` float: 1 where the edited sample regenerates, 0 where it keeps the
        source, the ramp of :attr:`blend` at the seams; ``frame_mask`` ``(B, N')`` marks valid latent
        frames (padding is 0)."""
        if num_parts != len(PART_NAMES):
            raise ValueError(f"in-painting names the {len(PART_NAMES)} latent body parts; the latents have {num_parts}")
        b, n = frame_mask.shape
        frame_w = torch.zeros(b, n)
        for i in range(b):
            valid = int(frame_mask[i].sum())
            s, e = self.latent_span(valid * self.unit_length)
            for f in range(s, e):
                d = min(f - s + 1 if s > 0 else math.inf, e - f if e < valid else math.inf)
                frame_w[i, f] = 1.0 if self.frames is None else min(1.0, d / (self.blend + 1))
        parts = self.parts or PART_NAMES
        part_w = torch.tensor([1.0 if p in parts else 0.0 for p in PART_NAMES])
        m = frame_w[:, :, None] * part_w[None, None, :]
        return (m * frame_mask[:, :, None].to(m))[..., None].to(frame_mask.device)

    @property
    def edited_guidance(self) -> Optional[float]:
        """The edited branch's guidance weight (:attr:`guidance`; ``"auto"`` resolved), None: the motion's."""
        if self.guidance == "auto":
            return SPAN_GUIDANCE if self.frames is not None else None
        return self.guidance

    def passes_for(self, inverted: bool) -> int:
        """Times each :attr:`jump` of steps is denoised (:attr:`resample`; ``"auto"`` resolved: :data:`PARTS_RESAMPLE`
        when body parts alone of an inverted motion are regenerated without a pasted prior (:meth:`prior_for`), where
        it was chosen; 1 for a frame span, for a generated source and with a prior, which replaced it for an inverted
        motion's parts). ``inverted``: the edit is of an inversion."""
        if self.resample == "auto":
            return PARTS_RESAMPLE if (self.frames is None and inverted and self.prior_for(inverted) == "none") else 1
        return int(self.resample)

    def candidates_for(self, inverted: bool, motions: int = 1) -> int:
        """Edits run and ranked (:attr:`candidates`; ``"auto"`` resolved: :data:`SPAN_CANDIDATES` when a frame span of
        one inverted motion is regenerated from fresh noise, where it was chosen; 1 for body parts alone, for a
        generated source and for a batch of ``motions`` > 1). ``inverted``: the edit is of an inversion."""
        if self.candidates == "auto":
            ranked = self.frames is not None and inverted and self.fresh_noise(inverted) and motions == 1
            return SPAN_CANDIDATES if ranked else 1
        return int(self.candidates)

    def score_for(self, inverted: bool) -> str:
        """What the candidates' scorer reads (:attr:`score`; ``"auto"`` resolved: ``"prior"`` for a frame span of an
        inverted motion with a pasted prior, where it was chosen, ``"whole"`` for every other edit):
        ``"whole"`` (the edited motion) or ``"parts"`` (the regenerated parts alone,
        :func:`~salad_core.attention.ranking.isolate_parts`) for the evaluator, or ``"prior"`` (the heights'
        distance to the pasted prior, :func:`~salad_core.attention.ranking.prior_height_cm`). ``inverted``: the edit
        is of an inversion (as for :meth:`candidates_for`)."""
        if self.score == "auto":
            ranked_span = self.frames is not None and inverted and self.prior_for(inverted) == "prompt"
            return "prior" if ranked_span else "whole"
        return self.score

    def seam_bound_for(self, inverted: bool) -> Optional[float]:
        """The seam bound the candidates are ranked with (:attr:`seam_bound`; ``"auto"`` resolved: :data:`SEAM_BOUND`
        for a frame span of an inverted motion, where it was chosen, None for a generated source), None for body
        parts alone (no seam) and for no bound (by distance alone). ``inverted``: the edit is of an inversion (as
        for :meth:`candidates_for`)."""
        if self.frames is None:
            return None
        if self.seam_bound == "auto":
            return SEAM_BOUND if (inverted or self.score_for(inverted) == "first_smooth") else None
        return self.seam_bound

    def prior_for(self, inverted: bool) -> str:
        """``"prompt"`` or ``"none"`` (:attr:`prior`; ``"auto"`` resolved: ``"prompt"`` for an inverted motion (body
        parts and frame spans) and for a frame span of a generated source, where it was chosen; ``"none"`` for body
        parts alone of a generated source). ``inverted``: the edit is of an inversion."""
        if self.prior == "auto":
            parts_of_a_generation = self.frames is None and not inverted
            return "none" if parts_of_a_generation else "prompt"
        return self.prior

    def prior_strength_for(self, inverted: bool) -> float:
        """:attr:`prior_strength` (``"auto"`` resolved: :data:`SPAN_PRIOR_STRENGTH` for a frame span of an inverted
        motion, :data:`PRIOR_STRENGTH` otherwise). ``inverted``: the edit is of an inversion."""
        if self.prior_strength == "auto":
            return SPAN_PRIOR_STRENGTH if (self.frames is not None and inverted) else PRIOR_STRENGTH
        return float(self.prior_strength)

    def prior_release(self, num_steps: int, inverted: bool = False) -> int:
        """The first step (of ``num_steps``) in which the region is free of the pasted prior (:meth:`prior_for`): the
        latents after steps ``0 .. release - 2`` are set to the prior's at that level, step ``release - 1``'s output
        as well, so step ``release`` starts from the prior noised to its own level; 0 without a prior."""
        if self.prior_for(inverted) == "none":
            return 0
        return int(round((1.0 - self.prior_strength_for(inverted)) * int(num_steps)))

    def prior_window(self, num_frames: int, min_frames: int) -> tuple[int, int, int, int]:
        """Where the pasted prior comes from and goes, for a motion of ``num_frames`` frames: ``(s, e, frames, c)``,
        the region's latent frames ``[s, e)``, the prior motion's length in motion frames (the span's, at least
        ``min_frames`` rounded up to whole latent frames; the whole motion for body parts alone) and the prior's
        first latent frame that goes to ``s`` (its middle ``e - s`` latent frames are pasted)."""
        s, e = self.latent_span(num_frames)
        if self.frames is None:
            return s, e, num_frames, 0
        unit = self.unit_length
        n_prior = max(e - s, math.ceil(min_frames / unit))
        return s, e, n_prior * unit, (n_prior - (e - s)) // 2

    def resampling(self, fraction: float, index: int, num_steps: int, passes: int) -> bool:
        """Whether the sampler resamples after step ``index`` (of ``num_steps``; ``fraction`` = index / num_steps)
        with ``passes`` (:meth:`passes_for`): ``passes`` > 1, the step ends a :attr:`jump`, it is not the last step
        and the replacement is active."""
        return (passes > 1 and (index + 1) % self.jump == 0 and index + 1 < num_steps
                and self.active(fraction))

    def fresh_noise(self, inverted: bool) -> bool:
        """Whether the regenerated region starts from new noise drawn from :attr:`seed` (:meth:`region_noise`), not
        the source's (:attr:`noise`; ``inverted``: the edit is of an inversion)."""
        return self.noise in ("fresh", "matched") or (self.noise == "auto" and inverted)

    def region_noise(self, source_noise: torch.Tensor, frame_mask: torch.Tensor) -> torch.Tensor:
        """``(B, N', P, Dz)`` new noise for the regenerated region (:meth:`fresh_noise`): white noise of
        :func:`~salad_core.attention.edits.seeded_noise` from :attr:`seed`; with ``noise="matched"`` shaped by
        :func:`matched_noise` to ``source_noise``'s statistics (``(B, N', P, Dz)``) over ``frame_mask``'s
        ``(B, N')`` valid frames."""
        white = seeded_noise(self.seed, source_noise.shape).to(source_noise)
        return matched_noise(white, source_noise, frame_mask) if self.noise == "matched" else white

    def frame_span(self, num_frames: int) -> tuple[int, int] | None:
        """The regenerated motion frames ``[s, e)`` (whole latent frames), None when every frame is."""
        if self.frames is None:
            return None
        s, e = self.latent_span(num_frames)
        return s * self.unit_length, min(num_frames, e * self.unit_length)

    def joint_weights(self, num_frames: int, skeleton="humanml3d") -> "np.ndarray":
        """``(N, J)`` composite weights (:mod:`~salad_core.attention.composite`): the regenerated parts' joints
        over the regenerated frames, ramping over :attr:`fade` frames at a span's seams."""
        from .composite import frame_weights, part_joint_weights

        fw = frame_weights(num_frames, self.frame_span(num_frames), self.fade)
        return fw[:, None] * part_joint_weights(self.parts or PART_NAMES, skeleton)[None]

    def describe(self) -> str:
        """``arms@40:80`` (the :func:`parse_inpaint` notation)."""
        parts = "all" if self.parts is None else ",".join(p.replace(" ", "_") for p in self.parts)
        if self.frames is None:
            return parts
        s, e = self.frames
        return f"{parts}@{'' if s is None else s}:{'' if e is None else e}"


def parse_inpaint(spec: str, *, blend: int = 1, unit_length: int = 4) -> Inpaint:
    """The command line's ``PARTS[@START:END]`` -> :class:`Inpaint`.

    ``PARTS`` is a comma- (or ``+``-) separated list of part and group names (``arms``,
    ``left_arm,head``, ``all``; spaces may be written ``_`` or ``-``); ``@START:END`` a motion-frame
    span with either end optional (``@40:80``, ``@:40`` a prefix, ``@80:`` a suffix); ``PARTS`` may be
    empty with a span (``@40:80`` = ``all@40:80``: every part over those frames).

    Raises
    ------
    ValueError
        The notation is wrong or the :class:`Inpaint` it names is (the message names the problem).
    """
    if not isinstance(spec, str) or not spec.strip():
        raise ValueError(f"inpaint spec {spec!r} is empty; use PARTS[@START:END], e.g. 'arms' or 'legs@40:80'")
    text = spec.strip()
    parts_text, at, span = text.partition("@")
    parts: Optional[str] = parts_text.strip() or None
    frames = None
    if at:
        if span.count(":") != 1:
            raise ValueError(f"inpaint spec {spec!r}: the span after '@' must be START:END (either may be empty)")
        a, b = (v.strip() for v in span.split(":"))
        try:
            frames = (int(a) if a else None, int(b) if b else None)
        except ValueError:
            raise ValueError(f"inpaint spec {spec!r}: START and END must be integers (motion frames)") from None
        if frames == (None, None):
            raise ValueError(f"inpaint spec {spec!r}: give START and/or END after '@'")
        if parts is not None and _norm(parts) == "all":
            parts = None
    elif parts is None:
        raise ValueError(f"inpaint spec {spec!r} names no part and no span")
    return Inpaint(parts=parts, frames=frames, blend=blend, unit_length=unit_length)
