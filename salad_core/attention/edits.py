"""Typed edit specifications and the pure kernels that apply them to attention maps.

SALAD supplement B (Algorithm 1) edits the cross-attention maps ``M`` of the source prompt, ``M*``
of the target prompt, into ``M_hat = Edit(M, M*, t)`` which the edited sample then uses. Each
modulation is a small frozen dataclass, validated on construction, with its step window given as
fractions ``p = i / S`` of the sampling steps (the official code's ``p``; step 0 is the noisiest):

==========================  ================================================================
:class:`WordSwap`           source maps (words paired in order) while ``p < 1 - tau``, the
                            target's own afterwards (paper: tau = 0.8, i.e. the first 20 %)
:class:`Refine`             target columns aligned to a source token take that source column
                            (:func:`~salad_core.attention.align.global_align`), inserted tokens
                            keep the target's own maps
:class:`Reweight`           scale the post-softmax columns of chosen words by ``s`` in [-3, 3]
:class:`Mirror`             swap the rows of counterpart body parts (legs, arms or all)
:class:`InjectSelfAttention` the edited sample uses the source's temporal / skeletal
                            self-attention for an early window (official default 0.2)
==========================  ================================================================

Edits beyond the paper (MotionCLR, Chen et al. 2024, describes what they mean; written here for
SALAD's 7-part x frame x word maps):

==========================  ================================================================
:class:`Erase`              remove a phrase: its token columns lose their mass (given to the
                            prompt's other words, to the special tokens, or to nobody)
:class:`Shift`              move a phrase in time: its columns slide ``frames / unit_length``
                            latent frames along the frame axis
:class:`ShiftTemporal`      move what some body parts do in time through their temporal
                            self-attention (the source's, slid along both frame axes)
:class:`ExampleBased`       variations of an example: the edited sample starts from its own
                            noise and takes the example's temporal self-attention early on
==========================  ================================================================

In-painting, :class:`~salad_core.attention.inpaint.Inpaint` (:mod:`.inpaint`), is an edit of the latents, not of
the maps (role ``"latent"``): it composes with all of the above. So is mirroring a real take through the inversion
of its mirror image, :class:`~salad_core.attention.mirror_take.MirrorTake` (:mod:`.mirror_take`, role ``"take"``),
which flips an inverted take's leading limb where :class:`Mirror` alone only damps it.

Specs compose in order, Prompt-to-Prompt style: at most one *replacement* (WordSwap or Refine)
builds the base map from ``M`` and ``M*``; *modifiers* (Reweight, Mirror, Erase, Shift) change the map in
the order given; with no replacement the base is the source's own map ``M`` (paper: reweighting
and mirroring modulate ``M_t``), which needs the target to be the source prompt.

Each spec applies its own kernel: :meth:`EditSpec.bind` looks up what the spec needs in the
prompts (the word-swap token matrix, the refinement alignment, the re-weighted columns) once and
returns an :data:`EditKernel` ``kernel(maps, own) -> maps`` that the controller
(:class:`~salad_core.attention.controller.EditController`) composes without knowing the kinds. The
kernels below are pure functions of tensors: they never modify their inputs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, ClassVar, Optional, Sequence, Union

import torch

from salad_core.data.texts import split_words
from salad_core.skeleton import PART_MIRROR, PART_NAMES

from .align import global_align, word_swap_matrix

if TYPE_CHECKING:  # pragma: no cover - annotations only (capture imports nothing from here)
    from .capture import TokenInfo

__all__ = [
    "EditSpec",
    "EditKernel",
    "WordSwap",
    "Refine",
    "Reweight",
    "Mirror",
    "InjectSelfAttention",
    "MirrorSelfAttention",
    "Erase",
    "Shift",
    "ExampleBased",
    "ShiftTemporal",
    "ERASE_MODES",
    "MIRROR_GROUPS",
    "REWEIGHT_RANGE",
    "mirror_permutation",
    "mirror_parts",
    "mirror_self_attention",
    "reweight_columns",
    "map_columns",
    "refine_columns",
    "erase_columns",
    "shift_columns",
    "shift_temporal",
    "seeded_noise",
    "validate_edits",
]

#: Allowed scales of :class:`Reweight` (paper supplement B: [-3, 3] gives reasonable edits).
REWEIGHT_RANGE: tuple[float, float] = (-3.0, 3.0)
#: Body parts each :class:`Mirror` choice swaps with their counterparts (``PART_MIRROR``).
MIRROR_GROUPS: dict[str, tuple[str, ...]] = {
    "legs": ("left leg", "right leg"),
    "arms": ("left arm", "right arm"),
    "all": tuple(p for p, q in zip(PART_NAMES, PART_MIRROR) if PART_NAMES.index(p) != q),
}
_SELF_KINDS = ("temporal", "skeletal")
#: Axis of the body parts in the cross maps the controller edits, ``(B, H, N', P, W)``.
_PART_AXIS = 3
#: Axis of the latent frames in those maps.
_FRAME_AXIS = 2
#: Where :class:`Erase` puts the mass it takes from the phrase's columns (see :func:`erase_columns`).
ERASE_MODES: tuple[str, ...] = ("special", "others", "zero")

#: ``kernel(maps, own) -> maps``: a bound edit (:meth:`EditSpec.bind`). ``maps`` ``(B, H, N', P, W)``
#: are the maps it edits (the source's for a replacement, the base built so far for a modifier, the
#: source's self-attention for an injection); ``own`` the target's own maps ``M*`` where the step
#: has them (else None; only prompt refinement reads them).
EditKernel = Callable[[torch.Tensor, Optional[torch.Tensor]], torch.Tensor]


def _window(value, name: str) -> tuple[float, float]:
    try:
        start, stop = (float(v) for v in value)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be a (start, stop) pair of step fractions, got {value!r}") from None
    if not (math.isfinite(start) and math.isfinite(stop) and 0.0 <= start < stop <= 1.0):
        raise ValueError(f"{name}={value!r} must satisfy 0 <= start < stop <= 1 (fractions i/S of the "
                         "sampling steps; step 0 is the noisiest)")
    return start, stop


def _distinct(value, allowed: tuple[str, ...], name: str) -> tuple[str, ...]:
    """A name or a sequence of names -> a non-empty tuple of distinct entries of ``allowed``."""
    items = (value,) if isinstance(value, str) else tuple(value)
    if not items or any(v not in allowed for v in items) or len(set(items)) != len(items):
        raise ValueError(f"{name}={value!r} must be distinct entries of {allowed}")
    return items


def _is_span(value) -> bool:
    return (isinstance(value, (tuple, list)) and len(value) == 2
            and all(isinstance(v, int) and not isinstance(v, bool) for v in value))


def _phrases(value, name: str) -> tuple[Union[str, tuple[int, int]], ...]:
    """Words of an edit: a word or phrase, a ``(start, stop)`` word span, or a sequence of those."""
    items = (value,) if isinstance(value, str) or _is_span(value) else value
    try:
        items = tuple(items)
    except TypeError:
        raise TypeError(f"{name}={value!r} must be a word or phrase, a (start, stop) word span, or a sequence of "
                        "those") from None
    out: list[Union[str, tuple[int, int]]] = []
    for item in items:
        if isinstance(item, str) and split_words(item):
            out.append(" ".join(split_words(item)))
        elif _is_span(item) and 0 <= item[0] < item[1]:
            out.append((int(item[0]), int(item[1])))
        else:
            raise ValueError(f"{name}={value!r}: {item!r} is neither a word or phrase (with at least one letter) "
                             "nor a (start, stop) word span with 0 <= start < stop")
    if not out:
        raise ValueError(f"{name}={value!r} is empty; name at least one word, phrase or word span")
    return tuple(out)


def _phrase_columns(maps_of: "TokenInfo", words, kind: str) -> list[list[int]]:
    """Per prompt of ``maps_of``, the sorted token columns of ``words`` (errors list the prompt's words)."""
    columns = []
    for b in range(len(maps_of)):
        cols: set[int] = set()
        for word in words:
            try:
                cols.update(maps_of.word_columns(b, word))
            except (ValueError, IndexError):
                raise ValueError(f"{kind} word {word!r} is not in the prompt {maps_of.prompts[b]!r}; "
                                 f"its words are {maps_of.words[b]}") from None
        columns.append(sorted(cols))
    return columns


@dataclass(frozen=True)
class EditSpec:
    """Base of the edit specifications (see the module docstring).

    ``role`` says how the controller composes it: ``"replace"`` builds the base map from ``M`` (and
    ``M*``), ``"modify"`` changes the map built so far, ``"inject"`` hands the source's
    self-attention to the edited rows. ``reads_target`` is True when the kernel reads the target's
    own maps ``M*`` during its window.
    """

    role: ClassVar[str] = "modify"
    reads_target: ClassVar[bool] = False

    def active(self, fraction: float) -> bool:
        """Whether the edit applies at step fraction ``p = i / S``."""
        start, stop = self.window
        return start <= fraction < stop

    @property
    def window(self) -> tuple[float, float]:
        """``(start, stop)`` step fractions where the edit applies: its ``steps`` (WordSwap derives
        them from ``tau``)."""
        return self.steps

    @property
    def edited_seed(self) -> int | None:
        """Noise seed of the edited sample when it must not share the source's noise (None: it
        shares it, Algorithm 1 line 4; :class:`ExampleBased` sets one)."""
        return None

    @property
    def replaces(self) -> bool:
        """True for the replacement edits (WordSwap, Refine) that build the base map."""
        return self.role == "replace"

    @property
    def site_kinds(self) -> tuple[str, ...]:
        """Attention kinds the edit touches."""
        return ("cross",)

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """This edit's kernel for ``B`` source/target prompt pairs whose maps have ``width`` token
        columns; ``maps_of`` is the prompt whose maps the modifiers edit (the target after a
        replacement, else the source)."""
        raise NotImplementedError  # pragma: no cover - every subclass defines it


@dataclass(frozen=True)
class WordSwap(EditSpec):
    """Word swap (supplement B): ``M_hat = M`` (source) while ``t >= tau T``, ``M*`` afterwards.

    ``t`` counts down from ``T``, so the source maps are used for the first ``1 - tau`` of the
    steps (paper tau = 0.8: the first 20 %). The prompts must have the same number of words; word
    ``i`` of the target takes the maps of word ``i`` of the source (see
    :func:`~salad_core.attention.align.word_swap_matrix`). The official code instead copies all 77
    CLIP columns position by position; with MiniLM's variable token counts words must be paired.
    """

    role: ClassVar[str] = "replace"

    tau: float = 0.8   # switch point in diffusion time: source maps while t >= tau * T

    def __post_init__(self) -> None:
        if isinstance(self.tau, bool) or not isinstance(self.tau, (int, float)) or not 0.0 <= float(self.tau) < 1.0:
            raise ValueError(f"WordSwap.tau={self.tau!r} must be in [0, 1): the source maps are used while "
                             "t >= tau*T, i.e. for the first (1 - tau) of the steps (paper: 0.8)")
        object.__setattr__(self, "tau", float(self.tau))

    @property
    def window(self) -> tuple[float, float]:
        return (0.0, 1.0 - self.tau)

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`map_columns` by the word-pairing matrices ``(B, W, W)`` of the prompt pairs."""
        matrices = torch.zeros(len(source), width, width)
        for b in range(len(source)):
            m = word_swap_matrix(source.tokens[b], source.token_to_word[b], source.words[b], target.tokens[b],
                                 target.token_to_word[b], target.words[b])
            matrices[b, :m.shape[0], :m.shape[1]] = torch.from_numpy(m)
        return lambda maps, own: map_columns(maps, matrices.to(maps.device))


@dataclass(frozen=True)
class Refine(EditSpec):
    """Prompt refinement (supplement B): ``M_hat[:, :, k] = M[:, :, A(k)]`` where the target token
    ``k`` is aligned to source token ``A(k)``, else ``M*[:, :, k]``.

    This follows the paper (and Prompt-to-Prompt): source columns are *re-indexed* by the
    alignment, so an inserted word in the middle of the prompt does not shift the later words'
    maps. The official code skips the re-indexing (its mapper is commented out), so there the
    words after an insertion receive their neighbours' maps.
    """

    role: ClassVar[str] = "replace"
    reads_target: ClassVar[bool] = True

    steps: tuple[float, float] = (0.0, 1.0)   # window of step fractions where the source maps are injected

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", _window(self.steps, "Refine.steps"))

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`refine_columns` by the alignments ``(B, W)`` of the prompt pairs."""
        mapping = torch.full((len(source), width), -1, dtype=torch.long)
        for b in range(len(source)):
            aligned = global_align(source.tokens[b], target.tokens[b])
            mapping[b, :len(aligned)] = torch.tensor(aligned, dtype=torch.long)

        def kernel(maps: torch.Tensor, own: torch.Tensor | None) -> torch.Tensor:
            if own is None:
                raise RuntimeError("prompt refinement needs the probe's maps at this step")
            return refine_columns(maps, own, mapping)
        return kernel


@dataclass(frozen=True)
class Reweight(EditSpec):
    """Attention re-weighting (supplement B): multiply the columns of ``words`` by ``scale``.

    Post-softmax and without re-normalisation, as the paper and the official code; negative
    scales give "semantically opposite" motions (paper). ``words`` are looked up in the prompt
    whose maps are edited (the target; the source when no replacement is given); a word missing
    from it is an error that lists the prompt's words.
    """

    words: Union[str, tuple[str, ...]] = ()    # word(s) or phrase(s) whose token columns are scaled
    scale: float = 1.0                         # s in [-3, 3]; 1 leaves the maps unchanged
    steps: tuple[float, float] = (0.0, 1.0)   # window of step fractions

    def __post_init__(self) -> None:
        words = (self.words,) if isinstance(self.words, str) else tuple(self.words)
        if not words or not all(isinstance(w, str) and split_words(w) for w in words):
            raise ValueError(f"Reweight.words={self.words!r} must be a word or a sequence of words "
                             "(each with at least one letter)")
        object.__setattr__(self, "words", tuple(" ".join(split_words(w)) for w in words))
        if isinstance(self.scale, bool) or not isinstance(self.scale, (int, float)) or not math.isfinite(self.scale):
            raise TypeError(f"Reweight.scale must be a finite number, got {self.scale!r}")
        lo, hi = REWEIGHT_RANGE
        if not lo <= float(self.scale) <= hi:
            raise ValueError(f"Reweight.scale={self.scale!r} is outside [{lo:g}, {hi:g}], the range the paper "
                             "found to give reasonable edits")
        object.__setattr__(self, "scale", float(self.scale))
        object.__setattr__(self, "steps", _window(self.steps, "Reweight.steps"))

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`reweight_columns` of the words' token columns in each prompt of ``maps_of``."""
        columns = _phrase_columns(maps_of, self.words, "Reweight")
        return lambda maps, own: reweight_columns(maps, columns, self.scale, per_row=True)


@dataclass(frozen=True)
class Mirror(EditSpec):
    """Attention mirroring (supplement B): ``M_hat[j] = M[C(j)]`` for the body parts of ``parts``.

    ``parts``: ``"legs"`` (official ``lower``), ``"arms"`` (``upper``) or ``"all"``; counterparts
    come from :data:`salad_core.skeleton.PART_MIRROR`. Root, spine and head map to themselves.

    On an inverted real take this only damps the leading limb: the inverted noise's part tokens carry the
    take's own sides (:mod:`salad_core.attention.mirror_take`); add
    :class:`~salad_core.attention.mirror_take.MirrorTake` (``mirror_take_edits``) to flip it.
    """

    parts: str = "all"                          # "legs", "arms" or "all"
    steps: tuple[float, float] = (0.0, 1.0)   # window of step fractions

    def __post_init__(self) -> None:
        aliases = {"lower": "legs", "upper": "arms"}
        parts = aliases.get(self.parts, self.parts) if isinstance(self.parts, str) else self.parts
        if parts not in MIRROR_GROUPS:
            raise ValueError(f"Mirror.parts={self.parts!r}; allowed: {sorted(MIRROR_GROUPS)} "
                             "(or the official names 'lower', 'upper')")
        object.__setattr__(self, "parts", parts)
        object.__setattr__(self, "steps", _window(self.steps, "Mirror.steps"))

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`mirror_parts` along the body-part axis of the cross maps."""
        return lambda maps, own: mirror_parts(maps, self.parts, part_axis=_PART_AXIS)


@dataclass(frozen=True)
class InjectSelfAttention(EditSpec):
    """The edited sample uses the source's self-attention maps during ``steps`` (official
    ``src_proportion`` = 0.2 for every edit mode: all layers and heads, conditional branch only).

    It fixes the overall composition (timing, skeleton coordination) of the source early on.
    """

    role: ClassVar[str] = "inject"

    steps: tuple[float, float] = (0.0, 0.2)                      # window of step fractions
    kinds: tuple[str, ...] = ("temporal", "skeletal")             # which self-attention to inject

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", _window(self.steps, "InjectSelfAttention.steps"))
        object.__setattr__(self, "kinds", _distinct(self.kinds, _SELF_KINDS, "InjectSelfAttention.kinds"))

    @property
    def site_kinds(self) -> tuple[str, ...]:
        return self.kinds

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """The source's self-attention maps, as they are, for the edited rows."""
        return lambda maps, own: maps


