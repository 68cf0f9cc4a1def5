"""The T2M evaluation protocol: replications, the "Real motion" row, CFG sweeps, ablations, tables.

One *replication* (Guo et al. 2022; ``humanml3d_eval_facts`` §5) iterates the test split in a
fresh random order and cuts it into batches of 32. Each item carries a random caption of its
clip and a random crop whose length is a multiple of 4 (the T2M loader, here
:class:`~salad_core.data.dataset.MotionTextDataset`). For every batch the generator is asked for
motions with exactly those captions and lengths. The captions, the real motions and the
generated motions are all embedded with the evaluator. From the embeddings we get:

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
Each :class:`EvalResult` records the settings that produced it. :func:`results_frame` turns
results into a pandas DataFrame. :func:`to_markdown`, :func:`to_latex` and
:func:`plot_cfg_sweep` (SALAD Fig. 5: FID and R-precision against the CFG weight ``w``) export
that frame. The paper's own numbers come only from :func:`paper_cfg_sweep`, and they are
labelled as the paper's.

Any object with the generator call below can be evaluated (``SaladPipeline``, its ablations,
``KeyMotionPipeline``)::

    out = gen(prompts, lengths=lengths, seed=seed, guidance_scale=w, num_steps=steps)
    out.features   # (B, N, D) de-normalised features, zero past each length
    out.lengths    # (B,) frames
"""
from __future__ import annotations

import logging
import math
from dataclasses import asdict, dataclass, field, replace
from os import PathLike
from typing import Any, Iterable, Mapping, Protocol, Sequence, runtime_checkable

import numpy as np
import pandas as pd
import torch

from salad_core.skeleton import Skeleton, get_skeleton

from . import metrics as M

__all__ = [
    "MotionGenerator",
    "EvalSettings",
    "EvalResult",
    "RealBatch",
    "METRICS",
    "REAL_NAME",
    "DEFAULT_CFG_SCALES",
    "real_batches",
    "evaluate_real",
    "evaluate_generator",
    "cfg_sweep",
    "run_ablation",
    "results_frame",
    "format_mean_ci",
    "to_markdown",
    "to_latex",
    "plot_cfg_sweep",
    "paper_cfg_sweep",
]

logger = logging.getLogger(__name__)

#: Metric columns, in table order.
METRICS = ("R-precision top-1", "R-precision top-2", "R-precision top-3", "FID", "MM-Dist", "Diversity",
           "MultiModality")
#: Suffix of the confidence half-width column of a metric.
CI_SUFFIX = " ±"
#: Direction marks of the paper's tables (higher, lower, closer to real is better).
_ARROWS = {"R-precision top-1": "↑", "R-precision top-2": "↑", "R-precision top-3": "↑", "FID": "↓",
           "MM-Dist": "↓", "Diversity": "→", "MultiModality": "↑"}
_LATEX_ARROWS = {"↑": r"$\uparrow$", "↓": r"$\downarrow$", "→": r"$\rightarrow$"}
#: Row name of the real-motion reference.
REAL_NAME = "Real motion"
#: The CFG weights of SALAD Fig. 5 / supplement Table 1: 1.5, 2.5, ..., 12.5.
DEFAULT_CFG_SCALES = tuple(float(w) for w in np.arange(1.5, 13.0, 1.0))
#: Settings columns of :func:`results_frame`, in order.
SETTING_COLUMNS = ("kind", "split", "batch_size", "replications", "samples", "mm", "mm_prompts", "mm_repeats",
                   "diversity_pairs", "num_steps", "guidance_scale", "solver", "seed", "max_samples", "quick",
                   "weights", "evaluator", "data")
# Seed-sequence tags keep the random streams of the protocol apart.
_TAG_ORDER, _TAG_GEN, _TAG_MM, _TAG_DIV, _TAG_MMPAIRS, _TAG_REF = range(6)
#: Data-loader epoch offset of the independent reference pass of the real row.
_REFERENCE_EPOCH = 1_000_000


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


