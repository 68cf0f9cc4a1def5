"""Process-group setup for ``torchrun`` and the small collectives the trainers need.

Under ``torchrun --nproc_per_node=N`` the environment holds ``RANK``, ``WORLD_SIZE`` and
``LOCAL_RANK``; the backend is NCCL on GPUs and gloo on CPU. Without those variables everything
here degrades to a single process (world size 1) and no collective is called.

Randomness that the loss depends on (diffusion timesteps, noise, VAE reparameterisation noise,
caption dropping) is drawn by :class:`GlobalBatchRandom`: every rank holds an identically seeded
generator, draws the values for the whole *global* batch and keeps the rows of its own samples.
With :class:`torch.utils.data.DistributedSampler` the rank-``r`` sample ``i`` of a step is global
sample ``r + W*i``, so a sample meets the same noise whatever the number of processes, and a run on
``W`` processes reproduces a single-process run with the same global batch.
"""
from __future__ import annotations

import datetime
import logging
import os
from dataclasses import dataclass
from typing import Any, Sequence

import torch
import torch.distributed as dist

__all__ = [
    "DistEnv",
    "init_distributed",
    "shutdown_distributed",
    "all_reduce_sum",
    "all_gather_objects",
    "broadcast_object",
    "barrier",
    "GlobalBatchRandom",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DistEnv:
    """Where this process sits in the job."""

    rank: int = 0                   # global rank
    world_size: int = 1             # number of processes
    local_rank: int = 0             # rank on this machine (GPU index)
    local_world_size: int = 1       # processes on this machine
    device: str = "cpu"             # torch device string of this process

    @property
    def is_main(self) -> bool:
        """Only the main process writes files, logs and shows progress."""
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.world_size > 1


def _env_int(name: str, default: int) -> int:
    value = os.environ.get(name)
    if value is None or value == "":
        return default
    try:
        return int(value)
    except ValueError:
        raise ValueError(f"environment variable {name}={value!r} is not an integer") from None


def init_distributed(device: str = "auto", timeout_s: float = 1800.0) -> DistEnv:
    """Join the ``torchrun`` process group if the environment describes one.

    Parameters
    ----------
    device : "auto", "cpu", "cuda" or "cuda:N"
        "auto" picks ``cuda:LOCAL_RANK`` when CUDA is available, else the CPU. Under DDP with
        CUDA the local rank always selects the GPU.
    timeout_s : float
        Collective timeout.
    """
    world = _env_int("WORLD_SIZE", 1)
    rank = _env_int("RANK", 0)
    local_rank = _env_int("LOCAL_RANK", 0)
    local_world = _env_int("LOCAL_WORLD_SIZE", world)
    use_cuda = torch.cuda.is_available() if device == "auto" else device.startswith("cuda")
    if use_cuda and not torch.cuda.is_available():
        raise RuntimeError(f"device={device!r} was asked for but CUDA is not available; use 'cpu' or 'auto'")
    if use_cuda:
        index = local_rank if (world > 1 or device in ("auto", "cuda")) else int(device.split(":")[1])
        dev = f"cuda:{index}"
        torch.cuda.set_device(index)
    else:
        dev = "cpu"
    if world > 1 and not dist.is_initialized():
        if not 0 <= rank < world:
            raise ValueError(f"RANK={rank} is outside WORLD_SIZE={world}")
        backend = "nccl" if use_cuda else "gloo"
        dist.init_process_group(backend=backend, rank=rank, world_size=world,
                                timeout=datetime.timedelta(seconds=timeout_s))
        log.info("joined process group: rank %d of %d (%s, %s)", rank, world, backend, dev)
    elif dist.is_initialized():
        world, rank = dist.get_world_size(), dist.get_rank()
    return DistEnv(rank=rank, world_size=world, local_rank=local_rank,
                   local_world_size=max(1, local_world), device=dev)


def shutdown_distributed() -> None:
    """Leave the process group (no-op without one)."""
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def all_reduce_sum(tensor: torch.Tensor, env: DistEnv) -> torch.Tensor:
    """Sum ``tensor`` over ranks in place (no-op on one process); returns it."""
    if env.distributed:
        dist.all_reduce(tensor, op=dist.ReduceOp.SUM)
    return tensor


def all_gather_objects(obj: Any, env: DistEnv) -> list[Any]:
    """Every rank's ``obj`` (picklable, produced by this process), in rank order."""
    if not env.distributed:
        return [obj]
    out: list[Any] = [None] * env.world_size
    dist.all_gather_object(out, obj)
    return out


def broadcast_object(obj: Any, env: DistEnv, src: int = 0) -> Any:
    """Rank ``src``'s ``obj`` on every rank (picklable, produced by this process)."""
    if not env.distributed:
        return obj
    box = [obj if env.rank == src else None]
    dist.broadcast_object_list(box, src=src)
    return box[0]


def barrier(env: DistEnv) -> None:
    if env.distributed:
        dist.barrier()


class GlobalBatchRandom:
    """Random draws for a global batch, of which this rank keeps its own rows.

    Parameters
    ----------
    generator : torch.Generator
        Seeded identically on every rank (CPU generator; values are moved to ``device``).
    env : DistEnv
        This process; rows ``rank, rank + W, rank + 2W, ...`` of each draw are kept.
    device : str
        Device of the returned tensors.
    """

    def __init__(self, generator: torch.Generator, env: DistEnv, device: str | torch.device = "cpu") -> None:
        self.generator = generator
        self.env = env
        self.device = torch.device(device)

    def _local(self, full: torch.Tensor) -> torch.Tensor:
        return full[self.env.rank::self.env.world_size].to(self.device, non_blocking=True)

    def global_size(self, local_batch: int) -> int:
        return local_batch * self.env.world_size

    def randn(self, local_batch: int, shape: Sequence[int]) -> torch.Tensor:
        """Standard normal ``(local_batch, *shape)``."""
        full = torch.randn((self.global_size(local_batch), *shape), generator=self.generator)
        return self._local(full)

    def rand(self, local_batch: int, shape: Sequence[int] = ()) -> torch.Tensor:
        """Uniform [0, 1) ``(local_batch, *shape)``."""
        full = torch.rand((self.global_size(local_batch), *shape), generator=self.generator)
        return self._local(full)

    def randint(self, local_batch: int, high: int, low: int = 0) -> torch.Tensor:
        """Integers in ``[low, high)``, shape ``(local_batch,)`` (long)."""
        full = torch.randint(low, high, (self.global_size(local_batch),), generator=self.generator)
        return self._local(full)