@dataclass(frozen=True)
class MirrorSelfAttention(EditSpec):
    """The edited sample uses the source's self-attention with counterpart body parts swapped
    (a companion of :class:`Mirror`, beyond the paper).

    :class:`Mirror` swaps which body part reads which words; the parts' own structure, when each
    moves and which parts follow which, lives in the self-attention. Here, during ``steps``, the
    edited rows take the source's maps relabelled by the mirror permutation ``C`` of ``parts``
    (:func:`mirror_self_attention`): temporal maps ``(B, P, H, N', N')`` of part ``j`` are those of
    ``C(j)``; skeletal maps ``(B, N', H, P, P)`` become ``M[C(i), C(k)]``. So the left arm moves in
    time as the source's right arm did and relates to the body as it did. Use it with
    :class:`Mirror` of the same parts: ``[Mirror("all"), MirrorSelfAttention("all")]``.
    """

    role: ClassVar[str] = "inject"

    parts: str = "all"                                        # "legs", "arms" or "all"
    steps: tuple[float, float] = (0.0, 1.0)                  # window of step fractions
    kinds: tuple[str, ...] = ("temporal", "skeletal")         # which self-attention to mirror

    def __post_init__(self) -> None:
        object.__setattr__(self, "parts", Mirror(self.parts).parts)        # the same names and aliases
        object.__setattr__(self, "steps", _window(self.steps, "MirrorSelfAttention.steps"))
        object.__setattr__(self, "kinds", _distinct(self.kinds, _SELF_KINDS, "MirrorSelfAttention.kinds"))

    @property
    def site_kinds(self) -> tuple[str, ...]:
        return self.kinds

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *,
             maps_of: "TokenInfo") -> dict[str, EditKernel]:
        """One kernel per attention kind (the controller picks the site's): the source's maps
        relabelled by :func:`mirror_self_attention`."""
        return {kind: (lambda maps, own, kind=kind: mirror_self_attention(maps, kind, self.parts))
                for kind in self.kinds}


