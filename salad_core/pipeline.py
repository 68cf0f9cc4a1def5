"""SaladPipeline: text -> motion, the thin orchestration of text encoder, denoiser, sampler and VAE.

Models know nothing of sampling, the sampler (:func:`salad_core.sampling.denoise`) knows nothing of
text or motion formats; this module joins them:

1. validate prompts and lengths; encode the prompts and the null text once;
2. draw per-sample initial noise ``(N'_max, P, Dz)`` from a per-sample seed, so a motion does not
   depend on what else is in the batch, and generate only the latent frames the longest motion of
   the batch needs (padded frames are masked, so the result is the same as padding to 196);
3. denoise with classifier-free guidance; decode with the VAE; de-normalise; recover joints.

A pretrained folder holds ``pipeline.json`` (text encoder, diffusion config, skeleton, solver),
``vae.{safetensors,json}``, ``denoiser.{safetensors,json}`` and ``stats.safetensors`` (Mean/Std).
``SaladPipeline.from_pretrained()`` with no path loads the shipped default from
``salad_core/weights/salad``.
"""
from __future__ import annotations

import json
import logging
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch

from salad_core.io import (CheckpointError, atomic_write_text, config_from_dict, config_to_dict, load_model,
                           load_tensors, save_checkpoint, save_tensors)
from salad_core.models.denoiser import Denoiser
from salad_core.models.vae import MotionVAE
from salad_core.motion import denormalize, features_to_joints, normalize
from salad_core.sampling import DiffusionConfig, denoise, make_scheduler
from salad_core.skeleton import Skeleton, get_skeleton
from salad_core.text import TextBatch, load_text_encoder

__all__ = ["SaladPipeline", "MotionOutput", "default_weights_dir", "validate_prompts", "validate_lengths"]

log = logging.getLogger(__name__)


def default_weights_dir() -> Path:
    """Folder of the shipped default SALAD weights (package data)."""
    return Path(__file__).resolve().parent / "weights" / "salad"


@dataclass
class MotionOutput:
    """Generated motions.

    Attributes
    ----------
    features : np.ndarray
        ``(B, N_max, D)`` de-normalised HumanML3D features, zero beyond each length.
    joints : list of np.ndarray
        Per sample ``(N_b, J, 3)`` joint positions (metres for HumanML3D).
    texts : list of str
    lengths : list of int
        Frames per sample (multiples of 4).
    latents : torch.Tensor
        ``(B, N'_max, P, Dz)`` final latents (padded frames zero).
    noise : torch.Tensor
        ``(B, N'_max, P, Dz)`` the initial noise, so the same start can be reused for edits.
    seeds : list of int
        Per-sample noise seeds.
    attention : object or None
        Captured attention maps (:class:`salad_core.attention.AttentionMaps`) when requested.
    settings : dict
        Guidance scale, steps, solver: everything needed to regenerate.
    """

    features: np.ndarray
    joints: list[np.ndarray]
    texts: list[str]
    lengths: list[int]
    latents: torch.Tensor
    noise: torch.Tensor
    seeds: list[int]
    attention: Any = None
    settings: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.texts)


def validate_prompts(prompts: str | Sequence[str]) -> list[str]:
    """A prompt or a list of prompts -> list of stripped non-empty strings (clear errors otherwise)."""
    if isinstance(prompts, str):
        prompts = [prompts]
    if not isinstance(prompts, (list, tuple)):
        raise TypeError(f"prompts must be a string or a list of strings, got {type(prompts).__name__}")
    if len(prompts) == 0:
        raise ValueError("prompts is empty; give at least one text prompt")
    out = []
    for i, p in enumerate(prompts):
        if not isinstance(p, str):
            raise TypeError(f"prompt {i} must be a string, got {type(p).__name__}: {p!r}")
        if not p.strip():
            raise ValueError(f"prompt {i} is empty or whitespace; describe a motion, e.g. 'a person walks forward'")
        out.append(" ".join(p.split()))
    return out