# ----------------------------------------------------------------------------------- settings
@dataclass(frozen=True)
class EvalSettings:
    """How one evaluation is run; recorded with every result."""

    split: str = "test"                 # split file stem of the dataset
    batch_size: int = 32                # R-precision batch (32 in every published table)
    replications: int = 20              # repetitions of the whole protocol (mean ± 95% CI over them)
    mm: bool = True                     # compute MultiModality (extra mm_prompts x mm_repeats generations)
    mm_prompts: int = 100               # captions used for MultiModality (T2M: 100; MoMask/SALAD: 96)
    mm_repeats: int = 30                # generations per MultiModality caption
    mm_pairs: int = 10                  # pairs of generations compared per caption
    diversity_pairs: int = 300          # Diversity pairs (100 when there are at most this many samples)
    num_steps: int = 50                 # sampler steps given to the generator
    guidance_scale: float = 7.5         # CFG weight w given to the generator (paper default 7.5)
    solver: str | None = None           # scheduler name given to the generator (None: its default, not passed)
    seed: int = 0                       # seeds crops, captions, batch order, noise and metric draws
    max_samples: int | None = None      # cap on samples per replication (quick mode); None: whole split
    quick: bool = False                 # marks a quick (non-protocol) run in every output

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ValueError(f"EvalSettings.{name}={getattr(self, name)!r} is invalid; {allowed}")

        def is_int(v: Any) -> bool:
            return isinstance(v, (int, np.integer)) and not isinstance(v, bool)

        need(isinstance(self.split, str) and bool(self.split.strip()), "split", "use a split name such as 'test'")
        need(is_int(self.batch_size) and self.batch_size >= 2, "batch_size", "use an int >= 2 (32 for the protocol)")
        for name in ("replications", "mm_prompts", "mm_pairs", "diversity_pairs", "num_steps"):
            need(is_int(getattr(self, name)) and getattr(self, name) >= 1, name, "use an int >= 1")
        need(is_int(self.mm_repeats) and self.mm_repeats > self.mm_pairs, "mm_repeats",
             f"use an int > mm_pairs={self.mm_pairs}")
        need(isinstance(self.mm, bool), "mm", "use True or False")
        need(isinstance(self.quick, bool), "quick", "use True or False")
        need(isinstance(self.guidance_scale, (int, float)) and not isinstance(self.guidance_scale, bool)
             and math.isfinite(self.guidance_scale), "guidance_scale", "use a finite float")
        need(self.solver is None or (isinstance(self.solver, str) and bool(self.solver)), "solver",
             "use None or a scheduler name")
        need(is_int(self.seed) and self.seed >= 0, "seed", "use an int >= 0")
        need(self.max_samples is None or (is_int(self.max_samples) and self.max_samples >= self.batch_size),
             "max_samples", f"use None or an int >= batch_size={self.batch_size}")

    @classmethod
    def quick_mode(cls, **changes: Any) -> "EvalSettings":
        """Quick settings: 2 replications of at most 64 samples, MultiModality off (if switched on:
        32 prompts x 12 repeats), ``quick=True``.

        Numbers from quick runs are not comparable with the protocol's (fewer samples make FID
        larger and the CIs wider); every output says so.
        """
        base = dict(replications=2, max_samples=64, mm=False, mm_prompts=32, mm_repeats=12, quick=True)
        return cls(**{**base, **changes})

    def replace(self, **changes: Any) -> "EvalSettings":
        """A validated copy with some fields changed."""
        return replace(self, **changes)

    def protocol_deviations(self) -> list[str]:
        """How these settings fall short of the T2M protocol (20 replications of the whole split,
        MultiModality on); empty for the protocol itself. Generation settings (steps, w, solver)
        are choices within the protocol and are not listed."""
        return _deviations(self.replications, self.max_samples, self.mm)

    def describe(self) -> str:
        """One line for humans, starting with the mode."""
        short = self.protocol_deviations()
        mode = ("QUICK MODE (not the full protocol)" if self.quick else
                f"reduced protocol ({', '.join(short)})" if short else "full protocol")
        mm = f"on ({self.mm_prompts} prompts x {self.mm_repeats})" if self.mm else "off"
        cap = f", at most {self.max_samples} samples per replication" if self.max_samples else ""
        return (f"{mode}: split={self.split}, batch {self.batch_size}, {self.replications} replications{cap}, "
                f"MultiModality {mm}, steps {self.num_steps}, w {self.guidance_scale:g}, "
                f"solver {self.solver or 'default'}, seed {self.seed}")


#: Replications of the T2M protocol.
PROTOCOL_REPLICATIONS = 20


def _deviations(replications, max_samples, mm) -> list[str]:
    out = []
    if replications is not None and int(replications) < PROTOCOL_REPLICATIONS:
        out.append(f"{int(replications)} replications instead of {PROTOCOL_REPLICATIONS}")
    if max_samples is not None and not (isinstance(max_samples, float) and math.isnan(max_samples)):
        out.append(f"at most {int(max_samples)} samples per replication instead of the whole split")
    if mm is False:
        out.append("no MultiModality")
    return out


