"""Train a small T2M evaluator on a HumanML3D-layout corpus (our procedural corpus) and ship it.

The architecture is the official one (:class:`~salad_core.eval.t2m.T2MEvaluator`) with smaller
widths (:data:`SMALL_SIZES`). The recipe is the T2M one (Guo et al. 2022;
``humanml3d_eval_facts`` §4.2), in two phases that both run through the shared trainer
(:func:`salad_core.train.common.fit`), so both get atomic checkpoints, exact resume, a progress
bar and ``log.jsonl``:

1. **Movement encoder.** The movement encoder is pretrained as a snippet autoencoder on
   ``movement_window``-frame windows, then frozen (T2M's ``Decomp_SP001_SM001``). The loss is
   ``L1(recon) + sparsity * mean|code| + smoothness * mean|code_t+1 - code_t|``. Our decoder has
   two transposed convolutions that mirror the encoder. With ``movement_steps=0`` the movement
   encoder is instead trained jointly with the matching loss.
2. **Matching.** The text and motion encoders are trained with the contrastive loss
   (:func:`~salad_core.eval.t2m.matching_loss`: margin 10, negatives by a random cyclic shift of
   the motions within the batch). Batches are 32 random caption/crop items
   (:class:`~salad_core.data.dataset.MotionTextDataset`), the gradient norm is clipped at 0.5,
   and ``best.*`` is the checkpoint with the lowest validation loss (T2M's ``finest.tar``).

The optimiser is Adam (AdamW with zero weight decay). T2M's learning rate is 1e-4 for a 20 M
parameter model trained for days. The small model trained for minutes uses 1e-3 in
``scripts/reproduce_evaluator.sh`` (chosen by the short comparison reported there); the config
default stays 1e-4.

Normalisation: the evaluator's statistics are the corpus ``Mean.npy``/``Std.npy`` (computed on its
training split), stored in the checkpoint's ``mean``/``std`` buffers like the official
evaluator's ``meta`` statistics. Word vectors: :mod:`salad_core.eval.vocab` (MiniLM-derived,
bundled in the checkpoint).

At the end the retrieval accuracy of the chosen checkpoint is measured on the test split (real
motions against their own captions: R-precision top-1/2/3 in batches of 32, chance 1/32, 2/32,
3/32) and written to ``retrieval.json``. :func:`export_evaluator` copies the model into a
package folder with a model card that quotes those figures.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

import torch
from torch import nn
from torch.utils.data import default_collate

from salad_core.io import CheckpointError, atomic_write_text, config_from_dict, register_model
from salad_core.skeleton import get_skeleton
from salad_core.train.common import StepContext, TrainResult, TrainTask, fit
from salad_core.train.config import TrainConfig
from salad_core.train.distributed import DistEnv, init_distributed

from .t2m import EvaluatorConfig, MovementConvEncoder, T2MEvaluator, load_evaluator, matching_loss, save_evaluator
from .vocab import VECTOR_MODES, build_word_vectorizer

__all__ = [
    "SMALL_SIZES",
    "EvaluatorTrainConfig",
    "MovementConvDecoder",
    "MovementAutoencoder",
    "MatchingObjective",
    "EvaluatorTrainReport",
    "small_evaluator_config",
    "build_movement_task",
    "build_matching_task",
    "train_evaluator",
    "retrieval_accuracy",
    "export_evaluator",
    "default_evaluator_dir",
    "load_packaged_evaluator",
    "main",
]

log = logging.getLogger(__name__)

#: Widths of the shipped small evaluator (the official ones are 512 / 512 / 512 / 512 / 1024).
SMALL_SIZES: dict[str, int] = dict(dim_text_hidden=128, dim_coemb=128, dim_movement_enc_hidden=128,
                                   dim_movement_latent=128, dim_motion_hidden=128)
MOVEMENT_AE_TYPE = "t2m_movement_ae"
#: File stem of the evaluator inside a package folder, and its model card.
PACKAGE_STEM = "evaluator"
MODEL_CARD = "MODEL_CARD.md"


# ------------------------------------------------------------------------------------ config
@dataclass(frozen=True)
class EvaluatorTrainConfig(TrainConfig):
    """The T2M evaluator recipe on top of the shared training fields (see the module docstring)."""

    batch_size: int = 32                        # T2M batch (also the R-precision batch)
    max_epochs: int = 100                       # matching phase, used when max_steps is None
    lr: float = 1e-4                            # T2M's Adam learning rate (matching phase)
    warmup_steps: int = 0                       # T2M uses no warm-up
    milestones: tuple[int, ...] = ()            # constant learning rate
    gamma: float = 1.0                          # (unused without milestones)
    betas: tuple[float, float] = (0.9, 0.999)   # Adam defaults, as T2M
    weight_decay: float = 0.0                   # AdamW with zero decay is Adam
    grad_clip: float | None = 0.5               # T2M clips the gradient norm at 0.5
    val_every: int = 250                        # validate (and keep best.*) every K steps
    ckpt_every: int = 500                       # write latest + train state every K steps
    log_every: int = 25                         # log every K steps
    margin: float = 10.0                        # contrastive margin (T2M)
    word_vectors: str = "contextual"            # vocab.VECTOR_MODES: how words get MiniLM vectors
    movement_steps: int = 2000                  # snippet-autoencoder steps (0: train the movement encoder jointly)
    movement_lr: float = 1e-3                   # learning rate of the autoencoder phase
    movement_window: int = 40                   # frames per autoencoder snippet (T2M: 40 ... our clips are >= 40)
    sparsity: float = 0.001                     # weight of mean |code| in the autoencoder loss (T2M "SP001")
    smoothness: float = 0.001                   # weight of mean |code_t+1 - code_t| (T2M "SM001")
    freeze_movement: bool = True                # keep the pretrained movement encoder fixed (T2M)

    def __post_init__(self) -> None:
        super().__post_init__()

        def need(ok: bool, name: str, allowed: str) -> None:
            if not ok:
                raise ValueError(f"EvaluatorTrainConfig.{name}={getattr(self, name)!r} is invalid; {allowed}")

        need(self.margin > 0, "margin", "use a positive float (T2M: 10)")
        need(self.word_vectors in VECTOR_MODES, "word_vectors", f"use one of {VECTOR_MODES}")
        need(isinstance(self.movement_steps, int) and self.movement_steps >= 0, "movement_steps", "use an int >= 0")
        need(self.movement_lr > 0, "movement_lr", "use a positive float")
        need(isinstance(self.movement_window, int) and self.movement_window >= 8 and self.movement_window % 4 == 0,
             "movement_window", "use a multiple of 4, at least 8")
        need(self.sparsity >= 0, "sparsity", "use a float >= 0")
        need(self.smoothness >= 0, "smoothness", "use a float >= 0")
        need(self.batch_size >= 2, "batch_size", "use >= 2: negatives come from other items of the batch")

    def base(self, **changes: Any) -> TrainConfig:
        """The shared-trainer fields only (a plain :class:`TrainConfig`), with ``changes``."""
        shared = {f.name: getattr(self, f.name) for f in dataclasses.fields(TrainConfig)}
        return TrainConfig(**{**shared, **changes})


def small_evaluator_config(vectorizer, skeleton: str = "humanml3d", sizes: Mapping[str, int] | None = None) -> EvaluatorConfig:
    """The evaluator config for a vocabulary: :data:`SMALL_SIZES` (or ``sizes``), the skeleton's
    feature width, and the vectorizer's words and width."""
    sizes = dict(SMALL_SIZES if sizes is None else sizes)
    allowed = set(SMALL_SIZES)
    bad = sorted(set(sizes) - allowed)
    if bad:
        raise ValueError(f"sizes has unknown keys {bad}; allowed: {sorted(allowed)}")
    return EvaluatorConfig.for_skeleton(skeleton, **sizes, dim_word=vectorizer.dim, vocab=tuple(vectorizer.words),
                                        max_text_len=vectorizer.max_text_len)


