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
    "read_checkpoint_doc",
    "checkpoint_files",
    "build_model",
    "load_model",
    "CheckpointError",
    "CheckpointTypeError",
]


_UMASK = os.umask(0)
os.umask(_UMASK)


class CheckpointError(ValueError):
    """A checkpoint is missing, truncated, corrupt or does not fit the model; or a weight folder's JSON
    is invalid, beyond the limits of :mod:`salad_core.limits`, or names a file outside the folder."""


class CheckpointTypeError(CheckpointError, TypeError):
    """A weight folder's JSON holds a value of the wrong type (``"solver": 42``): both a
    :class:`CheckpointError` and a :class:`TypeError`."""


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

    from salad_core import limits

    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"weight file not found: {path}")
    limits.check_file_size(path, limits.CHECKPOINT_MAX_BYTES, "weight file", CheckpointError)
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


#: The keys of a checkpoint's ``<stem>.json``.
CHECKPOINT_KEYS = ("type", "config", "meta")


def read_checkpoint_doc(cfg_path: str | os.PathLike) -> dict[str, Any]:
    """The checked ``{"type", "config", "meta"}`` document of a checkpoint's ``.json``.

    Read with :func:`salad_core.limits.read_json` (size, UTF-8, nesting before parsing); ``type`` must
    be a string, ``config`` and ``meta`` objects, and no other key may appear (a misspelt one is named
    with the closest known key). Raises :class:`CheckpointError` (:class:`CheckpointTypeError` for a
    wrong type).
    """
    from salad_core import limits

    cfg_path = Path(cfg_path)
    if not cfg_path.is_file():
        raise CheckpointError(f"checkpoint config not found: {cfg_path}")
    doc = limits.read_json(cfg_path, "checkpoint config", error=CheckpointError, expect=None)
    if not isinstance(doc, dict) or "type" not in doc or "config" not in doc:
        raise CheckpointError(f"checkpoint config {cfg_path} lacks the 'type' and 'config' keys")
    limits.check_fields(doc, {"type": str, "config": dict, "meta": dict}, str(cfg_path), CheckpointError,
                        CheckpointTypeError)
    return doc


def checkpoint_files(stem_or_path: str | os.PathLike) -> tuple[Path, Path]:
    """``(<stem>.json, <stem>.safetensors)`` of a checkpoint given its stem, .json or .safetensors path:
    the two files :func:`read_checkpoint` opens."""
    p = Path(stem_or_path)
    stem = p.with_suffix("") if p.suffix in (".json", ".safetensors") else p
    try:
        return stem.with_suffix(".json"), stem.with_suffix(".safetensors")
    except ValueError as exc:       # a path with an empty name ("/")
        raise CheckpointError(f"{stem_or_path} is not a checkpoint path ({exc})") from None


def read_checkpoint(stem_or_path: str | os.PathLike) -> tuple[dict[str, Any], dict[str, torch.Tensor]]:
    """Return ``(doc, state_dict)`` for a checkpoint given its stem, .json or .safetensors path
    (:func:`checkpoint_files`; the document checked by :func:`read_checkpoint_doc`, the weights by
    :func:`load_tensors`)."""
    cfg_path, weights_path = checkpoint_files(stem_or_path)
    doc = read_checkpoint_doc(cfg_path)
    return doc, load_tensors(weights_path)


def _state_mismatch(own: dict[str, Any], state: dict[str, torch.Tensor], source: str) -> list[str]:
    """What keeps ``state`` from loading into a model whose state dict is ``own`` (empty: it fits)."""
    missing = sorted(set(own) - set(state))
    unexpected = sorted(set(state) - set(own))
    bad_shape = [k for k in own if k in state and tuple(own[k].shape) != tuple(state[k].shape)]
    parts = []
    if missing:
        parts.append(f"missing keys {missing[:5]}{'...' if len(missing) > 5 else ''}")
    if unexpected:
        parts.append(f"unexpected keys {unexpected[:5]}{'...' if len(unexpected) > 5 else ''}")
    if bad_shape:
        k = bad_shape[0]
        parts.append(f"shape mismatch at {k}: model {tuple(own[k].shape)} vs {source} {tuple(state[k].shape)}")
    return parts


def load_state_into(model: torch.nn.Module, state: dict[str, torch.Tensor], *, source: str = "checkpoint") -> None:
    """Strictly load ``state`` into ``model`` (casting dtypes), with a clear error on mismatch."""
    own = model.state_dict()
    parts = _state_mismatch(own, state, source)
    if parts:
        raise CheckpointError(f"{source} does not fit {type(model).__name__}: " + "; ".join(parts))
    cast = {k: v.to(own[k].dtype) for k, v in state.items()}
    model.load_state_dict(cast, strict=True)


# registry of model types that checkpoints can rebuild: type -> (config class, builder)
_REGISTRY: dict[str, tuple[type, Callable[[Any], torch.nn.Module]]] = {}


def register_model(model_type: str, config_cls: type, builder: Callable[[Any], torch.nn.Module]) -> None:
    """Register how to rebuild ``model_type`` from its config dict (called by model modules)."""
    _REGISTRY[model_type] = (config_cls, builder)