@dataclass(frozen=True)
class Erase(EditSpec):
    """Erase a phrase (MotionCLR's erasing): its token columns lose all their attention.

    ``words`` is a word or phrase ("waves his right hand"), a ``(start, stop)`` word span (the
    corpus annotations' spans) or a sequence of those, looked up in the prompt whose maps are
    edited. ``mode`` says where the removed mass goes (:func:`erase_columns`): ``"special"``
    (default) gives it to the special tokens (``[CLS]``, ``[SEP]``), which carry the sentence but no
    word of their own; ``"others"`` re-normalises every (part, frame) over the prompt's remaining
    tokens, so the parts follow the other words there; ``"zero"`` drops it, which is
    ``Reweight(words, 0)``. The default was chosen by ``lab/scripts/editing/measure_new_edits.py`` (shipped
    weights, 16 held-out captions, 50 steps): the erased phrase's parts lost 31 % of their activity
    with ``"special"``, 15 % with ``"others"`` (deleting the words from the prompt: 11 %), while the
    other parts moved 2.2 and 2.3 cm (deleting the words: 4.6 cm).
    """

    words: Union[str, tuple, Sequence] = ()   # word(s), phrase(s) or (start, stop) word span(s)
    mode: str = "special"                      # where the removed mass goes: "special", "others", "zero"
    steps: tuple[float, float] = (0.0, 1.0)   # window of step fractions

    def __post_init__(self) -> None:
        object.__setattr__(self, "words", _phrases(self.words, "Erase.words"))
        if self.mode not in ERASE_MODES:
            raise ValueError(f"Erase.mode={self.mode!r}; allowed: {ERASE_MODES}")
        object.__setattr__(self, "steps", _window(self.steps, "Erase.steps"))

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`erase_columns` of the phrase's columns in each prompt of ``maps_of``."""
        columns = _phrase_columns(maps_of, self.words, "Erase")
        keep = [[j for j in range(len(maps_of.tokens[b])) if j not in set(columns[b])] for b in range(len(maps_of))]
        special = [[j for j, w in enumerate(maps_of.token_to_word[b]) if w is None and j not in set(columns[b])]
                   for b in range(len(maps_of))]
        receivers = {"others": keep, "special": special, "zero": None}[self.mode]
        if receivers is not None and not all(receivers):
            bad = next(b for b in range(len(maps_of)) if not receivers[b])
            raise ValueError(f"Erase(mode={self.mode!r}) has no token left to take the mass in prompt "
                             f"{maps_of.prompts[bad]!r}; use mode='zero' or erase fewer words")
        return lambda maps, own: erase_columns(maps, columns, receivers)


