"""The T2M evaluation protocol: score a generator (or the real motions) over replications.

One *replication* (Guo et al. 2022; ``humanml3d_eval_facts`` §5) iterates the test split in a
fresh random order and cuts it into batches of 32 (:mod:`salad_core.eval.batches`). Each item
carries a random caption of its clip and a random crop whose length is a multiple of 4. For every
batch the generator is asked for motions with exactly those captions and lengths. The captions,
the real motions and the generated motions are all embedded with the evaluator. From the
embeddings we get:

- R-precision top-1/2/3 and MM-Dist: each caption against the generated motions of its batch;
- FID: generated vs real motion embeddings of the same batches (MoMask / SALAD);
- Diversity: 300 random pairs of generated motions (100 when there are at most 300);
- MultiModality: the first ``mm_prompts`` (100) captions, each generated ``mm_repeats`` (30)
  times, 10 pairs. These generations are separate from the main pass (MoMask/SALAD reuse the
  30th sample for the other metrics; the difference only matters in the order of draws).

The "Real motion" row scores the real motions as if they were generated. Its FID compares each
replication's real embeddings with an independent pass over the split (other crops and
captions), as T2M's ground-truth row does (0.002 on HumanML3D).

Replications (20) are reported as ``mean ± 1.96 std / sqrt(R)`` (:func:`~salad_core.eval.metrics.mean_ci`).
Each :class:`~salad_core.eval.settings.EvalResult` records the settings that produced it. Tables
are made by :mod:`salad_core.eval.tables`, the paper's own numbers live in
:mod:`salad_core.eval.paper_tables` and the CFG-sweep figure (SALAD Fig. 5) in
:func:`salad_viz.plots.plot_cfg_sweep`.

Any object with the generator call below can be evaluated (``SaladPipeline``, its ablations,
``KeyMotionPipeline``)::

    out = gen(prompts, lengths=lengths, seed=seed, guidance_scale=w, num_steps=steps)
    out.features   # (B, N, D) de-normalised features, zero past each length
    out.lengths    # (B,) frames
"""
from __future__ import annotations

import logging
import math
from dataclasses import asdict
from os import PathLike
from typing import Any, Iterable, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np
import torch

from salad_core.skeleton import Skeleton

from . import metrics as M
from .batches import (
    REFERENCE_EPOCH,
    TAG_DIV,
    TAG_GEN,
    TAG_MM,
    TAG_MMPAIRS,
    RealBatch,
    batches_for,
    derived_rng,
    derived_seed,
    evaluation_dataset,
    motion_embeddings,
    num_batches,
    skeleton_of,
    text_embeddings,
)
from .settings import DEFAULT_CFG_SCALES, METRICS, REAL_NAME, EvalResult, EvalSettings

__all__ = [
    "MotionGenerator",
    "evaluate_real",
    "evaluate_generator",
    "cfg_sweep",
    "run_ablation",
]

logger = logging.getLogger(__name__)


@runtime_checkable
class MotionGenerator(Protocol):
    """What the protocol needs from a text-to-motion model.

    ``__call__`` returns an object with ``features`` ``(B, N, D)`` (de-normalised, numpy or
    tensor, zero past each length, ``N >= max(lengths)``) and ``lengths`` ``(B,)``.
    ``SaladPipeline`` and ``KeyMotionPipeline`` satisfy it; ``solver=`` is passed only when
    :attr:`EvalSettings.solver` is set.
    """

    def __call__(self, prompts: Sequence[str], lengths: Sequence[int] | None = None, seed: int = 0,
                 guidance_scale: float = 7.5, num_steps: int = 50) -> Any: ...