# ----------------------------------------------------------------------- phase 1: snippet AE
class MovementConvDecoder(nn.Module):
    """Movement codes ``(B, N', D_lat)`` -> motion without contacts ``(B, 4 N', D_out)``.

    Two transposed convolutions (k4, s2, p1) with LeakyReLU 0.2 mirror the encoder's two
    stride-2 convolutions; a Linear maps to the feature width.
    """

    def __init__(self, input_size: int, hidden_size: int, output_size: int) -> None:
        super().__init__()
        self.main = nn.Sequential(
            nn.ConvTranspose1d(input_size, hidden_size, 4, 2, 1),
            nn.LeakyReLU(0.2),
            nn.ConvTranspose1d(hidden_size, output_size, 4, 2, 1),
            nn.LeakyReLU(0.2),
        )
        self.out_net = nn.Linear(output_size, output_size)

    def forward(self, codes: torch.Tensor) -> torch.Tensor:
        """``codes (B, N', D_lat)`` -> ``(B, 4 N', D_out)``."""
        x = self.main(codes.transpose(1, 2))           # (B, D_out, 4 N')
        return self.out_net(x.transpose(1, 2))


class MovementAutoencoder(nn.Module):
    """The movement encoder of an :class:`EvaluatorConfig` with a decoder, for pretraining.

    ``encoder`` is built exactly as ``T2MEvaluator.movement_encoder``, so its state dict can be
    copied into the evaluator.
    """

    def __init__(self, config: EvaluatorConfig, sparsity: float = 0.001, smoothness: float = 0.001) -> None:
        super().__init__()
        self.config = config
        c = config
        self.sparsity, self.smoothness = float(sparsity), float(smoothness)
        self.encoder = MovementConvEncoder(c.movement_input_dim, c.dim_movement_enc_hidden, c.dim_movement_latent)
        self.decoder = MovementConvDecoder(c.dim_movement_latent, c.dim_movement_enc_hidden, c.movement_input_dim)

    def forward(self, motion: torch.Tensor) -> dict[str, torch.Tensor]:
        """``motion (B, N, D)`` normalised windows (``N`` a multiple of 4) -> losses."""
        x = motion[..., : self.config.movement_input_dim]   # foot contacts are never seen (§4.3)
        codes = self.encoder(x)                             # (B, N / 4, D_lat)
        recon = self.decoder(codes)                         # (B, N, D_in)
        rec = (recon - x).abs().mean()
        sparse = codes.abs().mean()
        smooth = (codes[:, 1:] - codes[:, :-1]).abs().mean() if codes.shape[1] > 1 else codes.new_zeros(())
        return {"loss": rec + self.sparsity * sparse + self.smoothness * smooth, "rec": rec, "sparsity": sparse,
                "smoothness": smooth}


