"""What ``salad bench`` measures and how much: the constants of the runs, the table's row and the plans.

:class:`Plan` says how many steps, rounds and seconds each section spends (quick or full);
:class:`Case` is a denoiser configuration to time; :class:`Row` is one line of the table.
"""
from __future__ import annotations

from dataclasses import dataclass

from salad_core.models.denoiser import DenoiserConfig
from salad_core.skeleton import get_skeleton

__all__ = ["SKELETON", "MOTION_FRAMES", "SHORT_FRAMES", "SAMPLING_STEPS", "GUIDANCE", "PROMPT_TOKENS", "BATCHES",
           "SECTIONS", "OPTIONAL_SECTIONS", "COLUMNS", "SOURCE", "SWAPPED", "REFINED", "Row", "Case", "Plan"]

SKELETON = get_skeleton("humanml3d")
MOTION_FRAMES = SKELETON.max_length            # 196 frames = 49 latent frames
SHORT_FRAMES = 120                             # the CLI's default length (6 s at 20 fps)
SAMPLING_STEPS = 50                            # DDIM steps of the paper's sampler
GUIDANCE = 7.5                                 # classifier-free guidance (paper default)
#: Valid tokens of the random prompts (start/end tokens included), drawn uniformly: HumanML3D captions
#: are about 12 words. The rest of the padded width (CLIP: 77) is masked padding, which the denoiser
#: does not attend to (:func:`salad_core.models.kernels.trim_masked_keys`).
PROMPT_TOKENS = (8, 24)
BATCHES = (1, 32)
SECTIONS = ("memory", "overheads", "speed", "training")
#: Sections run only when asked for by name.
OPTIONAL_SECTIONS = ("compile", "train", "realtime")
COLUMNS = ["section", "measure", "setting", "value", "unit", "reference", "ratio", "note"]

SOURCE = "a man walks forward and waves his right hand"
SWAPPED = "a man walks forward and raises his right hand"          # same word count: word swap
REFINED = "a man slowly walks forward and waves his right hand high"


@dataclass
class Row:
    """One line of the table: ``value`` in ``unit``, optionally against a ``reference`` (``ratio``)."""

    section: str
    measure: str
    setting: str
    value: float
    unit: str
    reference: float | None = None
    ratio: float | None = None
    note: str = ""


@dataclass(frozen=True)
class Case:
    """A denoiser configuration to time, with its text length."""

    name: str               # "paper" or "default"
    config: DenoiserConfig
    tokens: int             # W, text tokens per prompt


@dataclass(frozen=True)
class Plan:
    """How much is timed; :meth:`for_mode` gives the quick and the full plans."""

    quick: bool
    b1_steps: int                    # timed DDIM steps at batch 1 (after one warm-up step)
    b32_steps: int                   # timed DDIM steps at batch 32 (extrapolated to 50 if fewer)
    b32_warmup: bool                 # a warm-up step at batch 32 too (quick: the batch-1 run warmed the model)
    matmul_time: float               # seconds of repeated timing per GEMM shape (best rate kept)
    edit_frames: int                 # motion length of the overhead and memory runs
    edit_steps: int                  # DDIM steps of the overhead runs
    edit_rounds: int                 # interleaved rounds (median)
    train_steps: int                 # timed optimiser steps (after train_warmup)
    train_warmup: int
    b1_pairs: int = 3                # roofline: steps timed side by side with their matrix products (batch 1)
    b32_pairs: int = 1               # the same at batch 32
    memory_steps: tuple[int, ...] = (50, 200)
    extras: bool = False             # full only: forward variants and the naive Algorithm 1 reference

    @classmethod
    def for_mode(cls, quick: bool) -> "Plan":
        if quick:
            return cls(True, b1_steps=5, b32_steps=1, b32_warmup=False, matmul_time=0.05, edit_frames=SHORT_FRAMES,
                       edit_steps=10, edit_rounds=1, train_steps=1, train_warmup=1)
        return cls(False, b1_steps=SAMPLING_STEPS, b32_steps=SAMPLING_STEPS, b32_warmup=True, matmul_time=0.3,
                   edit_frames=MOTION_FRAMES, edit_steps=SAMPLING_STEPS, edit_rounds=3, train_steps=5,
                   train_warmup=2, b1_pairs=20, b32_pairs=5, extras=True)
