"""The training loop shared by every trainer.

A trainer (VAE, denoiser, ...) describes itself as a :class:`TrainTask`: the model to save, an
*objective* module whose ``forward`` returns the losses, the data, and a ``prepare`` function that
turns a collated batch into the objective's inputs (moving tensors, drawing noise, encoding text
without gradients). :func:`fit` does the rest: AdamW with the warm-up/step schedule, DDP, seeded
data order, periodic validation, atomic checkpoints, exact resume, SIGINT handling, the progress
bar and ``log.jsonl``.

Out folder layout::

    config.json                       model type and config, train config, task details
    latest.safetensors / .json        the model after the last checkpointed step (``load_model`` reads it)
    best.safetensors / .json          the model with the lowest validation loss so far
    train_state.safetensors / .json   optimiser, RNG states, step/epoch counters (see ``state.py``)
    log.jsonl                         one JSON object per logged step / validation
    mean_std.safetensors              (VAE, denoiser) the feature normalisation the model was trained with

Batches: a task that declares its items' lengths (``TrainTask.lengths``: the denoiser, KeyMotion's
MMAE) gets length-bucketed batches (:class:`~salad_core.train.batching.LengthBucketBatchSampler`,
``config.batching="buckets"``, the default) so that a batch is padded by a few frames only; other
tasks, and ``batching="random"``, get the random batches of ``DistributedSampler``.
``config.autocast="bf16"`` runs the objective's forward under ``torch.autocast`` (opt-in: float32 weights,
optimiser and validation; :func:`autocast_context`).
``config.json`` records the batching, the torch threads and the task's numerics, and every
``log.jsonl`` line states the threads and the valid frames per second.

Exactness of resume: the data order is a function of ``(seed, epoch)``
(``DistributedSampler`` or the bucketing sampler), a resumed epoch skips the batches already used without loading them,
the learning rate is a function of the step, and all RNG states (per rank) are restored. So
``k`` steps, stop, resume, ``N - k`` steps gives the same weights as ``N`` steps in one go.
"""
from __future__ import annotations

import contextlib
import itertools
import json
import logging
import math
import os
import signal
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader, Dataset, DistributedSampler, Sampler

from salad_core.io import atomic_write_text, config_to_dict, load_state_into, save_checkpoint, save_tensors
from salad_core.openmp import wait_policy

from .config import RESUME_MUTABLE_FIELDS, TrainConfig, make_adamw
from .distributed import (
    DistEnv,
    GlobalBatchRandom,
    all_gather_objects,
    all_reduce_sum,
    barrier,
    broadcast_object,
    init_distributed,
)
from .schedules import lr_at_step, set_lr
from .warm_start import WARM_START, load_warm_start, rewarm_factor
from .state import (
    TrainState,
    capture_rng,
    load_train_state,
    optimizer_from_flat,
    optimizer_to_flat,
    restore_rng,
    save_train_state,
)

__all__ = ["TrainTask", "TrainResult", "fit", "StepContext", "ResumableBatchSampler", "seed_everything", "make_loader",
           "make_sampler", "validate", "autocast_context", "native_bf16_cpu"]

log = logging.getLogger(__name__)

Batch = dict[str, Any]


@dataclass
class StepContext:
    """What ``prepare`` gets besides the batch."""

    rand: GlobalBatchRandom         # draws for the global batch, sliced to this rank's samples
    env: DistEnv                    # this process
    train: bool                     # False during validation
    step: int                       # optimiser steps completed before this batch