register_model(MOVEMENT_AE_TYPE, EvaluatorConfig, MovementAutoencoder)


def build_movement_task(data_dir: str | os.PathLike, evaluator: T2MEvaluator, config: EvaluatorTrainConfig,
                        env: DistEnv) -> TrainTask:
    """The :class:`TrainTask` of the snippet-autoencoder phase (model seeded with ``config.seed``)."""
    from salad_core.data.dataset import MotionWindowDataset

    sk = _skeleton_of_config(evaluator.config)
    mean, std = evaluator.mean.cpu().numpy(), evaluator.std.cpu().numpy()
    train_set = MotionWindowDataset(data_dir, "train", window=config.movement_window, skeleton=sk, mean=mean, std=std)
    torch.manual_seed(config.seed)
    ae = MovementAutoencoder(evaluator.config, config.sparsity, config.smoothness).to(env.device)

    def prepare(batch: dict[str, torch.Tensor], ctx: StepContext) -> dict[str, torch.Tensor]:
        return {"motion": batch["motion"].to(ctx.env.device, non_blocking=True)}

    return TrainTask(model=ae, model_type=MOVEMENT_AE_TYPE, model_config=evaluator.config, objective=ae,
                     train_set=train_set, val_set=None, collate=default_collate, prepare=prepare,
                     meta={"data": str(Path(data_dir)), "window": config.movement_window},
                     extra_config={"kind": "evaluator_movement_ae", "data": str(Path(data_dir).resolve())})


