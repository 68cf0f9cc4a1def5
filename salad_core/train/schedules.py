"""Learning-rate schedule: linear warm-up, then step decay (paper supplement A.3).

The schedule is a pure function of the iteration, so resuming needs only the step counter and
there is no scheduler object whose state could drift from it.
"""
from __future__ import annotations

from bisect import bisect_right
from typing import Sequence

import torch

__all__ = ["lr_at_step", "set_lr"]


def lr_at_step(step: int, base_lr: float, warmup_steps: int, milestones: Sequence[int], gamma: float) -> float:
    """Learning rate for 0-based iteration ``step``.

    * ``step < warmup_steps``: ``base_lr * (step + 1) / (warmup_steps + 1)`` (the official
      ``update_lr_warm_up``);
    * afterwards: ``base_lr * gamma ** k`` with ``k`` the number of milestones ``m`` with
      ``m <= step - warmup_steps``, i.e. a ``MultiStepLR`` that is stepped once per iteration only
      after warm-up, as in the official trainers.

    The official code leaves the last warm-up value ``base_lr * warm / (warm + 1)`` in place
    (``MultiStepLR`` is multiplicative); we use ``base_lr`` exactly, 0.05 % apart at warm = 2000.
    """
    if step < 0:
        raise ValueError(f"step={step} is invalid; iterations are counted from 0")
    if step < warmup_steps:
        return base_lr * (step + 1) / (warmup_steps + 1)
    return base_lr * gamma ** bisect_right(list(milestones), step - warmup_steps)


def set_lr(optimizer: torch.optim.Optimizer, lr: float) -> None:
    """Set the learning rate of every parameter group."""
    for group in optimizer.param_groups:
        group["lr"] = lr