@dataclass(frozen=True)
class Shift(EditSpec):
    """Move a phrase in time (MotionCLR's sequence shifting, on the cross-attention):
    ``M_hat[..., t, :, k] = M[..., t - n, :, k]`` for the phrase's token columns ``k``.

    ``frames`` is the shift in motion frames (positive: later); one latent frame covers
    ``unit_length`` motion frames (4 for HumanML3D and KIT-ML, 0.2 s at 20 fps), so ``frames`` must be
    a multiple of it and the maps move by ``n = frames / unit_length`` latent frames. Frames the phrase
    leaves get none of its attention; what slides past either end is dropped. With ``keep_sums``
    (default) the other columns of each (part, frame) are rescaled so that its total attention is
    what it was, i.e. the phrase's mass is exchanged with the other words' (see :func:`shift_columns`).

    The maps move exactly (tests), but with the shipped weights the motion does not follow them:
    shifting 16 held-out captions' phrases by 20 frames moved their parts' activity by -0.3 frames on
    average along the shift, 2 of 16 within the 10 % target (with :class:`ShiftTemporal` too: +2
    frames, 3 of 16; ``lab/scripts/editing/measure_new_edits.py --sections b``).
    """

    words: Union[str, tuple, Sequence] = ()   # word(s), phrase(s) or (start, stop) word span(s)
    frames: int = 0                            # shift in motion frames (positive: later)
    unit_length: int = 4                       # motion frames per latent frame
    keep_sums: bool = True                     # rescale the other columns to keep each row's total
    steps: tuple[float, float] = (0.0, 1.0)   # window of step fractions

    def __post_init__(self) -> None:
        object.__setattr__(self, "words", _phrases(self.words, "Shift.words"))
        for name in ("frames", "unit_length"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int):
                raise TypeError(f"Shift.{name} must be an int, got {value!r}")
        if self.unit_length < 1:
            raise ValueError(f"Shift.unit_length={self.unit_length!r} must be a positive number of motion frames")
        if self.frames % self.unit_length:
            lo = self.frames - self.frames % self.unit_length
            raise ValueError(f"Shift.frames={self.frames} is not a multiple of unit_length={self.unit_length} "
                             f"(one latent frame); use {lo} or {lo + self.unit_length}")
        if not isinstance(self.keep_sums, bool):
            raise TypeError(f"Shift.keep_sums must be a bool, got {self.keep_sums!r}")
        object.__setattr__(self, "steps", _window(self.steps, "Shift.steps"))

    @property
    def latent_frames(self) -> int:
        """The shift in latent frames, ``frames / unit_length``."""
        return self.frames // self.unit_length

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`shift_columns` of the phrase's columns in each prompt of ``maps_of``."""
        columns = _phrase_columns(maps_of, self.words, "Shift")
        return lambda maps, own: shift_columns(maps, columns, self.latent_frames, keep_sums=self.keep_sums)