# --------------------------------------------------------------------------- phase 2: matching
class MatchingObjective(nn.Module):
    """``forward(word_embs, pos_ohot, sent_lens, motion, lengths, shift) -> dict(loss, positive, negative)``.

    Parameters
    ----------
    evaluator : T2MEvaluator
    margin : float
    freeze_movement : bool
        Keep ``evaluator.movement_encoder`` fixed and in eval mode (no dropout), as T2M.
    """

    def __init__(self, evaluator: T2MEvaluator, margin: float = 10.0, freeze_movement: bool = True) -> None:
        super().__init__()
        self.evaluator = evaluator
        self.margin = float(margin)
        self.freeze_movement = bool(freeze_movement)
        if self.freeze_movement:
            for p in evaluator.movement_encoder.parameters():
                p.requires_grad_(False)

    def train(self, mode: bool = True) -> "MatchingObjective":
        super().train(mode)
        if self.freeze_movement:
            self.evaluator.movement_encoder.eval()
        return self

    def forward(self, word_embs: torch.Tensor, pos_ohot: torch.Tensor, sent_lens: torch.Tensor, motion: torch.Tensor,
                lengths: torch.Tensor, shift: int) -> dict[str, torch.Tensor]:
        """Shapes: ``word_embs (B, L, d)``, ``pos_ohot (B, L, 15)``, ``sent_lens (B,)``,
        ``motion (B, N, D)`` normalised, ``lengths (B,)``; ``shift`` in ``[1, B-1]`` (0 only for B = 1)."""
        text, mot = self.evaluator(word_embs, pos_ohot, sent_lens, motion, lengths)
        if shift == 0:
            # a batch of one (the last validation batch) has no negative; count its positive term
            pos = torch.nn.functional.pairwise_distance(text, mot).pow(2).mean()
            return {"loss": pos, "positive": pos, "negative": pos.new_zeros(())}
        out = matching_loss(text, mot, margin=self.margin, shift=int(shift))
        return {"loss": out.total, "positive": out.positive, "negative": out.negative}


def build_matching_task(data_dir: str | os.PathLike, evaluator: T2MEvaluator, config: EvaluatorTrainConfig,
                        env: DistEnv, freeze_movement: bool) -> TrainTask:
    """The :class:`TrainTask` of the contrastive matching phase."""
    from salad_core.data.dataset import MotionTextDataset, collate_motion_text

    sk = _skeleton_of_config(evaluator.config)
    mean, std = evaluator.mean.cpu().numpy(), evaluator.std.cpu().numpy()
    kw = dict(skeleton=sk, mean=mean, std=std, random_crop=True, seed=config.seed)
    train_set = MotionTextDataset(data_dir, "train", **kw)
    try:
        val_set = MotionTextDataset(data_dir, "val", **kw)
    except (FileNotFoundError, ValueError) as exc:
        log.warning("no validation split for the evaluator (%s): best.* will not be written", exc)
        val_set = None
    vectorizer = evaluator.vectorizer

    def prepare(batch: dict[str, Any], ctx: StepContext) -> dict[str, Any]:
        w, p, n = vectorizer.process_batch(batch["tokens"])
        b = len(n)
        # one shift per batch, drawn from the trainer's shared stream (reproducible, resumable)
        shift = int(ctx.rand.randint(1, b, low=1)[0]) if b >= 2 else 0
        dev = ctx.env.device
        return {"word_embs": torch.from_numpy(w).to(dev), "pos_ohot": torch.from_numpy(p).to(dev),
                "sent_lens": torch.from_numpy(n), "motion": batch["motion"].to(dev, non_blocking=True),
                "lengths": batch["length"], "shift": shift}

    return TrainTask(model=evaluator, model_type="t2m_evaluator", model_config=evaluator.config,
                     objective=MatchingObjective(evaluator, config.margin, freeze_movement),
                     train_set=train_set, val_set=val_set, collate=collate_motion_text, prepare=prepare,
                     meta={"data": str(Path(data_dir)), "word_vectors": config.word_vectors},
                     extra_config={"kind": "evaluator_matching", "data": str(Path(data_dir).resolve()),
                                   "freeze_movement": freeze_movement})