def validate_lengths(lengths: int | Sequence[int] | None, n: int, skeleton: Skeleton,
                     default: int = 120) -> list[int]:
    """Per-sample lengths in frames: positive, at most ``skeleton.max_length``; lengths that are
    not multiples of ``unit_length`` are floored to one, with a warning saying so."""
    unit, max_len = skeleton.unit_length, skeleton.max_length
    if lengths is None:
        lengths = [default] * n
    elif isinstance(lengths, (int, np.integer)) and not isinstance(lengths, bool):
        lengths = [int(lengths)] * n
    elif isinstance(lengths, (list, tuple, np.ndarray)):
        lengths = list(lengths)
        if len(lengths) != n:
            raise ValueError(f"got {len(lengths)} lengths for {n} prompts; give one length per prompt or a single int")
    else:
        raise TypeError(f"lengths must be an int or a list of ints, got {type(lengths).__name__}")
    out = []
    for i, length in enumerate(lengths):
        if isinstance(length, bool) or not isinstance(length, (int, np.integer)):
            if isinstance(length, float) and math.isfinite(length) and float(length).is_integer():
                length = int(length)
            else:
                raise TypeError(f"length {i} must be an integer number of frames, got {length!r}")
        length = int(length)
        if length < unit or length > max_len:
            raise ValueError(f"length {i} is {length} frames; allowed: {unit}..{max_len} "
                             f"(at {skeleton.fps:g} fps, multiples of {unit})")
        if length % unit:
            floored = length - length % unit
            warnings.warn(f"length {i} ({length} frames) is not a multiple of {unit}; using {floored}",
                          stacklevel=3)
            length = floored
        out.append(length)
    return out


