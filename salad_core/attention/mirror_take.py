"""Mirroring a limb of a real take through the inversion of the take's mirror image.

Why :class:`~salad_core.attention.edits.Mirror` alone does not flip a real take. Measured with the shipped
weights (``lab/scripts/editing/measure_mirror_real.py``, ``diagnosis`` in ``lab/records/editing/mirror_real.json``):
the exact inversion's per-step corrections are nil (fixed-point inversion converges; removing them from the edited
branch changes nothing), but the inverted noise is not noise: its standard deviation is 1.1-1.7 instead of 1 and
neighbouring latent frames correlate (lag-1 autocorrelation 0.15-0.52 instead of 0). The deterministic sampler
regenerates the take from it without any attention (the edited branch with no edit is the source, 0.0 cm). Each
part token of that noise carries its own part's motion, so swapping which body part reads which words (the
cross-attention rows) only damps the leading limb: the right leg's noise still holds the right leg's kick. A
generated motion starts from white noise, where the cross-attention decides the side.

The mirror image of the take's *features* is exact (:func:`salad_core.motion.mirror_features`), and inverting it
gives noise whose limb tokens hold the mirrored limbs. :class:`MirrorTake` uses it: the edited branch starts from
the source's inverted noise with the chosen parts' tokens taken from the mirror's (and the mirror's exact
corrections on them); during ``follow`` the chosen parts' latents are the mirror's own inversion trajectory; during
``keep`` every other part's latent is the source branch's (the source's own reconstruction trajectory, as
in-painting keeps its region), so the untouched parts stay the source's in the latent space and the chosen limb is
denoised in their context. ``parts="all"`` takes every token, root, spine and head included, from the mirror: the
take's exact mirror image (a turn to the left becomes a turn to the right); ``"limbs"`` mirrors arms and legs and
keeps the root (path, heading), spine and head.

Use it with :class:`~salad_core.attention.edits.Mirror` of the same limbs (:func:`mirror_take_edits`): the mirrored
cross-attention keeps the limbs reading the words as the mirror does. The defaults (``follow=(0, 0.2)``,
``keep=(0, 1)``) were chosen on 10 one-sided *procedural validation* clips (never on the held-out real takes):
leading limb swapped in 10 of 10, the other parts moved 0.71 cm (root-aligned MPJPE), against 7 of 10 and 3.8 cm
for ``Mirror`` alone.

The mirror's inversion costs one more inversion of the take (:func:`invert_mirror`)::

    inv = pipe.invert(features, "a person kicks")
    out = pipe.edit(inversion=inv, edits=mirror_take_edits("legs", invert_mirror(pipe, inv)))
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, Sequence

import numpy as np
import torch

from salad_core.side_words import mirror_side_words
from salad_core.skeleton import PART_NAMES

from .edits import EditKernel, EditSpec, Mirror, _window

if TYPE_CHECKING:  # pragma: no cover
    from .capture import TokenInfo
    from .inversion import Inversion

__all__ = ["MirrorTake", "MIRROR_TAKE_GROUPS", "invert_mirror", "mirror_prompt", "mirror_take_edits",
           "mirror_take_mask"]

#: Parts each :class:`MirrorTake` choice takes from the mirror image ("all": every token, the exact mirror image).
MIRROR_TAKE_GROUPS: dict[str, tuple[str, ...]] = {
    "legs": ("left leg", "right leg"),
    "arms": ("left arm", "right arm"),
    "limbs": ("left leg", "right leg", "left arm", "right arm"),
    "all": tuple(PART_NAMES),
}
_ALIASES = {"lower": "legs", "upper": "arms"}


def mirror_prompt(prompt: str) -> str:
    """``prompt`` with its side words swapped ("left" <-> "right", "clockwise" <-> "counterclockwise"), the
    caption of the mirror image; capitalisation of the first letter kept."""
    return mirror_side_words(prompt)


def mirror_take_mask(parts: str, num_parts: int = len(PART_NAMES)) -> torch.Tensor:
    """``(1, 1, P, 1)`` float mask, 1 on the parts ``parts`` takes from the mirror image."""
    if num_parts != len(PART_NAMES):
        raise ValueError(f"MirrorTake needs the {len(PART_NAMES)} latent body parts, the latents have {num_parts}")
    m = torch.zeros(1, 1, num_parts, 1)
    for p in MIRROR_TAKE_GROUPS[parts]:
        m[0, 0, PART_NAMES.index(p)] = 1.0
    return m


@dataclass(frozen=True)
class MirrorTake(EditSpec):
    """Mirror ``parts`` of an inverted take with the inversion of its mirror image (see the module docstring).

    Parameters
    ----------
    parts : str
        ``"legs"`` (or ``"lower"``), ``"arms"`` (``"upper"``), ``"limbs"`` (both pairs; root, spine and head kept)
        or ``"all"`` (every part: the take's exact mirror image, turns reversed).
    mirrored : Inversion
        :func:`invert_mirror` of the edited inversion: the same prompts' mirror, lengths, steps and guidance.
    follow : (start, stop)
        Step fractions during which the chosen parts' latents are the mirror's inversion trajectory (then they
        are denoised freely with the edit's attention). ``None``: never.
    keep : (start, stop)
        Step fractions during which every other part's latent is the source branch's. ``None``: never (the
        other parts are denoised freely next to the mirrored ones).
    composite : bool
        After decoding, take the other parts' features from the source's decoding and hang the mirrored limbs
        from the source's pelvis / chest (:mod:`salad_core.attention.composite`): the VAE decoder's convolutions
        otherwise let the mirrored legs' tokens move the torso and arms (held-out kicks and spins: 3-3.9 cm
        root-aligned). Default on.
    """

    role: ClassVar[str] = "take"

    parts: str = "legs"
    mirrored: Any = field(default=None, compare=False, repr=False)
    follow: tuple[float, float] | None = (0.0, 0.2)
    keep: tuple[float, float] | None = (0.0, 1.0)
    composite: bool = True

    def __post_init__(self) -> None:
        parts = _ALIASES.get(self.parts, self.parts) if isinstance(self.parts, str) else self.parts
        if parts not in MIRROR_TAKE_GROUPS:
            raise ValueError(f"MirrorTake.parts={self.parts!r}; allowed: {sorted(MIRROR_TAKE_GROUPS)} "
                             "(or 'lower', 'upper')")
        object.__setattr__(self, "parts", parts)
        from .inversion import Inversion

        if not isinstance(self.mirrored, Inversion):
            raise TypeError("MirrorTake.mirrored must be the Inversion of the take's mirror image "
                            f"(invert_mirror(pipe, inversion)), got {type(self.mirrored).__name__}")
        for name in ("follow", "keep"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, _window(value, f"MirrorTake.{name}"))

    @property
    def window(self) -> tuple[float, float]:
        return (0.0, 1.0)

    def following(self, fraction: float) -> bool:
        """Whether the chosen parts follow the mirror's trajectory after the step at ``fraction``."""
        return self.follow is not None and self.follow[0] <= fraction < self.follow[1]

    def keeping(self, fraction: float) -> bool:
        """Whether the other parts are the source branch's after the step at ``fraction``."""
        return self.keep is not None and self.keep[0] <= fraction < self.keep[1]

    def mask(self, num_parts: int) -> torch.Tensor:
        """``(1, 1, P, 1)``: 1 on the parts taken from the mirror image."""
        return mirror_take_mask(self.parts, num_parts)

    def joint_weights(self, num_frames: int, skeleton="humanml3d") -> np.ndarray:
        """``(N, J)`` composite weights (:mod:`~salad_core.attention.composite`): 1 on the mirrored parts' joints."""
        from .composite import part_joint_weights

        return np.repeat(part_joint_weights(MIRROR_TAKE_GROUPS[self.parts], skeleton)[None], int(num_frames), 0)

    def check(self, noise: torch.Tensor, num_steps: int) -> None:
        """Refuse a mirror inversion that does not match the edited one's noise shape and steps."""
        inv = self.mirrored
        if tuple(inv.noise.shape) != tuple(noise.shape):
            raise ValueError(f"MirrorTake: the mirror's inverted noise has shape {tuple(inv.noise.shape)}, the edit's "
                             f"{tuple(noise.shape)}; invert the mirror of the same takes (invert_mirror)")
        if inv.trajectory.shape[0] != num_steps + 1:
            raise ValueError(f"MirrorTake: the mirror was inverted with {inv.trajectory.shape[0] - 1} steps, the edit "
                             f"runs {num_steps}; invert it with the same steps (invert_mirror)")

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """No map edit (the latents are edited in :func:`~salad_core.attention.editing.edit_latents`)."""
        return lambda maps, own: maps


def invert_mirror(pipe, inversion: "Inversion", *, swap_sides: bool = False, progress: bool = False) -> "Inversion":
    """Invert the exact mirror image of an inversion's takes (:func:`salad_core.motion.mirror_features`) with the
    same prompts, method, guidance, steps, iterations and exactness.

    The same prompts (not their mirror, :func:`mirror_prompt`, which ``swap_sides=True`` uses): the edited branch
    runs the source's prompt, and from the mirror's noise and corrections under that prompt it regenerates the
    mirror image exactly (``MirrorTake("all")``); the defaults were chosen this way."""
    from salad_core.motion import mirror_features

    feats = [np.asarray(mirror_features(np.asarray(f, np.float32)), np.float32) for f in inversion.features]
    prompts = [mirror_prompt(p) if swap_sides else p for p in inversion.prompts]
    guidance = inversion.guidance if inversion.guidance is not None else inversion.guidance_scale
    return pipe.invert(feats if len(feats) > 1 else feats[0], prompts, method=inversion.method,
                       guidance_scale=guidance, num_steps=inversion.num_steps, iterations=inversion.iterations,
                       exact=inversion.exact, reconstruct=False, progress=progress)


def mirror_take_edits(parts: str, mirrored: "Inversion", **kwargs) -> list[EditSpec]:
    """``[Mirror(limbs), MirrorTake(parts, mirrored, **kwargs)]``: the mirror's latents and the mirrored
    cross-attention of the same limbs (``"limbs"`` -> ``Mirror("all")``). ``parts="all"`` (the exact mirror
    image) adds no map edit: the mirror's own trajectory regenerates its mirror image."""
    take = MirrorTake(parts, mirrored, **kwargs)
    if take.parts == "all":
        return [take]
    return [Mirror({"limbs": "all"}.get(take.parts, take.parts)), take]


def composite(mask: torch.Tensor, mirrored: torch.Tensor | None, source: torch.Tensor | None,
              like: torch.Tensor) -> torch.Tensor | None:
    """``mask * mirrored + (1 - mask) * source`` (a missing tensor counts as zeros; both missing: None)."""
    if mirrored is None and source is None:
        return None
    mirrored = torch.zeros_like(like) if mirrored is None else mirrored.to(like)
    source = torch.zeros_like(like) if source is None else source.to(like)
    return mask.to(like) * mirrored + (1.0 - mask.to(like)) * source


def take_of(edits: Sequence[EditSpec]) -> MirrorTake | None:
    """The :class:`MirrorTake` among ``edits``, if any."""
    return next((e for e in edits if isinstance(e, MirrorTake)), None)
