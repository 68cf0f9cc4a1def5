"""Building blocks shared by the three KeyMotion models (keyframe VAE, PST denoiser, MMAE).

* :func:`position_sinusoid`: the sinusoidal encoding (Vaswani et al., the paper's "SPE") of
  real-valued positions, used for token positions and for keyframe indices.
* :class:`Attention` and :class:`TransformerBlock`: a small pre-norm transformer block with
  optional self-attention, optional cross-attention and a feed-forward layer, on
  ``scaled_dot_product_attention`` with boolean key masks (True = a key that may be used).
  Padded keys are never attended to, so valid outputs do not depend on padding. Dropout acts on
  the residual branches and the feed-forward hidden layer, not on the attention probabilities:
  on the CPU that dropout forces the slow reference attention kernel and took a fifth of an MMAE
  training step.
* Kinematic losses on **de-normalised** features through the differentiable
  :func:`salad_core.motion.features_to_joints`: :func:`bone_lengths`, :func:`bone_length_loss`
  (KeyMotion eq. 5) and :func:`velocity_loss` (eq. 11), all in metres (joints are multiplied by
  ``skeleton.feature_scale``).
* :class:`Normalizer`: the dataset mean/std kept as persistent buffers inside a model, so that a
  checkpoint carries the statistics its kinematic losses and outputs depend on.
"""
from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from salad_core.models.gemm import Linear
from salad_core.models.layers import get_activation
from salad_core.motion import features_to_joints
from salad_core.skeleton import Skeleton, available_skeletons, get_skeleton

__all__ = [
    "position_sinusoid",
    "Attention",
    "TransformerBlock",
    "Normalizer",
    "pose_joints",
    "bone_lengths",
    "bone_length_loss",
    "velocity_loss",
    "foot_contact_loss",
    "planted_foot_velocity_loss",
    "masked_mean",
    "check_positive_int",
    "check_unit_interval",
    "check_non_negative",
    "check_skeleton_name",
    "FeatureModel",
    "transformer_blocks",
]


# ------------------------------------------------------------------------------- validation
def check_positive_int(owner: str, name: str, value: object) -> None:
    """Raise ``ValueError`` naming ``owner.name`` unless ``value`` is an int >= 1."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{owner}.{name}={value!r} is invalid; use an integer >= 1")


def check_unit_interval(owner: str, name: str, value: object) -> None:
    """Raise unless ``value`` is a float in [0, 1)."""
    if not isinstance(value, (int, float)) or not 0.0 <= float(value) < 1.0:
        raise ValueError(f"{owner}.{name}={value!r} is invalid; use a float in [0, 1)")


def check_non_negative(owner: str, name: str, value: object) -> None:
    """Raise unless ``value`` is a finite float >= 0."""
    if not isinstance(value, (int, float)) or not math.isfinite(float(value)) or float(value) < 0:
        raise ValueError(f"{owner}.{name}={value!r} is invalid; use a finite float >= 0")


def check_skeleton_name(config: object) -> None:
    """Raise ``TypeError`` naming the config's class unless ``config.skeleton`` is a string; store the
    skeleton's registered name in it (the config is a frozen dataclass; an unknown name raises ``ValueError``)."""
    if not isinstance(config.skeleton, str):
        raise TypeError(f"{type(config).__name__}.skeleton must be a skeleton name {available_skeletons()}, "
                        f"got {type(config.skeleton).__name__}")
    object.__setattr__(config, "skeleton", get_skeleton(config.skeleton).name)


# ------------------------------------------------------------------------------- encodings
def position_sinusoid(positions: torch.Tensor, dim: int, base: float = 10000.0) -> torch.Tensor:
    """Sinusoidal encoding of real-valued positions: ``(...,)`` -> ``(..., dim)``.

    Channel ``2i`` is ``sin(p / base^(2i/dim))`` and ``2i+1`` the cosine, as the transformer table
    (:func:`salad_core.models.embeddings.sinusoidal_table`) at integer positions; here positions may
    be fractional (decoded keyframe indices). Differentiable in ``positions``.
    """
    if dim < 2 or dim % 2:
        raise ValueError(f"dim must be an even integer >= 2 for a sin/cos encoding, got {dim}")
    half = torch.arange(0, dim, 2, device=positions.device, dtype=torch.float32)
    freq = torch.exp(half * (-math.log(base) / dim))                    # (dim/2,)
    angle = positions.float()[..., None] * freq                         # (..., dim/2)
    out = torch.stack([torch.sin(angle), torch.cos(angle)], dim=-1)     # (..., dim/2, 2)
    return out.flatten(-2)                                              # sin, cos interleaved