# ------------------------------------------------------------------------------------ helpers
def _generate(gen, captions: list[str], lengths: np.ndarray, seed: int, settings: EvalSettings,
              dim: int) -> np.ndarray:
    """Call ``gen`` and return its features ``(B, max(lengths), D)`` zeroed past each length."""
    kwargs = dict(lengths=[int(n) for n in lengths], seed=seed, guidance_scale=float(settings.guidance_scale),
                  num_steps=int(settings.num_steps))
    if settings.solver is not None:
        kwargs["solver"] = settings.solver
    out = gen(list(captions), **kwargs)
    feats = getattr(out, "features", None)
    if feats is None:
        raise TypeError(f"the generator returned {type(out).__name__}, which has no .features (B, N, D)")
    feats = feats.detach().cpu().numpy() if torch.is_tensor(feats) else np.asarray(feats)
    b, n_max = len(captions), int(lengths.max())
    if feats.ndim != 3 or feats.shape[0] != b or feats.shape[2] != dim or feats.shape[1] < n_max:
        raise ValueError(f"generator features have shape {feats.shape}; expected ({b}, N >= {n_max}, {dim})")
    got = np.asarray(getattr(out, "lengths", lengths)).reshape(-1)
    if got.shape != (b,) or (got != lengths).any():
        raise ValueError(f"the generator returned lengths {got.tolist()} for requested {lengths.tolist()}")
    feats = feats[:, :n_max].astype(np.float32)
    if not np.isfinite(feats).all():
        raise ValueError("the generator returned NaN or infinite features")
    feats = feats * (np.arange(n_max)[None, :, None] < lengths[:, None, None])  # SALAD zero-masks past m_len
    return feats


def _diversity_pairs(n: int, wanted: int) -> int:
    # MoMask/SALAD: 300 pairs when there are more than 300 samples, else 100; quick runs may have
    # even fewer samples, then every sample is used once
    return wanted if n > wanted else min(100, n - 1)


def _result_settings(settings: EvalSettings, kind: str, samples: int, dataset_root, evaluator,
                     weights: str | None, div_pairs: int) -> dict[str, Any]:
    s = asdict(settings)
    s.update(kind=kind, samples=int(samples), diversity_pairs=int(div_pairs), data=str(dataset_root),
             evaluator=getattr(evaluator, "source", None), weights=weights)
    if kind == "real":
        # nothing is generated for the real row
        s.update(num_steps=None, guidance_scale=None, solver=None, mm=False, weights=None)
    return s


def _generator_source(gen) -> str | None:
    src = getattr(gen, "source", None)
    return str(src) if src is not None else type(gen).__name__


# ---------------------------------------------------------------------------------- evaluation
@torch.no_grad()
def evaluate_real(dataset_root: str | PathLike, evaluator, settings: EvalSettings | None = None,
                  name: str = REAL_NAME) -> EvalResult:
    """The "Real motion" row: the split's real motions scored as if they were generated.

    Parameters
    ----------
    dataset_root : path
        HumanML3D-layout folder (``new_joint_vecs``, ``texts``, ``<split>.txt``).
    evaluator : T2MEvaluator
        With bundled word vectors and its own mean/std.
    settings : EvalSettings, optional
        Default: the full protocol. Generation settings are ignored (recorded as None).
    name : str

    Returns
    -------
    EvalResult
        R-precision, FID (against an independent pass over the same items: other crops and
        captions), MM-Dist, Diversity.
    """
    settings = settings or EvalSettings()
    evaluator.eval()
    sk = skeleton_of(evaluator)
    ds = evaluation_dataset(dataset_root, settings, sk)
    vals: dict[str, list[float]] = {m: [] for m in METRICS if m != "MultiModality"}
    samples = div_pairs = 0
    for r in range(settings.replications):
        batches = batches_for(ds, settings, r, r)
        text = np.concatenate([text_embeddings(evaluator, b.tokens) for b in batches])
        real = np.concatenate([motion_embeddings(evaluator, b.motions, b.lengths) for b in batches])
        # the reference: the same items (same order, so a capped --max-samples run compares like with
        # like, as the generator rows do) with independent crops and captions (another epoch)
        ref_batches = batches_for(ds, settings, REFERENCE_EPOCH + r, r)
        ref = np.concatenate([motion_embeddings(evaluator, b.motions, b.lengths) for b in ref_batches])
        samples, div_pairs = len(real), _diversity_pairs(len(real), settings.diversity_pairs)
        _score(vals, text, real, real_ref=ref, div_pairs=div_pairs, settings=settings,
               rng=derived_rng(settings, TAG_DIV, r))
        logger.info("%s: replication %d/%d: %s", name, r + 1, settings.replications,
                    ", ".join(f"{k} {v[-1]:.4f}" for k, v in vals.items()))
    return EvalResult(name, {k: tuple(v) for k, v in vals.items()},
                      _result_settings(settings, "real", samples, dataset_root, evaluator, None, div_pairs))