def _skeleton_of_config(config: EvaluatorConfig):
    for name in ("humanml3d", "kit"):
        sk = get_skeleton(name)
        if sk.feature_dim == config.dim_pose:
            return sk
    raise ValueError(f"no skeleton has {config.dim_pose}-d features")


# ------------------------------------------------------------------------------------ driver
@dataclass(frozen=True)
class EvaluatorTrainReport:
    """How :func:`train_evaluator` ended."""

    out_dir: Path
    checkpoint: Path                      # stem of the chosen model (best, else latest)
    movement: TrainResult | None          # the autoencoder phase (None when trained jointly)
    matching: TrainResult                 # the matching phase
    retrieval: dict[str, Any] | None      # retrieval_accuracy(...) on the test split, or None if skipped


def train_evaluator(data_dir: str | os.PathLike, out_dir: str | os.PathLike,
                    config: EvaluatorTrainConfig | None = None, sizes: Mapping[str, int] | None = None,
                    skeleton: str = "humanml3d", resume: bool = False, report_split: str | None = "test",
                    report_replications: int = 5, *, env: DistEnv | None = None,
                    on_step: Callable[[int], None] | None = None) -> EvaluatorTrainReport:
    """Train a small evaluator on a HumanML3D-layout folder (both phases), then measure retrieval.

    Parameters
    ----------
    data_dir : path
        Corpus with ``new_joint_vecs/``, ``texts/``, ``train.txt``, ``val.txt``, ``test.txt``,
        ``Mean.npy``, ``Std.npy``.
    out_dir : path
        Run folder: the matching phase's ``latest.*``, ``best.*``, ``train_state.*``,
        ``log.jsonl``, ``config.json``; the autoencoder phase in ``out_dir/movement/``;
        ``retrieval.json`` at the end.
    config : EvaluatorTrainConfig, optional
    sizes : mapping, optional
        Network widths (keys of :data:`SMALL_SIZES`); default :data:`SMALL_SIZES`.
    skeleton : str
        ``"humanml3d"`` (263-d features) or ``"kit"``.
    resume : bool
        Continue an interrupted run exactly (either phase).
    report_split : str or None
        Split on which to measure retrieval accuracy at the end (None: skip).
    report_replications : int
        Replications of that measurement (mean ± 95% CI).
    env : DistEnv, optional
    on_step : callable, optional
        Called after every optimiser step of either phase.
    """
    from salad_core.data.dataset import load_mean_std

    config = config or EvaluatorTrainConfig()
    env = env or init_distributed(config.device)
    out = Path(out_dir)
    vectorizer = build_word_vectorizer(data_dir, mode=config.word_vectors)
    model_config = small_evaluator_config(vectorizer, skeleton, sizes)
    mean, std = load_mean_std(data_dir, skeleton)
    torch.manual_seed(config.seed)
    evaluator = T2MEvaluator(model_config, vectorizer).to(env.device)
    with torch.no_grad():
        evaluator.mean.copy_(torch.from_numpy(mean))
        evaluator.std.copy_(torch.from_numpy(std))

    matching_started = (out / "train_state.safetensors").exists()
    movement_result = None
    joint = config.movement_steps == 0
    if not joint:
        ae_dir = out / "movement"
        if matching_started and resume:
            log.info("matching phase already started in %s: the movement encoder comes from its train state", out)
        else:
            ae_task = build_movement_task(data_dir, evaluator, config, env)
            # no validation pass: the autoencoder is only a feature extractor and its last weights are used
            ae_cfg = config.base(max_steps=config.movement_steps, lr=config.movement_lr, val_every=0)
            movement_result = fit(ae_task, ae_dir, ae_cfg, resume=resume, env=env, on_step=on_step)
            if movement_result.interrupted:
                raise KeyboardInterrupt(f"stopped during the movement autoencoder phase at step "
                                        f"{movement_result.step}; continue with resume=True (--resume)")
            evaluator.movement_encoder.load_state_dict(ae_task.model.encoder.state_dict())
            log.info("movement autoencoder: %d steps, last loss %s", movement_result.step, movement_result.last_loss)
    task = build_matching_task(data_dir, evaluator, config, env, freeze_movement=config.freeze_movement and not joint)
    task.meta["movement"] = "joint" if joint else f"pretrained snippet autoencoder, {config.movement_steps} steps"
    result = fit(task, out, config, resume=resume, env=env, on_step=on_step)
    stem = out / "best" if (out / "best.safetensors").exists() else out / "latest"
    retrieval = None
    if report_split is not None and env.is_main and not result.interrupted:
        chosen, _ = load_evaluator(stem)
        retrieval = retrieval_accuracy(chosen, data_dir, split=report_split, replications=report_replications,
                                       seed=config.seed)
        retrieval["checkpoint"] = stem.name
        retrieval["best_step"] = result.best_step
        retrieval["best_val_loss"] = result.best_val
        atomic_write_text(out / "retrieval.json", json.dumps(retrieval, indent=2) + "\n")
        log.info("retrieval on %s: top-1 %.3f, top-2 %.3f, top-3 %.3f", report_split, *retrieval["r_precision"])
    return EvaluatorTrainReport(out, stem, movement_result, result, retrieval)