# ------------------------------------------------------------------------------------ results
@dataclass(frozen=True)
class EvalResult:
    """Per-replication metric values of one evaluated model, and the settings that produced them."""

    name: str                                        # table row label
    values: Mapping[str, tuple[float, ...]]          # metric (from METRICS) -> one value per replication
    settings: Mapping[str, Any] = field(default_factory=dict)  # EvalSettings fields + kind, samples, weights, evaluator, data

    def summary(self) -> dict[str, tuple[float, float]]:
        """``metric -> (mean, 95% half-width)`` over the replications (only metrics computed)."""
        out = {}
        for m in METRICS:
            if m in self.values:
                mean, half = M.mean_ci(np.asarray(self.values[m], dtype=np.float64))
                out[m] = (float(mean), float(half))
        return out


@dataclass(frozen=True)
class RealBatch:
    """One evaluation batch of real test items (raw, de-normalised features)."""

    captions: list[str]            # B caption strings, as given to the generator
    tokens: list[list[str]]        # B "word/POS" token lists, as given to the evaluator
    lengths: np.ndarray            # (B,) int64 frames, multiples of the unit length
    motions: np.ndarray            # (B, N, D) float32 raw features, zero past each length
    names: list[str]               # dataset item names


# --------------------------------------------------------------------------------- internals
def _seed(settings: EvalSettings, *tags: int) -> int:
    return int(np.random.SeedSequence([settings.seed, *tags]).generate_state(1)[0])


def _rng(settings: EvalSettings, *tags: int) -> np.random.Generator:
    return np.random.default_rng(np.random.SeedSequence([settings.seed, *tags]))


def _skeleton_of(evaluator) -> Skeleton:
    d = evaluator.config.dim_pose
    for name in ("humanml3d", "kit"):
        sk = get_skeleton(name)
        if sk.feature_dim == d:
            return sk
    raise ValueError(f"the evaluator expects {d}-d features; no known skeleton has that width (263, 251)")


def _dataset(dataset_root, settings: EvalSettings, skeleton: Skeleton):
    from salad_core.data.dataset import MotionTextDataset

    # raw features: the evaluator normalises with its own statistics (humanml3d_eval_facts §5.4)
    return MotionTextDataset(dataset_root, settings.split, skeleton=skeleton, normalize=False, random_crop=True,
                             seed=settings.seed)


def _num_batches(n_items: int, settings: EvalSettings) -> int:
    n = n_items // settings.batch_size
    if n == 0:
        raise ValueError(f"split {settings.split!r} has {n_items} usable items, fewer than one batch of "
                         f"{settings.batch_size}")
    if settings.max_samples is not None:
        n = min(n, math.ceil(settings.max_samples / settings.batch_size))
    return n


def _batches_for(dataset, settings: EvalSettings, epoch: int, order_tag: int) -> list[RealBatch]:
    dataset.set_epoch(epoch)
    order = _rng(settings, _TAG_ORDER, order_tag).permutation(len(dataset))
    out = []
    bs = settings.batch_size
    for b in range(_num_batches(len(dataset), settings)):
        items = [dataset[int(i)] for i in order[b * bs:(b + 1) * bs]]
        lengths = np.array([it["length"] for it in items], dtype=np.int64)
        n = int(lengths.max())
        motions = np.stack([it["motion"][:n] for it in items]).astype(np.float32)
        out.append(RealBatch([it["caption"] for it in items], [list(it["tokens"]) for it in items], lengths,
                             motions, [it["name"] for it in items]))
    return out


def real_batches(dataset_root: str | PathLike, settings: EvalSettings, replication: int,
                 skeleton: str | Skeleton = "humanml3d") -> list[RealBatch]:
    """The real batches of one replication, exactly as :func:`evaluate_generator` iterates them.

    The crops, captions and order are a function of ``(settings.seed, replication)`` only, so the
    same call always returns the same batches (useful for replay generators in tests).
    """
    if not isinstance(replication, (int, np.integer)) or replication < 0:
        raise ValueError(f"replication={replication!r} must be an int >= 0")
    return _batches_for(_dataset(dataset_root, settings, get_skeleton(skeleton)), settings, int(replication),
                        int(replication))


