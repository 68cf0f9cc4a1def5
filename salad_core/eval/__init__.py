"""Evaluation: the T2M evaluator networks, their text input and the text-to-motion metrics.

- :mod:`salad_core.eval.metrics`: R-precision, MM-Dist, FID, Diversity, MultiModality, MPJPE,
  mean ± 95% CI (pure numpy functions on embeddings / joints).
- :mod:`salad_core.eval.t2m`: :class:`T2MEvaluator` (official ``finest.tar`` compatible) and
  its config, checkpoint helpers and the contrastive training loss.
- :mod:`salad_core.eval.word_vectorizer`: ``word/POS`` tokens -> word vectors + POS one-hots.
"""
from .metrics import (
    activation_statistics,
    diversity,
    euclidean_distance_matrix,
    fid,
    frechet_distance,
    matching_score,
    mean_ci,
    mpjpe,
    multimodality,
    r_precision,
)
from .t2m import (
    EvaluatorConfig,
    MatchingLoss,
    MotionEncoderBiGRUCo,
    MovementConvEncoder,
    T2MEvaluator,
    TextEncoderBiGRUCo,
    load_evaluator,
    matching_loss,
    official_paths,
    save_evaluator,
)
from .word_vectorizer import POS_ENUMERATOR, VIP_LISTS, UnsafePickleError, WordVectorizer, load_plain_pickle

__all__ = [
    "activation_statistics", "diversity", "euclidean_distance_matrix", "fid", "frechet_distance",
    "matching_score", "mean_ci", "mpjpe", "multimodality", "r_precision",
    "EvaluatorConfig", "MatchingLoss", "MotionEncoderBiGRUCo", "MovementConvEncoder", "T2MEvaluator",
    "TextEncoderBiGRUCo", "load_evaluator", "matching_loss", "official_paths", "save_evaluator",
    "POS_ENUMERATOR", "VIP_LISTS", "UnsafePickleError", "WordVectorizer", "load_plain_pickle",
]