def _score(vals: dict[str, list[float]], text: np.ndarray, motion: np.ndarray, real_ref: np.ndarray, div_pairs: int,
           settings: EvalSettings, rng: np.random.Generator) -> None:
    top = M.r_precision(text, motion, top_k=3, batch_size=settings.batch_size)
    for k, v in zip(METRICS[:3], top):
        vals[k].append(float(v))
    vals["FID"].append(M.fid(real_ref, motion))
    vals["MM-Dist"].append(M.matching_score(text, motion))
    vals["Diversity"].append(M.diversity(motion, n_pairs=div_pairs, rng=rng))


@torch.no_grad()
def evaluate_generator(gen: MotionGenerator, dataset_root: str | PathLike, evaluator,
                       settings: EvalSettings | None = None, name: str = "SALAD", weights: str | None = None,
                       progress: bool = False) -> EvalResult:
    """Evaluate a generator with the T2M protocol (see the module docstring).

    Parameters
    ----------
    gen : MotionGenerator
        E.g. ``SaladPipeline.from_pretrained()``.
    dataset_root : path
        HumanML3D-layout folder.
    evaluator : T2MEvaluator
        With bundled word vectors and its own mean/std.
    settings : EvalSettings, optional
        Default: the full protocol (20 replications, MultiModality on, w = 7.5, 50 steps).
    name : str
        Row label.
    weights : str, optional
        Recorded as the generator's weights (default: ``gen.source`` if it has one, else its type).
    progress : bool
        Show a progress bar over the generation calls.

    Returns
    -------
    EvalResult
        Per-replication R-precision top-1/2/3, FID, MM-Dist, Diversity (and MultiModality).
    """
    settings = settings or EvalSettings()
    evaluator.eval()
    sk = skeleton_of(evaluator)
    ds = evaluation_dataset(dataset_root, settings, sk)
    weights = weights if weights is not None else _generator_source(gen)
    metrics_here = [m for m in METRICS if settings.mm or m != "MultiModality"]
    vals: dict[str, list[float]] = {m: [] for m in metrics_here}
    n_batches = num_batches(len(ds), settings)
    n_mm = min(settings.mm_prompts, n_batches * settings.batch_size) if settings.mm else 0
    total_calls = settings.replications * (n_batches + settings.mm_repeats * math.ceil(n_mm / settings.batch_size))
    from tqdm.auto import tqdm

    bar = tqdm(total=total_calls, desc=f"eval {name}", unit="batch", disable=not progress)
    samples = div_pairs = 0
    try:
        for r in range(settings.replications):
            batches = batches_for(ds, settings, r, r)
            text, real, fake = [], [], []
            for i, b in enumerate(batches):
                feats = _generate(gen, b.captions, b.lengths, derived_seed(settings, TAG_GEN, r, i), settings,
                                  sk.feature_dim)
                text.append(text_embeddings(evaluator, b.tokens))
                real.append(motion_embeddings(evaluator, b.motions, b.lengths))
                fake.append(motion_embeddings(evaluator, feats, b.lengths))
                bar.update()
            text, real, fake = np.concatenate(text), np.concatenate(real), np.concatenate(fake)
            samples, div_pairs = len(fake), _diversity_pairs(len(fake), settings.diversity_pairs)
            _score(vals, text, fake, real_ref=real, div_pairs=div_pairs, settings=settings,
                   rng=derived_rng(settings, TAG_DIV, r))
            if settings.mm:
                vals["MultiModality"].append(_multimodality(gen, batches, n_mm, settings, evaluator, sk, r, bar))
            logger.info("%s: replication %d/%d: %s", name, r + 1, settings.replications,
                        ", ".join(f"{k} {v[-1]:.4f}" for k, v in vals.items()))
    finally:
        bar.close()
    return EvalResult(name, {k: tuple(v) for k, v in vals.items()},
                      _result_settings(settings, "generator", samples, dataset_root, evaluator, weights, div_pairs))


