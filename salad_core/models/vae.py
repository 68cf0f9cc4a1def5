"""The skeleto-temporal VAE of SALAD (paper §3.1, supplement A.1) and its "pose" ablation.

Data flow of the default ``kind="st"`` model (HumanML3D sizes; KIT has 21 joints, 251 features)::

    x (B, N, 263) --split per joint--> 22 tokens of 7/12/13 dims
      --joint-wise MLPs (motion_enc)--> (B, N, 22, 32)
      --conv_enc level 0: ResSTConv x2, STPool--> (B, N/2, 12, 32)
      --conv_enc level 1: ResSTConv x2, STPool--> (B, N/4, 7, 32)
      --dist (per-part linear 32 -> 64)--> mu, logvar (B, N/4, 7, 32) --reparameterise--> z
    z --conv_dec (STUnpool, ResSTConv x2) x2--> (B, N, 22, 32)
      --joint-wise MLPs (motion_dec), merge--> (B, N, 263)

Module names follow the official implementation, so ``state_dict()`` keys are the official keys
(fact sheet §6: ``motion_enc.layers.{j}.0.weight``, ``conv_enc.layers.{lvl}.{r}.layers.2...``,
``dist.weight``, ...) and official weights load strictly with :meth:`MotionVAE.from_official_state_dict`.

``kind="pose"`` is the "w/o ST-Latent" ablation (paper Table 3): a conventional VAE that treats
each pose as one vector. It is the same network on a one-node "skeleton": one MLP on the whole
feature vector, residual temporal convolutions and temporal pooling x4, and a latent
``(B, N/4, 1, Dz_pose)``. By default ``Dz_pose = 7 x 32 = 224``, so the denoiser sees exactly as
many latent numbers per latent frame as with the ``7 x 32`` ST latent and the comparison isolates
the *structure* of the latent, not its size.
"""
from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from salad_core.io import load_state_into, register_model
from salad_core.models.layers import (
    ACTIVATIONS,
    NORMS,
    MultiLinear,
    ResSTConv,
    STPool,
    STUnpool,
    get_activation,
)
from salad_core.skeleton import Skeleton, available_skeletons, get_skeleton

__all__ = ["VAEConfig", "VAEEncoding", "MotionVAE", "JointMLPEncoder", "JointMLPDecoder",
           "STConvEncoder", "STConvDecoder", "VAE_KINDS", "RECON_LOSSES"]

logger = logging.getLogger(__name__)

#: Model kinds: the paper's skeleto-temporal VAE and the one-vector-per-pose ablation.
VAE_KINDS: tuple[str, ...] = ("st", "pose")
#: Reconstruction criteria: SmoothL1 (beta 1, official default), L1, and L2 (an addition).
RECON_LOSSES: tuple[str, ...] = ("l1_smooth", "l1", "l2")


