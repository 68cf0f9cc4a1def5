"""Where a denoiser training step goes: a per-part profile, before/after the throughput changes.

:func:`profile_denoiser_training` builds the denoiser task twice on the same data, frozen VAE and
text encoder: *before* (``batching="random"``, ``latent_cache=False``: the release-0.5 trainer's
data path) and *after* (the configured defaults: random batches cut into length-sorted micro-batches, and
the latent cache; or length buckets when so configured), then runs
their optimiser steps interleaved (one step of each in turn, so the machine's speed swings hit both
alike) and times every part of a step:

``data``        next batch from the DataLoader (item crops, normalisation, collate)
``latents``     the frozen VAE's posteriors: encoder call, or cache lookup
``text``        caption features (the caption cache; prefilled, so a lookup)
``noise``       the rest of the batch preparation (draws, noising, targets, masks)
``forward``     the denoiser objective's forward (loss)
``backward``    ``loss.backward()``
``clip``        global gradient-norm clipping (``clip_grad_norm_``, timed whether or not the config clips)
``optimizer``   ``zero_grad`` and the AdamW step
``logging``     the loss averager (one ``.item()`` per ``log_every`` steps, amortised)
``validation``  one validation pass divided by ``val_every`` (amortised per step)

The part times are means over the timed steps (batches differ in length, so means, not medians,
give the rate). Start-up (data loading, text prefill, cache build) is reported apart.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from functools import partial
from typing import Any

import torch

from .common import optimizer_step
from .config import make_adamw

__all__ = ["PARTS", "StepProfile", "StepRunner", "profile_denoiser_training"]

PARTS = ("data", "latents", "text", "noise", "forward", "backward", "clip", "optimizer", "logging", "validation")


@dataclass(frozen=True)
class StepProfile:
    """Mean seconds per optimiser step by part, and the throughput of one trainer setting."""

    name: str                        # "before" or "after"
    parts: dict[str, float]          # part -> mean seconds per step
    steps: int                       # timed steps
    frames_per_step: float           # mean valid motion frames per step (samples x frames)
    padded_frames_per_step: float    # mean frames the latent batch covers (batch x longest)
    startup_s: float                 # task build: data, text prefill, latent cache

    @property
    def step_s(self) -> float:
        return float(sum(self.parts.values()))

    @property
    def steps_per_s(self) -> float:
        return 1.0 / self.step_s if self.step_s > 0 else float("nan")

    @property
    def frames_per_s(self) -> float:
        return self.frames_per_step * self.steps_per_s


class _Timed:
    """Forwards attribute access to ``target``; ``method`` calls add their time to ``sink[part]``."""

    def __init__(self, target: Any, method: str, sink: dict[str, float], part: str) -> None:
        self._target, self._method, self._sink, self._part = target, method, sink, part

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._target, name)
        if name != self._method:
            return attr

        def timed(*args: Any, **kwargs: Any) -> Any:
            t0 = time.perf_counter()
            try:
                return attr(*args, **kwargs)
            finally:
                self._sink[self._part] = self._sink.get(self._part, 0.0) + time.perf_counter() - t0

        return timed


class StepRunner:
    """One trainer setting: its task, optimiser, loader and part timers.

    ``build(config)`` returns the :class:`~salad_core.train.common.TrainTask`; :meth:`step` runs one
    optimiser step (adding its part times to the totals when ``record``), :meth:`result` gives the
    :class:`StepProfile`. ``bench/bench_training.py`` also drives it to time steps at other thread counts.
    """

    def __init__(self, name: str, build: Any, config: Any) -> None:
        from salad_core.train.common import ResumableBatchSampler, StepContext, make_loader, make_sampler
        from salad_core.train.distributed import DistEnv, GlobalBatchRandom

        t0 = time.perf_counter()
        self.name, self.config = name, config
        self.task = build(config)
        self.startup = time.perf_counter() - t0
        env = DistEnv()
        self.sink: dict[str, float] = {}
        prepare = self.task.prepare
        if isinstance(prepare, partial):     # the denoiser's: time its encoder, text and cache calls
            kw = dict(prepare.keywords)
            for name, method, part in (("vae", "encode", "latents"), ("text", "encode", "text"),
                                       ("latents", "lookup", "latents")):
                if kw.get(name) is not None:
                    kw[name] = _Timed(kw[name], method, self.sink, part)
            prepare = partial(prepare.func, *prepare.args, **kw)
        self.prepare = prepare
        self.params = [p for p in self.task.model.parameters() if p.requires_grad]
        self.optimizer = make_adamw(self.params, config, config.lr)
        if config.batching in ("buckets", "frames") and self.task.lengths is not None:
            from salad_core.train.batching import LengthBucketBatchSampler

            sampler: Any = LengthBucketBatchSampler(self.task.lengths, config.batch_size, seed=config.seed,
                                                    pool_batches=config.bucket_pool,
                                                    equal_frames=config.batching == "frames")
        else:
            sampler = ResumableBatchSampler(make_sampler(self.task.train_set, env, shuffle=True, seed=config.seed),
                                            config.batch_size, drop_last=True)
        self.loader = make_loader(self.task.train_set, sampler, self.task.collate, config, env, seed=config.seed)
        self.batches = iter(self.loader)
        self.ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(config.seed), env), env, True, 0)
        self.totals = {p: 0.0 for p in PARTS}
        self.frames = 0.0
        self.padded = 0.0
        self.steps = 0
        self.losses: list[torch.Tensor] = []
        self.step_losses: list[float] = []          # every step's loss (float), timed or not
        self.task.objective.train()

    def _next(self) -> Any:
        try:
            return next(self.batches)
        except StopIteration:
            self.batches = iter(self.loader)
            return next(self.batches)

    def step(self, record: bool) -> None:
        from salad_core.train.common import autocast_context

        t: dict[str, float] = {}
        t0 = time.perf_counter()
        batch = self._next()
        t["data"] = time.perf_counter() - t0
        self.sink.clear()
        t0 = time.perf_counter()
        inputs = self.prepare(batch, self.ctx)
        prep = time.perf_counter() - t0
        t["latents"], t["text"] = self.sink.get("latents", 0.0), self.sink.get("text", 0.0)
        t["noise"] = max(prep - t["latents"] - t["text"], 0.0)
        t0 = time.perf_counter()
        self.optimizer.zero_grad(set_to_none=True)
        t_zero = time.perf_counter() - t0
        parts = ([inputs] if self.task.split is None or self.config.micro_batches <= 1
                 else self.task.split(inputs, self.config.micro_batches))
        t["forward"] = t["backward"] = 0.0
        total = None
        for part in parts:                       # as train.common's forward/backward with micro-batches
            t0 = time.perf_counter()
            with autocast_context(self.config, "cpu"):            # as the trainer: forward under config.autocast
                losses = self.task.objective(**part)
            t["forward"] += time.perf_counter() - t0
            t0 = time.perf_counter()
            losses["loss"].backward()
            t["backward"] += time.perf_counter() - t0
            total = losses["loss"].detach() if total is None else total + losses["loss"].detach()
        t0 = time.perf_counter()
        torch.nn.utils.clip_grad_norm_(self.params, self.config.grad_clip or float("inf"))
        t["clip"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        optimizer_step(self.optimizer, self.params)
        t["optimizer"] = t_zero + time.perf_counter() - t0
        t0 = time.perf_counter()
        self.losses.append(total)
        if len(self.losses) >= self.config.log_every:
            float(torch.stack(self.losses).mean())
            self.losses.clear()
        t["logging"] = time.perf_counter() - t0
        self.step_losses.append(float(total))
        if record:
            for k, v in t.items():
                self.totals[k] += v
            self.steps += 1
            motion = batch["motion"]
            self.frames += float(batch["length"].sum()) if "length" in batch else float(motion.shape[0] * motion.shape[1])
            masks = [part.get("frame_mask") for part in parts]
            self.padded += (sum(float(m.shape[0] * m.shape[1] * 4) for m in masks)   # latent frames x 4
                            if all(m is not None for m in masks) else float(motion.shape[0] * motion.shape[1]))

    def validation_per_step(self) -> float:
        from salad_core.train.common import validate

        if self.task.val_set is None or not self.config.val_every:
            return 0.0
        t0 = time.perf_counter()
        validate(self.task, self.config, "cpu", 0)
        return (time.perf_counter() - t0) / self.config.val_every

    def result(self) -> StepProfile:
        n = max(self.steps, 1)
        parts = {k: v / n for k, v in self.totals.items()}
        return StepProfile(self.name, parts, self.steps, self.frames / n, self.padded / n, self.startup)


def profile_denoiser_training(data_dir: Any, vae_path: Any, model_config: Any, train_config: Any, *,
                              text_encoder: Any = "minilm", steps: int = 10, warmup: int = 2,
                              cache_dir: Any = None, diffusion_config: Any = None) -> tuple[StepProfile, StepProfile]:
    """Profile the denoiser step before (random batches, VAE per step) and after (as configured: micro-batches
    or buckets, latent cache).

    Parameters
    ----------
    data_dir, vae_path, model_config, train_config, text_encoder, diffusion_config
        As for :func:`~salad_core.train.denoiser_trainer.build_denoiser_task`; ``train_config`` is the
        *after* setting (``batching`` and ``latent_cache`` as configured), *before* is the same with
        ``batching="random"`` and ``latent_cache=False``.
    steps, warmup : int
        Timed and untimed steps of each setting (interleaved one by one).
    cache_dir : path, optional
        Latent cache folder for the *after* setting (default: a temporary folder).

    Returns
    -------
    (before, after) : StepProfile
    """
    import tempfile

    from salad_core.text import load_text_encoder
    from salad_core.train.denoiser_trainer import build_denoiser_task
    from salad_core.train.distributed import DistEnv

    encoder = load_text_encoder(text_encoder) if isinstance(text_encoder, str) else text_encoder
    cache_dir = cache_dir or tempfile.mkdtemp(prefix="salad_profile_cache_")

    def build(config: Any) -> Any:
        return build_denoiser_task(data_dir, vae_path, model_config, config, DistEnv(), encoder, diffusion_config,
                                   cache_dir=cache_dir)

    before_cfg = dataclasses.replace(train_config, batching="random", latent_cache=False, micro_batches=1,
                                     progress=False)
    runners = [StepRunner("before", build, before_cfg),
               StepRunner("after", build, dataclasses.replace(train_config, progress=False))]
    for i in range(warmup + steps):
        for r in runners:
            r.step(record=i >= warmup)
    out = []
    for r in runners:
        r.totals["validation"] = r.validation_per_step()
        out.append(r.result())
    return out[0], out[1]
