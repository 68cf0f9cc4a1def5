"""The Motion Masked AutoEncoder (MMAE) of KeyMotion: text-conditioned in-filling (paper §III-D, eqs. 9-11).

Data flow (default sizes)::

    motion (B, N, D) normalised, keyframe_mask (B, N) --zero every non-keyframe row (MAE masking)-->
    [masked motion ; keyframe flag] --Linear--> (B, N, w) + SPE(frame)
    layer l = 1 .. num_layers ("conditional residual transformer"):
        seq = [Linear_l(text) + SPE (B, W, w) ; h (B, N, w)]     text re-inserted at the leading positions
        h   = TransformerBlock_l(seq, key mask [text_mask ; frame_mask])[:, W:]
    --LN, Linear (zero-initialised)--> residual r (B, N, D)
    out = lerp(keyframes) + r          (or just r with lerp_residual=False)

Choices where the paper is silent or that we made:

* **Text at the leading positions of every layer.** Each layer gets its own projection of the
  text token features, prepended to the motion tokens; the layer's outputs at the text positions
  are dropped, so the condition enters every layer afresh (the paper's "adding CLIP text
  representations to the leading position in each layer").
* **Keyframe flag** (an addition): a 0/1 channel marks the keyframes, because a zeroed frame and a
  keyframe whose normalised features happen to be near zero are otherwise indistinguishable.
* **Residual over linear interpolation** (``lerp_residual``, an addition for small compute): the
  network predicts a correction to the per-channel linear interpolation between consecutive
  keyframes, and its output layer starts at zero, so an untrained MMAE already returns the
  interpolation. The network still predicts every frame, keyframes included (the paper lets the
  MMAE repair faulty keyframes); :meth:`MotionMaskedAutoencoder.infill` can paste the given
  keyframes back (``keep_keyframes=True``). ``lerp_residual=False`` is the paper's plain MAE.
* **Losses** (eq. 9): ``L = L_mse + λ_bone L_bone + λ_vel L_vel``: the MSE of normalised features
  over valid frames; the mean absolute bone-length error (eq. 10) and the mean absolute joint
  velocity error ``|Δp - Δp*|`` (eq. 11), both in metres on the joints recovered by
  :func:`salad_core.motion.features_to_joints` from de-normalised features (the "FK" of the
  paper). ``λ_bone = λ_vel = 1``.
* Default sizes are small for a 2-core CPU: 4 layers of width 128 (paper 8 of width 512).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.io import register_model
from salad_core.models.gemm import Linear
from salad_core.models.layers import ACTIVATIONS
from salad_core.motion import features_to_joints

from .models import (
    FeatureModel,
    bone_length_loss,
    check_non_negative,
    check_positive_int,
    check_skeleton_name,
    check_unit_interval,
    foot_contact_loss,
    masked_mean,
    planted_foot_velocity_loss,
    position_sinusoid,
    transformer_blocks,
    velocity_loss,
)

__all__ = ["MMAEConfig", "MotionMaskedAutoencoder", "keyframe_lerp", "scatter_keyframes"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MMAEConfig:
    """Configuration of :class:`MotionMaskedAutoencoder` (small CPU defaults)."""

    skeleton: str = "humanml3d"   # "humanml3d" or "kit": feature width D and bones
    max_length: int = 196         # longest motion (frames): rows of the frame positional table
    text_dim: int = 384           # C, width of the text encoder's token features (MiniLM 384)
    width: int = 128              # token channels (paper 512)
    num_layers: int = 4           # conditional residual transformer layers (paper 8)
    num_heads: int = 4            # attention heads (paper 8)
    ff_dim: int = 256             # feed-forward hidden width (paper 2048)
    dropout: float = 0.1          # dropout (paper 0.1)
    activation: str = "gelu"      # feed-forward activation
    lerp_residual: bool = True    # predict a correction to keyframe interpolation (our addition)
    lambda_bone: float = 1.0      # weight of the bone-length term (eq. 10), metres
    lambda_vel: float = 1.0       # weight of the joint-velocity term (eq. 11), metres per frame
    lambda_foot: float = 0.0      # weight of the foot-contact term (planted feet stay put; MDM's, not the paper's)
    lambda_foot_vel: float = 0.0  # weight of the planted-foot velocity error (truly still feet only; not the paper's)
    foot_vel_gate: float = 0.2    # fastest ground-truth foot speed (m/s) that the planted-foot term counts
    max_text_tokens: int = 512    # rows of the text positional table

    def __post_init__(self) -> None:
        name = type(self).__name__
        check_skeleton_name(self)
        for f in ("max_length", "text_dim", "width", "num_layers", "num_heads", "ff_dim", "max_text_tokens"):
            check_positive_int(name, f, getattr(self, f))
        if self.width % self.num_heads or self.width % 2:
            raise ValueError(f"{name}.width={self.width} must be even and divisible by num_heads={self.num_heads}")
        check_unit_interval(name, "dropout", self.dropout)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"{name}.activation={self.activation!r} is invalid; choose one of {ACTIVATIONS}")
        if not isinstance(self.lerp_residual, bool):
            raise ValueError(f"{name}.lerp_residual={self.lerp_residual!r} is invalid; use True or False")
        for f in ("lambda_bone", "lambda_vel", "lambda_foot", "lambda_foot_vel"):
            check_non_negative(name, f, getattr(self, f))
        if not (isinstance(self.foot_vel_gate, (int, float)) and self.foot_vel_gate > 0):
            raise ValueError(f"{name}.foot_vel_gate={self.foot_vel_gate!r} is invalid; use a positive speed in m/s")


def scatter_keyframes(keyframes: torch.Tensor, indices: torch.Tensor, num_frames: int
                      ) -> tuple[torch.Tensor, torch.Tensor]:
    """Place keyframes on a zero canvas.

    Parameters
    ----------
    keyframes : Tensor ``(B, K, D)``
    indices : Tensor ``(B, K)`` long
        Frame of each keyframe (``< num_frames``).
    num_frames : int
        ``N``, frames of the canvas.

    Returns
    -------
    motion : Tensor ``(B, N, D)`` (zero off the keyframes)
    keyframe_mask : Tensor ``(B, N)`` bool
    """
    b, k, d = keyframes.shape
    if indices.shape != (b, k):
        raise ValueError(f"indices must be (B, K) = {(b, k)}, got {tuple(indices.shape)}")
    if bool((indices < 0).any()) or bool((indices >= num_frames).any()):
        raise ValueError(f"keyframe indices must lie in [0, {num_frames - 1}], got {indices.tolist()}")
    motion = keyframes.new_zeros(b, num_frames, d)
    motion.scatter_(1, indices[..., None].expand(-1, -1, d), keyframes)
    mask = torch.zeros(b, num_frames, dtype=torch.bool, device=keyframes.device)
    mask.scatter_(1, indices, True)
    return motion, mask


def keyframe_lerp(motion: torch.Tensor, keyframe_mask: torch.Tensor) -> torch.Tensor:
    """Per-channel linear interpolation between consecutive keyframes.

    ``motion (B, N, D)`` (only rows where ``keyframe_mask (B, N)`` is True are read) ->
    ``(B, N, D)``. Frames before the first / after the last keyframe hold its value; keyframe rows
    are returned unchanged. Every sample needs at least one keyframe.
    """
    b, n, _ = motion.shape
    if not bool(keyframe_mask.any(1).all()):
        raise ValueError("keyframe_mask must mark at least one keyframe in every sample")
    t = torch.arange(n, device=motion.device).expand(b, n)
    prev = torch.cummax(torch.where(keyframe_mask, t, torch.full_like(t, -1)), 1).values          # (B, N)
    nxt = torch.flip(torch.cummin(torch.flip(torch.where(keyframe_mask, t, torch.full_like(t, n)), [1]), 1).values, [1])
    prev = torch.where(prev < 0, nxt, prev)
    nxt = torch.where(nxt >= n, prev, nxt)
    span = (nxt - prev).clamp_min(1).to(motion.dtype)
    alpha = ((t - prev).to(motion.dtype) / span)[..., None]                                        # (B, N, 1)
    d = motion.shape[-1]
    a = torch.gather(motion, 1, prev[..., None].expand(-1, -1, d))
    c = torch.gather(motion, 1, nxt[..., None].expand(-1, -1, d))
    return a + alpha * (c - a)


class MotionMaskedAutoencoder(FeatureModel):
    """Fills the frames between keyframes, conditioned on text (paper §III-D).

    Parameters
    ----------
    config : MMAEConfig, optional
    """

    def __init__(self, config: MMAEConfig | None = None) -> None:
        super().__init__(config or MMAEConfig())
        cfg = self.config
        d, w = self.feature_dim, cfg.width
        self.motion_in = Linear(d + 1, w)
        self.text_in = nn.ModuleList(Linear(cfg.text_dim, w) for _ in range(cfg.num_layers))
        self.layers = transformer_blocks(cfg, w)
        self.out_norm = nn.LayerNorm(w)
        self.out = Linear(w, d)
        if cfg.lerp_residual:
            # start exactly at the interpolation; the network learns the correction
            nn.init.zeros_(self.out.weight)
            nn.init.zeros_(self.out.bias)
        self.drop = nn.Dropout(cfg.dropout)
        self.register_buffer("frame_pe", position_sinusoid(torch.arange(cfg.max_length), w), persistent=False)
        self.register_buffer("text_pe", position_sinusoid(torch.arange(cfg.max_text_tokens), w), persistent=False)

    def set_normalization(self, mean, std) -> None:
        """Store the dataset statistics ``(D,)`` the model's inputs are normalised with."""
        self.norm.set(mean, std)

    def forward(self, motion: torch.Tensor, keyframe_mask: torch.Tensor, frame_mask: torch.Tensor,
                text: torch.Tensor, text_mask: torch.Tensor) -> torch.Tensor:
        """Predict the whole motion from its keyframes.

        Parameters
        ----------
        motion : Tensor ``(B, N, D)``
            Normalised features; only the keyframe rows are read (the rest is zeroed here, so a
            ground-truth motion can be passed directly during training).
        keyframe_mask : Tensor ``(B, N)`` bool
            True on keyframes (at least one per sample).
        frame_mask : Tensor ``(B, N)`` bool
            True on the frames of the motion (``t < length``); padded frames are ignored as keys.
        text, text_mask : Tensor ``(B, W, C)``, ``(B, W)`` bool

        Returns
        -------
        Tensor ``(B, N, D)``: normalised features of every frame (padded rows are meaningless).
        """
        cfg = self.config
        if motion.dim() != 3 or motion.shape[-1] != self.feature_dim:
            raise ValueError(f"motion must be (B, N, {self.feature_dim}) normalised {self.skeleton.name} features, "
                             f"got {tuple(motion.shape)}")
        b, n, _ = motion.shape
        if n > cfg.max_length:
            raise ValueError(f"motion has N={n} frames; MMAEConfig.max_length={cfg.max_length}")
        for name, m in (("keyframe_mask", keyframe_mask), ("frame_mask", frame_mask)):
            if tuple(m.shape) != (b, n):
                raise ValueError(f"{name} must be (B, N) = {(b, n)}, got {tuple(m.shape)}")
        if text.dim() != 3 or text.shape[0] != b or text.shape[2] != cfg.text_dim:
            raise ValueError(f"text must be (B={b}, W, C={cfg.text_dim}), got {tuple(text.shape)}")
        if tuple(text_mask.shape) != tuple(text.shape[:2]):
            raise ValueError(f"text_mask must be (B, W) = {tuple(text.shape[:2])}, got {tuple(text_mask.shape)}")
        if text.shape[1] > cfg.max_text_tokens:
            raise ValueError(f"text has {text.shape[1]} tokens; MMAEConfig.max_text_tokens={cfg.max_text_tokens}")
        kf = keyframe_mask.to(torch.bool)
        flag = kf.to(motion.dtype)[..., None]
        masked = motion * flag                                                 # MAE: zero the in-betweens
        h = self.drop(self.motion_in(torch.cat([masked, flag], -1)) + self.frame_pe[:n])   # (B, N, w)
        n_tok = text.shape[1]
        key_mask = torch.cat([text_mask.to(torch.bool), frame_mask.to(torch.bool)], 1)     # (B, W + N)
        text = text.to(h.dtype)
        for proj, layer in zip(self.text_in, self.layers):
            seq = torch.cat([proj(text) + self.text_pe[:n_tok], h], 1)         # text at the leading positions
            h = layer(seq, key_mask)[:, n_tok:]
        out = self.out(self.out_norm(h))
        if cfg.lerp_residual:
            out = keyframe_lerp(masked, kf) + out
        return out

    @torch.no_grad()
    def infill(self, keyframes: torch.Tensor, indices: torch.Tensor, lengths: torch.Tensor, text: torch.Tensor,
               text_mask: torch.Tensor, keep_keyframes: bool = False) -> torch.Tensor:
        """Complete motions from keyframes placed at their frames.

        Parameters
        ----------
        keyframes : Tensor ``(B, K, D)``
            Normalised keyframe features.
        indices : Tensor ``(B, K)`` long
            Their frames, ``< lengths``.
        lengths : Tensor ``(B,)``
            Motion lengths; the output has ``N = max(lengths)`` frames.
        text, text_mask : Tensor ``(B, W, C)``, ``(B, W)``
        keep_keyframes : bool
            Paste the given keyframes over the prediction at their frames.

        Returns
        -------
        Tensor ``(B, N, D)`` normalised; rows ``t >= length`` are zero.
        """
        lengths = torch.as_tensor(lengths, device=keyframes.device).long().reshape(-1)
        if lengths.shape[0] != keyframes.shape[0]:
            raise ValueError(f"lengths has {lengths.shape[0]} entries for {keyframes.shape[0]} keyframe sets")
        if bool((indices >= lengths[:, None]).any()):
            raise ValueError("every keyframe index must be < its motion's length")
        n = int(lengths.max())
        canvas, kf_mask = scatter_keyframes(keyframes, indices, n)
        frame_mask = torch.arange(n, device=keyframes.device)[None] < lengths[:, None]
        out = self(canvas, kf_mask, frame_mask, text, text_mask)
        if keep_keyframes:
            out = torch.where(kf_mask[..., None], canvas, out)
        return out * frame_mask[..., None].to(out.dtype)

    def loss(self, pred: torch.Tensor, target: torch.Tensor, frame_mask: torch.Tensor) -> dict[str, torch.Tensor]:
        """Eq. 9: ``L = L_mse + λ_bone L_bone + λ_vel L_vel`` over the valid frames, plus ``λ_foot L_foot``
        (:func:`~salad_core.keymotion.models.foot_contact_loss`) and ``λ_foot_vel L_foot_vel``
        (:func:`~salad_core.keymotion.models.planted_foot_velocity_loss`), both 0 by default: not in the paper.

        Parameters
        ----------
        pred, target : Tensor ``(B, N, D)`` normalised features
        frame_mask : Tensor ``(B, N)`` bool

        Returns
        -------
        dict of scalar tensors ``loss``, ``rec``, ``bone``, ``vel`` (and ``foot`` / ``foot_vel`` when their
        weights are above 0).
        """
        if pred.shape != target.shape:
            raise ValueError(f"pred must have the shape of target {tuple(target.shape)}, got {tuple(pred.shape)}")
        cfg = self.config
        rec = masked_mean(F.mse_loss(pred, target, reduction="none"), frame_mask)
        zero = rec.new_zeros(())
        bone, vel, foot, foot_vel = zero, zero, zero, zero
        if cfg.lambda_bone > 0 or cfg.lambda_vel > 0 or cfg.lambda_foot > 0 or cfg.lambda_foot_vel > 0:
            scale = self.skeleton.feature_scale
            true_feats = self.norm.denormalize(target)
            pj = features_to_joints(self.norm.denormalize(pred), self.skeleton) * scale     # (B, N, J, 3)
            tj = features_to_joints(true_feats, self.skeleton) * scale
            if cfg.lambda_bone > 0:
                bone = bone_length_loss(pj, tj, self.skeleton, frame_mask)
            if cfg.lambda_vel > 0:
                vel = velocity_loss(pj, tj, frame_mask)
            if cfg.lambda_foot > 0:
                contacts = true_feats[..., self.skeleton.feature_slices["contacts"]]
                foot = foot_contact_loss(pj, contacts, self.skeleton, frame_mask)
            if cfg.lambda_foot_vel > 0:
                foot_vel = planted_foot_velocity_loss(pj, tj, self.skeleton, frame_mask, cfg.foot_vel_gate)
        total = (rec + cfg.lambda_bone * bone + cfg.lambda_vel * vel + cfg.lambda_foot * foot
                 + cfg.lambda_foot_vel * foot_vel)
        out = {"loss": total, "rec": rec, "bone": bone, "vel": vel}
        if cfg.lambda_foot > 0:
            out["foot"] = foot
        if cfg.lambda_foot_vel > 0:
            out["foot_vel"] = foot_vel
        return out

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())


register_model("keymotion_mmae", MMAEConfig, MotionMaskedAutoencoder)
