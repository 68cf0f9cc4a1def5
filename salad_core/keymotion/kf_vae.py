"""The keyframe VAE of KeyMotion (paper §III-B, eqs. 2-6).

Data flow (default sizes; HumanML3D ``D = 263``)::

    keyframes (B, K, D) normalised --Linear--> (B, K, 120) ┐ concatenated
    positions (B, K) in [0, 1] --[u, SPE(u (Nmax-1))]--Linear--> (B, K, 8) ┘ -> (B, K, 128)
    [latent tokens (Lz, 128) ; keyframe tokens] + SPE over the token order
      --transformer encoder x layers--> latent-token outputs --LN, Linear--> mu, logvar (B, Lz, Dz)
    z = mu + eps * exp(logvar / 2)
    queries SPE(0..K-1) (B, K, 128), memory Linear(z) + SPE(0..Lz-1)
      --transformer decoder x layers (self-attn, cross-attn to the memory, FFN)-->
      --LN--> Linear -> keyframes (B, K, D)
              Linear -> gap logits (B, K-1) --softmax, cumsum--> positions (B, K), 0 = u_0 < ... < u_K-1 = 1

Choices where the paper is silent (its equations were lost in our copy) or that we changed:

* **Number of keyframes** ``K`` is fixed per model (``num_keyframes``, default 20, about the
  paper's 10 % of the 196-frame maximum). Every motion, whatever its length ``L >= K``, is
  represented by ``K`` keyframes, so all tensors are dense and no masks are needed; short motions
  simply get denser keyframes.
* **Index representation**: the keyframe index ``i_k`` of a motion of length ``L`` is encoded by
  its normalised position ``u_k = i_k / (L - 1)`` in ``[0, 1]`` (first keyframe 0, last 1). The
  index embedding (``index_dim`` channels, the paper's 16 of 272) is a linear map of
  ``[u_k, SPE(u_k (max_length - 1))]``, concatenated to the keyframe embedding (``frame_dim``).
* **Index decoding**: the decoder regresses the *gaps* between consecutive positions: the query
  tokens ``1 .. K-1`` give one logit each, a softmax turns them into positive gaps summing to 1,
  and their cumulative sum is ``u_1 .. u_K-1`` (``u_0 = 0``). The decoded positions are thus
  increasing, start at 0 and end at 1 by construction, so the decoded keyframes never need
  reordering (plain regression of ``u_k`` mis-ordered keyframes whose positions were close).
  :func:`positions_to_indices` turns positions into frames: ``round(u (L - 1))``, sort, clamp to
  ``[0, L - 1]``, make strictly increasing, and force the first and last keyframes to frames
  ``0`` and ``L - 1``.
* **Timing** (:attr:`KeyframeVAEConfig.timing`): ``"relative"`` (above; KeyMotion 0.2) makes a latent
  length-free, so the same latent decoded at a longer length plays its motion slower: asked for a
  one-action caption at three times its corpus length, such a model moves at a third to a half of
  its speed. ``"absolute"`` encodes ``u_k = i_k / (max_length - 1)`` (a frame index, as the paper's
  "position index"), query 0's logit takes the share after the last keyframe (so ``u_K-1 <= 1``
  and says how long the motion is), and :func:`positions_to_indices` reads ``round(u (max_length
  - 1))``: a latent keeps its pace at any length, only the last keyframe moving to ``L - 1``.
  Use :meth:`KeyframeVAE.positions_of` / :meth:`KeyframeVAE.indices_of`, which follow the model.
* **Losses** (eq. 2): ``L = L_rec + λ_kl L_kl + λ_bone L_bone + λ_index L_index`` with
  ``L_rec`` the MSE of the normalised keyframe features (eq. 3), ``L_kl`` the mean over latent
  elements of ``0.5 (mu^2 + sigma^2 - log sigma^2 - 1)`` (eq. 4), ``L_bone`` the mean absolute
  bone-length error in metres of each keyframe pose recovered alone (eq. 5,
  :func:`~salad_core.keymotion.models.pose_joints`), and ``L_index`` the mean absolute error of
  ``u`` (eq. 6; L1 rather than MSE, whose gradient vanishes at the one-frame errors that matter).
  Weights: ``λ_kl = 1e-4`` (as MLD), ``λ_bone = 1``, ``λ_index = 3`` (chosen on overfit runs:
  keyframes and indices are both recovered, the latter within one or two frames).
  **Feature-group terms** (an addition, default off): ``λ_root``, ``λ_local_vel``, ``λ_contact`` and
  ``λ_feet_height`` add the MSE of the normalised root (channels 0-3: rotation velocity, planar
  velocity, height), joint-velocity, foot-contact and foot-height channels (the ``y`` of the four
  contact joints' positions) once more. ``L_rec`` averages all ``D`` channels, so the few that carry
  a jump's flight weigh little in it. Swapping channel groups between true and decoded keyframes of 30
  validation jumps before the MMAE in-fills them (KeyMotion 0.2) showed which: the true keyframes
  in-fill a flight of -9.3 m/s^2, with the decoded foot heights instead -2.0 (and 70 frames "in
  flight" against 32), while the decoded keyframes with the true foot heights give -7.1 (-4.8 as
  decoded); the joint velocities, root and contact channels each moved it by less.
* **Latent**: ``Lz = 2`` tokens (the paper's best latent size for generation, supplement C) of
  ``Dz = 64`` channels, i.e. 128 numbers for ``K x D = 5260`` keyframe numbers; the encoder reads
  them off ``Lz`` learnable tokens prepended to the keyframe tokens, the decoder's queries are the
  fixed sinusoids of the keyframe slots ``0 .. K-1`` and its keys/values the projected latent.
* **Blocks** are pre-norm (more stable for tiny models trained briefly) with ReLU feed-forward
  as the paper's vanilla layers. Default sizes are small for a 2-core CPU (2 + 2 layers of
  width 128 instead of the paper's 8 + 8 of width 272).
* The normalisation statistics live inside the model (:class:`~salad_core.keymotion.models.Normalizer`)
  because the bone-length loss needs de-normalised features.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import NamedTuple

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.io import register_model
from salad_core.models.gemm import Linear
from salad_core.models.layers import ACTIVATIONS
from salad_core.skeleton import Skeleton, get_skeleton

from .models import (
    FeatureModel,
    bone_length_loss,
    check_non_negative,
    check_positive_int,
    check_skeleton_name,
    check_unit_interval,
    pose_joints,
    position_sinusoid,
    transformer_blocks,
)

__all__ = [
    "KeyframeVAEConfig",
    "KeyframeEncoding",
    "KeyframeDecoding",
    "KeyframeVAE",
    "indices_to_positions",
    "positions_to_indices",
    "KEYFRAME_TIMINGS",
    "gather_keyframes",
    "GROUP_TERMS",
    "group_channels",
]

log = logging.getLogger(__name__)

#: How keyframe positions are normalised (:attr:`KeyframeVAEConfig.timing`).
KEYFRAME_TIMINGS = ("relative", "absolute")


@dataclass(frozen=True)
class KeyframeVAEConfig:
    """Configuration of :class:`KeyframeVAE` (small CPU defaults; paper values in comments)."""

    skeleton: str = "humanml3d"   # "humanml3d" or "kit": sets the feature width D and the bones
    num_keyframes: int = 20       # K keyframes per motion (paper: 10 % of the frames)
    max_length: int = 196         # longest motion (frames); scales the index sinusoid
    frame_dim: int = 120          # keyframe embedding channels (paper 256)
    index_dim: int = 8            # keyframe-index embedding channels, even (paper 16)
    latent_size: int = 2          # Lz latent tokens (paper's best for generation: 2)
    latent_dim: int = 64          # Dz channels per latent token
    num_layers: int = 2           # encoder layers = decoder layers (paper 8)
    num_heads: int = 4            # attention heads (paper 4)
    ff_dim: int = 256             # feed-forward hidden width (paper 1024)
    dropout: float = 0.1          # dropout (paper 0.1)
    activation: str = "relu"      # feed-forward activation (paper: ReLU)
    lambda_kl: float = 1e-4       # weight of the KL term (eq. 4)
    lambda_bone: float = 1.0      # weight of the bone-length term (eq. 5), metres
    lambda_index: float = 3.0     # weight of the keyframe-position term (eq. 6, L1 on u)
    lambda_root: float = 0.0      # extra MSE weight of the root channels (0-3), normalised units
    lambda_local_vel: float = 0.0  # extra MSE weight of the joint-velocity channels
    lambda_contact: float = 0.0   # extra MSE weight of the four foot-contact channels
    lambda_feet_height: float = 0.0  # extra MSE weight of the four contact joints' height channels
    latent_noise: float = 0.0     # training only: std (latent units) of Gaussian noise added to the latent the
                                  # decoder reads, so it also decodes latents near the posteriors (0: off)
    timing: str = "relative"      # keyframe positions: "relative" u = i / (L - 1) (shipped 0.2); "absolute"
                                  # u = i / (max_length - 1), a frame index (the paper's), so a latent has a pace

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_skeleton_name(self)
        for f in ("num_keyframes", "max_length", "frame_dim", "index_dim", "latent_size", "latent_dim",
                  "num_layers", "num_heads", "ff_dim"):
            check_positive_int(name, f, getattr(self, f))
        if self.num_keyframes < 2:
            raise ValueError(f"{name}.num_keyframes={self.num_keyframes} is invalid; use >= 2 (first and last frame)")
        if self.num_keyframes > self.max_length:
            raise ValueError(f"{name}.num_keyframes={self.num_keyframes} exceeds max_length={self.max_length}")
        if self.index_dim % 2:
            raise ValueError(f"{name}.index_dim={self.index_dim} is invalid; use an even integer (sin/cos pairs)")
        if self.width % self.num_heads:
            raise ValueError(f"{name}: width frame_dim + index_dim = {self.width} must be divisible by "
                             f"num_heads={self.num_heads}")
        if self.width % 2:
            raise ValueError(f"{name}: width frame_dim + index_dim = {self.width} must be even")
        check_unit_interval(name, "dropout", self.dropout)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"{name}.activation={self.activation!r} is invalid; choose one of {ACTIVATIONS}")
        for f in ("lambda_kl", "lambda_bone", "lambda_index", "lambda_root", "lambda_local_vel", "lambda_contact",
                  "lambda_feet_height", "latent_noise"):
            check_non_negative(name, f, getattr(self, f))
        if self.timing not in KEYFRAME_TIMINGS:
            raise ValueError(f"{name}.timing={self.timing!r} is invalid; choose one of {KEYFRAME_TIMINGS}")

    @property
    def width(self) -> int:
        """Token channels of the transformer: ``frame_dim + index_dim`` (paper 272)."""
        return self.frame_dim + self.index_dim


class KeyframeEncoding(NamedTuple):
    """Posterior of a batch of keyframe sets; each ``(B, Lz, Dz)``."""

    z: torch.Tensor       # sample (or mu when not sampling)
    mu: torch.Tensor
    logvar: torch.Tensor


class KeyframeDecoding(NamedTuple):
    """Decoded keyframes: ``keyframes (B, K, D)`` normalised, ``positions (B, K)`` increasing ``u`` in [0, 1]."""

    keyframes: torch.Tensor
    positions: torch.Tensor


# ------------------------------------------------------------------------- index helpers
def _check_lengths(lengths: torch.Tensor, minimum: int, why: str) -> torch.Tensor:
    lengths = torch.as_tensor(lengths).long().reshape(-1)
    if bool((lengths < minimum).any()):
        raise ValueError(f"lengths must all be >= {minimum} ({why}), got {lengths.tolist()}")
    return lengths


def _span(lengths: torch.Tensor, span: int | None) -> torch.Tensor:
    """``(B, 1)`` float frames that ``u = 1`` stands for: ``L - 1`` per motion, or ``span`` for all."""
    if span is None:
        return (lengths[:, None] - 1).float()
    if isinstance(span, bool) or not isinstance(span, int) or span < 1:
        raise ValueError(f"span={span!r} must be a positive int (frames u = 1 stands for) or None (L - 1)")
    if bool((lengths - 1 > span).any()):
        raise ValueError(f"lengths {lengths.tolist()} exceed span + 1 = {span + 1} frames")
    return torch.full((len(lengths), 1), float(span), device=lengths.device)


def indices_to_positions(indices: torch.Tensor, lengths: torch.Tensor, span: int | None = None) -> torch.Tensor:
    """Normalised positions ``u = i / (L - 1)`` (``span`` None: relative to each motion's length) or ``u = i /
    span`` (absolute, e.g. ``span = max_length - 1``): ``indices (B, K)`` long, ``lengths (B,)`` -> ``(B, K)``
    float."""
    lengths = _check_lengths(lengths, 2, "a first and a last frame").to(indices.device)
    return indices.float() / _span(lengths, span)


def positions_to_indices(positions: torch.Tensor, lengths: torch.Tensor, span: int | None = None) -> torch.Tensor:
    """Frame indices from decoded positions: ``(B, K)`` float, ``lengths (B,)`` -> ``(B, K)`` long.

    ``round(u (L - 1))`` (``span`` None) or ``round(u span)``, clamped to ``[0, L - 1]``, sorted, then made
    strictly increasing inside ``[0, L - 1]`` with the first keyframe at frame 0 and the last at ``L - 1``.
    Requires ``L >= K``. With absolute positions a latent decoded for another length than its own keeps its
    keyframes' frames (its pace) and only the last keyframe moves to ``L - 1``.

    Strictness is solved on ``c_k = i_k - k``: the indices are strictly increasing in ``[0, L-1]``
    exactly when ``c`` is non-decreasing in ``[0, L - K]``, which a running maximum and a clamp
    give while moving each index as little as that order allows.
    """
    if positions.dim() != 2:
        raise ValueError(f"positions must be (B, K), got shape {tuple(positions.shape)}")
    b, k = positions.shape
    lengths = _check_lengths(lengths, k, "the number of keyframes").to(positions.device)
    if lengths.shape[0] != b:
        raise ValueError(f"lengths has {lengths.shape[0]} entries for a batch of {b}")
    last = (lengths - 1)[:, None].float()
    idx = torch.round(positions.detach().float() * _span(lengths, span)).clamp(min=0).minimum(last).long()
    idx, _ = torch.sort(idx, dim=1)
    ramp = torch.arange(k, device=positions.device)[None]
    c = torch.cummax(idx - ramp, dim=1).values
    c = c.clamp(min=0).minimum((lengths - k)[:, None])
    c[:, 0] = 0
    c[:, -1] = lengths - k
    return c + ramp


def gather_keyframes(motion: torch.Tensor, indices: torch.Tensor) -> torch.Tensor:
    """Rows of ``motion (B, N, D)`` at ``indices (B, K)`` -> ``(B, K, D)``."""
    return torch.gather(motion, 1, indices[..., None].expand(-1, -1, motion.shape[-1]))


#: ``KeyframeVAEConfig`` loss weight -> the feature group it weighs again (:func:`group_channels`).
GROUP_TERMS = {"lambda_root": "root", "lambda_local_vel": "local_vel", "lambda_contact": "contacts",
               "lambda_feet_height": "feet_height"}


def group_channels(skeleton: str | Skeleton, group: str) -> list[int]:
    """Feature columns of a group of :data:`GROUP_TERMS`: a ``Skeleton.feature_slices`` group, or
    ``"feet_height"``, the ``y`` of the contact joints' positions (``ric``, one column per joint)."""
    sk = get_skeleton(skeleton)
    if group == "feet_height":
        ric = sk.feature_slices["ric"].start
        return [ric + 3 * (j - 1) + 1 for j in sk.contact_joints]
    if group not in sk.feature_slices:
        raise ValueError(f"unknown feature group {group!r}; use 'feet_height' or one of {sorted(sk.feature_slices)}")
    return list(range(sk.feature_dim))[sk.feature_slices[group]]


# ---------------------------------------------------------------------------------- model
class KeyframeVAE(FeatureModel):
    """Keyframes and their positions <-> a small latent ``(B, Lz, Dz)`` (paper §III-B).

    Parameters
    ----------
    config : KeyframeVAEConfig, optional
    """

    def __init__(self, config: KeyframeVAEConfig | None = None) -> None:
        super().__init__(config or KeyframeVAEConfig())
        cfg = self.config
        d, w = self.feature_dim, cfg.width
        self.frame_embed = Linear(d, cfg.frame_dim)
        self.index_embed = Linear(cfg.index_dim + 1, cfg.index_dim)
        self.latent_tokens = nn.Parameter(torch.randn(cfg.latent_size, w) * 0.02)
        self.encoder = transformer_blocks(cfg, w)
        self.encoder_norm = nn.LayerNorm(w)
        self.to_dist = Linear(w, 2 * cfg.latent_dim)
        self.latent_in = Linear(cfg.latent_dim, w)
        self.decoder = transformer_blocks(cfg, w, cross_attention=True)
        self.decoder_norm = nn.LayerNorm(w)
        self.to_keyframes = Linear(w, d)
        self.to_positions = Linear(w, 1)
        self.drop = nn.Dropout(cfg.dropout)            # the encoder's input dropout (the decoder has its own)
        n_tok = cfg.latent_size + cfg.num_keyframes
        self.register_buffer("token_pe", position_sinusoid(torch.arange(n_tok), w), persistent=False)
        self.register_buffer("query_pe", position_sinusoid(torch.arange(cfg.num_keyframes), w), persistent=False)
        self.register_buffer("memory_pe", position_sinusoid(torch.arange(cfg.latent_size), w), persistent=False)
        self._group_columns = {g: torch.tensor(group_channels(self.skeleton, g)) for g in GROUP_TERMS.values()}

    # ------------------------------------------------------------------------ properties
    @property
    def num_keyframes(self) -> int:
        return self.config.num_keyframes

    @property
    def latent_shape(self) -> tuple[int, int]:
        """``(Lz, Dz)``."""
        return (self.config.latent_size, self.config.latent_dim)

    @property
    def position_span(self) -> int | None:
        """Frames a position of 1 stands for: None for relative timing (each motion's ``L - 1``), ``max_length - 1``
        for absolute timing (:attr:`KeyframeVAEConfig.timing`)."""
        return None if self.config.timing == "relative" else self.config.max_length - 1

    def positions_of(self, indices: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """The positions this model encodes for keyframe ``indices (B, K)`` of motions of ``lengths (B,)``
        (:func:`indices_to_positions` with :attr:`position_span`)."""
        return indices_to_positions(indices, lengths, self.position_span)

    def indices_of(self, positions: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """Frame indices ``(B, K)`` of decoded ``positions`` for motions of ``lengths (B,)``
        (:func:`positions_to_indices` with :attr:`position_span`)."""
        return positions_to_indices(positions, lengths, self.position_span)

    def set_normalization(self, mean, std) -> None:
        """Store the dataset statistics ``(D,)`` the model's inputs are normalised with."""
        self.norm.set(mean, std)

    def encoder_modules(self) -> list[nn.Module]:
        """The modules that map keyframes to ``mu, logvar``, its input dropout included (the learnable latent
        tokens are frozen with them by :meth:`freeze_encoder`)."""
        return [self.frame_embed, self.index_embed, self.drop, self.encoder, self.encoder_norm, self.to_dist]

    def freeze_encoder(self) -> int:
        """Turn off gradients of the encoder (decoder fine-tuning: the posteriors a PST was trained on
        stay the same); returns how many parameter tensors were frozen."""
        params = [p for m in self.encoder_modules() for p in m.parameters()] + [self.latent_tokens]
        for p in params:
            p.requires_grad_(False)
        return len(params)

    # ----------------------------------------------------------------------- encode/decode
    def _check_inputs(self, keyframes: torch.Tensor, positions: torch.Tensor) -> None:
        k, d = self.config.num_keyframes, self.feature_dim
        if keyframes.dim() != 3 or keyframes.shape[1:] != (k, d):
            raise ValueError(f"keyframes must be (B, {k}, {d}) normalised {self.skeleton.name} features, "
                             f"got {tuple(keyframes.shape)}")
        if positions.shape != keyframes.shape[:2]:
            raise ValueError(f"positions must be (B, K) = {tuple(keyframes.shape[:2])}, got {tuple(positions.shape)}")

    def encode(self, keyframes: torch.Tensor, positions: torch.Tensor, sample: bool = True,
               generator: torch.Generator | None = None) -> KeyframeEncoding:
        """Posterior of keyframes.

        Parameters
        ----------
        keyframes : Tensor ``(B, K, D)``
            Normalised keyframe features, in time order.
        positions : Tensor ``(B, K)``
            Normalised positions (:meth:`positions_of`: ``u = i / (L - 1)``, or ``i / (max_length - 1)`` for
            absolute timing).
        sample : bool
            Return ``z = mu + eps sigma`` (else ``z = mu``).
        generator : torch.Generator, optional
            For ``eps``.
        """
        self._check_inputs(keyframes, positions)
        cfg = self.config
        b = keyframes.shape[0]
        pos = positions.to(keyframes.dtype)
        idx_feat = torch.cat([pos[..., None], position_sinusoid(pos * (cfg.max_length - 1), cfg.index_dim)], -1)
        tokens = torch.cat([self.frame_embed(keyframes), self.index_embed(idx_feat)], -1)   # (B, K, w)
        h = torch.cat([self.latent_tokens.expand(b, -1, -1), tokens], 1)                  # (B, Lz + K, w)
        h = self.drop(h + self.token_pe)
        for block in self.encoder:
            h = block(h)
        mu, logvar = self.to_dist(self.encoder_norm(h[:, : cfg.latent_size])).chunk(2, dim=-1)  # (B, Lz, Dz)
        if sample:
            eps = torch.randn(mu.shape, generator=generator, device=mu.device, dtype=mu.dtype)
            z = mu + eps * torch.exp(0.5 * logvar)
        else:
            z = mu
        return KeyframeEncoding(z, mu, logvar)

    def decode(self, z: torch.Tensor) -> KeyframeDecoding:
        """Latent ``z (B, Lz, Dz)`` -> keyframes ``(B, K, D)`` (normalised) and positions ``(B, K)``."""
        if z.dim() != 3 or tuple(z.shape[1:]) != self.latent_shape:
            raise ValueError(f"z must be (B, {self.latent_shape[0]}, {self.latent_shape[1]}), got {tuple(z.shape)}")
        b = z.shape[0]
        memory = self.latent_in(z) + self.memory_pe                       # (B, Lz, w)
        h = self.query_pe.to(z.dtype).expand(b, -1, -1)                   # (B, K, w) SPE queries
        for block in self.decoder:
            h = block(h, context=memory)
        h = self.decoder_norm(h)
        # positions as cumulated softmax gaps: increasing, first exactly 0; relative timing: the K-1 gaps sum to 1
        # (last exactly 1); absolute: query 0's logit is the share left after the last keyframe (last <= 1)
        if self.config.timing == "relative":
            gaps = torch.softmax(self.to_positions(h[:, 1:])[..., 0], dim=-1)        # (B, K-1)
        else:
            gaps = torch.softmax(self.to_positions(h)[..., 0], dim=-1)[:, 1:]        # (B, K-1), sum < 1
        positions = torch.cat([gaps.new_zeros(b, 1), torch.cumsum(gaps, -1)], -1)   # (B, K)
        return KeyframeDecoding(self.to_keyframes(h), positions)

    def forward(self, keyframes: torch.Tensor, positions: torch.Tensor, eps: torch.Tensor | None = None
                ) -> tuple[KeyframeDecoding, torch.Tensor, torch.Tensor]:
        """Sampled reconstruction: ``(decoding, mu, logvar)``; ``eps (B, Lz, Dz)`` optional noise."""
        enc = self.encode(keyframes, positions, sample=False)
        if eps is None:
            eps = torch.randn_like(enc.mu)
        z = enc.mu + eps * torch.exp(0.5 * enc.logvar)
        return self.decode(z), enc.mu, enc.logvar

    # ----------------------------------------------------------------------------- loss
    def loss(self, keyframes: torch.Tensor, positions: torch.Tensor, decoding: KeyframeDecoding,
             mu: torch.Tensor, logvar: torch.Tensor) -> dict[str, torch.Tensor]:
        """Eq. 2: ``L = L_rec + λ_kl L_kl + λ_bone L_bone + λ_index L_index``, plus the feature-group
        terms ``λ_root L_root + λ_local_vel L_local_vel + λ_contact L_contact`` (MSE of those channels).

        Parameters
        ----------
        keyframes, positions : Tensor ``(B, K, D)``, ``(B, K)``
            The targets (normalised features, normalised positions).
        decoding : KeyframeDecoding
            The reconstruction.
        mu, logvar : Tensor ``(B, Lz, Dz)``

        Returns
        -------
        dict of scalar tensors ``loss``, ``rec``, ``kl``, ``bone``, ``index``, and ``root``,
        ``local_vel``, ``contacts``, ``feet_height`` for the group terms whose weight is > 0.
        """
        self._check_inputs(keyframes, positions)
        cfg = self.config
        rec = F.mse_loss(decoding.keyframes, keyframes)
        kl = 0.5 * (mu.pow(2) + logvar.exp() - logvar - 1.0).mean()
        index = F.l1_loss(decoding.positions, positions.to(decoding.positions.dtype))
        if cfg.lambda_bone > 0:
            pred_j = pose_joints(self.norm.denormalize(decoding.keyframes), self.skeleton)   # (B, K, J, 3)
            true_j = pose_joints(self.norm.denormalize(keyframes), self.skeleton)
            bone = bone_length_loss(pred_j, true_j, self.skeleton)
        else:
            bone = rec.new_zeros(())
        total = rec + cfg.lambda_kl * kl + cfg.lambda_bone * bone + cfg.lambda_index * index
        out = {"rec": rec, "kl": kl, "bone": bone, "index": index}
        for weight_name, group in GROUP_TERMS.items():
            weight = getattr(cfg, weight_name)
            if weight > 0:
                cols = self._group_columns[group]
                out[group] = F.mse_loss(decoding.keyframes[..., cols], keyframes[..., cols])
                total = total + weight * out[group]
        return {"loss": total, **out}

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())


register_model("keymotion_kf_vae", KeyframeVAEConfig, KeyframeVAE)
