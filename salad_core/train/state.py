"""The resumable training state as ``train_state.safetensors`` + ``train_state.json``.

No pickles: every tensor (model weights, optimiser moments, RNG states) goes into one
safetensors file; every scalar (step, epoch, best metric, optimiser hyper-parameters, the
non-tensor parts of the RNG states) goes into a JSON document. The JSON document is stored twice:
inside the safetensors header (``metadata["state_json"]``), so the tensors and the scalars are
replaced by a single atomic rename and can never disagree, and as ``train_state.json`` for people
and tools to read.

Tensor names::

    model.<param>                 weights of the trained model at ``step``
    optim.<index>.<key>           optimiser state tensors (e.g. AdamW exp_avg, exp_avg_sq, step)
    rng.<rank>.torch              torch CPU generator state of each rank (dropout)
    rng.<rank>.cuda               torch CUDA generator state of each rank (when on a GPU)
    rng.<rank>.numpy              numpy MT19937 key of each rank
    rng.<rank>.python             python ``random`` state words of each rank
    rng.shared                    the generator shared by all ranks (noise, timesteps, cond drop)
"""
from __future__ import annotations

import json
import logging
import os
import random
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from salad_core.io import CheckpointError, atomic_write_text, load_tensors, save_tensors

__all__ = [
    "STATE_FORMAT",
    "RngState",
    "capture_rng",
    "restore_rng",
    "optimizer_to_flat",
    "optimizer_from_flat",
    "TrainState",
    "save_train_state",
    "load_train_state",
]

log = logging.getLogger(__name__)

STATE_FORMAT = "salad-train-state/1"


# --------------------------------------------------------------------------- RNG states
@dataclass
class RngState:
    """The global RNG states of one process: tensors plus JSON-ready scalars."""

    tensors: dict[str, torch.Tensor]
    scalars: dict[str, Any]


def capture_rng(device: str = "cpu") -> RngState:
    """Snapshot torch (CPU and, on a GPU, CUDA), numpy and python ``random`` global states."""
    tensors = {"torch": torch.get_rng_state().clone()}
    if device.startswith("cuda"):
        tensors["cuda"] = torch.cuda.get_rng_state(torch.device(device)).clone()
    name, key, pos, has_gauss, cached = np.random.get_state(legacy=True)
    tensors["numpy"] = torch.from_numpy(np.asarray(key, dtype=np.int64))
    version, words, gauss_next = random.getstate()
    tensors["python"] = torch.tensor(words, dtype=torch.int64)
    scalars = {"numpy": [name, int(pos), int(has_gauss), float(cached)], "python": [version, gauss_next]}
    return RngState(tensors, scalars)


def restore_rng(state: RngState, device: str = "cpu") -> None:
    """Inverse of :func:`capture_rng`."""
    torch.set_rng_state(state.tensors["torch"].to(torch.uint8))
    if "cuda" in state.tensors and device.startswith("cuda"):
        torch.cuda.set_rng_state(state.tensors["cuda"].to(torch.uint8), torch.device(device))
    name, pos, has_gauss, cached = state.scalars["numpy"]
    np.random.set_state((name, state.tensors["numpy"].numpy().astype(np.uint32), pos, has_gauss, cached))
    version, gauss_next = state.scalars["python"]
    random.setstate((version, tuple(int(w) for w in state.tensors["python"].tolist()), gauss_next))


# --------------------------------------------------------------------------- optimiser
def optimizer_to_flat(optimizer: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], dict[str, Any]]:
    """Split ``optimizer.state_dict()`` into tensors ``optim.<i>.<key>`` and a JSON part."""
    sd = optimizer.state_dict()
    tensors: dict[str, torch.Tensor] = {}
    scalars: dict[str, dict[str, Any]] = {}
    for index, entry in sd["state"].items():
        for key, value in entry.items():
            if torch.is_tensor(value):
                tensors[f"optim.{index}.{key}"] = value
            else:
                scalars.setdefault(str(index), {})[key] = value
    doc = {"class": type(optimizer).__name__, "param_groups": sd["param_groups"], "state_scalars": scalars}
    return tensors, json.loads(json.dumps(doc))


#: Optimiser options that choose how the update is computed, not what it is.
_IMPLEMENTATION_KEYS = ("fused", "foreach")


