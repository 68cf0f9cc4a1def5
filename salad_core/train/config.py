"""Training configurations (frozen dataclasses, JSON in and out).

Defaults are the official SALAD recipe (``options/vae_option.py`` and
``options/denoiser_option.py``; paper supplement A.3): AdamW with betas (0.9, 0.99), a linear
warm-up over 2,000 iterations, then step decay at fixed iterations.

``batch_size`` is the *global* batch: under ``torchrun`` each of the ``W`` processes takes
``batch_size / W`` samples, so the same config trains the same model whatever the number of
processes (see :mod:`salad_core.train.distributed`).
"""
from __future__ import annotations

import dataclasses
import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from salad_core.io import atomic_write_text, config_from_dict, config_to_dict

__all__ = [
    "TrainConfig",
    "VAETrainConfig",
    "DenoiserTrainConfig",
    "load_train_config",
    "save_train_config",
    "parse_overrides",
    "RESUME_MUTABLE_FIELDS",
    "BATCHING_MODES",
    "AUTOCAST_MODES",
    "ADAMW_IMPLEMENTATIONS",
    "make_adamw",
]

C = TypeVar("C", bound="TrainConfig")

#: Fields that may change between a run and its resumption without changing what is learned.
#: (Bit-identical resumption also needs the same torch thread count, device and AdamW implementation:
#: they change the floating-point reduction order.)
RESUME_MUTABLE_FIELDS = frozenset({
    "max_steps", "max_epochs", "val_every", "val_batches", "ckpt_every", "log_every",
    "num_workers", "num_threads", "device", "progress", "text_cache_size", "latent_cache_dir", "adamw",
})

#: Values of :attr:`TrainConfig.batching`.
BATCHING_MODES = ("buckets", "frames", "random")
#: Values of :attr:`TrainConfig.autocast` besides None (full precision).
AUTOCAST_MODES = ("bf16",)
#: Values of :attr:`TrainConfig.adamw`.
ADAMW_IMPLEMENTATIONS = ("fused", "foreach", "loop")


def make_adamw(params: list, config: "TrainConfig", lr: float):
    """``torch.optim.AdamW`` over ``params`` with the config's betas, epsilon, weight decay and
    implementation (:attr:`TrainConfig.adamw`); the three implementations compute the same update up to
    float rounding, the fused one in one kernel (its optimiser state dict is the same, so a run may resume
    with another implementation)."""
    import torch

    impl = {"fused": {"fused": True}, "foreach": {"foreach": True}, "loop": {"foreach": False}}[config.adamw]
    return torch.optim.AdamW(params, lr=lr, betas=tuple(config.betas), eps=config.adam_eps,
                             weight_decay=config.weight_decay, **impl)


