"""The official SALAD release as a :class:`~salad_core.pipeline.SaladPipeline` (FULL mode of the notebooks).

- :func:`read_official_options`: an official ``opt.txt`` as a dict;
- :func:`official_salad_pipeline`: the released VAE, denoiser, normalisation and CLIP text encoder
  read from the release's ``checkpoints`` folder (layout: ``salad_official_facts`` §6).
"""
from __future__ import annotations

import ast
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from salad_core.pipeline import SaladPipeline

__all__ = ["read_official_options", "official_salad_pipeline"]

_OFFICIAL_DS = {"humanml3d": "t2m", "kit": "kit"}
_CLIP_FOLDERS = {"ViT-B/32": "clip-vit-base-patch32", "ViT-L/14": "clip-vit-large-patch14"}


def read_official_options(path: str | os.PathLike) -> dict[str, Any]:
    """Parse an official ``opt.txt`` (``key: value`` lines) into a dict.

    Values become bool, int, float or list where they read as such, else stay strings; the
    ``---- Options ----`` banner lines are skipped.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"official options file not found: {path}")
    out: dict[str, Any] = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        if ":" not in line or line.lstrip().startswith("-"):
            continue
        key, value = (s.strip() for s in line.split(":", 1))
        if not key:
            continue
        if value in ("True", "False"):
            out[key] = value == "True"
            continue
        try:
            lit = ast.literal_eval(value)     # literals only: numbers, lists, None, quoted strings
        except (ValueError, SyntaxError):
            lit = value
        out[key] = lit
    return out


def official_salad_pipeline(checkpoints_dir: str | os.PathLike, dataset: str = "humanml3d",
                            name: str = "t2m_denoiser_vpred_vaegelu", *, checkpoint: str = "net_best_fid",
                            text_encoder: Any = None, meta_dir: str | os.PathLike | None = None) -> "SaladPipeline":
    """A :class:`~salad_core.pipeline.SaladPipeline` with the official released weights.

    Reads the release's layout (``salad_official_facts`` §6)::

        checkpoints/<t2m|kit>/<name>/opt.txt               denoiser options (vae_name, clip_version, schedule)
        checkpoints/<t2m|kit>/<name>/model/<checkpoint>.tar
        checkpoints/<t2m|kit>/<vae_name>/model/<checkpoint>.tar   (and its opt.txt: activation)
        checkpoints/<t2m|kit>/Comp_v6_KLD005/meta/{mean,std}.npy  normalisation (as the official code)
        checkpoints/clip-vit-base-patch32/                 the CLIP text encoder (HF folder)

    Parameters
    ----------
    checkpoints_dir : path
        The release's ``checkpoints`` folder.
    dataset : {"humanml3d", "kit"}
    name : str
        Denoiser run name (the released HumanML3D one by default).
    checkpoint : str
        Checkpoint stem; inference in the official code always loads ``net_best_fid``.
    text_encoder : encoder or path, optional
        Default: the CLIP folder named by ``clip_version`` in ``opt.txt``.
    meta_dir : path, optional
        Folder with ``mean.npy``/``std.npy`` (default: the evaluator's ``Comp_v6_KLD005/meta``).
    """
    from salad_core.models import Denoiser, MotionVAE, load_official_checkpoint
    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import DiffusionConfig
    from salad_core.skeleton import get_skeleton
    from salad_core.text import load_text_encoder

    sk = get_skeleton(dataset)
    if sk.name not in _OFFICIAL_DS:
        raise ValueError(f"dataset={dataset!r}: the release has {sorted(_OFFICIAL_DS)}")
    root = Path(checkpoints_dir)
    ds_dir = root / _OFFICIAL_DS[sk.name]
    opt = read_official_options(ds_dir / name / "opt.txt")
    vae_name = opt.get("vae_name")
    if not vae_name:
        raise ValueError(f"{ds_dir / name / 'opt.txt'} names no vae_name; is {name!r} a SALAD denoiser run?")
    vae_opt_path = ds_dir / str(vae_name) / "opt.txt"
    vae_opt = read_official_options(vae_opt_path) if vae_opt_path.is_file() else {}

    vae = load_official_checkpoint(ds_dir / str(vae_name) / "model" / f"{checkpoint}.tar", "vae", sk.name)
    act = vae_opt.get("activation", vae.config.activation)
    if act != vae.config.activation:       # not readable from the weights (MotionVAE.from_official_state_dict)
        vae = MotionVAE.from_official_state_dict(vae.official_state_dict(), sk.name, activation=act).eval()
    denoiser = load_official_checkpoint(ds_dir / name / "model" / f"{checkpoint}.tar", "denoiser")
    heads = int(opt.get("n_heads", denoiser.config.heads))
    den_act = opt.get("activation", denoiser.config.activation)
    den_act = den_act if den_act in ("gelu", "relu") else "gelu"   # official: anything but "relu" is GELU
    if heads != denoiser.config.heads or den_act != denoiser.config.activation:
        denoiser = Denoiser.from_official_state_dict(denoiser.official_state_dict(), heads=heads,
                                                     activation=den_act).eval()

    meta = Path(meta_dir) if meta_dir is not None else ds_dir / "Comp_v6_KLD005" / "meta"
    for f in ("mean.npy", "std.npy"):
        if not (meta / f).is_file():
            raise FileNotFoundError(f"normalisation statistics {meta / f} not found; pass meta_dir")
    from salad_core import limits

    mean, std = limits.read_npy(meta / "mean.npy"), limits.read_npy(meta / "std.npy")
    limits.check_stats(mean, std, str(meta))

    if text_encoder is None or isinstance(text_encoder, (str, os.PathLike)):
        if text_encoder is None:
            version = str(opt.get("clip_version", "ViT-B/32"))
            if version not in _CLIP_FOLDERS:
                raise ValueError(f"clip_version {version!r} in opt.txt; known: {sorted(_CLIP_FOLDERS)}")
            text_encoder = root / _CLIP_FOLDERS[version]
        text_encoder = load_text_encoder(text_encoder)
    base = DiffusionConfig()
    diffusion = DiffusionConfig(
        num_train_timesteps=int(opt.get("num_train_timesteps", base.num_train_timesteps)),
        beta_start=float(opt.get("beta_start", base.beta_start)), beta_end=float(opt.get("beta_end", base.beta_end)),
        beta_schedule=str(opt.get("beta_schedule", base.beta_schedule)),
        prediction_type=str(opt.get("prediction_type", base.prediction_type)))
    return SaladPipeline(vae, denoiser, text_encoder, mean, std, diffusion=diffusion, solver="ddim",
                         source=f"official SALAD {name}/{checkpoint} ({root})")