def optimizer_from_flat(optimizer: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], doc: dict[str, Any]) -> None:
    """Load what :func:`optimizer_to_flat` wrote into ``optimizer`` (same parameter layout)."""
    if doc.get("class") != type(optimizer).__name__:
        raise CheckpointError(f"train state holds a {doc.get('class')} optimiser, the trainer uses {type(optimizer).__name__}")
    state: dict[int, dict[str, Any]] = {}
    for name, value in tensors.items():
        if not name.startswith("optim."):
            continue
        _, index, key = name.split(".", 2)
        state.setdefault(int(index), {})[key] = value
    for index, entry in doc.get("state_scalars", {}).items():
        state.setdefault(int(index), {}).update(entry)
    groups = []
    for group in doc["param_groups"]:
        group = dict(group)
        if "betas" in group:
            group["betas"] = tuple(group["betas"])
        groups.append(group)
    own = optimizer.state_dict()["param_groups"]
    if [len(g["params"]) for g in own] != [len(g["params"]) for g in groups]:
        raise CheckpointError("train state optimiser has a different parameter layout than the model")
    for group, mine in zip(groups, own):          # the implementation is the trainer's (TrainConfig.adamw),
        for key in _IMPLEMENTATION_KEYS:          # not the saved run's: the update is the same
            if key in mine:
                group[key] = mine[key]
    optimizer.load_state_dict({"state": state, "param_groups": groups})


# --------------------------------------------------------------------------- whole state
@dataclass
class TrainState:
    """Everything a run needs to continue exactly where it stopped."""

    step: int                                   # optimiser steps completed
    epoch: int                                  # current epoch (data order is seeded by it)
    batch_in_epoch: int                         # batches of ``epoch`` already consumed
    model_state: dict[str, torch.Tensor]        # weights after ``step`` steps
    optim_tensors: dict[str, torch.Tensor]      # see optimizer_to_flat
    optim_doc: dict[str, Any]
    rng: list[RngState]                         # one per rank, in rank order
    shared_rng: torch.Tensor                    # state of the generator shared by all ranks
    best_val: float | None = None               # best validation loss so far
    best_step: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)  # lr, elapsed time, samples seen, ...

    def to_doc(self) -> dict[str, Any]:
        return {
            "format": STATE_FORMAT,
            "step": self.step,
            "epoch": self.epoch,
            "batch_in_epoch": self.batch_in_epoch,
            "world_size": len(self.rng),
            "best_val": self.best_val,
            "best_step": self.best_step,
            "optimizer": self.optim_doc,
            "rng": [r.scalars for r in self.rng],
            **self.extra,
        }


def save_train_state(out_dir: str | os.PathLike, state: TrainState) -> Path:
    """Write ``train_state.safetensors`` then ``train_state.json`` (each atomically)."""
    out_dir = Path(out_dir)
    doc = state.to_doc()
    text = json.dumps(doc, indent=2) + "\n"
    tensors: dict[str, torch.Tensor] = {f"model.{k}": v for k, v in state.model_state.items()}
    tensors.update(state.optim_tensors)
    for rank, rng in enumerate(state.rng):
        for key, value in rng.tensors.items():
            tensors[f"rng.{rank}.{key}"] = value
    tensors["rng.shared"] = state.shared_rng
    path = save_tensors(out_dir / "train_state.safetensors", tensors,
                        metadata={"format": STATE_FORMAT, "step": str(state.step), "state_json": text})
    atomic_write_text(out_dir / "train_state.json", text)
    return path


def load_train_state(out_dir: str | os.PathLike) -> TrainState:
    """Read the train state written by :func:`save_train_state`.

    The scalars come from the safetensors header, so they always match the tensors; a differing
    ``train_state.json`` (a crash between the two renames) is reported and ignored.
    """
    from safetensors import safe_open

    out_dir = Path(out_dir)
    path = out_dir / "train_state.safetensors"
    tensors = load_tensors(path)  # raises CheckpointError if missing or corrupt
    with safe_open(str(path), framework="pt") as fh:
        meta = fh.metadata() or {}
    if meta.get("format") != STATE_FORMAT or "state_json" not in meta:
        raise CheckpointError(f"{path} is not a salad train state (format {meta.get('format')!r}, expected {STATE_FORMAT!r})")
    doc = json.loads(meta["state_json"])
    side = out_dir / "train_state.json"
    if side.is_file():
        try:
            if json.loads(side.read_text()).get("step") != doc["step"]:
                log.warning("%s disagrees with %s; using the step-%d state in the weights file", side, path, doc["step"])
        except json.JSONDecodeError:
            log.warning("%s is not valid JSON; using the state in %s", side, path)
    model_state = {k[len("model."):]: v for k, v in tensors.items() if k.startswith("model.")}
    optim_tensors = {k: v for k, v in tensors.items() if k.startswith("optim.")}
    rng = []
    for rank, scalars in enumerate(doc["rng"]):
        prefix = f"rng.{rank}."
        rng.append(RngState({k[len(prefix):]: v for k, v in tensors.items() if k.startswith(prefix)}, scalars))
    known = {"format", "step", "epoch", "batch_in_epoch", "world_size", "best_val", "best_step", "optimizer", "rng"}
    return TrainState(
        step=int(doc["step"]), epoch=int(doc["epoch"]), batch_in_epoch=int(doc["batch_in_epoch"]),
        model_state=model_state, optim_tensors=optim_tensors, optim_doc=doc["optimizer"], rng=rng,
        shared_rng=tensors["rng.shared"], best_val=doc.get("best_val"), best_step=doc.get("best_step"),
        extra={k: v for k, v in doc.items() if k not in known},
    )
