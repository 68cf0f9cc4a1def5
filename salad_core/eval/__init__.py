"""Evaluation: the T2M evaluator networks, their text input and the text-to-motion metrics.

- :mod:`salad_core.eval.metrics`: R-precision, MM-Dist, FID, Diversity, MultiModality, MPJPE,
  mean ± 95% CI (pure numpy functions on embeddings / joints).
- :mod:`salad_core.eval.t2m`: :class:`T2MEvaluator` (official ``finest.tar`` compatible) and
  its config, checkpoint helpers and the contrastive training loss.
- :mod:`salad_core.eval.word_vectorizer`: ``word/POS`` tokens -> word vectors + POS one-hots.
- :mod:`salad_core.eval.vocab`: MiniLM-derived word vectors for our own evaluator's vocabulary.
- :mod:`salad_core.eval.protocol`: the T2M protocol (replications, "Real motion" row, CFG sweeps,
  ablations) with DataFrame / Markdown / LaTeX / plot outputs.
- :mod:`salad_core.eval.train_evaluator`: train, export and load the small evaluator shipped for
  the procedural corpus (imported lazily: it pulls in the trainer).
- :mod:`salad_core.eval.cli`: ``salad eval``.
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
from .vocab import build_word_vectorizer, corpus_vocabulary, minilm_word_vectors
from .protocol import (
    DEFAULT_CFG_SCALES,
    METRICS,
    EvalResult,
    EvalSettings,
    MotionGenerator,
    cfg_sweep,
    evaluate_generator,
    evaluate_real,
    format_mean_ci,
    paper_cfg_sweep,
    plot_cfg_sweep,
    results_frame,
    run_ablation,
    to_latex,
    to_markdown,
)

__all__ = [
    "activation_statistics", "diversity", "euclidean_distance_matrix", "fid", "frechet_distance",
    "matching_score", "mean_ci", "mpjpe", "multimodality", "r_precision",
    "EvaluatorConfig", "MatchingLoss", "MotionEncoderBiGRUCo", "MovementConvEncoder", "T2MEvaluator",
    "TextEncoderBiGRUCo", "load_evaluator", "matching_loss", "official_paths", "save_evaluator",
    "POS_ENUMERATOR", "VIP_LISTS", "UnsafePickleError", "WordVectorizer", "load_plain_pickle",
    "build_word_vectorizer", "corpus_vocabulary", "minilm_word_vectors",
    "DEFAULT_CFG_SCALES", "METRICS", "EvalResult", "EvalSettings", "MotionGenerator", "cfg_sweep",
    "evaluate_generator", "evaluate_real", "format_mean_ci", "paper_cfg_sweep", "plot_cfg_sweep",
    "results_frame", "run_ablation", "to_latex", "to_markdown",
]