class SaladPipeline:
    """Text-to-motion with SALAD: ``pipe(prompts, lengths=..., seed=...)``.

    Parameters
    ----------
    vae : MotionVAE
    denoiser : Denoiser
    text_encoder
        An encoder from :func:`salad_core.text.load_text_encoder` (``dim`` must equal the
        denoiser's ``text_dim``).
    mean, std : np.ndarray
        ``(D,)`` feature statistics the models were trained with.
    diffusion : DiffusionConfig
    solver : str
        Default scheduler name (``"ddim"``; see :data:`salad_core.sampling.SOLVERS`).
    """

    def __init__(self, vae: MotionVAE, denoiser: Denoiser, text_encoder, mean: np.ndarray, std: np.ndarray,
                 diffusion: DiffusionConfig | None = None, solver: str = "ddim", source: str | None = None) -> None:
        self.vae = vae.eval()
        self.denoiser = denoiser.eval()
        self.text_encoder = text_encoder
        self.diffusion = diffusion or DiffusionConfig()
        self.solver = solver
        self.source = source
        self.skeleton: Skeleton = vae.skeleton
        check_compatible(vae, denoiser, text_encoder)
        d = self.skeleton.feature_dim
        self.mean = np.asarray(mean, dtype=np.float32).reshape(-1)
        self.std = np.asarray(std, dtype=np.float32).reshape(-1)
        if self.mean.shape != (d,) or self.std.shape != (d,):
            raise ValueError(f"mean/std must have shape ({d},) for {self.skeleton.name}, "
                             f"got {self.mean.shape} and {self.std.shape}")
        for p in [*self.vae.parameters(), *self.denoiser.parameters()]:
            p.requires_grad_(False)

    # ------------------------------------------------------------------ loading
    @classmethod
    def from_pretrained(cls, path: str | Path | None = None, *, text_encoder=None) -> "SaladPipeline":
        """Load a pipeline folder (``None``: the shipped default weights)."""
        root = Path(path) if path is not None else default_weights_dir()
        cfg_path = root / "pipeline.json"
        if not cfg_path.is_file():
            hint = (" (the shipped weights are missing from this installation: reinstall salad, or train "
                    "them with scripts/train_default.sh)") if path is None else ""
            raise CheckpointError(f"no pipeline.json in {root}{hint}")
        cfg = json.loads(cfg_path.read_text())
        vae, _, _ = load_model(root / cfg.get("vae", "vae"))
        denoiser, _, _ = load_model(root / cfg.get("denoiser", "denoiser"))
        stats = load_tensors(root / cfg.get("stats", "stats.safetensors"))
        if text_encoder is None:
            text_encoder = load_text_encoder(cfg.get("text_encoder", "minilm"))
        diffusion = config_from_dict(DiffusionConfig, cfg.get("diffusion", {}))
        return cls(vae, denoiser, text_encoder, stats["mean"].numpy(), stats["std"].numpy(),
                   diffusion=diffusion, solver=cfg.get("solver", "ddim"), source=str(root))

    def save_pretrained(self, path: str | Path, *, dtype: torch.dtype | None = None, meta: dict | None = None) -> Path:
        """Write this pipeline as a folder that :meth:`from_pretrained` reads."""
        root = Path(path)
        root.mkdir(parents=True, exist_ok=True)
        save_checkpoint(root / "vae", self.vae, model_type="salad_vae", config=self.vae.config, dtype=dtype, meta=meta)
        save_checkpoint(root / "denoiser", self.denoiser, model_type="denoiser", config=self.denoiser.config,
                        dtype=dtype, meta=meta)
        save_tensors(root / "stats.safetensors", {"mean": torch.from_numpy(self.mean), "std": torch.from_numpy(self.std)})
        doc = {"vae": "vae", "denoiser": "denoiser", "stats": "stats.safetensors",
               "text_encoder": getattr(self.text_encoder, "source", "minilm"),
               "diffusion": config_to_dict(self.diffusion), "solver": self.solver,
               "skeleton": self.skeleton.name}
        atomic_write_text(root / "pipeline.json", json.dumps(doc, indent=2) + "\n")
        return root

    # ------------------------------------------------------------------ pieces
    @property
    def latent_shape(self) -> tuple[int, int]:
        """``(P, Dz)`` of one latent frame."""
        return self.vae.num_parts, self.vae.latent_dim

    def encode_text(self, prompts: list[str]) -> tuple[TextBatch, TextBatch]:
        """Token features of the prompts and of the null text "" (classifier-free guidance)."""
        batch = self.text_encoder.encode(prompts)
        null = self.text_encoder.encode([""], allow_empty=True)
        return batch, null

    def make_noise(self, seeds: Sequence[int], latent_frames: int) -> torch.Tensor:
        """``(B, N', P, Dz)`` standard-normal noise; sample ``b`` from ``torch.Generator(seed_b)``.

        Each sample's noise is drawn at the maximum latent length and cropped, so it does not depend
        on the batch's longest motion.
        """
        p, dz = self.latent_shape
        full = self.skeleton.max_length // self.skeleton.unit_length
        out = []
        for s in seeds:
            g = torch.Generator().manual_seed(int(s))
            out.append(torch.randn(full, p, dz, generator=g)[:latent_frames])
        return torch.stack(out)

    def frame_mask(self, lengths: Sequence[int], latent_frames: int) -> torch.Tensor:
        """``(B, N')`` bool, True on the latent frames each motion uses."""
        n_lat = torch.tensor([length // self.skeleton.unit_length for length in lengths])
        return torch.arange(latent_frames)[None, :] < n_lat[:, None]

    def decode(self, latents: torch.Tensor, lengths: Sequence[int]) -> tuple[np.ndarray, list[np.ndarray]]:
        """Latents ``(B, N', P, Dz)`` -> de-normalised features ``(B, 4N', D)`` (zero past each
        length) and per-sample joints ``(N_b, J, 3)``."""
        unit = self.skeleton.unit_length
        feats = np.zeros((latents.shape[0], latents.shape[1] * unit, self.skeleton.feature_dim), np.float32)
        joints = []
        with torch.inference_mode():
            for b, length in enumerate(lengths):
                # decode each motion at its own length: the VAE's temporal convolutions would
                # otherwise see the batch's zero padding near the end of shorter motions
                dec = self.vae.decode(latents[b:b + 1, : length // unit].float())[0].cpu().numpy()
                feats[b, :length] = denormalize(dec, self.mean, self.std)
                joints.append(features_to_joints(feats[b, :length], self.skeleton).astype(np.float32))
        return feats, joints

    def encode_motion(self, features: np.ndarray, *, sample: bool = False) -> torch.Tensor:
        """Raw (de-normalised) features ``(N, D)`` or ``(B, N, D)`` -> latents ``(B, N/4, P, Dz)``.

        ``N`` must be a multiple of 4. ``sample=False`` uses the posterior mean.
        """
        x = np.asarray(features, dtype=np.float32)
        if x.ndim == 2:
            x = x[None]
        d = self.skeleton.feature_dim
        if x.ndim != 3 or x.shape[-1] != d:
            raise ValueError(f"features must be (N, {d}) or (B, N, {d}), got {x.shape}")
        if not np.isfinite(x).all():
            raise ValueError("features contain NaN or infinite values")
        unit = self.skeleton.unit_length
        if x.shape[1] % unit:
            raise ValueError(f"motion length {x.shape[1]} is not a multiple of {unit}; crop it first")
        with torch.inference_mode():
            enc = self.vae.encode(torch.from_numpy(normalize(x, self.mean, self.std)), sample=sample)
        return enc.z if sample else enc.mu

    # ------------------------------------------------------------------ generate
    def __call__(self, prompts: str | Sequence[str], lengths: int | Sequence[int] | None = None,
                 seed: int | Sequence[int] = 0, guidance_scale: float = 7.5, num_steps: int = 50,
                 solver: str | None = None, capture_attention: bool | Any = False,
                 noise: torch.Tensor | None = None, progress: bool = False) -> MotionOutput:
        """Generate one motion per prompt.

        Parameters
        ----------
        prompts : str or list of str
        lengths : int or list of int, optional
            Frames per motion (default 120 = 6 s at 20 fps), multiples of 4, at most 196.
        seed : int or list of int
            Sample ``b`` uses noise seed ``seed + b`` (or ``seed[b]`` for a list).
        guidance_scale : float
            Classifier-free guidance weight ``w`` (paper default 7.5; 1 disables guidance).
        num_steps : int
            Sampler steps (50 DDIM steps by default).
        solver : str, optional
            Scheduler name (default: the pipeline's, "ddim"); e.g. "dpm++".
        capture_attention : bool or CaptureConfig
            Record the cross-attention maps (see :mod:`salad_core.attention`); never changes the
            motion.
        noise : torch.Tensor, optional
            ``(B, N', P, Dz)`` initial noise to reuse (overrides ``seed``).
        """
        prompts = validate_prompts(prompts)
        lengths = validate_lengths(lengths, len(prompts), self.skeleton)
        guidance_scale = _check_scale(guidance_scale)
        if not isinstance(num_steps, (int, np.integer)) or isinstance(num_steps, bool) or num_steps < 1:
            raise ValueError(f"num_steps must be a positive integer, got {num_steps!r}")
        seeds = _seeds(seed, len(prompts))
        n_lat = max(lengths) // self.skeleton.unit_length
        if noise is None:
            noise = self.make_noise(seeds, n_lat)
        else:
            noise = _check_noise(noise, (len(prompts), n_lat, *self.latent_shape))
        mask = self.frame_mask(lengths, n_lat)
        text, null = self.encode_text(prompts)
        cond = self.denoiser.prepare_text(text.features, text.mask)
        uncond = self.denoiser.prepare_text(null.features, null.mask)
        scheduler = make_scheduler(self.diffusion, solver or self.solver)
        settings = dict(guidance_scale=guidance_scale, num_steps=int(num_steps), solver=solver or self.solver,
                        weights=self.source)
        attention = None
        if capture_attention:
            from salad_core.attention.capture import capture_cross_attention

            with capture_cross_attention(self.denoiser, text, lengths, capture_attention) as store:
                latents = denoise(self.denoiser, scheduler, cond, uncond, noise, mask,
                                  guidance_scale=guidance_scale, num_steps=int(num_steps),
                                  controller_hooks=[store.on_step], progress=progress)
            attention = store.result()
        else:
            latents = denoise(self.denoiser, scheduler, cond, uncond, noise, mask,
                              guidance_scale=guidance_scale, num_steps=int(num_steps), progress=progress)
        feats, joints = self.decode(latents, lengths)
        return MotionOutput(feats, joints, prompts, lengths, latents, noise, seeds, attention, settings)


def check_compatible(vae: MotionVAE, denoiser: Denoiser, text_encoder=None) -> None:
    """Raise if the VAE latent, the denoiser and the text encoder do not fit together."""
    dc = denoiser.config
    if dc.num_parts != vae.num_parts or dc.latent_dim != vae.latent_dim:
        raise ValueError(f"the VAE and the denoiser do not fit together: VAE latent (P={vae.num_parts}, "
                         f"Dz={vae.latent_dim}) vs denoiser (P={dc.num_parts}, Dz={dc.latent_dim})")
    if text_encoder is not None and getattr(text_encoder, "dim", dc.text_dim) != dc.text_dim:
        raise ValueError(f"the text encoder gives {text_encoder.dim}-d features; the denoiser expects "
                         f"{dc.text_dim}-d (it was trained with another encoder)")


def _check_scale(scale: Any) -> float:
    try:
        value = float(scale)
    except (TypeError, ValueError):
        raise TypeError(f"guidance_scale must be a number, got {scale!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"guidance_scale must be finite, got {scale!r}")
    return value


def _seeds(seed: int | Sequence[int], n: int) -> list[int]:
    if isinstance(seed, (list, tuple)):
        if len(seed) != n:
            raise ValueError(f"got {len(seed)} seeds for {n} prompts")
        return [int(s) for s in seed]
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be an int or a list of ints, got {seed!r}")
    return [int(seed) + i for i in range(n)]


def _check_noise(noise: torch.Tensor, shape: tuple[int, ...]) -> torch.Tensor:
    if not isinstance(noise, torch.Tensor) or tuple(noise.shape) != shape:
        got = tuple(noise.shape) if isinstance(noise, torch.Tensor) else type(noise).__name__
        raise ValueError(f"noise must be a tensor of shape {shape}, got {got}")
    if not torch.isfinite(noise).all():
        raise ValueError("noise contains NaN or infinite values")
    return noise.float()
