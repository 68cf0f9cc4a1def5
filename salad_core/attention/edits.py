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

Specs compose in order, Prompt-to-Prompt style: at most one *replacement* (WordSwap or Refine)
builds the base map from ``M`` and ``M*``; *modifiers* (Reweight, Mirror) then change the map in
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
    "MIRROR_GROUPS",
    "REWEIGHT_RANGE",
    "mirror_permutation",
    "mirror_parts",
    "reweight_columns",
    "map_columns",
    "refine_columns",
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
    def window(self) -> tuple[float, float]:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

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

    @property
    def window(self) -> tuple[float, float]:
        return self.steps

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

    @property
    def window(self) -> tuple[float, float]:
        return self.steps

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """:func:`reweight_columns` of the words' token columns in each prompt of ``maps_of``."""
        columns = []
        for b in range(len(maps_of)):
            cols: list[int] = []
            for word in self.words:
                try:
                    cols += maps_of.word_columns(b, word)
                except ValueError:
                    raise ValueError(f"Reweight word {word!r} is not in the prompt {maps_of.prompts[b]!r}; "
                                     f"its words are {maps_of.words[b]}") from None
            columns.append(cols)
        return lambda maps, own: reweight_columns(maps, columns, self.scale, per_row=True)


@dataclass(frozen=True)
class Mirror(EditSpec):
    """Attention mirroring (supplement B): ``M_hat[j] = M[C(j)]`` for the body parts of ``parts``.

    ``parts``: ``"legs"`` (official ``lower``), ``"arms"`` (``upper``) or ``"all"``; counterparts
    come from :data:`salad_core.skeleton.PART_MIRROR`. Root, spine and head map to themselves.
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

    @property
    def window(self) -> tuple[float, float]:
        return self.steps

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
        kinds = (self.kinds,) if isinstance(self.kinds, str) else tuple(self.kinds)
        if not kinds or any(k not in _SELF_KINDS for k in kinds) or len(set(kinds)) != len(kinds):
            raise ValueError(f"InjectSelfAttention.kinds={self.kinds!r} must be distinct entries of {_SELF_KINDS}")
        object.__setattr__(self, "kinds", kinds)

    @property
    def window(self) -> tuple[float, float]:
        return self.steps

    @property
    def site_kinds(self) -> tuple[str, ...]:
        return self.kinds

    def bind(self, source: "TokenInfo", target: "TokenInfo", width: int, *, maps_of: "TokenInfo") -> EditKernel:
        """The source's self-attention maps, as they are, for the edited rows."""
        return lambda maps, own: maps


def validate_edits(edits: EditSpec | Sequence[EditSpec] | None) -> tuple[EditSpec, ...]:
    """A spec or a sequence of specs -> a validated tuple (at most one replacement, first)."""
    if edits is None:
        return ()
    if isinstance(edits, EditSpec):
        edits = (edits,)
    if isinstance(edits, (str, bytes)) or not isinstance(edits, Sequence):
        raise TypeError(f"edits must be an EditSpec or a sequence of them (WordSwap, Refine, Reweight, Mirror, "
                        f"InjectSelfAttention), got {type(edits).__name__}")
    out = tuple(edits)
    for i, e in enumerate(out):
        if not isinstance(e, EditSpec) or type(e) is EditSpec:
            raise TypeError(f"edits[{i}] must be WordSwap, Refine, Reweight, Mirror or InjectSelfAttention, got {e!r}")
    replacements = [e for e in out if e.role == "replace"]
    if len(replacements) > 1:
        raise ValueError(f"at most one replacement edit (WordSwap or Refine) per edit, got {replacements}")
    if replacements and any(e.role == "modify" for e in out[:out.index(replacements[0])]):
        raise ValueError("the replacement edit (WordSwap or Refine) must come before the modifiers "
                         "(Reweight, Mirror): it builds the map they modify")
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
