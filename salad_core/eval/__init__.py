"""Evaluation: the T2M evaluator networks, their text input, the text-to-motion metrics, the
protocol that runs them, its tables and the paper's published numbers. One job per module:

- :mod:`salad_core.eval.metrics`: R-precision, MM-Dist, FID, Diversity, MultiModality, MPJPE,
  mean ± 95% CI (pure numpy functions on embeddings / joints).
- :mod:`salad_core.eval.t2m`: :class:`T2MEvaluator` (official ``finest.tar`` compatible) and
  its config, checkpoint helpers and the contrastive training loss.
- :mod:`salad_core.eval.word_vectorizer`: ``word/POS`` tokens -> word vectors + POS one-hots.
- :mod:`salad_core.eval.vocab`: MiniLM-derived word vectors for our own evaluator's vocabulary.
- :mod:`salad_core.eval.settings`: :class:`EvalSettings`, :class:`EvalResult`, metric names.
- :mod:`salad_core.eval.batches`: the protocol's real test batches, random streams, embeddings.
- :mod:`salad_core.eval.protocol`: the T2M protocol (replications, "Real motion" row, CFG
  sweeps, ablations).
- :mod:`salad_core.eval.tables`: results as a DataFrame, Markdown and LaTeX.
- :mod:`salad_core.eval.paper_tables`: the paper's published numbers (Tables 1-3, supplement
  Tables 1-4), labelled as such.
- :mod:`salad_core.eval.reconstruction`: VAE reconstruction FID / MPJPE (Table 2).
- :mod:`salad_core.eval.physics`, :mod:`salad_core.eval.physics_prompts`: the physical
  plausibility benchmark.
- :mod:`salad_core.eval.guidance_sweep`: the default guidance chosen from one sweep over the T2M
  metrics and the physics benchmark (``salad eval --guidance-sweep``).
- :mod:`salad_core.eval.heldout`: held-out procedural clips; a notebook's data and evaluator.
- :mod:`salad_core.eval.official`: the official SALAD release as a pipeline.
- :mod:`salad_core.eval.length_buckets`: batches denoised in groups of similar length.
- :mod:`salad_core.eval.keymotion_roundtrip`: KeyMotion's keyframe VAE and MMAE on a motion's
  own keyframes.
- :mod:`salad_core.eval.train_evaluator`: train, export and load the small evaluator shipped for
  the procedural corpus (imported lazily: it pulls in the trainer).

The command line ``salad eval`` is :mod:`salad_core.cli.eval`. The CFG-sweep figure (SALAD Fig. 5) is
:func:`salad_viz.plots.plot_cfg_sweep` (salad_core draws nothing).
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
from .settings import DEFAULT_CFG_SCALES, METRICS, EvalResult, EvalSettings
from .protocol import MotionGenerator, cfg_sweep, evaluate_generator, evaluate_real, run_ablation
from .tables import format_mean_ci, results_frame, to_latex, to_markdown
from .paper_tables import paper_cfg_sweep

__all__ = [
    "activation_statistics", "diversity", "euclidean_distance_matrix", "fid", "frechet_distance",
    "matching_score", "mean_ci", "mpjpe", "multimodality", "r_precision",
    "EvaluatorConfig", "MatchingLoss", "MotionEncoderBiGRUCo", "MovementConvEncoder", "T2MEvaluator",
    "TextEncoderBiGRUCo", "load_evaluator", "matching_loss", "official_paths", "save_evaluator",
    "POS_ENUMERATOR", "VIP_LISTS", "UnsafePickleError", "WordVectorizer", "load_plain_pickle",
    "build_word_vectorizer", "corpus_vocabulary", "minilm_word_vectors",
    "DEFAULT_CFG_SCALES", "METRICS", "EvalResult", "EvalSettings", "MotionGenerator", "cfg_sweep",
    "evaluate_generator", "evaluate_real", "format_mean_ci", "paper_cfg_sweep",
    "results_frame", "run_ablation", "to_latex", "to_markdown",
]