def retrieval_accuracy(evaluator: T2MEvaluator, data_dir: str | os.PathLike, split: str = "test",
                       replications: int = 5, seed: int = 0) -> dict[str, Any]:
    """R-precision top-1/2/3 (batches of 32) and MM-Dist of real motions against their captions.

    This is the "Real motion" row of the protocol (:func:`salad_core.eval.protocol.evaluate_real`)
    on ``split``, summarised as mean ± 95% CI over ``replications`` random caption/crop draws.

    Returns
    -------
    dict
        ``r_precision`` (top-1, top-2, top-3 means), ``r_precision_ci`` (half-widths),
        ``mm_dist``, ``mm_dist_ci``, ``fid_real_vs_real``, ``diversity``, ``chance`` (k/32),
        ``split``, ``replications``, ``samples``.
    """
    from .protocol import evaluate_real
    from .settings import METRICS, EvalSettings

    settings = EvalSettings(split=split, replications=replications, mm=False, seed=seed)
    res = evaluate_real(data_dir, evaluator, settings)
    s = res.summary()
    return {
        "split": split, "replications": replications, "samples": res.settings["samples"],
        "r_precision": [s[m][0] for m in METRICS[:3]], "r_precision_ci": [s[m][1] for m in METRICS[:3]],
        "mm_dist": s["MM-Dist"][0], "mm_dist_ci": s["MM-Dist"][1], "fid_real_vs_real": s["FID"][0],
        "diversity": s["Diversity"][0],
        "chance": [k / settings.batch_size for k in (1, 2, 3)],
    }


# ---------------------------------------------------------------------------------- packaging
def default_evaluator_dir() -> Path:
    """Folder of the shipped evaluator for the procedural corpus (package data)."""
    return Path(__file__).resolve().parent.parent / "weights" / "evaluator"


def load_packaged_evaluator(folder: str | os.PathLike | None = None) -> tuple[T2MEvaluator, dict]:
    """Load ``<folder>/evaluator.{safetensors,json}`` (default: :func:`default_evaluator_dir`).

    Returns ``(evaluator in eval mode, meta)``; ``evaluator.source`` is set to the folder, so
    evaluation results record which evaluator produced them.
    """
    root = Path(folder) if folder is not None else default_evaluator_dir()
    stem = root / PACKAGE_STEM
    if not stem.with_suffix(".json").is_file():
        raise FileNotFoundError(
            f"no evaluator in {root} (expected {PACKAGE_STEM}.safetensors and {PACKAGE_STEM}.json). Train one with "
            f"scripts/reproduce_evaluator.sh, or: python -m salad_core.eval.train_evaluator --data CORPUS --out RUN "
            f"--export {root}")
    model, meta = load_evaluator(stem)
    model.source = str(root)
    return model, meta