def _multimodality(gen, batches: list[RealBatch], n_mm: int, settings: EvalSettings, evaluator, sk: Skeleton,
                   r: int, bar) -> float:
    """``mm_repeats`` generations of the replication's first ``n_mm`` captions -> MultiModality."""
    caps = [c for b in batches for c in b.captions][:n_mm]
    lens = np.concatenate([b.lengths for b in batches])[:n_mm]
    bs = settings.batch_size
    emb = np.empty((n_mm, settings.mm_repeats, evaluator.config.dim_coemb))   # (texts, repeats, C)
    for k in range(settings.mm_repeats):
        for start in range(0, n_mm, bs):
            sl = slice(start, min(start + bs, n_mm))
            feats = _generate(gen, caps[sl], lens[sl], derived_seed(settings, TAG_MM, r, k, start), settings,
                              sk.feature_dim)
            emb[sl, k] = motion_embeddings(evaluator, feats, lens[sl])
            bar.update()
    return M.multimodality(emb, n_pairs=settings.mm_pairs, rng=derived_rng(settings, TAG_MMPAIRS, r))


def cfg_sweep(gen: MotionGenerator, dataset_root: str | PathLike, evaluator, settings: EvalSettings | None = None,
              scales: Iterable[float] = DEFAULT_CFG_SCALES, name: str = "SALAD", include_real: bool = True,
              weights: str | None = None, progress: bool = False) -> list[EvalResult]:
    """Evaluate ``gen`` at every CFG weight ``w`` in ``scales`` (SALAD Fig. 5, supplement Table 1).

    Parameters
    ----------
    scales : iterable of float
        Default ``1.5, 2.5, ..., 12.5``.
    include_real : bool
        Put the "Real motion" row first.

    Returns
    -------
    list of EvalResult
        The real row (if asked), then one result per ``w`` named ``"{name} w={w:g}"``, each with
        its own ``guidance_scale`` in ``settings``.
    """
    settings = settings or EvalSettings()
    scales = [float(w) for w in scales]
    if not scales:
        raise ValueError("scales is empty; give at least one CFG weight, e.g. DEFAULT_CFG_SCALES")
    out = [evaluate_real(dataset_root, evaluator, settings)] if include_real else []
    for w in scales:
        out.append(evaluate_generator(gen, dataset_root, evaluator, settings.replace(guidance_scale=w),
                                      name=f"{name} w={w:g}", weights=weights, progress=progress))
    return out


def run_ablation(generators: Mapping[str, MotionGenerator], dataset_root: str | PathLike, evaluator,
                 settings: EvalSettings | None = None, include_real: bool = True,
                 progress: bool = False) -> list[EvalResult]:
    """Evaluate several generators (e.g. SALAD and its ablations, KeyMotion) with the same settings.

    Returns the real row (if asked) and one result per generator, in the mapping's order.
    """
    if not generators:
        raise ValueError("generators is empty; pass {name: generator}")
    settings = settings or EvalSettings()
    out = [evaluate_real(dataset_root, evaluator, settings)] if include_real else []
    for name, gen in generators.items():
        out.append(evaluate_generator(gen, dataset_root, evaluator, settings, name=name, progress=progress))
    return out