# ------------------------------------------------------------------------------ attention
class Attention(nn.Module):
    """Multi-head attention of queries ``(B, Q, w)`` over a context ``(B, S, w)``.

    Parameters
    ----------
    width : int
        Channels ``w`` of queries, keys and values (divisible by ``heads``).
    heads : int
        Attention heads.
    dropout : float
        Dropout on the attention probabilities (training only).
    """

    def __init__(self, width: int, heads: int, dropout: float = 0.0) -> None:
        super().__init__()
        if width % heads:
            raise ValueError(f"width={width} must be divisible by the number of heads {heads}")
        self.heads = heads
        self.dropout = dropout
        self.q = Linear(width, width)
        self.kv = Linear(width, 2 * width)
        self.out = Linear(width, width)

    def forward(self, x: torch.Tensor, context: torch.Tensor, key_mask: torch.Tensor | None = None) -> torch.Tensor:
        """``x (B, Q, w)``, ``context (B, S, w)``, ``key_mask (B, S)`` bool (True = usable key).

        Every query row must see at least one usable key (the callers guarantee it).
        """
        b, q_len, w = x.shape
        h = self.heads
        q = self.q(x).reshape(b, q_len, h, w // h).transpose(1, 2)                    # (B, H, Q, w/H)
        k, v = self.kv(context).reshape(b, context.shape[1], 2, h, w // h).permute(2, 0, 3, 1, 4)
        mask = None if key_mask is None else key_mask[:, None, None, :]                # (B, 1, 1, S)
        out = F.scaled_dot_product_attention(q, k, v, attn_mask=mask,
                                             dropout_p=self.dropout if self.training else 0.0)
        return self.out(out.transpose(1, 2).reshape(b, q_len, w))


class TransformerBlock(nn.Module):
    """Pre-norm block: ``[x += SelfAttn(LN x)] [x += CrossAttn(LN x, context)] x += FFN(LN x)``.

    Parameters
    ----------
    width, heads, ff_dim : int
        Token channels, attention heads, hidden width of the feed-forward layer.
    dropout : float
        Dropout on every residual branch and on the feed-forward hidden layer.
    self_attention, cross_attention : bool
        Which attention sub-layers the block has.
    activation : str
        Feed-forward activation (``"relu"`` as the paper's vanilla layers, ``"gelu"``, ``"silu"``).
    """

    def __init__(self, width: int, heads: int, ff_dim: int, dropout: float, *, self_attention: bool = True,
                 cross_attention: bool = False, activation: str = "gelu") -> None:
        super().__init__()
        if not (self_attention or cross_attention):
            raise ValueError("a TransformerBlock needs self_attention or cross_attention")
        # no dropout on attention probabilities (see the module docstring): only on residual branches
        self.self_attn = Attention(width, heads) if self_attention else None
        self.norm_self = nn.LayerNorm(width) if self_attention else None
        self.cross_attn = Attention(width, heads) if cross_attention else None
        self.norm_cross = nn.LayerNorm(width) if cross_attention else None
        self.norm_ctx = nn.LayerNorm(width) if cross_attention else None
        self.norm_ff = nn.LayerNorm(width)
        self.ff = nn.Sequential(Linear(width, ff_dim), get_activation(activation), nn.Dropout(dropout),
                                Linear(ff_dim, width))
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None, context: torch.Tensor | None = None,
                context_mask: torch.Tensor | None = None) -> torch.Tensor:
        """``x (B, Q, w)`` with key mask ``mask (B, Q)``; ``context (B, S, w)`` with ``context_mask (B, S)``."""
        if self.self_attn is not None:
            hx = self.norm_self(x)
            x = x + self.drop(self.self_attn(hx, hx, mask))
        if self.cross_attn is not None:
            if context is None:
                raise ValueError("this block has cross-attention: pass a context (B, S, w)")
            x = x + self.drop(self.cross_attn(self.norm_cross(x), self.norm_ctx(context), context_mask))
        return x + self.drop(self.ff(self.norm_ff(x)))


def transformer_blocks(config: object, width: int, *, cross_attention: bool = False) -> nn.ModuleList:
    """``config.num_layers`` :class:`TransformerBlock` of ``width`` channels with the config's
    ``num_heads``, ``ff_dim``, ``dropout`` and ``activation`` (self-attention, and cross-attention if asked)."""
    return nn.ModuleList(
        TransformerBlock(width, config.num_heads, config.ff_dim, config.dropout, cross_attention=cross_attention,
                         activation=config.activation)
        for _ in range(config.num_layers))


# ---------------------------------------------------------------------------- normaliser
#: Normalisation statistics closer than this (in units of the channel's std) count as the same: two
#: builds of one corpus differ by float rounding (about 4e-3 between two machines' builds of corpus 2.7),
#: fp16 weights round the stored statistics by about 5e-4 of their value (under 5e-3 of a std here).
NORMALISATION_TOLERANCE = 1e-2


def normalisation_gap(mean_a, std_a, mean_b, std_b) -> float:
    """Largest gap between two sets of statistics (each ``(D,)``, numpy or torch), in units of ``std_b``:
    ``max_d max(|mean_a - mean_b|, |std_a - std_b|) / std_b``. 0 for identical statistics."""
    mean_a, std_a, mean_b, std_b = (torch.as_tensor(v).detach().float().cpu().reshape(-1)
                                    for v in (mean_a, std_a, mean_b, std_b))
    scale = std_b.abs().clamp_min(1e-8)
    return float(torch.maximum((mean_a - mean_b).abs(), (std_a - std_b).abs()).div(scale).max())


class Normalizer(nn.Module):
    """Dataset ``mean`` and ``std`` ``(D,)`` as persistent buffers (saved in checkpoints).

    Fresh models hold ``mean = 0, std = 1``; trainers call :meth:`set` with the train split's
    statistics before training.
    """

    def __init__(self, dim: int) -> None:
        super().__init__()
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("std", torch.ones(dim))

    def set(self, mean, std) -> None:
        """Copy statistics ``(D,)`` (numpy or torch) into the buffers."""
        mean = torch.as_tensor(mean, dtype=self.mean.dtype).reshape(-1)
        std = torch.as_tensor(std, dtype=self.std.dtype).reshape(-1)
        if mean.shape != self.mean.shape or std.shape != self.std.shape:
            raise ValueError(f"mean and std must have shape {tuple(self.mean.shape)}, got "
                             f"{tuple(mean.shape)} and {tuple(std.shape)}")
        if not bool((std > 0).all()):
            raise ValueError("std must be positive everywhere")
        with torch.no_grad():
            self.mean.copy_(mean)
            self.std.copy_(std)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        """``x * std + mean`` over the last axis ``(..., D)``."""
        return x * self.std + self.mean

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """``(x - mean) / std`` over the last axis ``(..., D)``."""
        return (x - self.mean) / self.std


class FeatureModel(nn.Module):
    """A KeyMotion model of one skeleton's motion features: its ``config``, ``skeleton``, feature width
    ``feature_dim`` (D) and the dataset statistics ``norm`` (:class:`Normalizer`, ``(D,)``)."""

    def __init__(self, config: object) -> None:
        super().__init__()
        self.config = config
        self.skeleton = get_skeleton(config.skeleton)
        self.feature_dim = self.skeleton.feature_dim
        self.norm = Normalizer(self.feature_dim)


# --------------------------------------------------------------------------- kinematics
def pose_joints(features: torch.Tensor, skeleton: str | Skeleton) -> torch.Tensor:
    """Joints of each frame taken **alone**: de-normalised ``(..., K, D)`` -> ``(..., K, J, 3)`` metres.

    Keyframes are not consecutive, so integrating the root velocity across them (as
    :func:`features_to_joints` does over a sequence) would be meaningless. Each pose is
    recovered as a one-frame sequence instead: root at the origin in x/z, identity heading, its
    own root height. Bone lengths and root-relative positions are exact.
    """
    sk = get_skeleton(skeleton)
    single = features.reshape(-1, 1, features.shape[-1])                 # (M, 1, D)
    joints = features_to_joints(single, sk)[:, 0]                        # (M, J, 3)
    return joints.reshape(*features.shape[:-1], sk.num_joints, 3) * sk.feature_scale


def bone_lengths(joints: torch.Tensor, skeleton: str | Skeleton) -> torch.Tensor:
    """Lengths of the bones parent -> joint: ``(..., J, 3)`` -> ``(..., J-1)`` (root excluded)."""
    sk = get_skeleton(skeleton)
    child = torch.arange(1, sk.num_joints, device=joints.device)
    parent = torch.as_tensor(sk.parents[1:], device=joints.device)
    diff = joints[..., child, :] - joints[..., parent, :]
    # sqrt(|d|^2 + tiny): the gradient stays finite for a degenerate (zero-length) predicted bone
    return torch.sqrt(diff.pow(2).sum(-1) + 1e-12)


def masked_mean(err: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
    """Mean of ``err (B, T, ...)`` over the rows where ``mask (B, T)`` is True (all rows if None)."""
    if mask is None:
        return err.mean()
    per = err.reshape(err.shape[0], err.shape[1], -1)
    w = mask.to(per.dtype)[..., None]
    return (per * w).sum() / (w.sum() * per.shape[-1]).clamp_min(1.0)


def bone_length_loss(pred_joints: torch.Tensor, true_joints: torch.Tensor, skeleton: str | Skeleton,
                     mask: torch.Tensor | None = None) -> torch.Tensor:
    """KeyMotion eq. 5: mean ``| |p_j - p_par(j)| - |p*_j - p*_par(j)| |`` over frames and bones.

    Parameters
    ----------
    pred_joints, true_joints : Tensor ``(B, T, J, 3)``
        Generated and ground-truth joints (metres).
    skeleton : name or Skeleton
    mask : Tensor ``(B, T)`` bool, optional
        Frames that count.

    Returns
    -------
    Tensor ``()``: zero exactly when every predicted bone has its true length.
    """
    err = (bone_lengths(pred_joints, skeleton) - bone_lengths(true_joints, skeleton)).abs()  # (B, T, J-1)
    return masked_mean(err, mask)


def foot_contact_loss(pred_joints: torch.Tensor, true_contacts: torch.Tensor, skeleton: str | Skeleton,
                      mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean ``|p_{t+1} - p_t|`` (metres/frame, L1 over x, y, z) of the 4 contact joints at the frames where the
    ground truth has that foot joint in contact: zero when every planted foot stays put (the foot-contact
    term of MDM, Tevet et al. 2023, in KeyMotion's L1 form; not in the KeyMotion paper).

    Parameters
    ----------
    pred_joints : Tensor ``(B, T, J, 3)``
        Generated joints (metres).
    true_contacts : Tensor ``(B, T, 4)``
        The ground truth's contact channels (de-normalised features; > 0.5 is contact), in the
        skeleton's :attr:`~salad_core.skeleton.Skeleton.contact_joints` order.
    skeleton : name or Skeleton
    mask : Tensor ``(B, T)`` bool, optional
        Valid frames; a velocity counts when both of its frames are valid.
    """
    sk = get_skeleton(skeleton)
    feet = pred_joints[:, :, list(sk.contact_joints)]                       # (B, T, 4, 3)
    speed = (feet[:, 1:] - feet[:, :-1]).abs()                              # (B, T-1, 4, 3)
    w = (true_contacts[:, :-1] > 0.5)
    if mask is not None:
        w = w & (mask[:, 1:] & mask[:, :-1])[..., None]
    w = w.to(speed.dtype)[..., None]                                        # (B, T-1, 4, 1)
    return (speed * w).sum() / (w.sum() * 3).clamp_min(1.0)


def planted_foot_velocity_loss(pred_joints: torch.Tensor, true_joints: torch.Tensor, skeleton: str | Skeleton,
                               mask: torch.Tensor | None = None, max_speed: float = 0.2) -> torch.Tensor:
    """Mean ``|v - v*|`` (metres/frame, L1 over x, y, z) of the 4 contact joints at the frames where the ground
    truth's foot joint is truly planted: it moves slower than ``max_speed`` (m/s) between the two frames.

    HumanML3D's contact label admits feet moving up to 0.9 m/s, so a term on the label (e.g.
    :func:`foot_contact_loss`, which pushes the absolute foot speed to 0 wherever the label is on) fights the
    ground truth on rising heels and slow slides; this one asks only for the ground truth's own velocity, and only
    where the foot is really still.

    Parameters
    ----------
    pred_joints, true_joints : Tensor ``(B, T, J, 3)``
        Generated and ground-truth joints (metres).
    skeleton : name or Skeleton
        Its ``fps`` turns ``max_speed`` into metres per frame.
    mask : Tensor ``(B, T)`` bool, optional
        Valid frames; a velocity counts when both of its frames are valid.
    max_speed : float
        Fastest ground-truth foot speed (m/s) that counts as planted.
    """
    sk = get_skeleton(skeleton)
    feet = list(sk.contact_joints)
    vp = pred_joints[:, 1:, feet] - pred_joints[:, :-1, feet]               # (B, T-1, 4, 3)
    vt = true_joints[:, 1:, feet] - true_joints[:, :-1, feet]
    w = vt.norm(dim=-1) < max_speed / sk.fps                                 # (B, T-1, 4)
    if mask is not None:
        w = w & (mask[:, 1:] & mask[:, :-1])[..., None]
    w = w.to(vp.dtype)[..., None]
    return ((vp - vt).abs() * w).sum() / (w.sum() * 3).clamp_min(1.0)


def velocity_loss(pred_joints: torch.Tensor, true_joints: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """KeyMotion eq. 11: mean ``|v - v*|`` of joint velocities ``v_t = p_{t+1} - p_t`` (metres/frame).

    ``pred_joints, true_joints`` ``(B, N, J, 3)``; ``mask (B, N)``: a velocity counts when both of
    its frames are valid.
    """
    vp = pred_joints[:, 1:] - pred_joints[:, :-1]
    vt = true_joints[:, 1:] - true_joints[:, :-1]
    pair = None if mask is None else mask[:, 1:] & mask[:, :-1]
    return masked_mean((vp - vt).abs(), pair)