def _param_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def export_evaluator(run_dir: str | os.PathLike, target: str | os.PathLike | None = None,
                     checkpoint: str = "best") -> Path:
    """Copy a run's evaluator into a package folder with a model card.

    Parameters
    ----------
    run_dir : path
        A :func:`train_evaluator` run folder (``best.*`` or ``latest.*``, ``config.json``,
        optionally ``retrieval.json`` and ``movement/``).
    target : path, optional
        Default :func:`default_evaluator_dir`.
    checkpoint : {"best", "latest"}
        ``best`` falls back to ``latest`` when there was no validation.

    Returns
    -------
    Path of the written ``evaluator.safetensors``.
    """
    run = Path(run_dir)
    target = Path(target) if target is not None else default_evaluator_dir()
    if checkpoint not in ("best", "latest"):
        raise ValueError(f"checkpoint={checkpoint!r}; allowed: 'best', 'latest'")
    stem = run / checkpoint
    if checkpoint == "best" and not stem.with_suffix(".safetensors").exists():
        stem = run / "latest"
    if not stem.with_suffix(".json").is_file():
        raise CheckpointError(f"no evaluator checkpoint in {run} (looked for best.json and latest.json)")
    model, meta = load_evaluator(stem)
    retrieval = _read_json(run / "retrieval.json")
    run_cfg = _read_json(run / "config.json") or {}
    target.mkdir(parents=True, exist_ok=True)
    meta = {**meta, "checkpoint": stem.name, "retrieval": retrieval,
            "exported": time.strftime("%Y-%m-%d %H:%M:%S")}
    path = save_evaluator(target / PACKAGE_STEM, model, meta=meta)
    card = _model_card(model, meta, run_cfg, retrieval, run, path)
    atomic_write_text(target / MODEL_CARD, card)
    log.info("exported %s to %s (%.2f MB)", stem, path, path.stat().st_size / 2**20)
    return path


def _num(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, (int, float)) else "n/a"


def _read_json(path: Path) -> Any:
    return json.loads(path.read_text()) if path.is_file() else None


def _corpus_line(data: str | None) -> str:
    if not data:
        return "unknown"
    info = _read_json(Path(data) / "corpus.json")
    if not info:
        return f"`{data}`"
    return (f"procedural corpus v{info.get('version')} (seed {info.get('seed')}, size {info.get('size')!r}: "
            f"{info.get('clips')} clips, splits {info.get('splits')})")