@dataclass(frozen=True)
class VAEConfig:
    """Configuration of :class:`MotionVAE` (defaults = official ``options/vae_option.py``)."""

    skeleton: str = "humanml3d"       # "humanml3d" or "kit" (aliases such as "t2m" are canonicalised)
    kind: str = "st"                  # "st" skeleto-temporal (paper) | "pose" (ablation "w/o ST-Latent")
    latent_dim: int = 32              # "st": width D of every joint token, conv stack and latent part
    kernel_size: int = 3              # temporal Conv1d kernel (odd, length preserving)
    n_layers: int = 2                 # pooling levels; each halves time (2 -> N' = N/4, J 22 -> 12 -> 7)
    n_extra_layers: int = 1           # ResSTConv blocks per level in addition to the first one
    activation: str = "gelu"          # "relu" | "silu" | "gelu" (released "vaegelu" model uses gelu)
    dropout: float = 0.1              # dropout at the end of each ResSTConv
    norm: str = "none"                # "none" | "batch" | "layer" inside ResSTConv
    recon_loss: str = "l1_smooth"     # "l1_smooth" | "l1" | "l2" criterion for all reconstruction terms
    lambda_pos: float = 0.5           # weight of the ric (local joint position) slice term
    lambda_vel: float = 0.5           # weight of the local-velocity slice term
    lambda_kl: float = 0.02           # weight of the KL term (mean over elements)
    lambda_bone: float = 0.0          # weight of the bone-length term (an addition; 0 = official loss)
    lambda_root: float = 0.0          # weight of the integrated-root term (an addition; 0 = official loss):
                                      # yaw error (rad) + global joint error (m) over the window, see root_error
    lambda_root_features: float = 0.0  # extra weight of the root channels (features 0-3: angular velocity, x/z
                                      # velocity, height) in normalised units, on top of their share of rec
                                      # (an addition; 0 = official loss): rec averages 263 columns, so a
                                      # decoder can all but ignore these 4, which the whole path integrates
    lambda_foot: float = 0.0          # weight of the foot-contact term (an addition; 0 = official loss): speed
                                      # (m/frame) of the reconstruction's feet, integrated path, where the input's
                                      # contact channels say a foot is planted, see foot_slide
    foot_planted_step: float | None = 0.005  # foot_slide counts only steps where the input's own foot moves less
                                      # than this (m/frame; 0.005 = 0.1 m/s at 20 fps, the physics measure's skate
                                      # threshold); None: every step the contact channels mark (they mark feet up
                                      # to ~0.9 m/s, HumanML3D's velocity rule)
    latent_noise: float = 0.0         # training only: std of extra Gaussian noise on the sampled latent, so
                                      # the decoder learns latents near (not only on) the data (an addition)
    posterior_noise: float = 1.0      # training only: scale of the reparameterisation noise eps * sigma
                                      # (1 = official: decode posterior samples; 0 = decode the posterior
                                      # mean). Why: the heading rate lives in directions of mu whose spread is
                                      # below sigma, so a decoder trained on samples cannot read it
    pose_latent_dim: int | None = None  # "pose" only: Dz of the one-vector latent; None -> parts x latent_dim
    pose_width: int | None = None     # "pose" only: width of MLP/conv stack; None -> the pose latent dim

    def __post_init__(self) -> None:
        if not isinstance(self.skeleton, str):
            raise TypeError(f"skeleton must be a skeleton name {available_skeletons()}, got {type(self.skeleton).__name__}")
        # canonical name, so configs saved in checkpoints compare equal ("t2m" -> "humanml3d")
        object.__setattr__(self, "skeleton", get_skeleton(self.skeleton).name)
        if self.kind not in VAE_KINDS:
            raise ValueError(f"kind={self.kind!r} is not supported; choose one of {VAE_KINDS}")
        for name in ("latent_dim", "kernel_size", "n_layers"):
            val = getattr(self, name)
            if not isinstance(val, int) or isinstance(val, bool) or val < 1:
                raise ValueError(f"{name} must be a positive int, got {val!r}")
        if self.kernel_size % 2 == 0:
            raise ValueError(f"kernel_size must be odd so that convolutions keep the length, got {self.kernel_size}")
        levels = len(get_skeleton(self.skeleton).pooling_levels)
        if self.n_layers > levels:
            raise ValueError(f"n_layers={self.n_layers} exceeds the {levels} pooling levels of skeleton {self.skeleton!r}")
        if not isinstance(self.n_extra_layers, int) or self.n_extra_layers < 0:
            raise ValueError(f"n_extra_layers must be an int >= 0, got {self.n_extra_layers!r}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation={self.activation!r} is not supported; choose one of {ACTIVATIONS}")
        if self.norm not in NORMS:
            raise ValueError(f"norm={self.norm!r} is not supported; choose one of {NORMS}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must be in [0, 1), got {self.dropout}")
        if self.recon_loss not in RECON_LOSSES:
            raise ValueError(f"recon_loss={self.recon_loss!r} is not supported; choose one of {RECON_LOSSES}")
        for name in ("lambda_pos", "lambda_vel", "lambda_kl", "lambda_bone", "lambda_root", "lambda_root_features",
                     "lambda_foot", "latent_noise", "posterior_noise"):
            val = getattr(self, name)
            if not np.isfinite(val) or val < 0:
                raise ValueError(f"{name} must be a finite number >= 0, got {val}")
        if self.foot_planted_step is not None and (isinstance(self.foot_planted_step, bool)
                                                   or not np.isfinite(self.foot_planted_step)
                                                   or self.foot_planted_step <= 0):
            raise ValueError(f"foot_planted_step must be None or a finite number > 0 (m/frame), got "
                             f"{self.foot_planted_step!r}")
        for name in ("pose_latent_dim", "pose_width"):
            val = getattr(self, name)
            if val is not None and (not isinstance(val, int) or val < 1):
                raise ValueError(f"{name} must be None (automatic) or a positive int, got {val!r}")
            if val is not None and self.kind != "pose":
                raise ValueError(f"{name} is only used by kind='pose'; leave it None for kind={self.kind!r}")

    @property
    def downsample(self) -> int:
        """Temporal compression factor ``N / N'`` (2 per pooling level; 4 by default)."""
        return 2 ** self.n_layers

    @property
    def num_parts(self) -> int:
        """Latent tokens per frame: the groups of the last pooling level ("st") or 1 ("pose")."""
        if self.kind == "pose":
            return 1
        return len(get_skeleton(self.skeleton).pooling_levels[self.n_layers - 1])

    @property
    def z_dim(self) -> int:
        """Channels ``Dz`` of each latent token."""
        if self.kind == "st":
            return self.latent_dim
        if self.pose_latent_dim is not None:
            return self.pose_latent_dim
        # same numbers per latent frame as the ST latent (P x D, 7 x 32 = 224 by default)
        st_parts = len(get_skeleton(self.skeleton).pooling_levels[self.n_layers - 1])
        return st_parts * self.latent_dim

    @property
    def width(self) -> int:
        """Channel width of the MLPs and the conv stack."""
        if self.kind == "st":
            return self.latent_dim
        return self.pose_width if self.pose_width is not None else self.z_dim


class VAEEncoding(NamedTuple):
    """Result of :meth:`MotionVAE.encode`; each field is ``(B, N', P, Dz)``."""

    z: torch.Tensor       # sampled latent (or ``mu`` when ``sample=False``)
    mu: torch.Tensor      # posterior mean
    logvar: torch.Tensor  # posterior log-variance


