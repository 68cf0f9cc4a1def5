"""VAE reconstruction quality as in SALAD Table 2 and supplement Table 4: FID and MPJPE.

Each replication takes the same real batches as :func:`~salad_core.eval.protocol.evaluate_real`
(:func:`~salad_core.eval.batches.batches_for`: random crops of the split, lengths multiples of the
unit length), passes every clip through the VAE (normalise with the VAE's statistics, encode,
decode the posterior mean, de-normalise) and scores

* **FID** between the evaluator embeddings of the real clips and of their reconstructions (the
  official ``evaluation_vae``: same clips, so this measures what the VAE loses, with no sampling
  noise between two sets of motions);
* **MPJPE**: root-aligned mean per-joint position error of the recovered joints, averaged over
  poses, in the skeleton's unit (metres for HumanML3D), as the official ``test_vae``.

Results are mean ± 1.96·std/√R over R replications, like the generation tables.
:func:`reconstruction_frame` puts several VAEs in one DataFrame (with their trainable-parameter
counts) and :func:`reconstruction_markdown` renders it (also the paper's numbers, which
:func:`~salad_core.eval.paper_tables.paper_vae_tables` gives, labelled as such).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from os import PathLike
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd
import torch

from . import metrics as M
from .batches import batches_for, evaluation_dataset, motion_embeddings, skeleton_of
from .paper_tables import paper_vae_tables  # noqa: F401  (kept importable from here: notebook 06)
from .settings import EvalSettings
from .tables import format_mean_ci

__all__ = ["RECONSTRUCTION_METRICS", "ReconstructionResult", "reconstruct_features", "latent_spread",
           "evaluate_reconstruction",
           "part_errors", "reconstruction_frame", "reconstruction_markdown", "paper_vae_tables"]

logger = logging.getLogger(__name__)

#: Metric columns of the reconstruction tables, in order (both lower is better).
RECONSTRUCTION_METRICS = ("FID", "MPJPE")


@dataclass(frozen=True)
class ReconstructionResult:
    """Per-replication FID and MPJPE of one VAE, its size and the settings that produced them."""

    name: str
    values: Mapping[str, tuple[float, ...]]          # "FID" / "MPJPE" -> one value per replication
    parameters: int | None                           # learnable parameters of the VAE (frozen or not)
    settings: Mapping[str, Any] = field(default_factory=dict)

    def summary(self) -> dict[str, tuple[float, float]]:
        """``metric -> (mean, 95% half-width)`` over the replications."""
        out = {}
        for m in RECONSTRUCTION_METRICS:
            mean, half = M.mean_ci(np.asarray(self.values[m], dtype=np.float64))
            out[m] = (float(mean), float(half))
        return out


def _check_stats(mean, std, dim: int) -> tuple[np.ndarray, np.ndarray]:
    mean = np.asarray(mean, dtype=np.float32).reshape(-1)
    std = np.asarray(std, dtype=np.float32).reshape(-1)
    if mean.shape != (dim,) or std.shape != (dim,):
        raise ValueError(f"mean and std must be ({dim},) for {dim}-d features, got {mean.shape} and {std.shape}")
    if not (np.isfinite(mean).all() and np.isfinite(std).all()) or (std <= 0).any():
        raise ValueError("mean/std must be finite and std > 0")
    return mean, std


@torch.no_grad()
def reconstruct_features(vae, mean, std, motions: np.ndarray, lengths: Sequence[int], *,
                         sample: bool = False, seed: int = 0, latent_noise: float = 0.0,
                         latent_spread: torch.Tensor | None = None) -> np.ndarray:
    """Pass raw clips through a VAE, each at its own length.

    Parameters
    ----------
    vae : MotionVAE
    mean, std : array ``(D,)``
        The normalisation the VAE was trained with.
    motions : array ``(B, N, D)``
        Raw (de-normalised) features, zero past each length.
    lengths : sequence of B ints
        Frames of each clip; multiples of ``vae.config.downsample``.
    sample : bool
        Decode ``mu + eps * sigma`` instead of the posterior mean ``mu`` (the default).
    seed : int
        Seeds ``eps`` when ``sample``, and the latent noise.
    latent_noise : float
        Add ``latent_noise * latent_spread * eps'`` (Gaussian ``eps'``) to the latent before decoding: how much a
        decoder's output suffers from a latent that is off by a given share of the latents' spread (a generator's
        latents are never exact). 0 (the default) decodes the latent itself.
    latent_spread : tensor ``latent.shape[2:]``, e.g. ``(P, Dz)``
        The latents' spread per part and channel (:func:`latent_spread`); required when ``latent_noise`` > 0.

    Returns
    -------
    array ``(B, N, D)``
        Raw reconstructed features, zero past each length.
    """
    motions = np.asarray(motions, dtype=np.float32)
    if motions.ndim != 3:
        raise ValueError(f"motions must be (B, N, D), got shape {motions.shape}")
    b, n, d = motions.shape
    mean, std = _check_stats(mean, std, d)
    lengths = [int(x) for x in lengths]
    unit = int(vae.config.downsample)
    if len(lengths) != b:
        raise ValueError(f"got {len(lengths)} lengths for {b} motions")
    bad = [x for x in lengths if x <= 0 or x > n or x % unit]
    if bad:
        raise ValueError(f"lengths {bad} are not multiples of the VAE's downsampling {unit} within 1..{n}")
    if latent_noise < 0 or not math.isfinite(latent_noise):
        raise ValueError(f"latent_noise must be a finite share >= 0, got {latent_noise}")
    if latent_noise and latent_spread is None:
        raise ValueError("latent_noise > 0 needs latent_spread (salad_core.eval.reconstruction.latent_spread)")
    vae.eval()
    gen = torch.Generator().manual_seed(int(seed)) if sample else None
    noise_gen = torch.Generator().manual_seed(int(seed) + 7_919) if latent_noise else None
    out = np.zeros_like(motions)
    # clips of equal length share one forward pass (crops come in multiples of the unit length)
    for length in sorted(set(lengths)):
        idx = [i for i, x in enumerate(lengths) if x == length]
        x = torch.from_numpy((motions[idx, :length] - mean) / std)
        enc = vae.encode(x, sample=sample, generator=gen)
        z = enc.z
        if latent_noise:
            if tuple(latent_spread.shape) != tuple(z.shape[2:]):
                raise ValueError(f"latent_spread has shape {tuple(latent_spread.shape)}; the latents "
                                 f"{tuple(z.shape)} need {tuple(z.shape[2:])}")
            z = z + latent_noise * latent_spread.to(z.dtype) * torch.randn(z.shape, generator=noise_gen)
        rec = vae.decode(z).float().numpy()
        out[idx, :length] = rec * std + mean
    return out


@torch.no_grad()
def latent_spread(vae, mean, std, dataset_root: str | PathLike, skeleton,
                  settings: EvalSettings | None = None) -> torch.Tensor:
    """The spread of a VAE's latents per part and channel, ``sqrt(var(mu) + mean(sigma^2))`` over every latent
    frame of the first replication's crops of ``settings.split`` (the scale a latent diffusion model normalises
    by, :func:`salad_core.train.denoiser_trainer.denoiser_latent_stats`, here on the evaluation crops).
    ``skeleton`` is the clips' (e.g. ``skeleton_of(evaluator)``).

    Returns
    -------
    tensor ``(P, Dz)`` (the latents' shape past batch and frame)
    """
    settings = settings or EvalSettings()
    ds = evaluation_dataset(dataset_root, settings, skeleton)
    vae.eval()
    mus, variances = [], []
    for batch in batches_for(ds, settings, 0, 0):
        motions = np.asarray(batch.motions, dtype=np.float32)
        for length in sorted(set(int(x) for x in batch.lengths)):
            idx = [i for i, x in enumerate(batch.lengths) if int(x) == length]
            enc = vae.encode(torch.from_numpy((motions[idx, :length] - mean) / std), sample=False)
            mus.append(enc.mu.reshape(-1, *enc.mu.shape[2:]).double())
            variances.append(enc.logvar.exp().reshape(-1, *enc.mu.shape[2:]).double())
    mu, var = torch.cat(mus), torch.cat(variances)
    return (mu.var(0, unbiased=False) + var.mean(0)).sqrt().float()


@torch.no_grad()
def evaluate_reconstruction(vae, mean, std, dataset_root: str | PathLike, evaluator,
                            settings: EvalSettings | None = None, name: str = "VAE", *,
                            sample: bool = False, weights: str | None = None, latent_noise: float = 0.0,
                            latent_spread: torch.Tensor | None = None) -> ReconstructionResult:
    """FID and MPJPE of a VAE's reconstructions of the split's clips (see the module docstring).

    Parameters
    ----------
    vae : MotionVAE
        Skeleton-aware or pose-vector; its ``downsample`` must divide the evaluator's unit length
        crops (4 for both shipped kinds).
    mean, std : array ``(D,)``
        The VAE's normalisation statistics.
    dataset_root : path
        HumanML3D-layout folder.
    evaluator : T2MEvaluator
    settings : EvalSettings, optional
        Replications, split, batch size, sample cap and seed are used; generation settings are not.
    name : str
        Row label.
    sample : bool
        Decode a posterior sample instead of its mean.
    weights : str, optional
        Recorded as the VAE's source.
    latent_noise, latent_spread :
        Decode latents off by ``latent_noise`` times their spread (:func:`reconstruct_features`; recorded).

    Returns
    -------
    ReconstructionResult
    """
    from salad_core.motion import features_to_joints

    settings = settings or EvalSettings()
    evaluator.eval()
    sk = skeleton_of(evaluator)
    ds = evaluation_dataset(dataset_root, settings, sk)
    vals: dict[str, list[float]] = {m: [] for m in RECONSTRUCTION_METRICS}
    samples = 0
    for r in range(settings.replications):
        real_emb, rec_emb, errors, poses = [], [], 0.0, 0
        for i, batch in enumerate(batches_for(ds, settings, r, r)):
            rec = reconstruct_features(vae, mean, std, batch.motions, batch.lengths, sample=sample,
                                       seed=settings.seed * 1_000_003 + r * 1_009 + i, latent_noise=latent_noise,
                                       latent_spread=latent_spread)
            real_emb.append(motion_embeddings(evaluator, batch.motions, batch.lengths))
            rec_emb.append(motion_embeddings(evaluator, rec, batch.lengths))
            for k, length in enumerate(batch.lengths):
                gt = features_to_joints(batch.motions[k, :length], sk)
                pred = features_to_joints(rec[k, :length], sk)
                errors += M.mpjpe(pred, gt) * int(length)       # mean over poses of the whole replication
                poses += int(length)
        real_emb, rec_emb = np.concatenate(real_emb), np.concatenate(rec_emb)
        samples = len(real_emb)
        vals["FID"].append(M.fid(real_emb, rec_emb))
        vals["MPJPE"].append(errors / poses)
        logger.info("%s: replication %d/%d: FID %.4f, MPJPE %.4f", name, r + 1, settings.replications,
                    vals["FID"][-1], vals["MPJPE"][-1])
    params = vae.num_parameters() if hasattr(vae, "num_parameters") else None
    recorded = dict(kind="vae", split=settings.split, batch_size=settings.batch_size,
                    replications=settings.replications, samples=samples, seed=settings.seed,
                    max_samples=settings.max_samples, quick=settings.quick, sample=sample, latent_noise=latent_noise,
                    weights=weights, evaluator=getattr(evaluator, "source", type(evaluator).__name__),
                    data=str(dataset_root))
    return ReconstructionResult(name, {k: tuple(v) for k, v in vals.items()}, params, recorded)


def part_errors(pred_joints: np.ndarray, gt_joints: np.ndarray, skeleton="humanml3d") -> dict[str, float]:
    """Root-aligned position error per body part: ``{part name: mean error}`` over the part's joints
    and all poses (the joints of each of the 7 latent parts, ``skeleton.joint_to_part``).

    ``pred_joints``, ``gt_joints``: ``(..., N, J, 3)``. The root part (joint 0 only) is 0 by
    construction after root alignment and is left out.
    """
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton(skeleton)
    p = np.asarray(pred_joints, dtype=np.float64)
    g = np.asarray(gt_joints, dtype=np.float64)
    if p.shape != g.shape or p.ndim < 3 or p.shape[-2:] != (sk.num_joints, 3):
        raise ValueError(f"joints must both be (..., N, {sk.num_joints}, 3), got {p.shape} and {g.shape}")
    err = np.linalg.norm((p - p[..., :1, :]) - (g - g[..., :1, :]), axis=-1)     # (..., N, J)
    err = err.reshape(-1, sk.num_joints)
    part_of = np.asarray(sk.joint_to_part)
    return {name: float(err[:, (part_of == k) & (np.arange(sk.num_joints) != 0)].mean())
            for k, name in enumerate(sk.part_names)
            if ((part_of == k) & (np.arange(sk.num_joints) != 0)).any()}


def reconstruction_frame(results: Sequence[ReconstructionResult]) -> pd.DataFrame:
    """One row per VAE: ``name``, ``parameters``, ``FID``, ``FID ±``, ``MPJPE``, ``MPJPE ±`` and the settings."""
    if not results:
        raise ValueError("results is empty")
    rows = []
    for res in results:
        if not isinstance(res, ReconstructionResult):
            raise TypeError(f"results must hold ReconstructionResult objects, got {type(res).__name__}")
        row: dict[str, Any] = {"name": res.name, "parameters": res.parameters}
        for m, (mean, half) in res.summary().items():
            row[m], row[m + " ±"] = mean, half
        row.update(res.settings)
        rows.append(row)
    return pd.DataFrame(rows)


def _params(n) -> str:
    if n is None or (isinstance(n, float) and math.isnan(n)):
        return "-"
    return f"{n / 1e6:.2f}M" if n >= 1e5 else f"{int(n):,}"


def reconstruction_markdown(df: pd.DataFrame, digits: int = 3, mpjpe_scale: float = 100.0,
                            mpjpe_unit: str = "cm") -> str:
    """A Markdown table of :func:`reconstruction_frame` (or :func:`~salad_core.eval.paper_tables.paper_vae_tables`) rows.

    MPJPE is shown times ``mpjpe_scale`` (default: metres -> cm); the header names the unit.
    """
    missing = [c for c in ("name", *RECONSTRUCTION_METRICS) if c not in df.columns]
    if missing:
        raise ValueError(f"the DataFrame lacks the columns {missing}; build it with reconstruction_frame(results)")
    show_params = "parameters" in df.columns and df["parameters"].notna().any()
    header = ["Method", *(["Params"] if show_params else []), "FID ↓", f"MPJPE ({mpjpe_unit}) ↓"]
    lines = ["| " + " | ".join(header) + " |", "|:--" + "|--:" * (len(header) - 1) + "|"]
    for _, r in df.iterrows():
        cells = [str(r["name"])]
        if show_params:
            cells.append(_params(r["parameters"]))
        cells.append(format_mean_ci(r["FID"], r.get("FID ±", np.nan), digits))
        cells.append(format_mean_ci(r["MPJPE"] * mpjpe_scale, r.get("MPJPE ±", np.nan) * mpjpe_scale, digits))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"