def _motion_embeddings(evaluator, motions: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    x = evaluator.normalize(motions)                                  # (B, N, D) evaluator statistics
    return evaluator.motion_embeddings(x, torch.as_tensor(lengths), mask_padding=True).double().cpu().numpy()


def _text_embeddings(evaluator, tokens: list[list[str]]) -> np.ndarray:
    return evaluator.caption_embeddings(tokens).double().cpu().numpy()


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
    sk = _skeleton_of(evaluator)
    ds = _dataset(dataset_root, settings, sk)
    vals: dict[str, list[float]] = {m: [] for m in METRICS if m != "MultiModality"}
    samples = div_pairs = 0
    for r in range(settings.replications):
        batches = _batches_for(ds, settings, r, r)
        text = np.concatenate([_text_embeddings(evaluator, b.tokens) for b in batches])
        real = np.concatenate([_motion_embeddings(evaluator, b.motions, b.lengths) for b in batches])
        # the reference: the same items (same order, so a capped --max-samples run compares like with
        # like, as the generator rows do) with independent crops and captions (another epoch)
        ref_batches = _batches_for(ds, settings, _REFERENCE_EPOCH + r, r)
        ref = np.concatenate([_motion_embeddings(evaluator, b.motions, b.lengths) for b in ref_batches])
        samples, div_pairs = len(real), _diversity_pairs(len(real), settings.diversity_pairs)
        _score(vals, text, real, real_ref=ref, div_pairs=div_pairs, settings=settings, rng=_rng(settings, _TAG_DIV, r))
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
    sk = _skeleton_of(evaluator)
    ds = _dataset(dataset_root, settings, sk)
    weights = weights if weights is not None else _generator_source(gen)
    metrics_here = [m for m in METRICS if settings.mm or m != "MultiModality"]
    vals: dict[str, list[float]] = {m: [] for m in metrics_here}
    n_batches = _num_batches(len(ds), settings)
    n_mm = min(settings.mm_prompts, n_batches * settings.batch_size) if settings.mm else 0
    total_calls = settings.replications * (n_batches + settings.mm_repeats * math.ceil(n_mm / settings.batch_size))
    from tqdm.auto import tqdm

    bar = tqdm(total=total_calls, desc=f"eval {name}", unit="batch", disable=not progress)
    samples = div_pairs = 0
    try:
        for r in range(settings.replications):
            batches = _batches_for(ds, settings, r, r)
            text, real, fake = [], [], []
            for i, b in enumerate(batches):
                feats = _generate(gen, b.captions, b.lengths, _seed(settings, _TAG_GEN, r, i), settings, sk.feature_dim)
                text.append(_text_embeddings(evaluator, b.tokens))
                real.append(_motion_embeddings(evaluator, b.motions, b.lengths))
                fake.append(_motion_embeddings(evaluator, feats, b.lengths))
                bar.update()
            text, real, fake = np.concatenate(text), np.concatenate(real), np.concatenate(fake)
            samples, div_pairs = len(fake), _diversity_pairs(len(fake), settings.diversity_pairs)
            _score(vals, text, fake, real_ref=real, div_pairs=div_pairs, settings=settings,
                   rng=_rng(settings, _TAG_DIV, r))
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
            feats = _generate(gen, caps[sl], lens[sl], _seed(settings, _TAG_MM, r, k, start), settings, sk.feature_dim)
            emb[sl, k] = _motion_embeddings(evaluator, feats, lens[sl])
            bar.update()
    return M.multimodality(emb, n_pairs=settings.mm_pairs, rng=_rng(settings, _TAG_MMPAIRS, r))


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


# -------------------------------------------------------------------------------------- tables
def results_frame(results: Sequence[EvalResult]) -> pd.DataFrame:
    """One row per result: ``name``, each metric's mean and its ``" ±"`` half-width, then the settings.

    Metrics a result did not compute (MultiModality with ``mm`` off, or for the real row) are NaN.
    """
    if not results:
        raise ValueError("results is empty")
    rows = []
    for res in results:
        if not isinstance(res, EvalResult):
            raise TypeError(f"results must hold EvalResult objects, got {type(res).__name__}")
        row: dict[str, Any] = {"name": res.name}
        summ = res.summary()
        for m in METRICS:
            mean, half = summ.get(m, (np.nan, np.nan))
            row[m], row[m + CI_SUFFIX] = mean, half
        for k in SETTING_COLUMNS:
            row[k] = res.settings.get(k)
        rows.append(row)
    return pd.DataFrame(rows, columns=["name", *[c for m in METRICS for c in (m, m + CI_SUFFIX)], *SETTING_COLUMNS])


def format_mean_ci(mean: float, half: float, digits: int = 3, latex: bool = False) -> str:
    """``"0.511 ± 0.003"`` (LaTeX ``"$0.511^{\\pm 0.003}$"``); NaN gives ``"-"``."""
    if mean is None or half is None or not np.isfinite(mean):
        return "-"
    if not np.isfinite(half):
        return f"{mean:.{digits}f}"
    if latex:
        return f"${mean:.{digits}f}^{{\\pm {half:.{digits}f}}}$"
    return f"{mean:.{digits}f} ± {half:.{digits}f}"


def _check_frame(df: pd.DataFrame) -> None:
    if not isinstance(df, pd.DataFrame):
        raise TypeError(f"expected the DataFrame of results_frame(...), got {type(df).__name__}")
    missing = [c for c in ("name", *METRICS) if c not in df.columns]
    if missing:
        raise ValueError(f"the DataFrame lacks the columns {missing}; build it with results_frame(results)")


def _shown_metrics(*frames: pd.DataFrame) -> list[str]:
    return [m for m in METRICS if any(f[m].notna().any() for f in frames)]


def _kind(df: pd.DataFrame) -> pd.Series:
    return df["kind"] if "kind" in df.columns else pd.Series(["generator"] * len(df), index=df.index)


def _unique(df: pd.DataFrame, key: str) -> list:
    if key not in df.columns:
        return []
    return list(dict.fromkeys(v for v in df[key].tolist() if v is not None and not (isinstance(v, float) and np.isnan(v))))


#: Table headers of the generation settings that may become columns.
_SETTING_LABELS = {"guidance_scale": "w", "num_steps": "steps", "solver": "solver", "weights": "weights"}
#: Generation settings: read from generator rows only (the real row generates nothing).
_GEN_SETTINGS = ("guidance_scale", "num_steps", "solver", "weights", "mm")


def _varying_settings(*frames: pd.DataFrame) -> list[str]:
    """Generation settings that differ between generator rows (shown as table columns)."""
    out = []
    for k in ("guidance_scale", "num_steps", "solver", "weights"):
        if any(len(_unique(f[_kind(f) == "generator"], k)) > 1 for f in frames):
            out.append(k)
    return out


def _fmt_setting(v: Any) -> str:
    if isinstance(v, (bool, np.bool_)):
        return "on" if v else "off"
    if isinstance(v, (float, np.floating)):
        return f"{float(v):g}"
    return str(v)


def _note(df: pd.DataFrame) -> str:
    """Settings shared by the rows, as one sentence; quick mode first and loud."""
    quick = any(bool(v) for v in _unique(df, "quick"))
    gen_rows = df[_kind(df) == "generator"]
    short: list[str] = []
    for _, r in df.iterrows():
        mm = r.get("mm") if _kind(df).loc[r.name] == "generator" else None     # the real row has no MultiModality
        for d in _deviations(r.get("replications"), r.get("max_samples"), mm):
            if d not in short:
                short.append(d)
    if quick:
        parts = ["QUICK MODE: fewer replications and samples than the protocol, not comparable with published "
                 "numbers"]
    elif short:
        parts = [f"Reduced T2M protocol ({', '.join(short)}), not comparable with published numbers"]
    else:
        parts = ["Full T2M protocol"]
    for label, key in (("split", "split"), ("batch", "batch_size"), ("replications", "replications"),
                       ("samples/replication", "samples"), ("MultiModality", "mm"), ("steps", "num_steps"),
                       ("w", "guidance_scale"), ("solver", "solver"), ("seed", "seed"), ("weights", "weights"),
                       ("evaluator", "evaluator"), ("data", "data")):
        vals = _unique(gen_rows if key in _GEN_SETTINGS else df, key)
        if key == "solver" and not vals and len(gen_rows):
            vals = ["generator default"]
        if len(vals) == 1:
            parts.append(f"{label} {_fmt_setting(vals[0])}")
        elif len(vals) > 1:
            parts.append(f"{label} varies (see table)")
    return "; ".join(parts) + ". Mean ± 1.96·std/√R over R replications."


def _cells(df: pd.DataFrame, digits: int, latex: bool, shown: list[str],
           extra: list[str]) -> tuple[list[str], list[list[str]]]:
    header = ["Method", *[_SETTING_LABELS[k] for k in extra], *[f"{m} {_ARROWS[m]}" for m in shown]]
    rows = []
    for _, r in df.iterrows():
        cells = [str(r["name"])]
        for k in extra:
            v = r.get(k)
            cells.append("-" if v is None or (isinstance(v, float) and np.isnan(v)) else _fmt_setting(v))
        for m in shown:
            half = r.get(m + CI_SUFFIX, np.nan)
            cells.append(format_mean_ci(r[m], np.nan if half is None else half, digits, latex))
        rows.append(cells)
    return header, rows


def to_markdown(df: pd.DataFrame, digits: int = 3, reference: pd.DataFrame | None = None) -> str:
    """A Markdown table of ``results_frame(...)`` with a settings note (quick mode stated first).

    Parameters
    ----------
    df : DataFrame from :func:`results_frame`
    digits : int
    reference : DataFrame, optional
        Published numbers to show in a separate table below ours, e.g. :func:`paper_cfg_sweep`;
        their row names must say they are the paper's (``paper_cfg_sweep`` names them ``"paper: ..."``).
    """
    _check_frame(df)
    header, rows = _cells(df, digits, False, _shown_metrics(df), _varying_settings(df))
    lines = [f"**{_note(df)}**", ""]
    lines += _markdown_table(header, rows)
    if reference is not None:
        _check_reference(reference)
        rh, rr = _cells(reference, digits, False, _shown_metrics(reference), _varying_settings(reference))
        lines += ["", "Published numbers (copied from the paper, not computed here):", ""]
        lines += _markdown_table(rh, rr)
    return "\n".join(lines) + "\n"


def _markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    # pandas.DataFrame.to_markdown needs the optional tabulate package; this is all we need of it
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    fmt = lambda cells: "| " + " | ".join(c.ljust(w) for c, w in zip(cells, widths)) + " |"  # noqa: E731
    align = "|" + "|".join(":" + "-" * (w + 1) if i == 0 else "-" * (w + 1) + ":" for i, w in enumerate(widths)) + "|"
    return [fmt(header), align, *[fmt(r) for r in rows]]


def _check_reference(reference: pd.DataFrame) -> None:
    _check_frame(reference)
    unlabeled = [n for n in reference["name"] if "paper" not in str(n).lower()]
    if unlabeled:
        raise ValueError(f"reference rows must be labelled as published numbers (name containing 'paper'); "
                         f"got {unlabeled[:3]}")


_LATEX_SPECIAL = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "_": r"\_", "#": r"\#", "$": r"\$",
                  "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "±": r"$\pm$",
                  "·": r"$\cdot$"}