def _token_permutation(token_index: tuple[tuple[int, ...], ...]) -> tuple[torch.Tensor, torch.Tensor, list[int]]:
    """Flat gather order, its inverse and the token sizes; checks the split is a bijection."""
    perm = np.concatenate([np.asarray(t, dtype=np.int64) for t in token_index])
    width = perm.size
    if not np.array_equal(np.sort(perm), np.arange(width)):
        raise ValueError("token_index must use every feature column exactly once")
    inv = np.empty_like(perm)
    inv[perm] = np.arange(width)
    return torch.from_numpy(perm), torch.from_numpy(inv), [len(t) for t in token_index]


class JointMLPEncoder(nn.Module):
    """Split a pose vector into joint tokens and lift each with its own 2-layer MLP (suppl. A.1).

    ``layers[j] = Sequential(Linear(D_j, H), act, Linear(H, H))``, no weight sharing between
    joints (official ``MotionEncoder``).

    Parameters
    ----------
    token_index : tuple of tuples of int
        Feature columns of each token (``Skeleton.joint_feature_index``); every column once.
    hidden : int
        Output width ``H``.
    activation : str
        Activation between the two linears.

    Shapes
    ------
    ``x (B, N, D) -> (B, N, J, H)``
    """

    def __init__(self, token_index, hidden: int, activation: str = "gelu") -> None:
        super().__init__()
        perm, _, sizes = _token_permutation(tuple(tuple(t) for t in token_index))
        self.register_buffer("perm", perm, persistent=False)
        self.sizes = sizes
        self.layers = nn.ModuleList(
            nn.Sequential(nn.Linear(d, hidden), get_activation(activation), nn.Linear(hidden, hidden)) for d in sizes
        )

    @property
    def feature_dim(self) -> int:
        return int(self.perm.numel())

    def split(self, x: torch.Tensor) -> list[torch.Tensor]:
        """``(B, N, D)`` -> list of J tokens ``(B, N, D_j)`` (columns in token order)."""
        return list(x[..., self.perm].split(self.sizes, dim=-1))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        tokens = self.split(x)
        # J x (B, N, H) -> (B, N, J, H)
        return torch.stack([mlp(t) for mlp, t in zip(self.layers, tokens)], dim=-2)


class JointMLPDecoder(nn.Module):
    """Map each joint's hidden state back to its feature columns and re-assemble the pose vector.

    ``layers[j] = Sequential(Linear(H, H), act, Linear(H, D_j))`` (official ``MotionDecoder``).

    Shapes
    ------
    ``h (B, N, J, H) -> (B, N, D)``, columns in the original feature order.
    """

    def __init__(self, token_index, hidden: int, activation: str = "gelu") -> None:
        super().__init__()
        _, inv, sizes = _token_permutation(tuple(tuple(t) for t in token_index))
        self.register_buffer("inv_perm", inv, persistent=False)
        self.sizes = sizes
        self.layers = nn.ModuleList(
            nn.Sequential(nn.Linear(hidden, hidden), get_activation(activation), nn.Linear(hidden, d)) for d in sizes
        )

    def merge(self, tokens: list[torch.Tensor]) -> torch.Tensor:
        """List of J tokens ``(B, N, D_j)`` -> ``(B, N, D)`` (inverse of :meth:`JointMLPEncoder.split`)."""
        return torch.cat(tokens, dim=-1)[..., self.inv_perm]

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        if h.shape[-2] != len(self.layers):
            raise ValueError(f"JointMLPDecoder expects {len(self.layers)} joints on axis -2, got {tuple(h.shape)}")
        return self.merge([mlp(h[..., j, :]) for j, mlp in enumerate(self.layers)])


class STConvEncoder(nn.Module):
    """``layers[lvl] = Sequential(ResSTConv x (n_extra + 1), STPool)`` per pooling level.

    Parameters
    ----------
    width : int
        Channels ``C``.
    level_edges : sequence
        Graph edges at each resolution (``None`` entries: no skeletal term).
    level_nodes : sequence of int
        Node count at each resolution (length ``n_levels + 1``).
    pool_matrices : sequence of arrays ``(J_{l+1}, J_l)``

    Shapes
    ------
    ``(B, N, J_0, C) -> (B, N / 2**n_levels, J_last, C)``
    """

    def __init__(self, width: int, level_edges, level_nodes, pool_matrices, *, n_extra_layers: int,
                 kernel_size: int, activation: str, norm: str, dropout: float) -> None:
        super().__init__()
        block = dict(kernel_size=kernel_size, activation=activation, norm=norm, dropout=dropout)
        self.layers = nn.ModuleList(
            nn.Sequential(
                *[ResSTConv(width, level_edges[lvl], level_nodes[lvl], **block) for _ in range(n_extra_layers + 1)],
                STPool(pool),
            )
            for lvl, pool in enumerate(pool_matrices)
        )

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        for level in self.layers:
            h = level(h)
        return h


class STConvDecoder(nn.Module):
    """Mirror of :class:`STConvEncoder`: ``layers[k] = Sequential(STUnpool, ResSTConv x (n_extra + 1))``.

    Level ``k`` undoes encoder level ``n_levels - 1 - k``, reusing its graph and pooling groups.

    Shapes
    ------
    ``(B, N', J_last, C) -> (B, N' * 2**n_levels, J_0, C)``
    """

    def __init__(self, width: int, level_edges, level_nodes, pool_matrices, *, n_extra_layers: int,
                 kernel_size: int, activation: str, norm: str, dropout: float) -> None:
        super().__init__()
        block = dict(kernel_size=kernel_size, activation=activation, norm=norm, dropout=dropout)
        n = len(pool_matrices)
        self.layers = nn.ModuleList(
            nn.Sequential(
                STUnpool((np.asarray(pool_matrices[lvl]) > 0).astype(np.float32).T),
                *[ResSTConv(width, level_edges[lvl], level_nodes[lvl], **block) for _ in range(n_extra_layers + 1)],
            )
            for lvl in reversed(range(n))
        )

    def forward(self, h: torch.Tensor) -> torch.Tensor:
        for level in self.layers:
            h = level(h)
        return h


