"""Safe, atomic file I/O for checkpoints and outputs.

Our checkpoint format is a pair of files sharing a stem: ``<stem>.safetensors`` (the weights)
and ``<stem>.json`` (``{"type": <registered model type>, "config": {...}, "meta": {...}}``),
so a checkpoint rebuilds its model alone. Every write goes to a temporary file in the same
folder and is renamed into place, so an interrupted save never leaves a corrupt file and the
previous version stays intact. Nothing here unpickles anything.
"""
from __future__ import annotations

import dataclasses
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterator

import torch

__all__ = [
    "atomic_path",
    "atomic_write_bytes",
    "atomic_write_text",
    "save_tensors",
    "load_tensors",
    "config_to_dict",
    "save_checkpoint",
    "read_checkpoint",
    "CheckpointError",
]


_UMASK = os.umask(0)
os.umask(_UMASK)


class CheckpointError(ValueError):
    """A checkpoint is missing, truncated, corrupt or does not fit the model."""


@contextmanager
def atomic_path(path: str | os.PathLike, *, overwrite: bool = True) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    On any exception (including ``KeyboardInterrupt`` and a full disk) the temporary file is
    removed and ``path`` is left as it was.
    """
    path = Path(path)
    if not overwrite and path.exists():
        raise FileExistsError(f"{path} exists; pass --force (overwrite=True) to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        with open(tmp_path, "rb") as fh:  # make the bytes durable before the rename
            os.fsync(fh.fileno())
        os.chmod(tmp_path, 0o644 & ~_UMASK)  # mkstemp creates 0600; outputs are ordinary files
        os.replace(tmp_path, path)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, overwrite: bool = True) -> Path:
    with atomic_path(path, overwrite=overwrite) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path: str | os.PathLike, text: str, *, overwrite: bool = True) -> Path:
    return atomic_write_bytes(path, text.encode("utf-8"), overwrite=overwrite)


def save_tensors(path: str | os.PathLike, tensors: dict[str, torch.Tensor],
                 metadata: dict[str, str] | None = None, *, overwrite: bool = True) -> Path:
    """Write a dict of tensors as safetensors, atomically (contiguous CPU copies are made)."""
    from safetensors.torch import save_file

    flat = {k: v.detach().to("cpu").contiguous() for k, v in tensors.items()}
    with atomic_path(path, overwrite=overwrite) as tmp:
        save_file(flat, str(tmp), metadata=metadata)
    return Path(path)


def load_tensors(path: str | os.PathLike) -> dict[str, torch.Tensor]:
    """Read a safetensors file; a missing, truncated or corrupt file raises :class:`CheckpointError`."""
    from safetensors.torch import load_file

    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"weight file not found: {path}")
    try:
        return load_file(str(path))
    except Exception as exc:  # safetensors raises several types for bad headers / short files
        raise CheckpointError(f"cannot read weight file {path} (truncated or corrupt?): {exc}") from exc


def config_to_dict(config: Any) -> dict[str, Any]:
    """A frozen config dataclass as a JSON-ready dict (tuples become lists)."""
    if dataclasses.is_dataclass(config):
        return json.loads(json.dumps(dataclasses.asdict(config)))
    if isinstance(config, dict):
        return json.loads(json.dumps(config))
    raise TypeError(f"config must be a dataclass or dict, got {type(config).__name__}")


def save_checkpoint(stem: str | os.PathLike, model: torch.nn.Module, *, model_type: str, config: Any,
                    meta: dict[str, Any] | None = None, dtype: torch.dtype | None = None,
                    overwrite: bool = True) -> Path:
    """Write ``<stem>.safetensors`` and ``<stem>.json``; returns the safetensors path.

    ``dtype`` (e.g. ``torch.float16``) casts floating tensors for compact storage; loading casts
    back to the model's dtype. Non-persistent buffers are not saved.
    """
    stem = Path(stem)
    state = model.state_dict()
    if dtype is not None:
        state = {k: (v.to(dtype) if v.is_floating_point() else v) for k, v in state.items()}
    weights = stem.with_suffix(".safetensors")
    save_tensors(weights, state, metadata={"type": model_type}, overwrite=overwrite)
    doc = {"type": model_type, "config": config_to_dict(config), "meta": meta or {}}
    atomic_write_text(stem.with_suffix(".json"), json.dumps(doc, indent=2) + "\n", overwrite=overwrite)
    return weights


def read_checkpoint(stem_or_path: str | os.PathLike) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """Return ``(doc, state_dict)`` for a checkpoint given its stem, .json or .safetensors path."""
    p = Path(stem_or_path)
    stem = p.with_suffix("") if p.suffix in (".json", ".safetensors") else p
    cfg_path = stem.with_suffix(".json")
    if not cfg_path.is_file():
        raise CheckpointError(f"checkpoint config not found: {cfg_path}")
    try:
        doc = json.loads(cfg_path.read_text())
    except json.JSONDecodeError as exc:
        raise CheckpointError(f"checkpoint config {cfg_path} is not valid JSON: {exc}") from exc
    if not isinstance(doc, dict) or "type" not in doc or "config" not in doc:
        raise CheckpointError(f"checkpoint config {cfg_path} lacks the 'type' and 'config' keys")
    return doc, load_tensors(stem.with_suffix(".safetensors"))


def load_state_into(model: torch.nn.Module, state: dict[str, torch.Tensor], *, source: str = "checkpoint") -> None:
    """Strictly load ``state`` into ``model`` (casting dtypes), with a clear error on mismatch."""
    own = model.state_dict()
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    bad_shape = [k for k in own if k in state and tuple(own[k].shape) != tuple(state[k].shape)]
    if missing or unexpected or bad_shape:
        parts = []
        if missing:
            parts.append(f"missing keys {missing[:5]}{'...' if len(missing) > 5 else ''}")
        if unexpected:
            parts.append(f"unexpected keys {unexpected[:5]}{'...' if len(unexpected) > 5 else ''}")
        if bad_shape:
            k = bad_shape[0]
            parts.append(f"shape mismatch at {k}: model {tuple(own[k].shape)} vs {source} {tuple(state[k].shape)}")
        raise CheckpointError(f"{source} does not fit {type(model).__name__}: " + "; ".join(parts))
    cast = {k: v.to(own[k].dtype) for k, v in state.items()}
    model.load_state_dict(cast, strict=True)


# registry of model types that checkpoints can rebuild: type -> (config class, builder)
_REGISTRY: dict[str, tuple[type, Callable[[Any], torch.nn.Module]]] = {}


def register_model(model_type: str, config_cls: type, builder: Callable[[Any], torch.nn.Module]) -> None:
    """Register how to rebuild ``model_type`` from its config dict (called by model modules)."""
    _REGISTRY[model_type] = (config_cls, builder)


_REGISTRY_MODULES = ("salad_core.models", "salad_core.eval.t2m", "salad_core.keymotion.kf_vae",
                     "salad_core.keymotion.pst", "salad_core.keymotion.mmae", "salad_core.eval.train_evaluator")


def _import_model_registries() -> None:
    """Import every module that registers model types (lazily, to avoid import cycles)."""
    import importlib

    for mod in _REGISTRY_MODULES:
        importlib.import_module(mod)


def load_model(stem_or_path: str | os.PathLike) -> tuple[torch.nn.Module, Any, dict[str, Any]]:
    """Rebuild a model from our checkpoint alone; returns ``(model in eval mode, config, meta)``."""
    _import_model_registries()

    doc, state = read_checkpoint(stem_or_path)
    if doc["type"] not in _REGISTRY:
        raise CheckpointError(f"unknown model type {doc['type']!r} in {stem_or_path}; known: {sorted(_REGISTRY)}")
    config_cls, builder = _REGISTRY[doc["type"]]
    config = config_from_dict(config_cls, doc["config"])
    model = builder(config)
    load_state_into(model, state, source=str(stem_or_path))
    return model.eval(), config, doc.get("meta", {})


def config_from_dict(config_cls: type, data: dict[str, Any]) -> Any:
    """Build a (frozen) config dataclass from a dict, turning lists back into tuples and
    rejecting unknown keys with a clear error."""
    fields = {f.name: f for f in dataclasses.fields(config_cls)}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise CheckpointError(f"{config_cls.__name__}: unknown config keys {unknown}")
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items()}
    return config_cls(**kwargs)