def _model_card(model: T2MEvaluator, meta: dict, run_cfg: dict, retrieval: dict | None, run: Path, path: Path) -> str:
    c = model.config
    train = run_cfg.get("train", {})
    lines = [
        "# Evaluator for the procedural corpus (T2M architecture, small)",
        "",
        "Text-motion matching evaluator with the architecture of Guo et al. (CVPR 2022) and smaller widths,",
        "trained with the T2M contrastive recipe by `salad_core.eval.train_evaluator` on salad's procedural corpus.",
        "It defines FID, R-precision, MM-Dist, Diversity and MultiModality *for the procedural corpus only*;",
        "numbers computed with it are not comparable with published HumanML3D numbers (those use the official",
        "GloVe evaluator, `T2MEvaluator.from_official`).",
        "",
        "## Model",
        "",
        f"- widths: text hidden {c.dim_text_hidden}, motion hidden {c.dim_motion_hidden}, movement "
        f"{c.dim_movement_enc_hidden}/{c.dim_movement_latent}, shared embedding {c.dim_coemb}; features "
        f"{c.dim_pose}-d (the {c.num_contacts} foot contacts are ignored)",
        f"- parameters: {_param_count(model):,}; file `{path.name}`: {path.stat().st_size / 2**20:.2f} MB (float32)",
        f"- vocabulary: {len(c.vocab)} words (sos, eos, unk + the corpus lemmas), {c.dim_word}-d word vectors "
        f"derived from MiniLM ({meta.get('word_vectors', '?')!r} mode, `salad_core.eval.vocab`), bundled",
        "- normalisation: the corpus Mean/Std (training split), stored as the evaluator's `mean`/`std`",
        "",
        "## Training",
        "",
        f"- data: {_corpus_line(meta.get('data'))}",
        f"- movement encoder: {meta.get('movement', 'see config.json')}",
        f"- matching: Adam lr {train.get('lr')}, batch {train.get('batch_size')}, grad clip {train.get('grad_clip')}, "
        f"margin {train.get('margin')}, "
        f"{train.get('max_steps') if train.get('max_steps') is not None else str(train.get('max_epochs')) + ' epochs of'}"
        f" steps, seed {train.get('seed')}",
        f"- chosen checkpoint: `{meta.get('checkpoint')}` (step {meta.get('step')}, validation loss "
        f"{_num(meta.get('val_loss'))})",
        "",
        "## Retrieval accuracy (real test motions against their own captions)",
        "",
    ]
    if retrieval:
        rp, ci, ch = retrieval["r_precision"], retrieval["r_precision_ci"], retrieval["chance"]
        lines += [
            f"Split `{retrieval['split']}`, {retrieval['samples']} samples per replication, "
            f"{retrieval['replications']} replications (mean ± 1.96·std/√R), batches of 32:",
            "",
            "| metric | value | chance |",
            "|:--|--:|--:|",
            *[f"| R-precision top-{k} | {rp[k - 1]:.3f} ± {ci[k - 1]:.3f} | {ch[k - 1]:.3f} |" for k in (1, 2, 3)],
            f"| MM-Dist | {retrieval['mm_dist']:.3f} ± {retrieval['mm_dist_ci']:.3f} | |",
            f"| FID (real vs. real, other crops) | {retrieval['fid_real_vs_real']:.3f} | |",
            f"| Diversity (real) | {retrieval['diversity']:.3f} | |",
        ]
    else:
        lines += ["Not measured (the run has no retrieval.json)."]
    lines += ["", f"Computed by the code at export time from `{run}`.", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------- CLI
def main(argv: list[str] | None = None) -> int:
    """``python -m salad_core.eval.train_evaluator --data CORPUS --out RUN [--export DIR] ...``"""
    p = argparse.ArgumentParser(prog="python -m salad_core.eval.train_evaluator",
                                description="Train the small T2M evaluator on a HumanML3D-layout corpus.")
    p.add_argument("--data", required=True, help="corpus folder (HumanML3D layout)")
    p.add_argument("--out", required=True, help="run folder")
    p.add_argument("--steps", type=int, default=None, help="matching-phase steps (default: max_epochs)")
    p.add_argument("--movement-steps", type=int, default=None, help="autoencoder steps (0: joint training)")
    p.add_argument("--lr", type=float, default=None, help="matching learning rate (default 1e-4, T2M)")
    p.add_argument("--word-vectors", choices=VECTOR_MODES, default=None)
    p.add_argument("--sizes", default=None, help="JSON object of widths, e.g. '{\"dim_coemb\": 128}'")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--threads", type=int, default=None, help="torch CPU threads")
    p.add_argument("--val-every", type=int, default=None)
    p.add_argument("--report-replications", type=int, default=5)
    p.add_argument("--skeleton", default="humanml3d", choices=["humanml3d", "kit"])
    p.add_argument("--resume", action="store_true")
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--export", default=None, help="after training, write the evaluator and model card here")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    overrides = {k: v for k, v in dict(max_steps=args.steps, movement_steps=args.movement_steps, lr=args.lr,
                                       word_vectors=args.word_vectors, seed=args.seed, num_threads=args.threads,
                                       val_every=args.val_every).items() if v is not None}
    if args.no_progress:
        overrides["progress"] = False
    config = config_from_dict(EvaluatorTrainConfig, overrides)
    sizes = json.loads(args.sizes) if args.sizes else None
    report = train_evaluator(args.data, args.out, config, sizes=sizes, skeleton=args.skeleton, resume=args.resume,
                             report_replications=args.report_replications)
    if report.retrieval:
        r = report.retrieval
        print("retrieval on {split}: top-1 {0:.3f} top-2 {1:.3f} top-3 {2:.3f} (chance {3:.3f} {4:.3f} {5:.3f}); "
              "MM-Dist {6:.3f}".format(*r["r_precision"], *r["chance"], r["mm_dist"], split=r["split"]))
    if args.export:
        print(f"exported to {export_evaluator(args.out, args.export)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
