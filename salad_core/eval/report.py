"""Where the reproduction notebooks' building blocks used to live (before issue 26); kept so that
``from salad_core.eval.report import ...`` goes on working. Each name now lives in the module of its job:

- published numbers: :mod:`salad_core.eval.paper_tables` (``PAPER_TABLE1``, ``paper_table1``,
  ``PAPER_DENOISER_ABLATIONS``, ``paper_denoiser_ablations``);
- held-out procedural data and a notebook's data and evaluator: :mod:`salad_core.eval.heldout`;
- the official release: :mod:`salad_core.eval.official`;
- length-bucketed generation: :mod:`salad_core.eval.length_buckets`;
- KeyMotion round trips: :mod:`salad_core.eval.keymotion_roundtrip`.

New code should import from those modules.
"""
from __future__ import annotations

from .heldout import evaluation_data, heldout_corpus, procedural_eval_corpus
from .keymotion_roundtrip import Infilling, KeyframeRoundTrip, infill_from_keyframes, keyframe_roundtrip
from .length_buckets import BucketedOutput, LengthBucketed, length_groups
from .official import official_salad_pipeline, read_official_options
from .paper_tables import (
    PAPER_DENOISER_ABLATIONS,
    PAPER_TABLE1,
    PAPER_TABLE1_DEFAULT_ROWS,
    paper_denoiser_ablations,
    paper_table1,
)

__all__ = [
    "PAPER_TABLE1",
    "PAPER_TABLE1_DEFAULT_ROWS",
    "paper_table1",
    "PAPER_DENOISER_ABLATIONS",
    "paper_denoiser_ablations",
    "heldout_corpus",
    "procedural_eval_corpus",
    "evaluation_data",
    "read_official_options",
    "official_salad_pipeline",
    "LengthBucketed",
    "BucketedOutput",
    "length_groups",
    "KeyframeRoundTrip",
    "Infilling",
    "keyframe_roundtrip",
    "infill_from_keyframes",
]
