"""Continue a run from its weights alone: the warm start.

A run that is resumed exactly needs its whole train state (weights, AdamW moments, RNG streams:
``train_state.safetensors``, about three times the weights in float32). That is too large to keep in a
git repository stage after stage, and a run folder outside the repository is lost with the machine. A
*warm start* keeps only the weights of a step, in float16 (``warm_start.safetensors`` and
``warm_start.json`` in the run folder, the format of :func:`salad_core.io.save_checkpoint` with
``meta.step``), and the trainer (:func:`salad_core.train.common.train`, ``resume=True``) continues from it
when the run has no train state:

- the model takes the kept weights; the step counter, epoch and position in the epoch continue from the
  kept step (the data order of the epoch is the one an exact resume would have);
- AdamW starts with empty moments, so the learning rate is warmed up again over the config's
  ``warmup_steps`` (linearly from ``1 / warmup_steps`` of the scheduled rate; :func:`rewarm_factor`)
  instead of taking full-size sign-like first updates;
- the RNG streams are reseeded from the config's seed and the step.

So a warm-started run is not bit-identical to an uninterrupted one: the weights are rounded to float16
once, and the optimiser state is rebuilt. Every run of a stage of a staged study continues the same way,
so their comparison stays fair; the run's ``log.jsonl`` records the warm start.
"""
from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from pathlib import Path

import torch

from salad_core.io import CheckpointError, atomic_write_text, config_to_dict, read_checkpoint, save_tensors

__all__ = ["WARM_START", "WarmStart", "write_warm_start", "load_warm_start", "rewarm_factor"]

log = logging.getLogger(__name__)

#: File stem of a run folder's warm start.
WARM_START = "warm_start"


@dataclass(frozen=True)
class WarmStart:
    """Kept weights of a run at ``step``."""

    step: int
    model_type: str
    model_config: dict
    state: dict[str, torch.Tensor]
    source: str


def write_warm_start(checkpoint: str | Path, dest_stem: str | Path, *, dtype: torch.dtype = torch.float16) -> Path:
    """Write the weights of a run's checkpoint (``<stem>.safetensors`` + ``<stem>.json``, with ``meta.step``)
    as a warm start ``dest_stem.safetensors`` / ``.json``, floating tensors cast to ``dtype``.

    Returns the safetensors path. Raises :class:`~salad_core.io.CheckpointError` when the checkpoint has no step.
    """
    doc, state = read_checkpoint(checkpoint)
    step = doc.get("meta", {}).get("step")
    if step is None:
        raise CheckpointError(f"checkpoint {checkpoint} records no step (meta.step): it cannot be a warm start")
    dest = Path(dest_stem)
    dest.parent.mkdir(parents=True, exist_ok=True)
    cast = {k: (v.to(dtype) if v.is_floating_point() else v).contiguous() for k, v in state.items()}
    weights = save_tensors(dest.with_suffix(".safetensors"), cast, metadata={"type": doc["type"]})
    out = {"type": doc["type"], "config": doc["config"],
           "meta": {**doc.get("meta", {}), "step": int(step), "warm_start_of": str(checkpoint),
                    "dtype": str(dtype).replace("torch.", "")}}
    atomic_write_text(dest.with_suffix(".json"), json.dumps(out, indent=2) + "\n")
    return weights


def load_warm_start(run_dir: str | Path, model_type: str, model_config) -> WarmStart | None:
    """The warm start of ``run_dir`` (None when it has none).

    Raises :class:`~salad_core.io.CheckpointError` when it was written for another model type or
    another model configuration than the run's.
    """
    stem = Path(run_dir) / WARM_START
    if not stem.with_suffix(".json").is_file():
        return None
    doc, state = read_checkpoint(stem)
    if doc["type"] != model_type:
        raise CheckpointError(f"{stem}.json is a warm start of a {doc['type']!r} model; the run trains a "
                              f"{model_type!r}")
    want = json.loads(json.dumps(config_to_dict(model_config)))
    if doc["config"] != want:
        differ = sorted(k for k in set(want) | set(doc["config"]) if want.get(k) != doc["config"].get(k))
        raise CheckpointError(f"{stem}.json was written for another model configuration than the run's "
                              f"(fields {differ}): remove it, or train the run from its recipe")
    meta = doc.get("meta", {})
    return WarmStart(step=int(meta["step"]), model_type=doc["type"], model_config=doc["config"], state=state,
                     source=str(meta.get("warm_start_of", stem)))


def rewarm_factor(step: int, warm_from: int | None, warmup_steps: int) -> float:
    """The learning-rate factor of optimiser step ``step`` (0-based, before the update) of a run warm-started
    at ``warm_from``: ``min(1, (step - warm_from + 1) / warmup_steps)``; 1 when the run was not warm-started
    or ``warmup_steps`` is 0."""
    if warm_from is None or warmup_steps <= 0:
        return 1.0
    return min(1.0, (step - warm_from + 1) / warmup_steps)