@dataclass(frozen=True)
class ShiftTemporal(EditSpec):
    """Move what ``parts`` do in time through their temporal self-attention: the edited sample uses
    the source's temporal maps of those parts slid by ``frames`` along both frame axes
    (:func:`shift_temporal`), the other parts' maps as they are.

    A companion of :class:`Shift` (which moves a phrase's cross-attention columns) for a phrase whose
    timing the cross-attention alone does not move: ``[Shift(phrase, n), ShiftTemporal(parts, n)]``.
    ``frames`` and ``unit_length`` as in :class:`Shift`. It replaces the edited rows' temporal
    self-attention during ``steps`` (like :class:`InjectSelfAttention`; with both, the last wins).
    """

    role: ClassVar[str] = "inject"

    parts: Union[str, tuple[str, ...]] = ()    # body parts whose temporal maps move
    frames: int = 0                             # shift in motion frames (positive: later)
    unit_length: int = 4                        # motion frames per latent frame
    steps: tuple[float, float] = (0.0, 1.0)    # window of step fractions

    def __post_init__(self) -> None:
        object.__setattr__(self, "parts", _distinct(self.parts, PART_NAMES, "ShiftTemporal.parts"))
        Shift("x", self.frames, self.unit_length)          # the same checks of frames and unit_length
        object.__setattr__(self, "steps", _window(self.steps, "ShiftTemporal.steps"))

    @property
    def site_kinds(self) -> tuple[str, ...]:
        return ("temporal",)

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`shift_temporal` of the source's temporal maps ``(B, P, H, N', N')``."""
        rows = [PART_NAMES.index(p) for p in self.parts]
        n = self.frames // self.unit_length
        return lambda maps, own: shift_temporal(maps, rows, n)