@dataclass
class TrainTask:
    """One kind of model to train, as :func:`fit` sees it."""

    model: nn.Module                                   # the trained model (saved in checkpoints)
    model_type: str                                    # registered type name for ``save_checkpoint``
    model_config: Any                                  # its frozen config dataclass
    objective: nn.Module                               # forward(**inputs) -> dict with "loss"; holds ``model``
    train_set: Dataset                                 # items are collated by ``collate``
    val_set: Dataset | None                            # None or empty: no validation, no best.*
    collate: Callable[[list], Batch]                   # list of items -> batch dict
    prepare: Callable[[Batch, StepContext], dict[str, Any]]  # batch -> objective inputs (on device)
    meta: dict[str, Any] = field(default_factory=dict)  # stored in every checkpoint's JSON "meta"
    extra_config: dict[str, Any] = field(default_factory=dict)  # stored in config.json under "task"
    extra_files: dict[str, dict[str, torch.Tensor]] = field(default_factory=dict)  # name -> tensors, written once
    lengths: Any = None                                # (len(train_set),) item frames: enables length bucketing
    # (inputs, k) -> k input dicts whose losses sum to the batch's loss (micro-batches trimmed to their
    # own longest item); None: the task is never split
    split: Callable[[dict[str, Any], int], list[dict[str, Any]]] | None = None


@dataclass(frozen=True)
class TrainResult:
    """How a call of :func:`fit` ended."""

    out_dir: Path
    step: int                       # optimiser steps completed in total
    epoch: int
    interrupted: bool               # stopped by SIGINT/SIGTERM (a checkpoint of ``step`` was written)
    best_val: float | None
    best_step: int | None
    last_loss: float | None         # mean training loss over the last logging window
    steps_per_s: float              # optimiser steps per second in this call (without start-up, validation, checkpoints)
    frames_per_s: float = 0.0       # valid motion frames (samples x frames) per second, same time base
    threads: int = 0                # torch CPU threads the steps ran on


def optimizer_step(optimizer: torch.optim.Optimizer, params: list[torch.Tensor]) -> None:
    """``optimizer.step()``, then mark every parameter of ``params`` as modified in place.

    PyTorch's fused AdamW (:attr:`TrainConfig.adamw` "fused", the default) updates the parameters in one kernel
    without bumping their version counters, and the no-grad caches of the models (the stacked Q/K/V and the text
    keys/values, :func:`salad_core.models.inference.weight_signature`) know a weight changed only by its version:
    without this, every validation after the first ran with the Q/K/V weights of the first one (found in session
    32: fresh runs' validation loss rose while their training loss fell, and ``best`` was chosen by it).
    """
    optimizer.step()
    torch.autograd.graph.increment_version(params)


def seed_everything(seed: int) -> None:
    """Seed torch (all devices), numpy and python ``random``."""
    import random

    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    random.seed(seed)


class ResumableBatchSampler(Sampler[list[int]]):
    """Consecutive batches of an index sampler, starting after ``start`` batches.

    Skipping happens on indices, so batches already used in the epoch are never loaded.
    """

    def __init__(self, sampler: Sampler[int], batch_size: int, drop_last: bool, start: int = 0) -> None:
        self.sampler = sampler
        self.batch_size = batch_size
        self.drop_last = drop_last
        self.start = start

    def __iter__(self) -> Iterator[list[int]]:
        it = itertools.islice(iter(self.sampler), self.start * self.batch_size, None)
        while True:
            batch = list(itertools.islice(it, self.batch_size))
            if not batch or (self.drop_last and len(batch) < self.batch_size):
                return
            yield batch

    def __len__(self) -> int:
        n = len(self.sampler)  # type: ignore[arg-type]
        total = n // self.batch_size if self.drop_last else math.ceil(n / self.batch_size)
        return max(0, total - self.start)


class _StopRequest:
    """SIGINT/SIGTERM set a flag that the loop checks between steps.

    A step is never cut in half (the weights and the optimiser stay consistent), and the loop
    then writes a checkpoint of the last completed step. A second SIGINT interrupts at once (the
    previous checkpoint is intact because every write is atomic).
    """

    def __init__(self) -> None:
        self.requested = False
        self.signum: int | None = None

    def _handler(self, signum, frame) -> None:  # noqa: ANN001
        if self.requested and signum == signal.SIGINT:
            raise KeyboardInterrupt
        self.requested = True
        self.signum = signum
        log.warning("received %s: finishing the current step, then writing a checkpoint",
                    signal.Signals(signum).name)

    @contextmanager
    def installed(self) -> Iterator["_StopRequest"]:
        if threading.current_thread() is not threading.main_thread():
            yield self  # signals can only be handled in the main thread
            return
        old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        for s in old:
            signal.signal(s, self._handler)
        try:
            yield self
        finally:
            for s, h in old.items():
                signal.signal(s, h)