_REGISTRY_MODULES = ("salad_core.models", "salad_core.eval.t2m", "salad_core.keymotion.kf_vae",
                     "salad_core.keymotion.pst", "salad_core.keymotion.mmae", "salad_core.eval.train_evaluator",
                     "salad_core.train.consistency")


def _import_model_registries() -> None:
    """Import every module that registers model types (lazily, to avoid import cycles)."""
    import importlib

    for mod in _REGISTRY_MODULES:
        importlib.import_module(mod)


def _check_model_fits(builder: Callable[[Any], torch.nn.Module], config: Any, state: dict[str, torch.Tensor],
                      source: str) -> None:
    """Build the model on PyTorch's meta device (shapes only, no memory) and refuse, before the real
    build allocates anything, a model over :data:`salad_core.limits.MODEL_MAX_BYTES` or one the
    checkpoint's tensors do not fit (a config asking for a positional table of 10^10 rows whose file
    holds 5000). A builder that cannot run on the meta device is skipped (the real build checks)."""
    from salad_core import limits

    try:
        with torch.device("meta"):
            ghost = builder(config)
    except Exception:
        return
    tensors = [*ghost.named_parameters(), *ghost.named_buffers()]
    total = sum(t.numel() * t.element_size() for _, t in tensors)
    if total > limits.MODEL_MAX_BYTES:
        name, big = max(tensors, key=lambda nt: nt[1].numel() * nt[1].element_size())
        raise CheckpointError(f"{source}: its config builds a {type(ghost).__name__} of {limits.human_bytes(total)}, "
                              f"over the limit of {limits.human_bytes(limits.MODEL_MAX_BYTES)} (largest: {name} "
                              f"{tuple(big.shape)}); the config does not match the weights")
    parts = _state_mismatch(ghost.state_dict(), state, source)
    if parts:
        raise CheckpointError(f"{source} does not fit {type(ghost).__name__} as its config describes it: "
                              + "; ".join(parts))


def build_model(doc: dict[str, Any], state: dict[str, torch.Tensor], source: str,
                expected_type: str | None = None, config_source: str | None = None) -> tuple[torch.nn.Module, Any]:
    """The model of a checkpoint document (:func:`read_checkpoint`) with ``state`` loaded, in eval mode,
    and its config. The config is checked (:func:`config_from_dict` with ``source``: keys, JSON types,
    integers within :data:`salad_core.limits.CONFIG_MAX_INT`) and the model's size and shapes checked on
    the meta device before the real build; ``expected_type`` refuses another model type. Messages name
    ``source`` (``config_source`` for the config's, default ``source``)."""
    _import_model_registries()
    kind = doc["type"]
    if expected_type is not None and kind != expected_type:
        raise CheckpointError(f"{source} holds a {kind!r}, not a {expected_type!r}")
    if kind not in _REGISTRY:
        raise CheckpointError(f"unknown model type {kind!r} in {source}; known: {sorted(_REGISTRY)}")
    config_cls, builder = _REGISTRY[kind]
    config = config_from_dict(config_cls, doc["config"], source=f"{config_source or source}: 'config'")
    _check_model_fits(builder, config, state, source)
    model = builder(config)
    load_state_into(model, state, source=source)
    return model.eval(), config


def load_model(stem_or_path: str | os.PathLike, *, expected_type: str | None = None
               ) -> tuple[torch.nn.Module, Any, dict[str, Any]]:
    """Rebuild a model from our checkpoint alone; returns ``(model in eval mode, config, meta)``.

    Every problem (a missing, oversized, truncated or invalid file, a config of the wrong types or
    beyond the limits, weights that do not fit) raises :class:`CheckpointError` naming the file.
    """
    doc, state = read_checkpoint(stem_or_path)
    model, config = build_model(doc, state, str(stem_or_path), expected_type, str(checkpoint_files(stem_or_path)[0]))
    return model, config, doc.get("meta", {})


def config_from_dict(config_cls: type, data: dict[str, Any], *, source: str | None = None) -> Any:
    """Build a (frozen) config dataclass from a dict, turning lists back into tuples and
    rejecting unknown keys with a clear error (naming the closest known key).

    With ``source`` (where the dict comes from, e.g. ``"<folder>/pipeline.json: 'diffusion'"``) the dict
    is from outside: every value's JSON type is checked against the field's annotation, integers must
    lie within :data:`salad_core.limits.CONFIG_MAX_INT`, and anything the dataclass refuses raises
    :class:`CheckpointError` (:class:`CheckpointTypeError` for a wrong type) naming ``source``.
    """
    from salad_core import limits

    where = source or config_cls.__name__
    if not isinstance(data, dict):
        err = CheckpointTypeError if source else TypeError
        raise err(f"{where} must be an object {{...}} of {config_cls.__name__} fields, got {type(data).__name__} "
                  f"{limits.short_json(data)}")
    fields = {f.name: f for f in dataclasses.fields(config_cls)}
    unknown = [k for k in data if k not in fields]
    if unknown:
        raise CheckpointError(f"{where}: unknown config keys [{limits.unknown_keys_message(unknown, fields)}] for "
                              f"{config_cls.__name__}; known: {', '.join(fields)}")
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items()}
    if source is None:
        return config_cls(**kwargs)
    limits.check_config_values(config_cls, data, where, CheckpointError, CheckpointTypeError)
    try:
        return config_cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{where}: {exc}") from None