@dataclass(frozen=True)
class ExampleBased(EditSpec):
    """Variations of an example motion (MotionCLR's example-based generation).

    The source branch is the example (usually an inverted motion: ``pipe.edit(inversion=inv,
    edits=[ExampleBased(seed=1)])``); the edited sample starts from its *own* noise, drawn from
    ``seed`` (sample ``b``: ``seed + b``, the noise ``pipe(..., seed=seed)`` would use), and during
    ``steps`` its temporal self-attention (each part's frame-to-frame map) is the example's. The
    example's timing and structure then drive new content: similar yet not the same motion.
    Outside the window, or with a window that holds no step, it is plain sampling from ``seed``.

    Measured with the shipped weights (``lab/scripts/editing/measure_new_edits.py --sections c``: 3 inverted
    held-out clips x 3 seeds, 50 steps): the variations were 9.8-9.9 cm (root-aligned MPJPE) from the
    example against 10.2 cm for plain samples of its caption from the same seeds, and as diverse
    (4.6-5.2 cm between variations, 4.9 cm between plain samples), with the temporal maps over the
    first half or all of the steps; adding the skeletal maps made them farther (10.6 cm). So the
    example's self-attention barely constrains these weights: "similar" is not reached yet.
    """

    role: ClassVar[str] = "inject"

    seed: int = 1                                      # noise seed of the variation
    steps: tuple[float, float] = (0.0, 0.5)           # window of step fractions with the example's maps
    kinds: tuple[str, ...] = ("temporal",)            # which self-attention of the example to use

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not 0 <= self.seed < 2 ** 63:
            raise ValueError(f"ExampleBased.seed={self.seed!r} must be an int in 0..2**63-1")
        object.__setattr__(self, "steps", _window(self.steps, "ExampleBased.steps"))
        object.__setattr__(self, "kinds", _distinct(self.kinds, _SELF_KINDS, "ExampleBased.kinds"))

    @property
    def site_kinds(self) -> tuple[str, ...]:
        return self.kinds

    @property
    def edited_seed(self) -> int | None:
        return self.seed

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """The example's self-attention maps, as they are, for the edited rows."""
        return lambda maps, own: maps


def validate_edits(edits: EditSpec | Sequence[EditSpec] | None) -> tuple[EditSpec, ...]:
    """A spec or a sequence of specs -> a validated tuple (at most one replacement, first)."""
    if edits is None:
        return ()
    if isinstance(edits, EditSpec):
        edits = (edits,)
    if isinstance(edits, (str, bytes)) or not isinstance(edits, Sequence):
        raise TypeError(f"edits must be an EditSpec or a sequence of them (WordSwap, Refine, Reweight, Mirror, "
                        f"InjectSelfAttention, Erase, Shift, ExampleBased), got {type(edits).__name__}")
    out = tuple(edits)
    for i, e in enumerate(out):
        if not isinstance(e, EditSpec) or type(e) is EditSpec:
            raise TypeError(f"edits[{i}] must be WordSwap, Refine, Reweight, Mirror or InjectSelfAttention (or Erase, "
                            f"Shift, ShiftTemporal, ExampleBased, Inpaint), got {e!r}")
    latent = [e for e in out if e.role == "latent"]
    if len(latent) > 1:
        raise ValueError(f"at most one in-painting edit (Inpaint) per edit, got {latent}; name all the parts in one")
    takes = [e for e in out if e.role == "take"]
    if len(takes) > 1:
        raise ValueError(f"at most one MirrorTake per edit, got {takes}")
    seeded = [e for e in out if e.edited_seed is not None]
    if takes and seeded:
        raise ValueError(f"MirrorTake starts the edited sample from the mirror's noise; it cannot be combined with "
                         f"an edit that gives it its own noise ({seeded[0]!r})")
    if len(seeded) > 1:
        raise ValueError(f"at most one edit may give the edited sample its own noise, got {seeded}")
    replacements = [e for e in out if e.role == "replace"]
    if len(replacements) > 1:
        raise ValueError(f"at most one replacement edit (WordSwap or Refine) per edit, got {replacements}")
    if replacements and any(e.role == "modify" for e in out[:out.index(replacements[0])]):
        raise ValueError("the replacement edit (WordSwap or Refine) must come before the modifiers "
                         "(Reweight, Mirror, Erase, Shift): it builds the map they modify")
    return out


# ================================================================================ kernels
def mirror_permutation(parts: str, num_parts: int = len(PART_NAMES)) -> list[int]:
    """Index list ``C`` over the P body parts: the counterpart for the chosen group, else itself."""
    if parts not in MIRROR_GROUPS:
        raise ValueError(f"parts={parts!r}; allowed: {sorted(MIRROR_GROUPS)}")
    if num_parts != len(PART_NAMES):
        raise ValueError(f"mirroring needs the {len(PART_NAMES)} latent body parts, the maps have {num_parts}")
    chosen = {PART_NAMES.index(p) for p in MIRROR_GROUPS[parts]}
    return [PART_MIRROR[j] if j in chosen else j for j in range(num_parts)]


