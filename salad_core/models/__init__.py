"""SALAD's networks: the skeleto-temporal VAE and the skeleton-aware denoiser.

Importing this package registers the SALAD model types; :func:`salad_core.io.load_model` also
imports the evaluator and KeyMotion modules, which register theirs.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import torch

from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.models.vae import MotionVAE, VAEConfig

__all__ = ["MotionVAE", "VAEConfig", "Denoiser", "DenoiserConfig", "load_official_checkpoint"]

_OFFICIAL_KEYS = {"vae": ("vae",), "denoiser": ("denoiser",)}


def load_official_checkpoint(path_or_state_dict: str | Path | Mapping[str, torch.Tensor], kind: str = "denoiser",
                             dataset: str = "humanml3d") -> torch.nn.Module:
    """Build our module from an official SALAD checkpoint (``net_best_fid.tar`` etc.).

    Parameters
    ----------
    path_or_state_dict : path or mapping
        A checkpoint file, read with ``torch.load(..., weights_only=True)`` (never unpickles code),
        or an already loaded dict: either the state dict itself or the official wrapper
        ``{"vae": ...}`` / ``{"denoiser": ...}``.
    kind : {"vae", "denoiser"}
    dataset : {"humanml3d", "kit"}
        Skeleton of the VAE (the denoiser does not depend on it).

    Returns
    -------
    torch.nn.Module
        :class:`MotionVAE` or :class:`Denoiser` in eval mode with the official weights.
    """
    if kind not in _OFFICIAL_KEYS:
        raise ValueError(f"kind must be 'vae' or 'denoiser', got {kind!r}")
    if isinstance(path_or_state_dict, (str, Path)):
        path = Path(path_or_state_dict)
        if not path.is_file():
            raise FileNotFoundError(f"official checkpoint not found: {path}")
        try:
            obj = torch.load(path, map_location="cpu", weights_only=True)
        except Exception as exc:
            raise ValueError(f"cannot read official checkpoint {path} with weights_only=True: {exc}") from exc
    else:
        obj = path_or_state_dict
    if not isinstance(obj, Mapping):
        raise ValueError(f"official checkpoint must be a dict, got {type(obj).__name__}")
    for key in _OFFICIAL_KEYS[kind]:
        if key in obj and isinstance(obj[key], Mapping):
            obj = obj[key]
            break
    state = {k: v for k, v in obj.items() if isinstance(v, torch.Tensor)}
    if kind == "vae":
        model = MotionVAE.from_official_state_dict(state, dataset=dataset)
    else:
        state = {k: v for k, v in state.items() if not k.startswith("clip_model.") and "_cache_" not in k}
        model = Denoiser.from_official_state_dict(state)
    return model.eval()
