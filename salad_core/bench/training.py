"""The ``training`` and ``train`` sections: optimiser steps per second of the two trainers, and where a
denoiser training step goes (before/after the issue-19 throughput changes)."""
from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import torch

from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import make_scheduler

from .plan import SOURCE, Row

__all__ = ["TrainRecipe", "train_recipe", "adamw", "steps_per_second", "RandomText", "training_rows",
           "train_profile_rows"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrainRecipe:
    """Model configs and training configs whose step rate is measured."""

    vae: Any              # VAEConfig
    vae_train: Any        # VAETrainConfig (batch_size, window, optimiser)
    denoiser: DenoiserConfig
    denoiser_train: Any   # DenoiserTrainConfig (batch_size, max_length, cond_drop_prob, optimiser)
    diffusion: Any        # DiffusionConfig
    source: str           # where the recipe came from


def train_recipe(weights: str | Path | None = None) -> TrainRecipe:
    """The recipe in ``runs.json`` of ``weights`` or of the shipped weights, else the library defaults."""
    from salad_core.io import config_from_dict
    from salad_core.models.vae import VAEConfig
    from salad_core.pipeline import default_weights_dir
    from salad_core.sampling import DiffusionConfig
    from salad_core.train.config import DenoiserTrainConfig, VAETrainConfig

    folders = ([Path(weights)] if weights is not None else []) + [default_weights_dir()]
    for path in (f / "runs.json" for f in folders):
        try:
            runs = json.loads(path.read_text())
            v, d = runs["vae"]["config"], runs["denoiser"]["config"]
            return TrainRecipe(config_from_dict(VAEConfig, v["model"]), config_from_dict(VAETrainConfig, v["train"]),
                               config_from_dict(DenoiserConfig, d["model"]),
                               config_from_dict(DenoiserTrainConfig, d["train"]),
                               config_from_dict(DiffusionConfig, d.get("task", {}).get("diffusion", {})),
                               f"recipe of {path}")
        except FileNotFoundError:
            continue
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("cannot read the training recipe %s (%s)", path, exc)
    log.warning("no readable runs.json in %s; using the library's default training configs",
                ", ".join(map(str, folders)))
    return TrainRecipe(VAEConfig(), VAETrainConfig(), DenoiserConfig(text_dim=384), DenoiserTrainConfig(),
                       DiffusionConfig(), "library defaults")


def adamw(model: torch.nn.Module, config: Any) -> torch.optim.Optimizer:
    """The trainer's optimiser (:func:`salad_core.train.config.make_adamw`) over the trainable parameters."""
    from salad_core.train.config import make_adamw

    return make_adamw([p for p in model.parameters() if p.requires_grad], config, config.lr)


def steps_per_second(step: Callable[[], None], steps: int, warmup: int) -> float:
    for _ in range(warmup):
        step()
    t0 = time.perf_counter()
    for _ in range(steps):
        step()
    return steps / (time.perf_counter() - t0)


class RandomText:
    """Stands in for the trainer's caption cache: random token features, ``tokens`` per caption."""

    def __init__(self, dim: int, tokens: int, seed: int = 0) -> None:
        self.dim, self.tokens = dim, tokens
        self.generator = torch.Generator().manual_seed(seed)

    def encode(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        feats = torch.randn(len(captions), self.tokens, self.dim, generator=self.generator)
        return feats, torch.ones(len(captions), self.tokens, dtype=torch.bool)


def training_rows(recipe: TrainRecipe, steps: int, warmup: int = 1, text_tokens: int = 24) -> list[Row]:
    """Optimiser steps per second of the VAE and of the denoiser on random data (one process)."""
    from salad_core.models.vae import MotionVAE
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import DenoiserObjective, prepare_denoiser_batch
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom
    from salad_core.train.vae_trainer import VAEObjective

    g = torch.Generator().manual_seed(0)
    torch.manual_seed(0)
    # VAE: encode, reparameterise, decode, the four losses, backward, AdamW (VAEObjective)
    vc, vt = recipe.vae, recipe.vae_train
    vae = MotionVAE(vc).train()
    sk = vae.skeleton
    motion = torch.randn(vt.batch_size, vt.window, sk.feature_dim, generator=g)
    eps = torch.randn(vt.batch_size, vt.window // vae.downsample, vae.num_parts, vae.latent_dim, generator=g)
    objective, opt = VAEObjective(vae), adamw(vae, vt)

    def vae_step() -> None:
        opt.zero_grad(set_to_none=True)
        objective(motion, eps)["loss"].backward()
        opt.step()

    vae_rate = steps_per_second(vae_step, steps, warmup)
    del vae, objective, opt

    # denoiser: the trainer's batch preparation with a frozen (random) VAE, then forward/backward/AdamW
    dc, dt = recipe.denoiser, recipe.denoiser_train
    frozen = MotionVAE(vc).eval()
    for p in frozen.parameters():
        p.requires_grad_(False)
    den = Denoiser(dc).train()
    env = DistEnv()
    ctx = StepContext(rand=GlobalBatchRandom(torch.Generator().manual_seed(0), env), env=env, train=True, step=0)
    batch = {"motion": torch.randn(dt.batch_size, dt.max_length, sk.feature_dim, generator=g),
             "length": torch.full((dt.batch_size,), dt.max_length), "caption": [SOURCE] * dt.batch_size}
    latent_shape = (dt.max_length // frozen.downsample, frozen.num_parts, frozen.latent_dim)
    text = RandomText(dc.text_dim, text_tokens)
    scheduler = make_scheduler(recipe.diffusion, "ddim")
    objective, opt = DenoiserObjective(den), adamw(den, dt)

    def denoiser_step() -> None:
        inputs = prepare_denoiser_batch(batch, ctx, vae=frozen, text=text, scheduler=scheduler, config=dt,
                                        prediction_type=recipe.diffusion.prediction_type, latent_shape=latent_shape)
        opt.zero_grad(set_to_none=True)
        objective(**inputs)["loss"].backward()
        opt.step()

    den_rate = steps_per_second(denoiser_step, steps, warmup)
    timed = f"{steps} timed step{'s' * (steps > 1)} after {warmup} warm-up; {recipe.source}"
    return [
        Row("training", "VAE steps/s", f"batch {vt.batch_size} x {vt.window} frames, latent {vc.latent_dim}",
            vae_rate, "steps/s", note=f"random motions; {timed}"),
        Row("training", "denoiser steps/s",
            f"batch {dt.batch_size} x {dt.max_length} frames, width {dc.width}, {dc.layers} layers",
            den_rate, "steps/s", note=f"random motions and text ({text_tokens} tokens), frozen random VAE; {timed}"),
    ]


def train_profile_rows(recipe: TrainRecipe, steps: int, warmup: int, data: str | Path | None = None,
                       weights: str | Path | None = None, corpus_motions: int = 60,
                       text_encoder: Any = "minilm") -> tuple[list[Row], list[str]]:
    """The ``train`` section: a denoiser step part by part, before and after (see the module docstring).

    ``data`` is a HumanML3D-layout folder (default: a procedural corpus of ``corpus_motions`` motions
    built in a temporary folder); the frozen VAE is ``weights/vae`` (default: the shipped one).
    Returns the rows and notes for the table.
    """
    import tempfile

    from salad_core.pipeline import default_weights_dir
    from salad_core.train.profile import PARTS, profile_denoiser_training

    tmp = Path(tempfile.mkdtemp(prefix="salad_bench_train_"))
    if data is None:
        from salad_core.data.procedural.corpus import build_corpus

        data = tmp / "corpus"
        try:
            build_corpus(data, size=corpus_motions, seed=0, progress=False)
        except Exception as exc:  # the generator is someone else's code: say what to do instead
            raise RuntimeError(f"building the train section's procedural corpus failed ({type(exc).__name__}: "
                               f"{exc}); pass --train-data with a HumanML3D-layout folder") from exc
    vae = Path(weights or default_weights_dir()) / "vae"
    cfg = recipe.denoiser_train.replace(progress=False)
    t0 = time.perf_counter()
    before, after = profile_denoiser_training(data, vae, recipe.denoiser, cfg, steps=steps, warmup=warmup,
                                              cache_dir=tmp / "latent_cache", diffusion_config=recipe.diffusion,
                                              text_encoder=text_encoder)
    log.info("train: profiled in %.0f s", time.perf_counter() - t0)
    setting = f"batch {cfg.batch_size}, width {recipe.denoiser.width}, {recipe.denoiser.layers} layers"
    rows = [Row("train", f"part: {p}", "ms per step", 1e3 * after.parts[p], "ms", 1e3 * before.parts[p],
                before.parts[p] / after.parts[p] if after.parts[p] > 0 else None)
            for p in PARTS]
    rows += [
        Row("train", "denoiser step", setting, 1e3 * after.step_s, "ms", 1e3 * before.step_s,
            before.step_s / after.step_s, note="sum of the parts"),
        Row("train", "denoiser steps/s", setting, after.steps_per_s, "steps/s", before.steps_per_s,
            after.steps_per_s / before.steps_per_s, note="ratio = after / before"),
        Row("train", "samples x frames/s", "valid motion frames per second", after.frames_per_s, "frames/s",
            before.frames_per_s, after.frames_per_s / before.frames_per_s, note="ratio = after / before"),
        Row("train", "padding", "latent frames computed / valid", after.padded_frames_per_step / after.frames_per_step,
            "x", before.padded_frames_per_step / before.frames_per_step, note="items x longest item (per micro-batch) over valid frames"),
        Row("train", "start-up", "data, text prefill (+ latent cache after)", after.startup_s, "s", before.startup_s,
            note="before the first step; the cache is built once per VAE and corpus"),
    ]
    how = (f"random batches in {cfg.micro_batches} length-sorted micro-batches" if cfg.batching == "random"
           else f"length buckets of {cfg.bucket_pool} batches" + (", equal frames" if cfg.batching == "frames" else ""))
    notes = [f"train: value = after ({how}, latent cache), reference = before "
             f"(random batches, VAE encoder per step), {steps} timed steps each after {warmup} warm-up, interleaved "
             f"one by one in one process; part ratio = before / after; data: {data}; VAE: {vae}; "
             f"validation amortised over val_every={cfg.val_every} steps, logging over log_every={cfg.log_every}"]
    return rows, notes