def _latex_escape(s: str) -> str:
    return "".join(_LATEX_SPECIAL.get(ch, ch) for ch in s)


def to_latex(df: pd.DataFrame, digits: int = 3, reference: pd.DataFrame | None = None) -> str:
    """A booktabs ``tabular`` of ``results_frame(...)``; the settings note is a LaTeX comment above it.

    ``reference`` rows (e.g. :func:`paper_cfg_sweep`) follow a ``\\midrule`` under a heading that
    marks them as the paper's, and must be labelled so in their names.
    """
    _check_frame(df)
    frames = [df] if reference is None else [df, reference]
    if reference is not None:
        _check_reference(reference)
    shown, extra = _shown_metrics(*frames), _varying_settings(*frames)
    header, rows = _cells(df, digits, True, shown, extra)
    ref_rows = _cells(reference, digits, True, shown, extra)[1] if reference is not None else []
    head = [_latex_escape(h) for h in header]
    for a, b in _LATEX_ARROWS.items():
        head = [h.replace(a, b) for h in head]
    lines = [f"% {_note(df)}", r"\begin{tabular}{l" + "c" * (len(header) - 1) + "}", r"\toprule",
             " & ".join(head) + r" \\", r"\midrule"]
    lines += [" & ".join([_latex_escape(r[0]), *r[1:]]) + r" \\" for r in rows]
    if ref_rows:
        lines += [r"\midrule", r"\multicolumn{" + str(len(header)) + r"}{l}{\emph{Published (copied from the paper)}} \\"]
        lines += [" & ".join([_latex_escape(r[0]), *r[1:]]) + r" \\" for r in ref_rows]
    lines += [r"\bottomrule", r"\end{tabular}"]
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------- plot
def plot_cfg_sweep(df: pd.DataFrame, r_precision: str = "R-precision top-3", figsize=(9.0, 3.6)):
    """FID and R-precision against the CFG weight ``w`` (SALAD Fig. 5), with 95% CI error bars.

    Parameters
    ----------
    df : DataFrame from :func:`results_frame` (e.g. of :func:`cfg_sweep`)
        Generator rows need ``guidance_scale``; one line per generator weights/name stem. A
        "Real motion" row, if present, is drawn as a dashed horizontal line.
    r_precision : str
        Which R-precision column to plot (the paper's figure uses top-3).

    Returns
    -------
    matplotlib.figure.Figure
        Two axes: ``axes[0]`` FID, ``axes[1]`` R-precision. Built without pyplot (Agg-safe).
    """
    from matplotlib.figure import Figure

    _check_frame(df)
    if r_precision not in METRICS[:3]:
        raise ValueError(f"r_precision={r_precision!r}; allowed: {METRICS[:3]}")
    kind = df["kind"] if "kind" in df.columns else pd.Series(["generator"] * len(df), index=df.index)
    gen = df[(kind != "real") & df["guidance_scale"].notna()] if "guidance_scale" in df.columns else df.iloc[0:0]
    if gen.empty:
        raise ValueError("no generator rows with a guidance_scale to plot; build df from cfg_sweep results")
    real = df[kind == "real"]
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(1, 2)
    stems = gen["name"].astype(str).str.replace(r"\s+w=[-+0-9.eE]+$", "", regex=True)
    quick = "quick" in df.columns and bool(df["quick"].fillna(False).astype(bool).any())
    for ax, metric in zip(axes, ("FID", r_precision)):
        for stem in dict.fromkeys(stems):
            rows = gen[stems == stem].sort_values("guidance_scale")
            ax.errorbar(rows["guidance_scale"].astype(float).to_numpy(), rows[metric].to_numpy(float),
                        yerr=rows[metric + CI_SUFFIX].to_numpy(float), marker="o", capsize=3, label=stem)
        for _, r in real.iterrows():
            ax.axhline(float(r[metric]), color="0.4", linestyle="--", linewidth=1.0, label=str(r["name"]))
        ax.set_xlabel("CFG weight w")
        ax.set_ylabel(metric)
        ax.grid(alpha=0.3)
    axes[0].set_title("FID (lower is better)")
    axes[1].set_title(f"{r_precision} (higher is better)")
    axes[1].legend(fontsize=8)
    if quick:
        fig.suptitle("QUICK MODE: not the full protocol", color="tab:red")
    return fig