def mirror_parts(maps: torch.Tensor, parts: str = "all", part_axis: int = -2) -> torch.Tensor:
    """Swap counterpart body-part rows along ``part_axis`` (cross maps ``(..., N', P, W)``: -2).

    Returns a new tensor; applying it twice gives the input back exactly.
    """
    perm = mirror_permutation(parts, maps.shape[part_axis])
    return maps.index_select(part_axis, torch.tensor(perm, device=maps.device))


def mirror_self_attention(maps: torch.Tensor, kind: str, parts: str = "all") -> torch.Tensor:
    """Self-attention maps relabelled by the mirror permutation ``C`` of ``parts`` (a new tensor).

    ``kind="temporal"``: ``(B, P, H, N', N')``, part ``j``'s frame-to-frame map becomes part ``C(j)``'s.
    ``kind="skeletal"``: ``(B, N', H, P, P)``, ``out[..., i, k] = maps[..., C(i), C(k)]`` (queries and
    keys both relabelled, so each row still sums to what it did). ``C`` is an involution, so applying
    it twice gives the input back exactly.
    """
    if kind == "temporal":
        return mirror_parts(maps, parts, part_axis=1)
    if kind == "skeletal":
        return mirror_parts(mirror_parts(maps, parts, part_axis=-2), parts, part_axis=-1)
    raise ValueError(f"kind={kind!r}: self-attention kinds are {_SELF_KINDS}")


def reweight_columns(maps: torch.Tensor, columns: Sequence[int] | Sequence[Sequence[int]] | torch.Tensor,
                     scale: float, *, per_row: bool = False) -> torch.Tensor:
    """Multiply token columns (last axis) by ``scale``; a new tensor (no re-normalisation, as the
    paper and the official code).

    ``columns``: the column indices of every map, or with ``per_row`` one sequence of indices per
    entry of the leading axis (``maps (R, ..., W)``: per prompt of a batch).
    """
    if not per_row:
        weights = torch.ones(maps.shape[-1], dtype=maps.dtype, device=maps.device)
        weights[torch.as_tensor(columns, dtype=torch.long, device=maps.device)] = scale
        return maps * weights
    if len(columns) != maps.shape[0]:
        raise ValueError(f"per_row columns need one sequence per map ({maps.shape[0]}), got {len(columns)}")
    weights = torch.ones(maps.shape[0], maps.shape[-1], dtype=maps.dtype, device=maps.device)
    for r, cols in enumerate(columns):
        weights[r, torch.as_tensor(cols, dtype=torch.long, device=maps.device)] = scale
    return maps * weights.view(maps.shape[0], *(1,) * (maps.dim() - 2), maps.shape[-1])


def map_columns(source: torch.Tensor, matrix: torch.Tensor) -> torch.Tensor:
    """``out[..., k] = sum_j matrix[..., k, j] * source[..., j]`` (word-swap token mapping).

    ``source`` ``(R, H, N', P, W_s)``, ``matrix`` ``(R, W_t, W_s)`` -> ``(R, H, N', P, W_t)``.
    """
    return torch.einsum("rhnpj,rkj->rhnpk", source, matrix.to(source.dtype))


def refine_columns(source: torch.Tensor, target: torch.Tensor, mapping: torch.Tensor) -> torch.Tensor:
    """Prompt refinement: ``out[..., k] = source[..., A(k)]`` if ``A(k) >= 0`` else ``target[..., k]``.

    ``source`` ``(R, H, N', P, W_s)``, ``target`` ``(R, H, N', P, W_t)``, ``mapping`` ``(R, W_t)``
    long with -1 for inserted tokens.
    """
    idx = mapping.clamp(min=0).to(source.device)                       # (R, W_t)
    r, h, n, p, _ = source.shape
    gathered = torch.gather(source, -1, idx[:, None, None, None, :].expand(r, h, n, p, idx.shape[1]))
    keep = (mapping >= 0).to(source.device)[:, None, None, None, :]
    return torch.where(keep, gathered, target)


def erase_columns(maps: torch.Tensor, columns: Sequence[Sequence[int]],
                  receivers: Sequence[Sequence[int]] | None = None) -> torch.Tensor:
    """Take all attention from the token ``columns`` of each map; a new tensor.

    ``maps`` ``(R, ..., W)``: one entry of ``columns`` (and of ``receivers``) per leading row. The mass
    removed from each query (each (part, frame) of the cross maps) goes to the ``receivers`` columns in
    proportion to what they hold (so a probability row stays a probability row), or, where they hold
    nothing, equally to them; ``receivers=None`` drops it (``reweight_columns(maps, columns, 0)``).
    """
    if len(columns) != maps.shape[0] or (receivers is not None and len(receivers) != maps.shape[0]):
        raise ValueError(f"erase_columns needs one column list per map ({maps.shape[0]}), got {len(columns)}"
                         + ("" if receivers is None else f" and {len(receivers)} receiver lists"))
    w = maps.shape[-1]
    view = (maps.shape[0], *(1,) * (maps.dim() - 2), w)
    gone = torch.zeros(maps.shape[0], w, dtype=torch.bool, device=maps.device)
    for r, cols in enumerate(columns):
        gone[r, torch.as_tensor(list(cols), dtype=torch.long, device=maps.device)] = True
    out = maps.masked_fill(gone.view(view), 0.0)
    if receivers is None:
        return out
    take = torch.zeros(maps.shape[0], w, dtype=maps.dtype, device=maps.device)
    for r, cols in enumerate(receivers):
        take[r, torch.as_tensor(list(cols), dtype=torch.long, device=maps.device)] = 1.0
    take = take.view(view)
    removed = (maps - out).sum(-1, keepdim=True)                     # (R, ..., 1)
    held = (out * take).sum(-1, keepdim=True)
    # where the receivers hold some mass, add in proportion to it; else share it equally
    share = torch.where(held > 1e-12, out * take / held.clamp_min(1e-12), take / take.sum(-1, keepdim=True))
    return out + removed * share