def _resolve_threads(config: TrainConfig, env: DistEnv) -> None:
    if env.device.startswith("cuda"):
        return
    n = config.num_threads or max(1, (os.cpu_count() or 1) // env.local_world_size)
    if torch.get_num_threads() != n:
        torch.set_num_threads(n)


def make_loader(dataset: Dataset, sampler: Sampler, collate: Callable, config: TrainConfig, env: DistEnv,
            seed: int) -> DataLoader:
    # A dedicated generator keeps DataLoader (worker base seeds) from drawing on the global RNG,
    # which would make the model's dropout stream depend on how many loaders were created.
    gen = torch.Generator().manual_seed(seed)
    return DataLoader(dataset, batch_sampler=sampler, collate_fn=collate, num_workers=config.num_workers,
                      pin_memory=env.device.startswith("cuda"), generator=gen,
                      persistent_workers=False)


def make_sampler(dataset: Dataset, env: DistEnv, shuffle: bool, seed: int) -> DistributedSampler:
    # DistributedSampler also serves world size 1, so the data order of one process equals the
    # concatenation of the ranks' orders under DDP (rank r takes every W-th index).
    return DistributedSampler(dataset, num_replicas=env.world_size, rank=env.rank, shuffle=shuffle,
                              seed=seed, drop_last=False)


def _check_resume_config(out_dir: Path, config: TrainConfig) -> None:
    path = out_dir / "config.json"
    if not path.is_file():
        return
    try:
        old = json.loads(path.read_text()).get("train", {})
    except json.JSONDecodeError:
        return
    new = config_to_dict(config)
    changed = sorted(k for k in new if k not in RESUME_MUTABLE_FIELDS and old.get(k, new[k]) != new[k])
    if changed:
        log.warning("resuming with a changed training config (%s); the result will differ from an uninterrupted run",
                    ", ".join(f"{k}: {old.get(k)!r} -> {new[k]!r}" for k in changed))


def _forward_backward(objective: nn.Module, inputs: dict[str, Any], task: TrainTask, config: TrainConfig,
                      env: DistEnv) -> dict[str, torch.Tensor]:
    """Losses of one batch with their gradients accumulated; with ``config.micro_batches > 1`` and a
    task that can ``split``, as length-sorted micro-batches whose losses (each already divided by the
    whole batch's normaliser) sum to the batch's: the same gradient, fewer padded frames computed.
    Under DDP only the last micro-batch synchronises gradients."""
    parts = task.split(inputs, config.micro_batches) if task.split is not None and config.micro_batches > 1 else [inputs]
    total: dict[str, torch.Tensor] = {}
    for i, part in enumerate(parts):
        sync = contextlib.nullcontext() if i == len(parts) - 1 or not hasattr(objective, "no_sync") \
            else objective.no_sync()
        with sync:
            with autocast_context(config, env.device):
                losses = objective(**part)
            losses["loss"].backward()   # outside autocast: the backward runs in the forward's dtypes
        for k, v in losses.items():
            total[k] = total[k] + v.detach() if k in total else v.detach()
    return total


def autocast_context(config: TrainConfig, device: str) -> contextlib.AbstractContextManager:
    """``torch.autocast`` for ``config.autocast`` on ``device`` (a no-op context when it is None).

    With ``"bf16"`` the forward's matrix products (and the ops autocast lists for lower precision) run in
    bfloat16 while the weights, their gradients, the optimiser and the loss reductions stay in float32.
    """
    if config.autocast is None:
        return contextlib.nullcontext()
    dtypes = {"bf16": torch.bfloat16}
    return torch.autocast(torch.device(device).type, dtype=dtypes[config.autocast])


def native_bf16_cpu(cpuinfo: str | os.PathLike = "/proc/cpuinfo") -> bool | None:
    """Whether this CPU computes bfloat16 products natively (``avx512_bf16`` or ``amx_bf16`` among the
    flags of ``cpuinfo``); None where the flags cannot be read (not Linux).

    Without them, ``torch.autocast(bfloat16)`` on the CPU converts instead of computing faster: on a
    Xeon with ``avx512f`` but no ``avx512_bf16``, the VAE step measured 1,359 against 842 ms
    (``bench/bench_vae_step.py --autocast``) and the denoiser step 3.07 against 1.69 s
    (``bench/bench_denoiser_step.py``); with ``avx512_bf16`` the same steps were 1.6-1.9x *faster*.
    """
    try:
        text = Path(cpuinfo).read_text()
    except OSError:
        return None
    flags = set()
    for line in text.splitlines():
        if line.startswith("flags"):
            flags.update(line.partition(":")[2].split())
    if not flags:
        return None
    return bool(flags & {"avx512_bf16", "amx_bf16"})


def _bucketing(task: TrainTask, config: TrainConfig) -> bool:
    return config.batching in ("buckets", "frames") and task.lengths is not None


def _runtime(task: TrainTask, config: TrainConfig) -> dict[str, Any]:
    """How the run computes (recorded in ``config.json``; the model card reads it)."""
    from salad_core.allocator import allocator_tuned

    return {"torch_threads": torch.get_num_threads(),
            "batching": (f"length buckets (pools of {config.bucket_pool} batches"
                         + (", equal valid frames per batch)" if config.batching == "frames" else ")"))
            if _bucketing(task, config)
            else "random",
            "micro_batches": config.micro_batches if task.split is not None else 1,
            "autocast": config.autocast,
            "allocator": "tuned" if allocator_tuned() else "system default"}


def _write_config(out_dir: Path, task: TrainTask, config: TrainConfig) -> None:
    doc = {"model_type": task.model_type, "model": config_to_dict(task.model_config),
           "train": config_to_dict(config), "task": task.extra_config, "runtime": _runtime(task, config)}
    atomic_write_text(out_dir / "config.json", json.dumps(doc, indent=2) + "\n")


def _truncate_log(path: Path, step: int) -> None:
    """Drop log lines written after the checkpoint we resume from (they will be written again)."""
    if not path.is_file():
        return
    keep = []
    for line in path.read_text().splitlines():
        try:
            if json.loads(line).get("step", 0) <= step:
                keep.append(line)
        except json.JSONDecodeError:
            continue  # a line cut short by a crash
    atomic_write_text(path, "".join(l + "\n" for l in keep))


class _Averager:
    """Running sums of detached loss tensors; one ``.item()`` per logging window."""

    def __init__(self) -> None:
        self.sums: dict[str, torch.Tensor] = {}
        self.count = 0

    def add(self, losses: dict[str, torch.Tensor]) -> None:
        for k, v in losses.items():
            v = v.detach().float()
            self.sums[k] = self.sums[k] + v if k in self.sums else v.clone()
        self.count += 1

    def mean(self, env: DistEnv) -> dict[str, float]:
        if not self.count:
            return {}
        keys = sorted(self.sums)
        vec = torch.stack([self.sums[k] for k in keys]).to(torch.float64) / self.count
        if env.distributed:
            vec = all_reduce_sum(vec.to(env.device), env).cpu() / env.world_size
        out = dict(zip(keys, vec.tolist()))
        self.sums, self.count = {}, 0
        return out


@torch.no_grad()
def validate(task: TrainTask, config: TrainConfig, device: str, step: int) -> dict[str, float]:
    """Mean losses over the validation split, computed by one process with the unwrapped objective.

    Under DDP only rank 0 calls this and broadcasts the result: the figures (and so the choice of
    ``best``) do not depend on the number of processes, and no collective runs inside. The noise
    stream is reseeded at every validation so that values are comparable across steps.
    """
    assert task.val_set is not None
    env = DistEnv(device=device)
    objective = task.objective
    sampler = make_sampler(task.val_set, env, shuffle=False, seed=config.seed)
    batches = ResumableBatchSampler(sampler, config.batch_size, drop_last=False)
    loader = make_loader(task.val_set, batches, task.collate, config, env, seed=config.seed)
    gen = torch.Generator().manual_seed(config.seed + 7919)
    ctx = StepContext(GlobalBatchRandom(gen, env, device), env, train=False, step=step)
    was_training = objective.training
    objective.eval()
    sums: dict[str, float] = {}
    weight = 0.0
    try:
        for i, batch in enumerate(loader):
            if config.val_batches is not None and i >= config.val_batches:
                break
            losses = objective(**task.prepare(batch, ctx))
            n = float(_batch_len(batch))
            for k, v in losses.items():
                sums[k] = sums.get(k, 0.0) + float(v) * n
            weight += n
    finally:
        objective.train(was_training)
    return {k: v / weight for k, v in sums.items()} if weight else {}


def _batch_frames(batch: Batch) -> int:
    """Valid frames of a collated batch: the sum of ``length``, else batch x frames of ``motion``."""
    length = batch.get("length")
    if torch.is_tensor(length):
        return int(length.sum())
    motion = batch.get("motion")
    if torch.is_tensor(motion) and motion.dim() >= 2:
        return int(motion.shape[0] * motion.shape[1])
    return 0


def _batch_len(batch: Batch) -> int:
    for v in batch.values():
        if torch.is_tensor(v) and v.dim() > 0:
            return int(v.shape[0])
        if isinstance(v, (list, tuple)):
            return len(v)
    raise ValueError("cannot tell the batch size: the collated batch holds no tensor or list")


def fit(task: TrainTask, out_dir: str | os.PathLike, config: TrainConfig, *, resume: bool = False,
        env: DistEnv | None = None, on_step: Callable[[int], None] | None = None) -> TrainResult:
    """Train ``task.model`` and write the out folder described in the module docstring.

    Parameters
    ----------
    task : TrainTask
        The model, objective, data and batch preparation. ``task.model`` must already be built
        (seeded by the caller) and on ``env.device``.
    out_dir : path
        Output folder (created). Without ``resume`` it must not hold a train state yet.
    config : TrainConfig
        Optimisation, schedule, checkpointing and logging settings.
    resume : bool
        Continue from ``out_dir/train_state.safetensors`` (starts fresh if there is none).
    env : DistEnv, optional
        The process group (default: :func:`init_distributed`).
    on_step : callable, optional
        Called with the step count after every completed optimiser step (for tests and tools).
    """
    env = env or init_distributed(config.device)
    threads = torch.get_num_threads()
    try:
        _resolve_threads(config, env)
        return _fit(task, Path(out_dir), config, resume, env, on_step)
    finally:
        torch.set_num_threads(threads)  # leave the caller's process as it was


def _fit(task: TrainTask, out_dir: Path, config: TrainConfig, resume: bool, env: DistEnv,
         on_step: Callable[[int], None] | None) -> TrainResult:
    local_bs, rem = divmod(config.batch_size, env.world_size)
    if rem:
        raise ValueError(f"batch_size={config.batch_size} is not divisible by the number of processes "
                         f"({env.world_size}); it is the global batch and is split evenly")
    if env.is_main:
        out_dir.mkdir(parents=True, exist_ok=True)
    barrier(env)

    state_path = out_dir / "train_state.safetensors"
    if not resume and state_path.exists():
        raise FileExistsError(f"{out_dir} already holds a training run (train_state.safetensors); "
                              "pass resume=True (--resume) to continue it or choose another --out folder")

    model = task.model
    params = [p for p in model.parameters() if p.requires_grad]
    if not params:
        raise ValueError(f"{type(model).__name__} has no trainable parameters")
    optimizer = make_adamw(params, config, lr_at_step(0, config.lr, config.warmup_steps, config.milestones, config.gamma))
    objective = task.objective
    if env.distributed:
        from torch.nn.parallel import DistributedDataParallel as DDP

        objective = DDP(objective, device_ids=[torch.device(env.device).index] if env.device.startswith("cuda") else None)

    bucketing = _bucketing(task, config)
    if bucketing:
        from .batching import LengthBucketBatchSampler

        if len(task.lengths) != len(task.train_set):
            raise ValueError(f"task.lengths has {len(task.lengths)} entries for {len(task.train_set)} training items")
        train_sampler: Any = LengthBucketBatchSampler(task.lengths, config.batch_size, rank=env.rank,
                                                      world_size=env.world_size, seed=config.seed,
                                                      pool_batches=config.bucket_pool,
                                                      equal_frames=config.batching == "frames")
        steps_per_epoch = train_sampler.batches_per_epoch
    else:
        train_sampler = make_sampler(task.train_set, env, shuffle=True, seed=config.seed)
        steps_per_epoch = len(train_sampler) // local_bs
    if steps_per_epoch == 0:
        raise ValueError(f"the train split has {len(task.train_set)} items, fewer than one batch of "
                         f"{config.batch_size}; lower batch_size")
    total_steps = config.max_steps if config.max_steps is not None else config.max_epochs * steps_per_epoch
    has_val = task.val_set is not None and len(task.val_set) > 0
    if not has_val:
        log.warning("no validation items: best.* will not be written")

    # the generator shared by all ranks draws noise / timesteps / caption drops for the global batch
    shared = torch.Generator().manual_seed(config.seed)
    step, epoch, batch_in_epoch = 0, 0, 0
    best_val: float | None = None
    best_step: int | None = None
    samples_seen, elapsed_before = 0, 0.0
    warm_from: int | None = None          # the step a warm start continued from (learning rate warmed up again)

    warm = None if (not resume or state_path.exists()) else load_warm_start(out_dir, task.model_type, task.model_config)
    if resume and state_path.exists():
        st = load_train_state(out_dir)
        load_state_into(model, st.model_state, source=str(state_path))
        optimizer_from_flat(optimizer, st.optim_tensors, st.optim_doc)
        shared.set_state(st.shared_rng.to(torch.uint8))
        if len(st.rng) == env.world_size:
            restore_rng(st.rng[env.rank], env.device)
        else:
            log.warning("train state was written by %d process(es), now %d: per-rank RNG streams are reseeded",
                        len(st.rng), env.world_size)
            seed_everything(config.seed + 1_000_003 * (env.rank + 1) + st.step)
        step, epoch, batch_in_epoch = st.step, st.epoch, st.batch_in_epoch
        best_val, best_step = st.best_val, st.best_step
        samples_seen = int(st.extra.get("samples_seen", 0))
        elapsed_before = float(st.extra.get("elapsed_s", 0.0))
        warm_from = st.extra.get("warm_from")
        if env.is_main:
            _check_resume_config(out_dir, config)
            _truncate_log(out_dir / "log.jsonl", step)
        log.info("resumed %s at step %d (epoch %d, batch %d)", out_dir, step, epoch, batch_in_epoch)
    elif warm is not None:
        # the kept weights of a step, without optimiser state or RNG streams (salad_core.train.warm_start)
        load_state_into(model, warm.state, source=f"warm start {out_dir / WARM_START}")
        step = warm_from = warm.step
        epoch, batch_in_epoch = divmod(step, steps_per_epoch)
        shared.manual_seed(config.seed + 7_919 * step)
        seed_everything(config.seed + 1_000_003 * (env.rank + 1) + step)
        log.info("warm start of %s at step %d (epoch %d, batch %d) from the weights of %s: new AdamW moments, "
                 "learning rate warmed up again over %d steps", out_dir, step, epoch, batch_in_epoch, warm.source,
                 config.warmup_steps)
    else:
        if resume:
            log.info("resume asked but %s holds no train state: starting fresh", out_dir)
        # per-rank stream for dropout etc., distinct from the shared noise generator's seed
        seed_everything(config.seed + 1_000_003 * (env.rank + 1))
    if env.is_main:
        _write_config(out_dir, task, config)
        for name, tensors in task.extra_files.items():
            save_tensors(out_dir / name, tensors)
        if warm is not None:
            _truncate_log(out_dir / "log.jsonl", step)
            with open(out_dir / "log.jsonl", "a", encoding="utf-8") as fh:
                fh.write(json.dumps({"step": step, "warm_start": warm.source, "rewarm_steps": config.warmup_steps})
                         + "\n")

    def checkpoint(reason: str) -> None:
        # every rank contributes its RNG state (collective), only rank 0 writes
        rngs = all_gather_objects(capture_rng(env.device), env)
        if env.is_main:
            optim_tensors, optim_doc = optimizer_to_flat(optimizer)
            lr_now = optimizer.param_groups[0]["lr"]
            ts = TrainState(step=step, epoch=epoch, batch_in_epoch=batch_in_epoch,
                            model_state=model.state_dict(), optim_tensors=optim_tensors, optim_doc=optim_doc,
                            rng=rngs, shared_rng=shared.get_state(), best_val=best_val, best_step=best_step,
                            extra={"lr": lr_now, "samples_seen": samples_seen,
                                   "elapsed_s": elapsed_before + (time.perf_counter() - t_start),
                                   "model_type": task.model_type, "reason": reason,
                                   **({"warm_from": warm_from} if warm_from is not None else {})})
            try:
                save_train_state(out_dir, ts)
                save_checkpoint(out_dir / "latest", model, model_type=task.model_type, config=task.model_config,
                                meta={**task.meta, "step": step, "epoch": epoch})
            except OSError as exc:
                # each file is replaced atomically: it holds either its previous or its new version
                log.error("writing the checkpoint of step %d failed (%s); files not yet replaced keep the "
                          "previous checkpoint", step, exc)
                raise
            log.info("checkpoint: step %d (%s)", step, reason)
        barrier(env)

    log_path = out_dir / "log.jsonl"

    def write_log(entry: dict[str, Any]) -> None:
        if env.is_main:
            with open(log_path, "a", encoding="utf-8") as fh:
                fh.write(json.dumps(entry) + "\n")

    from tqdm.auto import tqdm

    bar = tqdm(total=total_steps, initial=min(step, total_steps), disable=not (env.is_main and config.progress),
               unit="step", dynamic_ncols=True, desc=task.model_type)
    avg = _Averager()
    last_loss: float | None = None
    interrupted = False
    stop = _StopRequest()
    stop_flag = torch.zeros(1, device=env.device)
    t_start = time.perf_counter()
    t_log, steps_at_log = t_start, step
    frames_this_call, frames_at_log = 0, 0
    if env.is_main:
        log.info("training %s on %s: %d torch thread(s)%s (OpenMP wait: %s), %s batches of %d, %d process(es)%s",
                 task.model_type, env.device, torch.get_num_threads(),
                 "" if env.device.startswith("cuda") else " per process", wait_policy(),
                 _runtime(task, config)["batching"], config.batch_size, env.world_size,
                 f", forward under {config.autocast} autocast" if config.autocast else "")
        if config.autocast == "bf16" and not env.device.startswith("cuda") and native_bf16_cpu() is False:
            log.warning("autocast='bf16' on a CPU without avx512_bf16/amx_bf16: bfloat16 is emulated here and "
                        "training is slower than in float32 (measured 1.6x for the VAE step, 1.8x for the "
                        "denoiser's); set \"autocast\": null in the config's train section to train in float32")
    steps_this_call = 0
    aux_seconds = 0.0  # validation and checkpoint time, left out of the reported speed
    objective.train()
    ctx = StepContext(GlobalBatchRandom(shared, env, env.device), env, train=True, step=step)

    try:
        with stop.installed():
            while step < total_steps and not interrupted:
                train_sampler.set_epoch(epoch)
                if hasattr(task.train_set, "set_epoch"):
                    task.train_set.set_epoch(epoch)
                if bucketing:
                    train_sampler.start = batch_in_epoch
                    batches = train_sampler
                else:
                    batches = ResumableBatchSampler(train_sampler, local_bs, drop_last=True, start=batch_in_epoch)
                loader = make_loader(task.train_set, batches, task.collate, config, env, seed=config.seed * 100_003 + epoch)
                finished_epoch = True
                for batch in loader:
                    lr = lr_at_step(step, config.lr, config.warmup_steps, config.milestones, config.gamma)
                    lr *= rewarm_factor(step, warm_from, config.warmup_steps)
                    set_lr(optimizer, lr)
                    ctx.step = step
                    inputs = task.prepare(batch, ctx)
                    optimizer.zero_grad(set_to_none=True)
                    losses = _forward_backward(objective, inputs, task, config, env)
                    if config.grad_clip is not None:
                        torch.nn.utils.clip_grad_norm_(params, config.grad_clip)
                    optimizer_step(optimizer, params)
                    step += 1
                    steps_this_call += 1
                    batch_in_epoch += 1
                    samples_seen += config.batch_size
                    frames_this_call += _batch_frames(batch) * env.world_size   # rank 0's count for every rank
                    avg.add(losses)
                    bar.update(1)
                    if on_step is not None:
                        on_step(step)

                    if step % config.log_every == 0 or step == total_steps:
                        means = avg.mean(env)
                        last_loss = means.get("loss", last_loss)
                        now = time.perf_counter()
                        span = max(now - t_log, 1e-9)
                        write_log({"step": step, "epoch": epoch, "lr": lr, **means,
                                   "steps_per_s": round((step - steps_at_log) / span, 4),
                                   "frames_per_s": round((frames_this_call - frames_at_log) / span, 1),
                                   "threads": torch.get_num_threads(),
                                   "elapsed_s": round(elapsed_before + now - t_start, 3)})
                        t_log, steps_at_log, frames_at_log = now, step, frames_this_call
                        bar.set_postfix(loss=f"{last_loss:.4g}" if last_loss is not None else "-", lr=f"{lr:.2e}")
                    if has_val and config.val_every and (step % config.val_every == 0 or step == total_steps):
                        t_aux = time.perf_counter()
                        val = validate(task, config, env.device, step) if env.is_main else None
                        val = broadcast_object(val, env)
                        is_best = best_val is None or val["loss"] < best_val
                        write_log({"step": step, "epoch": epoch, **{f"val_{k}": v for k, v in val.items()},
                                   "best": is_best})
                        if env.is_main:
                            log.info("step %d: validation loss %.5g%s", step, val["loss"], " (best)" if is_best else "")
                        if is_best:
                            best_val, best_step = val["loss"], step
                            if env.is_main:
                                save_checkpoint(out_dir / "best", model, model_type=task.model_type,
                                                config=task.model_config,
                                                meta={**task.meta, "step": step, "epoch": epoch, "val_loss": best_val})
                        aux_seconds += time.perf_counter() - t_aux
                    # all ranks must agree to stop at the same step, or the collectives would hang
                    stop_flag.fill_(1.0 if stop.requested else 0.0)
                    interrupted = bool(all_reduce_sum(stop_flag, env).item() > 0) if env.distributed else stop.requested
                    done = step >= total_steps
                    if interrupted or done or (config.ckpt_every and step % config.ckpt_every == 0):
                        t_aux = time.perf_counter()
                        checkpoint("interrupt" if interrupted else ("end" if done else "periodic"))
                        aux_seconds += time.perf_counter() - t_aux
                    if interrupted or done:
                        finished_epoch = batch_in_epoch >= steps_per_epoch
                        break
                if finished_epoch:
                    epoch += 1
                    batch_in_epoch = 0
    finally:
        bar.close()
    if total_steps == 0 and not state_path.exists():
        checkpoint("end")  # max_steps=0: still leave a loadable model and state
    seconds = time.perf_counter() - t_start - aux_seconds
    rate = steps_this_call / seconds if seconds > 0 else 0.0
    frame_rate = frames_this_call / seconds if seconds > 0 else 0.0
    if interrupted:
        log.warning("stopped at step %d by a signal; resume with resume=True (--resume)", step)
    return TrainResult(out_dir=out_dir, step=step, epoch=epoch, interrupted=interrupted, best_val=best_val,
                       best_step=best_step, last_loss=last_loss, steps_per_s=rate, frames_per_s=frame_rate,
                       threads=torch.get_num_threads())