class MotionVAE(nn.Module):
    """Skeleto-temporal VAE (``kind="st"``) or one-vector-per-pose VAE (``kind="pose"``).

    Parameters
    ----------
    config : VAEConfig, optional
        Defaults to the official HumanML3D configuration.

    Attributes
    ----------
    config : VAEConfig
    skeleton : Skeleton
    num_parts : int
        Latent tokens per latent frame ``P`` (7 for "st", 1 for "pose").
    latent_dim : int
        Channels per latent token ``Dz`` (32 for "st", 224 by default for "pose").
    downsample : int
        ``N / N'`` (4).

    Notes
    -----
    Inputs are **normalised** features (``(x - Mean) / Std``), as in the official training.
    The official code always samples ``z`` (also in evaluation and when encoding latents for the
    denoiser); ``encode(..., sample=False)`` is offered here for deterministic use.
    """

    def __init__(self, config: VAEConfig | None = None) -> None:
        super().__init__()
        config = VAEConfig() if config is None else config
        if not isinstance(config, VAEConfig):
            raise TypeError(f"config must be a VAEConfig, got {type(config).__name__}")
        self.config = config
        self.skeleton: Skeleton = get_skeleton(config.skeleton)
        self.num_parts = config.num_parts
        self.latent_dim = config.z_dim
        self.downsample = config.downsample
        self.feature_dim = self.skeleton.feature_dim
        width = config.width
        sk = self.skeleton

        if config.kind == "st":
            token_index = sk.joint_feature_index
            pools = [sk.pool_matrix(lvl) for lvl in range(config.n_layers)]
            nodes = [sk.num_joints] + [p.shape[0] for p in pools]
            edges = list(sk.level_edges[: config.n_layers])
        else:
            # one token holding the whole pose vector; a one-node graph has no skeletal term and
            # its skeletal pooling is the identity, so only the temporal structure remains
            token_index = (tuple(range(self.feature_dim)),)
            pools = [np.ones((1, 1), dtype=np.float32)] * config.n_layers
            nodes = [1] * (config.n_layers + 1)
            edges = [None] * config.n_layers
        stack = dict(n_extra_layers=config.n_extra_layers, kernel_size=config.kernel_size,
                     activation=config.activation, norm=config.norm, dropout=config.dropout)

        self.motion_enc = JointMLPEncoder(token_index, width, config.activation)
        self.conv_enc = STConvEncoder(width, edges, nodes, pools, **stack)
        # per-part head -> (mu, logvar); a separate linear per latent part (fact sheet §1.3)
        self.dist = MultiLinear(self.num_parts, width, 2 * self.latent_dim)
        # only the "pose" variant can have a latent narrower/wider than its conv stack
        self.latent_proj = nn.Linear(self.latent_dim, width) if self.latent_dim != width else None
        self.conv_dec = STConvDecoder(width, edges, nodes, pools, **stack)
        self.motion_dec = JointMLPDecoder(token_index, width, config.activation)

    # ------------------------------------------------------------------ API
    def encode(self, x: torch.Tensor, sample: bool = True, generator: torch.Generator | None = None) -> VAEEncoding:
        """Encode normalised motion features.

        Parameters
        ----------
        x : Tensor ``(B, N, D)``
            Normalised features, ``D = skeleton.feature_dim``, ``N`` a multiple of ``downsample``.
        sample : bool
            ``True`` (official behaviour): ``z = mu + eps * exp(logvar / 2)``; ``False``: ``z = mu``.
        generator : torch.Generator, optional
            Source of ``eps`` (same seed -> same ``z``).

        Returns
        -------
        VAEEncoding
            ``z, mu, logvar``, each ``(B, N / downsample, P, Dz)``.
        """
        self._check_motion(x, "x")
        h = self.motion_enc(x)                        # (B, N, J, C)
        h = self.conv_enc(h)                          # (B, N', P, C)
        mu, logvar = self.dist(h).chunk(2, dim=-1)    # (B, N', P, 2Dz) -> 2 x (B, N', P, Dz)
        if not sample:
            return VAEEncoding(mu, mu, logvar)
        if generator is not None:
            eps = torch.randn(mu.shape, generator=generator, device=generator.device, dtype=mu.dtype).to(mu.device)
        else:
            eps = torch.randn_like(mu)
        return VAEEncoding(mu + eps * torch.exp(0.5 * logvar), mu, logvar)

    def decode(self, z: torch.Tensor) -> torch.Tensor:
        """Decode latents ``z (B, N', P, Dz)`` to normalised features ``(B, N' * downsample, D)``."""
        if z.ndim != 4 or tuple(z.shape[2:]) != (self.num_parts, self.latent_dim):
            raise ValueError(
                f"z must be (B, N', {self.num_parts}, {self.latent_dim}) for this VAE, got {tuple(z.shape)}"
            )
        h = z if self.latent_proj is None else self.latent_proj(z)  # (B, N', P, C)
        h = self.conv_dec(h)                                         # (B, N, J, C)
        return self.motion_dec(h)                                    # (B, N, D)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Sampled reconstruction: ``x (B, N, D) -> (recon (B, N, D), mu, logvar (B, N', P, Dz))``."""
        z, mu, logvar = self.encode(x, sample=True)
        return self.decode(z), mu, logvar

    def loss(self, x: torch.Tensor, recon: torch.Tensor, mu: torch.Tensor, logvar: torch.Tensor,
             mask: torch.Tensor | None = None,
             stats: tuple[torch.Tensor, torch.Tensor] | None = None) -> dict[str, torch.Tensor]:
        """Training objective ``L = L_rec + λ_pos L_pos + λ_vel L_vel + λ_kl L_kl`` (paper eq. 3),
        plus ``λ_bone L_bone`` when ``config.lambda_bone > 0`` (an addition, see :meth:`bone_lengths`),
        ``λ_root L_root`` when ``config.lambda_root > 0`` (an addition, see :meth:`root_error`),
        ``λ_foot L_foot`` when ``config.lambda_foot > 0`` (an addition, see :meth:`foot_slide`) and
        ``λ_rf L_root_feat`` when ``config.lambda_root_features > 0`` (an addition: the criterion on the
        root slice, features 0-3, averaged over those 4 columns, so they weigh ``1 + 263 λ_rf / 4`` times
        what ``rec`` alone gives them).

        All reconstruction terms compare **normalised** features, as the official trainer does:
        ``rec`` on the whole vector, ``pos`` on the ``ric`` slice (root-relative joint positions,
        no forward kinematics) and ``vel`` on the ``local_vel`` slice. The position and velocity
        columns are therefore counted twice (once in ``rec``), which is the official weighting.
        ``kl = 0.5 * mean(mu^2 + exp(logvar) - logvar - 1)`` is a mean over elements.

        Parameters
        ----------
        x, recon : Tensor ``(B, N, D)``
        mu, logvar : Tensor ``(B, N', P, Dz)``
        mask : Tensor ``(B, N)`` bool, optional
            Valid frames. Reconstruction terms average over valid frames only; the KL averages
            over latent frames that cover at least one valid frame.
        stats : (mean, std) of Tensor ``(D,)``, optional
            The features' normalisation; needed by the bone-length and root terms (both measure
            de-normalised features: metres and radians).

        Returns
        -------
        dict with scalar tensors ``loss``, ``rec``, ``pos``, ``vel``, ``kl`` (and ``bone`` in metres
        when ``lambda_bone > 0``; ``root`` = ``root_yaw`` (rad) + ``root_pos`` (m) when ``lambda_root > 0``;
        ``root_feat`` (normalised units) when ``lambda_root_features > 0``; ``foot`` (metres per frame) when
        ``lambda_foot > 0``).
        """
        if x.shape != recon.shape:
            raise ValueError(f"recon must have the shape of x {tuple(x.shape)}, got {tuple(recon.shape)}")
        self._check_motion(x, "x", check_length=False)
        if mu.shape != logvar.shape or mu.ndim != 4 or mu.shape[0] != x.shape[0]:
            raise ValueError(f"mu and logvar must both be (B, N', P, Dz) with B={x.shape[0]}, "
                             f"got {tuple(mu.shape)} and {tuple(logvar.shape)}")
        b, n, _ = x.shape
        cfg = self.config
        err = self._criterion(recon, x)  # (B, N, D) elementwise
        kl_el = 0.5 * (mu.pow(2) + logvar.exp() - logvar - 1.0)  # (B, N', P, Dz)
        if mask is None:
            frame_w = torch.ones(b, n, dtype=x.dtype, device=x.device)
            lat_w = torch.ones(mu.shape[:2], dtype=x.dtype, device=x.device)
        else:
            if mask.shape != (b, n):
                raise ValueError(f"mask must be (B, N) = {(b, n)}, got {tuple(mask.shape)}")
            n_lat = mu.shape[1]
            if n != n_lat * self.downsample:
                raise ValueError(f"x has {n} frames but mu has {n_lat} latent frames (expected {n // self.downsample})")
            frame_w = mask.to(x.dtype)
            # (B, N) -> (B, N', downsample): a latent frame counts if any of its frames is valid
            lat_w = mask.reshape(b, n_lat, self.downsample).any(dim=-1).to(x.dtype)

        def masked_mean(e: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
            # e (B, T, ...) weighted by w (B, T): mean over valid frames and all other elements
            per = e.reshape(b, w.shape[1], -1)
            return (per * w[..., None]).sum() / (w.sum() * per.shape[-1]).clamp_min(1.0)

        sl = self.skeleton.feature_slices
        rec = masked_mean(err, frame_w)
        pos = masked_mean(err[..., sl["ric"]], frame_w)
        vel = masked_mean(err[..., sl["local_vel"]], frame_w)
        kl = masked_mean(kl_el, lat_w)
        total = rec + cfg.lambda_pos * pos + cfg.lambda_vel * vel + cfg.lambda_kl * kl
        out = {"loss": total, "rec": rec, "pos": pos, "vel": vel, "kl": kl}
        if cfg.lambda_root_features > 0:
            # the root channels again, averaged over their own 4 columns (normalised units, as rec)
            root_feat = masked_mean(err[..., sl["root"]], frame_w)
            out["root_feat"] = root_feat
            total = total + cfg.lambda_root_features * root_feat
            out["loss"] = total
        if cfg.lambda_bone > 0:
            if stats is None:
                raise ValueError("lambda_bone > 0 needs stats=(mean, std) of the features to measure bone lengths")
            mean, std = (torch.as_tensor(t, dtype=x.dtype, device=x.device) for t in stats)
            err_len = (self.bone_lengths(recon * std + mean) - self.bone_lengths(x * std + mean)).abs()
            bone = masked_mean(err_len, frame_w)                      # metres, mean over bones and frames
            out["bone"] = bone
            total = total + cfg.lambda_bone * bone
            out["loss"] = total
        integrated = {"lambda_root": "integrate the root", "lambda_foot": "integrate the feet"}
        need = [name for name in integrated if getattr(cfg, name) > 0]
        if need:
            if stats is None:
                raise ValueError(f"{need[0]} > 0 needs stats=(mean, std) of the features to {integrated[need[0]]}")
            mean, std = (torch.as_tensor(t, dtype=torch.float32, device=x.device) for t in stats)
            # integration in float32 even under bf16 autocast: sums of N small velocities lose digits
            with torch.autocast(x.device.type, enabled=False):
                raw_recon, raw_x = recon.float() * std + mean, x.float() * std + mean
                if cfg.lambda_root > 0:
                    yaw_err, pos_err = self.root_error(raw_recon, raw_x, mask)
                    out["root_yaw"], out["root_pos"] = yaw_err, pos_err
                    out["root"] = yaw_err + pos_err
                    total = total + cfg.lambda_root * out["root"]
                if cfg.lambda_foot > 0:
                    out["foot"] = self.foot_slide(raw_recon, raw_x, mask)
                    total = total + cfg.lambda_foot * out["foot"]
            out["loss"] = total
        return out

    def foot_slide(self, recon: torch.Tensor, target: torch.Tensor,
                   mask: torch.Tensor | None = None) -> torch.Tensor:
        """The foot-contact term: mean speed (metres per frame) of the reconstruction's contact joints (ankles and
        toes) over the frames where the **input's** contact channels say that joint is planted and, unless
        ``config.foot_planted_step`` is None, the input's own joint moves less than that between the two frames.
        The second condition keeps the term off feet that really move: HumanML3D's contact channels mark any
        foot slower than ~0.9 m/s. Measured (``lab/scripts/vae/measure_decoder_feet.py``, 60 corpus 2.4 test clips,
        SALAD 0.3's VAE: MPJPE 1.54 cm, skating 0.054 m/s, the clips 0.007): 1,500-step decoder fine-tunes
        with lambda 20 gave 2.50 cm / 0.066 m/s (channels alone) and 2.31 cm / 0.059 m/s (with this
        condition), against 1.52 cm / 0.054 m/s without the term; so neither variant lowers skating by
        fine-tuning the decoder. Most of that skating is in the root-relative feet (the true root with the
        reconstructed ``ric`` still skates 0.056 m/s), not in the root path (0.031 m/s).

        Why: every other term compares features, and a reconstruction 1-2 cm off in position can still let a
        planted foot slide by centimetres per frame, which the eye reads as skating (the v3 general VAE's
        reconstructions of corpus clips slide 0.061 m/s where the clips slide 0.008). Speeds are
        taken on the global joints of :meth:`root_trajectory` (the path the recovery integrates), between
        frames ``t`` and ``t + 1`` where the joint is in contact at both and both are valid.

        Parameters
        ----------
        recon, target : Tensor ``(B, N, D)``
            De-normalised features (the target's contact channels are 0/1 labels).
        mask : Tensor ``(B, N)`` bool, optional

        Returns
        -------
        Tensor: scalar, metres per frame (0 when no frame is in contact).
        """
        sk = self.skeleton
        _, joints = self.root_trajectory(recon, mask)
        feet = joints[..., list(sk.contact_joints), :]                       # (B, N, 4, 3)
        step = feet[:, 1:] - feet[:, :-1]                                    # (B, N-1, 4, 3)
        contact = target[..., sk.feature_slices["contacts"]] > 0.5           # (B, N, 4)
        both = contact[:, 1:] & contact[:, :-1]
        if self.config.foot_planted_step is not None:
            with torch.no_grad():
                _, ref = self.root_trajectory(target, mask)
                ref_feet = ref[..., list(sk.contact_joints), :]
                ref_step = (ref_feet[:, 1:] - ref_feet[:, :-1]).pow(2).sum(-1).sqrt()
            both = both & (ref_step < self.config.foot_planted_step)
        if mask is not None:
            valid = mask[:, 1:] & mask[:, :-1]
            both = both & valid[..., None]
        sq = step.pow(2).sum(-1)
        moving = sq.gt(0) & both
        speed = torch.where(moving, torch.where(moving, sq, torch.ones_like(sq)).sqrt(), torch.zeros_like(sq))
        return speed.sum() / both.sum().clamp_min(1).to(speed.dtype)

    def root_trajectory(self, features: torch.Tensor,
                        mask: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Integrated root yaw and global joint positions of de-normalised features, in torch.

        The integration is HumanML3D's ``recover_root_rot_pos`` / ``recover_from_ric``
        (:func:`salad_core.motion.features_to_joints`, tested equal): the half-angle
        ``a_t = sum_{s<t} f[s, 0]`` starts at 0 on the window's first frame, the root x/z path sums
        the linear velocities ``f[s-1, 1:3]`` rotated from the heading frame of frame ``s`` to the world,
        and joint ``j > 0`` is the ``ric`` position rotated by the heading plus the root x/z. It is
        written here without :mod:`salad_core.motion`'s input checks, which read values back from the
        tensor every call (a training step must not synchronise or raise on a wild early prediction).

        Parameters
        ----------
        features : Tensor ``(B, N, D)``
            De-normalised features (metres, radians, metres per frame).
        mask : Tensor ``(B, N)`` bool, optional
            Valid frames; the root velocities of masked frames count as zero, so padding never moves
            the integrated root.

        Returns
        -------
        yaw : Tensor ``(B, N)``
            Heading angle in radians (``2 a_t``; 0 on the first frame).
        joints : Tensor ``(B, N, J, 3)``
            Global joint positions in metres (root x/z integrated from the window's start).
        """
        from salad_core.quaternion import qinv, qrot

        sk = self.skeleton
        vel = features[..., :3]                                              # (B, N, 3) yaw vel, x vel, z vel
        if mask is not None:
            vel = vel * mask[..., None].to(vel.dtype)
        zero = torch.zeros_like(vel[..., :1, :])
        prev = torch.cat([zero, vel[..., :-1, :]], dim=-2)                   # row t-1 moves frame t
        half = torch.cumsum(prev[..., 0], dim=-1)                            # (B, N) half-angle
        c, s, z = torch.cos(half), torch.sin(half), torch.zeros_like(half)
        heading = torch.stack([c, z, s, z], dim=-1)                          # (B, N, 4) world -> heading
        to_world = qinv(heading)
        step = qrot(to_world, torch.stack([prev[..., 1], z, prev[..., 2]], dim=-1))
        xz = torch.cumsum(step, dim=-2)                                      # (B, N, 3), y unused
        root = torch.stack([xz[..., 0], features[..., 3], xz[..., 2]], dim=-1)
        ric = features[..., sk.feature_slices["ric"]].unflatten(-1, (sk.num_joints - 1, 3))
        offset = torch.stack([xz[..., 0], z, xz[..., 2]], dim=-1)[..., None, :]
        body = qrot(to_world[..., None, :], ric) + offset                    # (B, N, J-1, 3)
        return 2.0 * half, torch.cat([root[..., None, :], body], dim=-2)

    def root_error(self, recon: torch.Tensor, target: torch.Tensor,
                   mask: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """The integrated-root term: ``(yaw error in rad, global joint error in m)``.

        Why: the other terms compare features frame by frame, so a small bias in the root's angular
        or linear velocity costs almost nothing while it integrates into a heading that drifts by tens
        of degrees over a clip. Both windows are integrated from the same start
        (:meth:`root_trajectory`) and compared on valid frames:

        * ``yaw = mean_t |yaw_rec(t) - yaw_in(t)|`` (radians), and
        * ``pos = mean_{t,j} ||p_rec(t, j) - p_in(t, j)||`` (metres): the global joint positions
          (ric joints rotated by the integrated yaw plus the integrated root path; the root joint
          carries the root height).

        A constant yaw-velocity bias ``b`` (half-angle per frame) gives ``yaw(t) = 2 b t``, so the
        term grows with the window: ``b (N - 1)`` on average over ``N`` frames.

        Parameters
        ----------
        recon, target : Tensor ``(B, N, D)``
            De-normalised features.
        mask : Tensor ``(B, N)`` bool, optional
            Valid frames (the others are neither integrated nor averaged).

        Returns
        -------
        (Tensor, Tensor)
            Scalars: mean absolute yaw error (rad) and mean joint distance (m).
        """
        yaw_r, joints_r = self.root_trajectory(recon, mask)
        yaw_t, joints_t = self.root_trajectory(target, mask)
        sq = (joints_r - joints_t).pow(2).sum(-1)                            # (B, N, J)
        # sqrt has an infinite slope at 0: take it only where the distance is positive (exact 0 otherwise)
        pos = sq.gt(0)
        dist = torch.where(pos, torch.where(pos, sq, torch.ones_like(sq)).sqrt(), torch.zeros_like(sq))
        yaw = (yaw_r - yaw_t).abs()
        if mask is None:
            return yaw.mean(), dist.mean()
        w = mask.to(yaw.dtype)
        n = w.sum().clamp_min(1.0)
        return (yaw * w).sum() / n, (dist.mean(-1) * w).sum() / n

    def bone_lengths(self, features: torch.Tensor) -> torch.Tensor:
        """Bone lengths ``(..., N, J-1)`` (metres) of de-normalised features ``(..., N, D)``.

        Read from the root height and the ``ric`` slice (root-relative joint positions in the
        heading frame, whose x/z put the root at the origin), so no forward kinematics is needed:
        bone ``j`` joins joint ``j`` and its parent. Why a bone term: the decoder otherwise lets
        limbs stretch where the latent is slightly off the data (issue: bones of generated motions
        drifted by up to 49 cm).
        """
        sk = self.skeleton
        sl = sk.feature_slices
        ric = features[..., sl["ric"]].unflatten(-1, (sk.num_joints - 1, 3))          # (..., N, J-1, 3)
        root_y = features[..., sl["root_y"]]                                           # (..., N, 1)
        root = torch.cat([torch.zeros_like(root_y), root_y, torch.zeros_like(root_y)], dim=-1)
        joints = torch.cat([root.unsqueeze(-2), ric], dim=-2)                         # (..., N, J, 3)
        parents = torch.as_tensor(sk.parents[1:], device=features.device)
        return (joints[..., 1:, :] - joints[..., parents, :]).norm(dim=-1)

    # ------------------------------------------------------- official weights
    @classmethod
    def from_official_state_dict(cls, state_dict: dict[str, torch.Tensor], dataset: str = "humanml3d",
                                 **config_overrides) -> "MotionVAE":
        """Build a VAE from an official SALAD state dict (``checkpoint["vae"]``) and load it strictly.

        ``latent_dim``, ``n_layers``, ``n_extra_layers`` and ``norm`` are read from the keys and
        shapes; ``activation`` and ``dropout`` cannot be, so they take the defaults (GELU, as the
        released "vaegelu" model) unless given in ``config_overrides``.

        Parameters
        ----------
        state_dict : dict
            The official VAE weights, or the whole checkpoint dict holding them under ``"vae"``.
        dataset : str
            ``"humanml3d"`` (``"t2m"``) or ``"kit"``.

        Raises
        ------
        salad_core.io.CheckpointError
            On missing, unexpected or mis-shaped keys (names the first offending key).
        """
        if isinstance(state_dict.get("vae"), dict):
            state_dict = state_dict["vae"]
        skeleton = get_skeleton(dataset)
        n_mlps = len({k.split(".")[2] for k in state_dict if k.startswith("motion_enc.layers.")})
        if n_mlps and n_mlps != skeleton.num_joints:
            raise ValueError(
                f"the state dict has {n_mlps} joint MLPs but dataset={dataset!r} has {skeleton.num_joints} joints; "
                f"choose the dataset the weights were trained on ({', '.join(available_skeletons())})"
            )
        inferred: dict[str, object] = {"skeleton": skeleton.name, "kind": "st"}
        first = state_dict.get("motion_enc.layers.0.0.weight")
        if first is not None:
            inferred["latent_dim"] = int(first.shape[0])
        blocks = [re.match(r"conv_enc\.layers\.(\d+)\.(\d+)\.layers\.", k) for k in state_dict]
        blocks = [(int(m.group(1)), int(m.group(2))) for m in blocks if m]
        if blocks:
            inferred["n_layers"] = max(lvl for lvl, _ in blocks) + 1
            inferred["n_extra_layers"] = max(r for _, r in blocks)  # indices 0..n_extra are ResSTConv
        if any(k.endswith(".layers.0.running_mean") for k in state_dict):
            inferred["norm"] = "batch"
        elif any(re.search(r"\.layers\.0\.weight$", k) and k.startswith("conv_") for k in state_dict):
            inferred["norm"] = "layer"
        inferred.update(config_overrides)
        config = VAEConfig(**inferred)
        model = cls(config)
        load_state_into(model, dict(state_dict), source="official SALAD VAE state dict")
        logger.info("loaded an official SALAD VAE (%s, %d tensors)", config.skeleton, len(state_dict))
        return model

    def official_state_dict(self) -> dict[str, torch.Tensor]:
        """The weights in the official key layout (identical to ``state_dict()`` by construction)."""
        if self.config.kind != "st":
            raise ValueError("the official code has no kind='pose' VAE; use state_dict() for it")
        return dict(self.state_dict())

    def num_parameters(self, trainable_only: bool = True) -> int:
        """Parameter count; the official script's figure (0.168M) includes the frozen graph matrices.

        ``trainable_only`` leaves out the graph matrices (adjacency, pooling), which are structure,
        not weights; it does not depend on ``requires_grad``, so a VAE frozen for inference counts the
        same as in training.
        """
        return sum(p.numel() for p in self.parameters()
                   if not (trainable_only and getattr(p, "salad_constant", False)))

    # -------------------------------------------------------------- helpers
    def _criterion(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        if self.config.recon_loss == "l1_smooth":
            return F.smooth_l1_loss(pred, target, reduction="none", beta=1.0)
        if self.config.recon_loss == "l1":
            return F.l1_loss(pred, target, reduction="none")
        return F.mse_loss(pred, target, reduction="none")

    def _check_motion(self, x: torch.Tensor, name: str, check_length: bool = True) -> None:
        if x.ndim != 3 or x.shape[-1] != self.feature_dim:
            raise ValueError(f"{name} must be (B, N, {self.feature_dim}) normalised {self.skeleton.name} features, "
                             f"got {tuple(x.shape)}")
        if check_length and (x.shape[1] == 0 or x.shape[1] % self.downsample):
            raise ValueError(f"{name} has N={x.shape[1]} frames; N must be a positive multiple of "
                             f"{self.downsample} (crop or pad the motion)")


register_model("salad_vae", VAEConfig, MotionVAE)