def shift_columns(maps: torch.Tensor, columns: Sequence[Sequence[int]], shift: int, *,
                  frame_axis: int = _FRAME_AXIS, keep_sums: bool = True) -> torch.Tensor:
    """Slide the token ``columns`` of each map by ``shift`` steps along ``frame_axis``; a new tensor.

    ``maps`` ``(R, ..., W)`` (cross maps ``(R, H, N', P, W)``: ``frame_axis`` 2), one column list per
    leading row: ``out[..., t, ..., k] = maps[..., t - shift, ..., k]`` where ``0 <= t - shift < N'``,
    else 0. With ``keep_sums`` each query's other columns are scaled by ``(total - new) / (total - old)``
    (``old``/``new``: the phrase's mass there before/after), so every query keeps its total; a query
    whose other columns hold nothing keeps them as they are. ``shift = 0`` returns a copy.
    """
    if len(columns) != maps.shape[0]:
        raise ValueError(f"shift_columns needs one column list per map ({maps.shape[0]}), got {len(columns)}")
    axis = frame_axis % maps.dim()
    if axis in (0, maps.dim() - 1):
        raise ValueError(f"frame_axis={frame_axis} must be an inner axis of maps with shape {tuple(maps.shape)}")
    if shift == 0:
        return maps.clone()
    n, w = maps.shape[axis], maps.shape[-1]
    chosen = torch.zeros(maps.shape[0], w, dtype=maps.dtype, device=maps.device)
    for r, cols in enumerate(columns):
        chosen[r, torch.as_tensor(list(cols), dtype=torch.long, device=maps.device)] = 1.0
    chosen = chosen.view(maps.shape[0], *(1,) * (maps.dim() - 2), w)
    phrase = maps * chosen
    moved = torch.zeros_like(phrase)
    if abs(shift) < n:
        src = phrase.narrow(axis, max(0, -shift), n - abs(shift))
        moved.narrow(axis, max(0, shift), n - abs(shift)).copy_(src)
    rest = maps - phrase
    if keep_sums:
        old, new = phrase.sum(-1, keepdim=True), moved.sum(-1, keepdim=True)
        rest_sum = rest.sum(-1, keepdim=True)
        scale = torch.where(rest_sum > 1e-12, (rest_sum + old - new).clamp_min(0.0) / rest_sum.clamp_min(1e-12),
                            torch.ones_like(rest_sum))
        rest = rest * scale
    return rest + moved


def shift_temporal(maps: torch.Tensor, parts: Sequence[int], shift: int) -> torch.Tensor:
    """Temporal self-attention ``(B, P, H, N', N')`` with the maps of ``parts`` slid by ``shift`` frames
    along both the query and the key axis: ``out[t, s] = maps[t - shift, s - shift]`` (queries before
    the start or past the end take the nearest row); each moved row is re-normalised to its own sum
    (keys slid past an end lose their weight). ``shift = 0`` returns a copy."""
    out = maps.clone()
    if shift == 0 or not len(parts):
        return out
    n = maps.shape[-1]
    rows = torch.tensor(list(parts), dtype=torch.long, device=maps.device)
    sel = maps.index_select(1, rows)                                        # (B, p, H, N', N')
    q = (torch.arange(n, device=maps.device) - shift).clamp(0, n - 1)
    sel = sel.index_select(-2, q)                                           # query t <- t - shift
    moved = torch.zeros_like(sel)
    if abs(shift) < n:
        moved.narrow(-1, max(0, shift), n - abs(shift)).copy_(sel.narrow(-1, max(0, -shift), n - abs(shift)))
    total, kept = sel.sum(-1, keepdim=True), moved.sum(-1, keepdim=True)
    moved = torch.where(kept > 1e-12, moved * total / kept.clamp_min(1e-12), sel)
    out[:, rows] = moved
    return out


def seeded_noise(seed: int, shape: Sequence[int], full_frames: int | None = None) -> torch.Tensor:
    """``(B, N', P, Dz)`` standard-normal noise, sample ``b`` from ``torch.Generator(seed + b)``, drawn at
    ``full_frames`` latent frames and cropped to ``N'`` (default: the skeletons' 196 / 4 = 49), exactly as
    :meth:`salad_core.pipeline.SaladPipeline.make_noise` draws it for ``seed=seed``."""
    from salad_core.skeleton import get_skeleton

    b, n, p, dz = (int(v) for v in shape)
    if full_frames is None:
        sk = get_skeleton()
        full_frames = sk.max_length // sk.unit_length
    full_frames = max(int(full_frames), n)
    out = []
    for i in range(b):
        g = torch.Generator().manual_seed(int(seed) + i)
        out.append(torch.randn(full_frames, p, dz, generator=g)[:n])
    return torch.stack(out)