# ------------------------------------------------------------------------------- paper numbers
# SALAD supplement Table 1 (v-prediction, 50 DDIM steps): CFG weight -> top-1, top-2, top-3, FID,
# MM-Dist, Diversity as printed (mean, 95% half-width). Published numbers, never computed here.
_PAPER_TABLE1 = {
    "humanml3d": {
        "Real motion": ((.511, .003), (.703, .003), (.797, .002), (.002, .000), (2.974, .008), (9.503, .065)),
        1.5: ((.438, .003), (.622, .002), (.727, .002), (1.291, .020), (3.411, .011), (9.298, .085)),
        2.5: ((.517, .003), (.705, .002), (.801, .002), (.457, .011), (2.945, .011), (9.616, .089)),
        3.5: ((.548, .003), (.738, .002), (.829, .002), (.223, .006), (2.782, .009), (9.711, .092)),
        4.5: ((.563, .003), (.755, .002), (.842, .002), (.132, .004), (2.711, .008), (9.737, .090)),
        5.5: ((.573, .003), (.763, .002), (.850, .002), (.093, .003), (2.674, .008), (9.741, .094)),
        6.5: ((.578, .003), (.767, .002), (.854, .002), (.078, .003), (2.656, .009), (9.722, .095)),
        7.5: ((.581, .003), (.769, .003), (.857, .002), (.076, .002), (2.649, .009), (9.696, .096)),
        8.5: ((.581, .003), (.770, .002), (.857, .002), (.083, .002), (2.650, .009), (9.669, .094)),
        9.5: ((.581, .003), (.771, .002), (.858, .002), (.097, .003), (2.655, .009), (9.638, .093)),
        10.5: ((.581, .003), (.770, .002), (.857, .001), (.116, .003), (2.663, .008), (9.608, .094)),
        11.5: ((.581, .002), (.769, .002), (.857, .002), (.138, .003), (2.673, .008), (9.577, .093)),
        12.5: ((.578, .002), (.768, .002), (.856, .002), (.164, .003), (2.686, .008), (9.657, .091)),
    },
    "kit": {
        "Real motion": ((.424, .005), (.649, .006), (.779, .006), (.031, .004), (2.788, .012), (11.08, .097)),
        1.5: ((.439, .005), (.656, .006), (.774, .007), (.837, .033), (2.755, .018), (11.033, .115)),
        2.5: ((.471, .006), (.691, .005), (.809, .005), (.489, .017), (2.593, .013), (11.085, .118)),
        3.5: ((.480, .006), (.706, .005), (.818, .006), (.396, .013), (2.562, .013), (11.086, .120)),
        4.5: ((.484, .006), (.709, .005), (.823, .006), (.352, .011), (2.559, .015), (11.083, .122)),
        5.5: ((.484, .006), (.710, .005), (.824, .006), (.324, .009), (2.571, .016), (11.078, .122)),
        6.5: ((.481, .007), (.708, .006), (.824, .006), (.308, .009), (2.588, .016), (11.077, .119)),
        7.5: ((.480, .007), (.707, .006), (.826, .006), (.298, .009), (2.608, .015), (11.079, .119)),
        8.5: ((.476, .008), (.705, .005), (.823, .006), (.294, .008), (2.630, .015), (11.083, .120)),
        9.5: ((.477, .007), (.704, .005), (.822, .005), (.294, .008), (2.651, .015), (11.089, .120)),
        10.5: ((.474, .006), (.703, .005), (.820, .006), (.297, .009), (2.674, .015), (11.096, .121)),
        11.5: ((.472, .006), (.702, .006), (.818, .006), (.303, .009), (2.697, .015), (11.102, .121)),
        12.5: ((.471, .006), (.697, .006), (.815, .006), (.311, .010), (2.719, .015), (11.108, .122)),
    },
}