@dataclass(frozen=True)
class TrainConfig:
    """Fields shared by every trainer. Subclasses only change defaults and add task fields."""

    batch_size: int = 64                       # global batch (split across DDP processes)
    max_steps: int | None = None               # stop after this many optimiser steps (wins over max_epochs)
    max_epochs: int = 500                      # used when max_steps is None
    lr: float = 5e-4                           # peak learning rate, reached at the end of warm-up
    warmup_steps: int = 2000                   # linear warm-up lr*(it+1)/(warm+1) for it < warm
    milestones: tuple[int, ...] = (50_000,)    # iterations after warm-up at which lr is multiplied by gamma
    gamma: float = 0.1                         # decay factor at each milestone
    betas: tuple[float, float] = (0.9, 0.99)   # AdamW betas
    weight_decay: float = 1e-6                 # AdamW (decoupled) weight decay
    adam_eps: float = 1e-8                     # AdamW epsilon (torch default, as the official trainers)
    adamw: str = "fused"                       # AdamW implementation: "fused" (one kernel over all parameters,
                                               # 3-5x faster steps on CPU, the same update to float rounding:
                                               # bench/bench_optimizer_step.py), "foreach", or "loop" (PyTorch's
                                               # CPU default before session 18, a Python loop over the tensors)
    grad_clip: float | None = None             # max global grad norm; None disables clipping
    val_every: int = 1000                      # validate every K steps (0: never)
    val_batches: int | None = None             # cap on validation batches (None: the whole split)
    ckpt_every: int = 500                      # write latest + train state every K steps (0: only at the end)
    log_every: int = 10                        # log (log.jsonl, progress bar) every K steps
    seed: int = 1234                           # seeds model init, data order and the noise/cond-drop stream
    num_workers: int = 0                       # DataLoader worker processes per rank
    num_threads: int = 0                       # torch CPU threads per rank (0: cores / local ranks: 1.49-1.63x over 1 on 2 quiet cores)
    device: str = "auto"                       # "auto" (cuda if available), "cpu", "cuda"
    progress: bool = True                      # tqdm progress bar on rank 0
    batching: str = "buckets"                  # "buckets": length-sorted pools (tasks that declare item lengths,
                                               # see train.batching); "frames": the same pools cut into batches
                                               # of equal valid frames; "random": the release-0.5 random batches
    bucket_pool: int = 16                      # global batches per length-sorted pool (1: random batches)
    micro_batches: int = 1                     # split each batch into K length-sorted micro-batches, each trimmed
                                               # to its own longest item (tasks with a ``split``; same gradient)
    autocast: str | None = None                # "bf16": forward passes under torch.autocast(bfloat16) with float32
                                               # weights, gradients, optimiser and loss reductions (faster on CPUs
                                               # with bf16 instructions: docs/performance.md); None: full precision.
                                               # Changes the numerics (opt-in; validation stays in float32)

    def __post_init__(self) -> None:
        def need(cond: bool, name: str, allowed: str) -> None:
            if not cond:
                raise ValueError(f"{type(self).__name__}.{name}={getattr(self, name)!r} is invalid; {allowed}")

        need(isinstance(self.batch_size, int) and self.batch_size >= 1, "batch_size", "use an integer >= 1")
        need(self.max_steps is None or (isinstance(self.max_steps, int) and self.max_steps >= 0),
             "max_steps", "use None or an integer >= 0")
        need(isinstance(self.max_epochs, int) and self.max_epochs >= 0, "max_epochs", "use an integer >= 0")
        need(self.lr > 0, "lr", "use a positive float")
        need(isinstance(self.warmup_steps, int) and self.warmup_steps >= 0, "warmup_steps", "use an integer >= 0")
        need(all(isinstance(m, int) and m >= 0 for m in self.milestones)
             and list(self.milestones) == sorted(self.milestones), "milestones",
             "use non-negative integers in increasing order")
        need(0 < self.gamma <= 1, "gamma", "use a float in (0, 1]")
        need(len(self.betas) == 2 and all(0 <= b < 1 for b in self.betas), "betas", "use two floats in [0, 1)")
        need(self.weight_decay >= 0, "weight_decay", "use a float >= 0")
        need(self.adam_eps > 0, "adam_eps", "use a positive float")
        need(self.adamw in ADAMW_IMPLEMENTATIONS, "adamw", f"use one of {ADAMW_IMPLEMENTATIONS}")
        need(self.grad_clip is None or self.grad_clip > 0, "grad_clip", "use None or a positive float")
        for name in ("val_every", "ckpt_every", "num_workers", "num_threads"):
            need(isinstance(getattr(self, name), int) and getattr(self, name) >= 0, name, "use an integer >= 0")
        need(self.val_batches is None or (isinstance(self.val_batches, int) and self.val_batches >= 1),
             "val_batches", "use None or an integer >= 1")
        need(isinstance(self.log_every, int) and self.log_every >= 1, "log_every", "use an integer >= 1")
        need(self.batching in BATCHING_MODES, "batching", f"use one of {BATCHING_MODES}")
        need(isinstance(self.bucket_pool, int) and self.bucket_pool >= 1, "bucket_pool", "use an integer >= 1")
        need(isinstance(self.micro_batches, int) and self.micro_batches >= 1, "micro_batches", "use an integer >= 1")
        need(self.autocast is None or self.autocast in AUTOCAST_MODES, "autocast",
             f"use None (full precision) or one of {AUTOCAST_MODES}")
        need(isinstance(self.seed, int) and 0 <= self.seed < 2**62, "seed", "use an integer in [0, 2**62)")
        need(self.device in ("auto", "cpu", "cuda") or self.device.startswith("cuda:"), "device",
             "use 'auto', 'cpu', 'cuda' or 'cuda:N'")

    def replace(self: C, **changes: Any) -> C:
        """A copy with some fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True)
class VAETrainConfig(TrainConfig):
    """The skeleto-temporal VAE recipe (official ``vae_option.py``)."""

    batch_size: int = 256                      # global batch of windows
    max_epochs: int = 50                       # over all sliding windows of the train split
    lr: float = 2e-4                           # paper A.3
    milestones: tuple[int, ...] = (150_000, 250_000)
    gamma: float = 0.05                        # official option (the paper text says 0.1)
    weight_decay: float = 0.0
    window: int = 64                           # frames per training window (latent gets window/4)
    general_data: str | None = None            # uncaptioned general-motion folder mixed in (scripts/build_general_motion.py)
    general_ratio: float = 0.5                 # share of training windows drawn from general_data
    init_from: str | None = None               # VAE run or pipeline folder whose weights (and normalisation)
                                               # start the model; its architecture must match (fine-tuning)
    train_parts: str = "all"                   # "all" | "decoder": "decoder" freezes the encoder (motion_enc,
                                               # conv_enc, dist) so its posteriors, which a trained denoiser
                                               # relies on, stay bit-identical; needs init_from

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.init_from is not None and (not isinstance(self.init_from, str) or not self.init_from):
            raise ValueError(f"VAETrainConfig.init_from must be a folder path (str) or None, got {self.init_from!r}")
        if self.train_parts not in ("all", "decoder"):
            raise ValueError(f"VAETrainConfig.train_parts={self.train_parts!r} is invalid; use 'all' or 'decoder'")
        if self.train_parts == "decoder" and self.init_from is None:
            raise ValueError("VAETrainConfig.train_parts='decoder' needs init_from (a trained VAE): a frozen "
                             "randomly initialised encoder has no latent space worth keeping")
        if not isinstance(self.window, int) or self.window < 4:
            raise ValueError(f"VAETrainConfig.window={self.window!r} is invalid; use an integer >= 4")
        if self.general_data is not None and not isinstance(self.general_data, str):
            raise ValueError(f"VAETrainConfig.general_data must be a folder path (str) or None, got {self.general_data!r}")
        if isinstance(self.general_ratio, bool) or not isinstance(self.general_ratio, (int, float)) \
                or not 0.0 <= float(self.general_ratio) < 1.0:
            raise ValueError(f"VAETrainConfig.general_ratio must be in [0, 1), got {self.general_ratio!r}")


@dataclass(frozen=True)
class DenoiserTrainConfig(TrainConfig):
    """The latent denoiser recipe (official ``denoiser_option.py``)."""

    batch_size: int = 64
    max_epochs: int = 500
    lr: float = 5e-4                           # official option (paper A.3 states 2e-4 for both)
    milestones: tuple[int, ...] = (50_000,)
    gamma: float = 0.1
    weight_decay: float = 1e-6
    val_every: int = 2000
    max_length: int = 196                      # motions are cropped/padded to this many frames
    cond_drop_prob: float = 0.1                # captions replaced by "" for classifier-free guidance
    val_cond_drop: bool = False                # also drop captions during validation
    text_cache_size: int = 32768               # captions whose token features are kept (0: encode every batch);
                                               # when all fit, they are encoded up front in batches
    vae_pad_to_max: bool = True                # encode motions padded to max_length (official; batch-independent latents)
    latent_cache: bool = True                  # VAE posteriors of every training window encoded once (train.latent_cache)
    latent_cache_dir: str | None = None        # where the cache lives (None: the run folder's latent_cache/)
    latent_cache_dtype: str = "float32"        # "float32" (exact) or "float16" (half the disk, ~5e-4 relative)
    latent_norm: bool = False                  # diffuse (z - mean) / std, per part and channel, with the training
                                               # set's latent statistics (an addition; stored with the weights)
    # random batches cut into 4 length-sorted micro-batches: the gradient of a random batch (the loss curve
    # of release 0.5, step for step) at 2.03x its samples x frames/s with the latent cache (measured with
    # bench/bench_training.py; length buckets were as fast but learnt less per step: train.batching)
    batching: str = "random"
    micro_batches: int = 4

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.latent_cache_dtype not in ("float32", "float16"):
            raise ValueError(f"DenoiserTrainConfig.latent_cache_dtype={self.latent_cache_dtype!r} is invalid; "
                             "use 'float32' or 'float16'")
        if not 0.0 <= self.cond_drop_prob <= 1.0:
            raise ValueError(f"DenoiserTrainConfig.cond_drop_prob={self.cond_drop_prob!r} is invalid; use a float in [0, 1]")
        if not isinstance(self.max_length, int) or self.max_length < 4:
            raise ValueError(f"DenoiserTrainConfig.max_length={self.max_length!r} is invalid; use an integer >= 4")
        if not isinstance(self.text_cache_size, int) or self.text_cache_size < 0:
            raise ValueError(f"DenoiserTrainConfig.text_cache_size={self.text_cache_size!r} is invalid; use an integer >= 0")


def load_train_config(path: str | os.PathLike, cls: type[C], **overrides: Any) -> C:
    """Read a config JSON file (either the bare config or a ``config.json`` of a run, whose
    ``"train"`` entry is used); ``overrides`` that are not None replace fields."""
    data = json.loads(Path(path).read_text())
    if isinstance(data, dict) and "train" in data and isinstance(data["train"], dict):
        data = data["train"]
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a training config must be a JSON object, got {type(data).__name__}")
    data = {**data, **{k: v for k, v in overrides.items() if v is not None}}
    return config_from_dict(cls, data)


def parse_overrides(items: list[str], *, dotted: bool = False) -> dict[str, Any]:
    """Command-line overrides ``KEY=VALUE`` -> ``{KEY: VALUE}``, VALUE read as JSON when it parses, else as text
    (``lr=1e-3`` -> 0.001, ``kind=pose`` -> "pose"). ``dotted``: keys must name a section, ``SECTION.KEY``
    (``model.pose_width=46``). Raises ValueError naming the item that is not of that form."""
    out: dict[str, Any] = {}
    form = "SECTION.KEY=VALUE, e.g. model.pose_width=46" if dotted else "KEY=VALUE, e.g. lr=0.001"
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key or (dotted and "." not in key.strip(".")):
            raise ValueError(f"{item!r} is not an override: use {form}")
        try:
            out[key] = json.loads(value)
        except json.JSONDecodeError:
            out[key] = value
    return out


def save_train_config(path: str | os.PathLike, config: TrainConfig) -> Path:
    """Write ``config`` as JSON (atomically)."""
    return atomic_write_text(path, json.dumps(config_to_dict(config), indent=2) + "\n")