def paper_row(name: str, cells: Mapping[str, tuple[float, float] | None], source: str, **settings: Any) -> dict:
    """One published row in the shape of :func:`results_frame`: ``"paper: <name>"``, the given
    metrics as ``(mean, 95% half-width)`` (None or absent: NaN, a cell the paper does not print),
    ``kind="paper"``, the protocol's split/batch/replications, ``data=source`` and ``settings``."""
    unknown = set(cells) - set(METRICS)
    if unknown:
        raise ValueError(f"unknown metrics {sorted(unknown)}; known: {METRICS}")
    row: dict[str, Any] = {"name": f"paper: {name}"}
    for m in METRICS:
        cell = cells.get(m)
        row[m], row[m + CI_SUFFIX] = cell if cell is not None else (np.nan, np.nan)
    row.update({k: None for k in SETTING_COLUMNS})
    row.update(kind="paper", split="test", batch_size=32, replications=PROTOCOL_REPLICATIONS, data=source,
               **settings)
    return row


def paper_frame(rows: Sequence[dict]) -> pd.DataFrame:
    """Rows of :func:`paper_row` as a DataFrame with :func:`results_frame`'s columns."""
    return pd.DataFrame(list(rows), columns=["name", *[c for m in METRICS for c in (m, m + CI_SUFFIX)],
                                             *SETTING_COLUMNS])


def paper_cfg_sweep(dataset: str = "humanml3d") -> pd.DataFrame:
    """The SALAD paper's own CFG sweep (supplement Table 1) as a :func:`results_frame`-shaped frame.

    Rows are named ``"paper: Real motion"`` and ``"paper: SALAD w=..."``, with ``kind`` ``"paper"``
    and ``data`` naming the source. Only for display beside our numbers (``reference=`` of
    :func:`to_markdown` / :func:`to_latex`); nothing here is computed.
    """
    key = get_skeleton(dataset).name
    if key not in _PAPER_TABLE1:
        raise ValueError(f"no published CFG sweep for {dataset!r}; available: {sorted(_PAPER_TABLE1)}")
    rows = []
    for w, cells in _PAPER_TABLE1[key].items():
        real = w == "Real motion"
        rows.append(paper_row(REAL_NAME if real else f"SALAD w={w:g}", dict(zip(METRICS[:6], cells)),
                              f"SALAD paper, supplement Table 1 ({key})",
                              guidance_scale=None if real else float(w), num_steps=None if real else 50))
    return paper_frame(rows)
