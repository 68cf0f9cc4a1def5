"""The Parallel Skip Transformer (PST) denoiser of KeyMotion (paper §III-C, Fig. 3, eqs. 7-8).

Data flow (default sizes)::

    condition: [time token, length token, text tokens (B, W, C) -Linear-> (B, W, w)
                (+ side embedding of text_sides (B, W) with side_cue)] + SPE
      --transformer encoder x num_cond_layers (key mask: padded text tokens)--> c_0 (B, 2 + W, w)
    latents x_t (B, Lz, Dz) --Linear--> + SPE --> x_0 (B, Lz, w)
    parallel cross layers i = 0 .. L-1 (two streams updated from the previous layer's outputs):
      x_{i+1} = XBlock_i(x_i, context c_i)      self-attn, cross-attn to the text stream, FFN
      c_{i+1} = CBlock_i(c_i, context x_i)      self-attn, cross-attn to the latent stream, FFN
      with skip connections: the input of layer L-1-i (i < L // 2) is first
      Linear([stream ; output of layer i]) for each stream (concatenation, then projection)
    out: [x_L ; masked mean of c_L over valid tokens] --LN, Linear--> eps (B, Lz, Dz)

Choices where the paper is silent or that we made:

* **Skip wiring.** With ``L`` parallel cross layers numbered ``0 .. L-1``, the output of layer
  ``i`` (for ``i < L // 2``) is concatenated with the input of layer ``L - 1 - i`` and projected
  back to ``w`` by a linear layer, in both streams (the U-Net/MLD pairing). Counting layers from
  1 as the paper does, the outputs of layers ``l`` and ``L - l`` are concatenated and projected
  before layer ``L - l + 1``: the paper's skip "from layer l to layer L - l". With odd ``L`` the
  middle layer has no skip; with even ``L`` the middle pair ``(L/2 - 1, L/2)`` is adjacent, so its skip
  concatenates layer ``L/2``'s input with itself (the paper's pairing, kept by default for the shipped weights;
  ``PSTConfig(middle_skip=False)`` drops it). :attr:`ParallelSkipTransformer.skip_pairs` lists the 0-based
  ``(source, receiver)`` pairs.
* **Parallel streams** follow ViLBERT's co-attention: each stream's block is self-attention,
  cross-attention to the *other* stream's previous output, then a feed-forward layer (pre-norm).
* **Output.** "The two-stream representation is concatenated and projected": each latent token
  is concatenated with the masked mean of the text stream and projected to ``Dz``.
* **Length token** (an addition): the requested motion length is a condition token next to the
  timestep token (sinusoid of ``L`` then an MLP). Keyframes of a 40-frame and a 196-frame motion
  differ (denser sampling), and the pipeline knows ``L`` at generation time.
* **Side cue** (an addition, opt-in: ``PSTConfig.side_cue``): the PST trained without it ignores
  "left"/"right" (the side of a waved hand is decided by the initial noise;
  :mod:`salad_core.keymotion.sides` has the measurement). With it, ``text_sides (B, W)`` (0 no side,
  1 left, 2 right per token, :func:`~salad_core.keymotion.sides.side_ids`) select rows of
  ``side_embed`` (``nn.Embedding(3, w)``, zero-initialised, row 0 fixed at zero) added to the projected
  text tokens. A PST fine-tuned from a checkpoint without the cue therefore starts as exactly that
  model, and prompts without a side word are never changed by it. A cue PST must be given
  ``text_sides``; the null (empty-prompt) branch of guidance gets zeros.
* **Side-canonical training** (an addition, opt-in: ``PSTConfig.side_canonical``): the keyframe latent does
  not hold left and right along any consistent direction (a linear probe tells a motion from its mirror image
  in 60 % of held-out pairs; the mean left-minus-right latent is 1.9 against 19.9 per pair), so the mean a
  denoiser regresses at high noise is the same for "left" and "right" and the PST learnt to ignore the side
  (``lab/scripts/keymotion/keymotion_side_probe.py``). A side-canonical PST is trained only on captions whose
  first side word is of the right kind: an item whose caption names the left kind first is replaced by its
  exact mirror image (:func:`salad_core.motion.mirror_features` of its keyframes, caption by
  :func:`~salad_core.keymotion.sides.mirror_side_words`). At sampling the pipeline mirrors such prompts,
  generates, and mirrors the motion back, so the side follows from the data's mirror symmetry rather than
  from a feature the PST must learn. Nothing changes for prompts without a side word.
* **Diffusion**: ε-prediction on a scaled-linear schedule (beta 0.00085 -> 0.012, 1000 steps,
  as MLD/Stable Diffusion): :data:`PST_DIFFUSION`. Classifier-free guidance (eq. 8)
  ``eps = eps_u + w (eps_c - eps_u)`` with the empty prompt as the unconditional text; both
  branches run in one batched forward in :meth:`ParallelSkipTransformer.guided`, which
  :class:`PSTPrediction` asks at every step of salad's one sampling loop
  (:func:`salad_core.sampling.denoise`, through :func:`sample_latents`). By default the VAE latents
  are diffused as they are (as MLD).
* **Latent normalisation** (an addition, opt-in: ``PSTConfig.latent_norm``): the PST diffuses
  ``(z - mean) / std`` with per-token, per-channel training-set statistics kept as buffers
  ``latent_mean`` / ``latent_std`` ``(Lz, Dz)`` in its weights (:meth:`ParallelSkipTransformer.set_latent_stats`,
  computed by :func:`salad_core.keymotion.train.kf_latent_stats`), as latent diffusion models rescale
  theirs; :func:`sample_latents` returns latents in the VAE's space. KeyMotion 0.2's keyframe latents
  spread 1.72 (per channel across clips 1.57, posterior sigma 0.015) while its PST's samples at w 7.5
  spread 2.98: off the data the decoder learnt.
* **Sizes**: width 128, 4 heads, one condition encoder layer and 4 parallel cross layers (the
  paper's layer counts were lost in our copy; its width is 272), about 2 M parameters.
"""
from __future__ import annotations

import logging
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Callable, ContextManager

import torch
from torch import nn

from salad_core.io import register_model
from salad_core.models.embeddings import timestep_sinusoid
from salad_core.models.gemm import Linear
from salad_core.models.layers import ACTIVATIONS
from salad_core.sampling import DiffusionConfig, Guidance, StepInfo, as_guidance, denoise

from .models import TransformerBlock, check_positive_int, check_unit_interval, position_sinusoid
from .sides import NO_SIDE, NUM_SIDES

__all__ = ["PSTConfig", "ParallelSkipTransformer", "ParallelCrossLayer", "PST_DIFFUSION", "PSTPrediction",
           "sample_latents"]

log = logging.getLogger(__name__)

#: KeyMotion's diffusion: ε-prediction on the scaled-linear schedule (paper §III-C).
PST_DIFFUSION = DiffusionConfig(num_train_timesteps=1000, beta_start=0.00085, beta_end=0.012,
                                beta_schedule="scaled_linear", prediction_type="epsilon")


@dataclass(frozen=True)
class PSTConfig:
    """Configuration of :class:`ParallelSkipTransformer` (small CPU defaults)."""

    latent_size: int = 2          # Lz tokens of the keyframe latent (KeyframeVAEConfig.latent_size)
    latent_dim: int = 64          # Dz channels per latent token (KeyframeVAEConfig.latent_dim)
    text_dim: int = 384           # C, width of the text encoder's token features (MiniLM 384)
    width: int = 128              # w, token channels of both streams (paper 272)
    num_heads: int = 4            # attention heads (paper 4)
    ff_dim: int = 256             # feed-forward hidden width (paper 1024)
    num_cond_layers: int = 1      # transformer encoder layers over [time, length, text]
    num_cross_layers: int = 4     # L parallel cross layers; skips pair layer i with L-1-i
    dropout: float = 0.1          # dropout (paper 0.1)
    activation: str = "gelu"      # feed-forward activation
    max_length: int = 196         # longest motion (frames) the length token is scaled by
    length_condition: bool = True  # add the motion-length token to the condition (our addition)
    max_text_tokens: int = 512    # rows of the text positional table
    side_cue: bool = False        # add a learned left/right embedding to the text tokens (needs text_sides)
    latent_norm: bool = False     # diffuse (z - latent_mean) / latent_std (training-set statistics in the weights)
    middle_skip: bool = True      # with even L, also the adjacent middle pair (L/2-1, L/2), whose skip concatenates
                                  # layer L/2's input with itself (the paper's pairing; KeyMotion 0.2 has it); False
                                  # drops that degenerate pair
    side_canonical: bool = False  # trained on side-canonical data: a caption whose first side word is of the left
                                  # kind was replaced by its mirror image (motion and caption); the pipeline mirrors
                                  # such prompts, generates, and mirrors the motion back (keymotion.sides)

    def __post_init__(self) -> None:
        name = type(self).__name__
        for f in ("latent_size", "latent_dim", "text_dim", "width", "num_heads", "ff_dim", "num_cross_layers",
                  "max_length", "max_text_tokens"):
            check_positive_int(name, f, getattr(self, f))
        if isinstance(self.num_cond_layers, bool) or not isinstance(self.num_cond_layers, int) or self.num_cond_layers < 0:
            raise ValueError(f"{name}.num_cond_layers={self.num_cond_layers!r} is invalid; use an integer >= 0")
        if self.width % self.num_heads or self.width % 2:
            raise ValueError(f"{name}.width={self.width} must be even and divisible by num_heads={self.num_heads}")
        check_unit_interval(name, "dropout", self.dropout)
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"{name}.activation={self.activation!r} is invalid; choose one of {ACTIVATIONS}")
        if not isinstance(self.length_condition, bool):
            raise ValueError(f"{name}.length_condition={self.length_condition!r} is invalid; use True or False")
        if not isinstance(self.side_cue, bool):
            raise ValueError(f"{name}.side_cue={self.side_cue!r} is invalid; use True or False")
        if not isinstance(self.latent_norm, bool):
            raise ValueError(f"{name}.latent_norm={self.latent_norm!r} is invalid; use True or False")
        if not isinstance(self.middle_skip, bool):
            raise ValueError(f"{name}.middle_skip={self.middle_skip!r} is invalid; use True or False")
        if not isinstance(self.side_canonical, bool):
            raise ValueError(f"{name}.side_canonical={self.side_canonical!r} is invalid; use True or False")


class ParallelCrossLayer(nn.Module):
    """One two-stream layer: latent block and text block updated in parallel (ViLBERT co-attention).

    ``skip_x`` / ``skip_c`` are the projections ``Linear(2w, w)`` of the skip connection into this
    layer (None for layers that receive no skip).
    """

    def __init__(self, config: PSTConfig, receives_skip: bool) -> None:
        super().__init__()
        w = config.width
        kw = dict(cross_attention=True, activation=config.activation)
        self.x_block = TransformerBlock(w, config.num_heads, config.ff_dim, config.dropout, **kw)
        self.c_block = TransformerBlock(w, config.num_heads, config.ff_dim, config.dropout, **kw)
        self.skip_x = Linear(2 * w, w) if receives_skip else None
        self.skip_c = Linear(2 * w, w) if receives_skip else None

    def forward(self, x: torch.Tensor, c: torch.Tensor, c_mask: torch.Tensor,
                skip: tuple[torch.Tensor, torch.Tensor] | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """``x (B, Lz, w)``, ``c (B, S, w)``, ``c_mask (B, S)``; ``skip`` = (x, c) of the paired layer."""
        if self.skip_x is not None:
            if skip is None:
                raise ValueError("this layer receives a skip connection: pass the paired layer's outputs")
            x = self.skip_x(torch.cat([x, skip[0]], -1))
            c = self.skip_c(torch.cat([c, skip[1]], -1))
        x_new = self.x_block(x, context=c, context_mask=c_mask)   # latents attend to the text stream
        c_new = self.c_block(c, c_mask, context=x)                # text attends to the latent stream
        return x_new, c_new


class ParallelSkipTransformer(nn.Module):
    """ε-prediction denoiser of keyframe latents ``(B, Lz, Dz)`` conditioned on text and length.

    Parameters
    ----------
    config : PSTConfig, optional
    """

    def __init__(self, config: PSTConfig | None = None) -> None:
        super().__init__()
        self.config = cfg = config or PSTConfig()
        w = cfg.width
        self.time_mlp = nn.Sequential(Linear(w, w), nn.SiLU(), Linear(w, w))
        self.length_mlp = nn.Sequential(Linear(w, w), nn.SiLU(), Linear(w, w)) if cfg.length_condition else None
        self.text_in = Linear(cfg.text_dim, w)
        self.side_embed = nn.Embedding(NUM_SIDES, w, padding_idx=NO_SIDE) if cfg.side_cue else None
        if self.side_embed is not None:
            nn.init.zeros_(self.side_embed.weight)     # starts as the PST without the cue
        self.cond_layers = nn.ModuleList(
            TransformerBlock(w, cfg.num_heads, cfg.ff_dim, cfg.dropout, activation=cfg.activation)
            for _ in range(cfg.num_cond_layers))
        self.latent_in = Linear(cfg.latent_dim, w)
        receivers = {j for _, j in self.skip_pairs}
        self.cross_layers = nn.ModuleList(ParallelCrossLayer(cfg, i in receivers) for i in range(cfg.num_cross_layers))
        self.out_norm = nn.LayerNorm(2 * w)
        self.out = Linear(2 * w, cfg.latent_dim)
        self.drop = nn.Dropout(cfg.dropout)
        self.register_buffer("latent_pe", position_sinusoid(torch.arange(cfg.latent_size), w), persistent=False)
        if cfg.latent_norm:                            # identity until set_latent_stats (saved with the weights)
            self.register_buffer("latent_mean", torch.zeros(cfg.latent_size, cfg.latent_dim))
            self.register_buffer("latent_std", torch.ones(cfg.latent_size, cfg.latent_dim))
        n_special = 2 if cfg.length_condition else 1
        self.register_buffer("cond_pe", position_sinusoid(torch.arange(cfg.max_text_tokens + n_special), w),
                             persistent=False)

    # ------------------------------------------------------------------ latent normalisation
    def set_latent_stats(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Store the training latents' ``mean`` and ``std`` ``(Lz, Dz)`` (needs ``config.latent_norm``)."""
        if not self.config.latent_norm:
            raise ValueError("this PST diffuses the latents as they are (PSTConfig.latent_norm=False): it has no "
                             "latent statistics to set")
        shape = (self.config.latent_size, self.config.latent_dim)
        mean, std = torch.as_tensor(mean, dtype=torch.float32), torch.as_tensor(std, dtype=torch.float32)
        if tuple(mean.shape) != shape or tuple(std.shape) != shape:
            raise ValueError(f"latent mean and std must be {shape}, got {tuple(mean.shape)} and {tuple(std.shape)}")
        if not bool(torch.isfinite(mean).all()) or not bool((std > 0).all()) or not bool(torch.isfinite(std).all()):
            raise ValueError("latent std must be finite and > 0 and the mean finite")
        self.latent_mean.copy_(mean)
        self.latent_std.copy_(std)

    def normalize_latents(self, z: torch.Tensor) -> torch.Tensor:
        """VAE latents ``(B, Lz, Dz)`` -> the space the PST diffuses (identity without ``latent_norm``)."""
        if not self.config.latent_norm:
            return z
        return (z - self.latent_mean.to(z.dtype)) / self.latent_std.to(z.dtype)

    def denormalize_latents(self, z: torch.Tensor) -> torch.Tensor:
        """Inverse of :meth:`normalize_latents`."""
        if not self.config.latent_norm:
            return z
        return z * self.latent_std.to(z.dtype) + self.latent_mean.to(z.dtype)

    @property
    def skip_pairs(self) -> tuple[tuple[int, int], ...]:
        """``(source, receiver)`` layer pairs ``(i, L - 1 - i)`` for ``i < L // 2`` (0-based); without
        :attr:`PSTConfig.middle_skip`, only pairs whose receiver is not the source's next layer (for even
        ``L`` the middle pair's receiver gets its own input twice)."""
        n = self.config.num_cross_layers
        pairs = tuple((i, n - 1 - i) for i in range(n // 2))
        if not self.config.middle_skip:
            pairs = tuple((i, j) for i, j in pairs if j > i + 1)
        return pairs

    @property
    def num_special_tokens(self) -> int:
        """Condition tokens before the text: time (and length)."""
        return 2 if self.config.length_condition else 1

    # --------------------------------------------------------------------------- forward
    def _timesteps(self, timesteps, b: int, device) -> torch.Tensor:
        t = torch.as_tensor(timesteps, device=device)
        if t.dim() == 0:
            t = t.expand(b)
        t = t.reshape(-1)
        if t.shape[0] == 1 and b > 1:
            t = t.expand(b)
        if t.shape[0] != b:
            raise ValueError(f"timesteps must be a scalar or have B={b} (or 1) entries, got shape {tuple(t.shape)}")
        return t

    def _check_sides(self, text_sides: torch.Tensor | None, text: torch.Tensor) -> None:
        """``text_sides`` must be given exactly when ``config.side_cue``: ``(B, W)`` integer ids in 0..2."""
        if self.side_embed is None:
            if text_sides is not None:
                raise ValueError("text_sides was given but this PST has no side cue (PSTConfig.side_cue=False); "
                                 "pass text_sides=None")
            return
        if text_sides is None:
            raise ValueError("this PST has a side cue (PSTConfig.side_cue=True): pass text_sides (B, W), the side "
                             "ids of the text tokens (salad_core.keymotion.sides.side_ids; zeros for the empty prompt)")
        if tuple(text_sides.shape) != tuple(text.shape[:2]):
            raise ValueError(f"text_sides must be (B, W) = {tuple(text.shape[:2])}, got {tuple(text_sides.shape)}")
        if text_sides.dtype == torch.bool or text_sides.is_floating_point() or text_sides.is_complex():
            raise ValueError(f"text_sides must hold integer side ids (0 none, 1 left, 2 right), got {text_sides.dtype}")
        if text_sides.numel() and not 0 <= int(text_sides.min()) <= int(text_sides.max()) < NUM_SIDES:
            raise ValueError(f"text_sides must be in 0..{NUM_SIDES - 1} (0 none, 1 left, 2 right), got values "
                             f"{int(text_sides.min())}..{int(text_sides.max())}")

    def condition(self, timesteps: torch.Tensor, text: torch.Tensor, text_mask: torch.Tensor,
                  lengths: torch.Tensor | None, text_sides: torch.Tensor | None = None
                  ) -> tuple[torch.Tensor, torch.Tensor]:
        """Condition stream ``c_0 (B, S, w)`` and its key mask ``(B, S)``, ``S = specials + W``.

        ``text_sides (B, W)`` long: side ids of the text tokens, required exactly when
        ``config.side_cue`` (their embedding is added to the projected text tokens).
        """
        cfg = self.config
        b, n_tok = text.shape[:2]
        if n_tok > cfg.max_text_tokens:
            raise ValueError(f"text has {n_tok} tokens; PSTConfig.max_text_tokens={cfg.max_text_tokens}")
        self._check_sides(text_sides, text)
        w = cfg.width
        dtype = self.text_in.weight.dtype
        tok = [self.time_mlp(timestep_sinusoid(timesteps, w).to(dtype))[:, None]]          # (B, 1, w)
        if self.length_mlp is not None:
            if lengths is None:
                raise ValueError("this PST is length-conditioned: pass lengths (B,) in frames")
            lengths = torch.as_tensor(lengths, device=text.device).reshape(-1)
            if lengths.numel() == 1:
                lengths = lengths.expand(b)
            if lengths.shape[0] != b:
                raise ValueError(f"lengths must have B={b} entries, got {lengths.shape[0]}")
            tok.append(self.length_mlp(position_sinusoid(lengths.float(), w).to(dtype))[:, None])
        text_tokens = self.text_in(text.to(dtype))                                          # (B, W, w)
        if self.side_embed is not None:
            sides = self.side_embed(text_sides.to(device=text.device, dtype=torch.long))         # (B, W, w)
            text_tokens = text_tokens + sides.to(text_tokens.dtype)
        c = torch.cat(tok + [text_tokens], 1)
        c = self.drop(c + self.cond_pe[: c.shape[1]])
        special = torch.ones(b, len(tok), dtype=torch.bool, device=text.device)
        mask = torch.cat([special, text_mask.to(device=text.device, dtype=torch.bool)], 1)
        for block in self.cond_layers:
            c = block(c, mask)
        return c, mask

    def forward(self, x: torch.Tensor, timesteps, text: torch.Tensor, text_mask: torch.Tensor,
                lengths: torch.Tensor | None = None, text_sides: torch.Tensor | None = None) -> torch.Tensor:
        """Predict the noise of ``x_t``.

        Parameters
        ----------
        x : Tensor ``(B, Lz, Dz)``
            Noisy latents.
        timesteps : Tensor ``(B,)``, ``(1,)`` or scalar
            Diffusion timesteps.
        text : Tensor ``(B, W, C)``
            Token features of the prompts (the empty prompt for the unconditional branch).
        text_mask : Tensor ``(B, W)`` bool
            True on real tokens.
        lengths : Tensor ``(B,)``, optional
            Motion lengths in frames (required when ``config.length_condition``).
        text_sides : LongTensor ``(B, W)``, optional
            Side ids of the text tokens (0 none, 1 left, 2 right;
            :func:`~salad_core.keymotion.sides.side_ids`): required when ``config.side_cue``, an
            error otherwise.

        Returns
        -------
        Tensor ``(B, Lz, Dz)``: the predicted noise ε (eq. 7).
        """
        cfg = self.config
        if x.dim() != 3 or tuple(x.shape[1:]) != (cfg.latent_size, cfg.latent_dim):
            raise ValueError(f"x must be (B, {cfg.latent_size}, {cfg.latent_dim}), got {tuple(x.shape)}")
        b = x.shape[0]
        if text.dim() != 3 or text.shape[0] != b or text.shape[2] != cfg.text_dim:
            raise ValueError(f"text must be (B={b}, W, C={cfg.text_dim}), got {tuple(text.shape)}")
        if tuple(text_mask.shape) != tuple(text.shape[:2]):
            raise ValueError(f"text_mask must be (B, W) = {tuple(text.shape[:2])}, got {tuple(text_mask.shape)}")
        t = self._timesteps(timesteps, b, x.device)
        c, c_mask = self.condition(t, text, text_mask, lengths, text_sides)
        h = self.drop(self.latent_in(x) + self.latent_pe)
        sources = {i for i, _ in self.skip_pairs}
        partner = {j: i for i, j in self.skip_pairs}
        saved: dict[int, tuple[torch.Tensor, torch.Tensor]] = {}
        for i, layer in enumerate(self.cross_layers):
            h, c = layer(h, c, c_mask, saved.get(partner[i]) if i in partner else None)
            if i in sources:
                saved[i] = (h, c)
        w_mask = c_mask.to(c.dtype)[..., None]
        pooled = (c * w_mask).sum(1) / w_mask.sum(1).clamp_min(1.0)                        # (B, w)
        out = torch.cat([h, pooled[:, None].expand(-1, h.shape[1], -1)], -1)                 # (B, Lz, 2w)
        return self.out(self.out_norm(out))

    def guided(self, x: torch.Tensor, timesteps, text: torch.Tensor, text_mask: torch.Tensor,
               null_text: torch.Tensor, null_mask: torch.Tensor, guidance_scale: "float | Guidance",
               lengths: torch.Tensor | None = None, text_sides: torch.Tensor | None = None) -> torch.Tensor:
        """Classifier-free guided noise (eq. 8) with both branches in one batched forward.

        ``null_text (B or 1, W0, C)`` / ``null_mask`` are the empty prompt's features; the two
        texts are padded to a common width (padding is masked, so it changes nothing).
        ``text_sides (B, W)`` (side-cue PSTs only) are the prompts' side ids, padded the same way;
        the null branch gets zeros (the empty prompt names no side).
        ``guidance_scale`` is the weight ``w`` or a :class:`~salad_core.sampling.Guidance` (its
        ``rescale`` acts per sample over the ``Lz x Dz`` latent; its interval is applied by
        :class:`PSTPrediction`, not here).
        """
        b = x.shape[0]
        guidance = as_guidance(guidance_scale)
        if not guidance.cfg:
            return self(x, timesteps, text, text_mask, lengths, text_sides)
        null_text, null_mask = null_text.expand(b, -1, -1), null_mask.expand(b, -1)
        width = max(text.shape[1], null_text.shape[1])
        texts = torch.cat([_pad_tokens(null_text, width), _pad_tokens(text, width)])
        masks = torch.cat([_pad_mask(null_mask, width), _pad_mask(text_mask, width)])
        sides = None
        if text_sides is not None:
            if tuple(text_sides.shape) != tuple(text.shape[:2]):
                raise ValueError(f"text_sides must be (B, W) = {tuple(text.shape[:2])}, got {tuple(text_sides.shape)}")
            sides = torch.cat([text_sides.new_zeros((b, width)), _pad_sides(text_sides, width)])
        t = self._timesteps(timesteps, b, x.device)
        lens = None
        if lengths is not None:
            lens = torch.as_tensor(lengths, device=x.device).reshape(-1)
            lens = lens.expand(b) if lens.numel() == 1 else lens
        out = self(torch.cat([x, x]), torch.cat([t, t]), texts, masks,
                   None if lens is None else torch.cat([lens, lens]), sides)
        uncond, cond = out.chunk(2)
        # eq. 8: eps_u + w (eps_c - eps_u); Guidance works on (B, N', P, Dz), so the latent is one "frame"
        return guidance.combine(uncond[:, None], cond[:, None])[:, 0]

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())


def _pad_tokens(x: torch.Tensor, width: int) -> torch.Tensor:
    return torch.nn.functional.pad(x, (0, 0, 0, width - x.shape[1]))


def _pad_mask(m: torch.Tensor, width: int) -> torch.Tensor:
    return torch.nn.functional.pad(m.to(torch.bool), (0, width - m.shape[1]), value=False)


def _pad_sides(s: torch.Tensor, width: int) -> torch.Tensor:
    return torch.nn.functional.pad(s, (0, width - s.shape[1]), value=NO_SIDE)


class PSTPrediction:
    """KeyMotion's guided noise prediction (eq. 8) as a :class:`~salad_core.sampling.Prediction`.

    Without guidance (``w = 1``, or a step outside a :class:`~salad_core.sampling.Guidance`'s
    interval) the conditional branch alone; otherwise both branches in one batched forward
    (:meth:`ParallelSkipTransformer.guided`).

    Parameters
    ----------
    guidance_scale : float or Guidance
        The weight ``w`` (plain eq. 8) or a Guidance with a guidance ``rescale`` and/or a noise
        ``interval`` (``lo <= t / T <= hi``) outside which the step is unguided.
    lengths : Tensor ``(B,)``, optional
        Motion lengths (frames) for a length-conditioned PST.
    text_sides : LongTensor ``(B, W)``, optional
        Side ids of the prompts' tokens, for a PST with ``config.side_cue`` (required by it).
    """

    desc = "keyframe denoising"

    def __init__(self, pst: ParallelSkipTransformer, text: torch.Tensor, text_mask: torch.Tensor,
                 null_text: torch.Tensor | None, null_mask: torch.Tensor | None,
                 guidance_scale: "float | Guidance", lengths: torch.Tensor | None = None,
                 text_sides: torch.Tensor | None = None) -> None:
        self.guidance = as_guidance(guidance_scale)
        if self.guidance.cfg and (null_text is None or null_mask is None):
            raise ValueError(f"guidance_scale={guidance_scale} needs the empty prompt's features "
                             "(null_text, null_mask)")
        pst._check_sides(text_sides, text)       # fail before the loop, not at its first step
        self.model = pst
        self.batch_size = text.shape[0]
        self.text, self.text_mask, self.null_text, self.null_mask = text, text_mask, null_text, null_mask
        self.guidance_scale, self.lengths, self.text_sides = guidance_scale, lengths, text_sides
        self.num_train_timesteps = PST_DIFFUSION.num_train_timesteps

    def session(self, timesteps: torch.Tensor, num_train_timesteps: int) -> ContextManager[None]:
        self.num_train_timesteps = int(num_train_timesteps)
        return nullcontext()

    def guided(self, timestep: float) -> bool:
        return self.guidance.active(timestep, self.num_train_timesteps)

    def __call__(self, z: torch.Tensor, t: torch.Tensor, info: StepInfo) -> torch.Tensor:
        """Predicted noise ``(B, Lz, Dz)`` of the keyframe latents ``z`` at ``t``."""
        if not info.cfg:
            return self.model(z, t, self.text, self.text_mask, self.lengths, self.text_sides)
        return self.model.guided(z, t, self.text, self.text_mask, self.null_text, self.null_mask,
                                 self.guidance, self.lengths, self.text_sides)


def sample_latents(pst: ParallelSkipTransformer, scheduler, text: torch.Tensor, text_mask: torch.Tensor,
                   null_text: torch.Tensor | None, null_mask: torch.Tensor | None, noise: torch.Tensor, *,
                   lengths: torch.Tensor | None = None, guidance_scale: "float | Guidance" = 4.0, num_steps: int = 50,
                   progress: bool = False, generator: torch.Generator | None = None,
                   callback: Callable[[StepInfo, torch.Tensor], None] | None = None,
                   text_sides: torch.Tensor | None = None) -> torch.Tensor:
    """Reverse diffusion of keyframe latents with classifier-free guidance (eq. 8).

    The loop is :func:`salad_core.sampling.denoise` with :class:`PSTPrediction`.

    Parameters
    ----------
    pst : ParallelSkipTransformer
        Run in eval mode for the loop (its mode is restored afterwards).
    scheduler
        A diffusers scheduler for :data:`PST_DIFFUSION` (``make_scheduler(PST_DIFFUSION, "ddim")``);
        ``set_timesteps`` is called here.
    text, text_mask : Tensor ``(B, W, C)``, ``(B, W)``
        The prompts' token features.
    null_text, null_mask : Tensor ``(1 or B, W0, C)``, ``(1 or B, W0)``
        The empty prompt's features; may be None only when ``guidance_scale == 1``.
    noise : Tensor ``(B, Lz, Dz)``
        Initial standard-normal latents (scaled by ``init_noise_sigma`` here); not modified.
    lengths : Tensor ``(B,)``, optional
        Motion lengths (frames) for a length-conditioned PST.
    guidance_scale : float or Guidance
        CFG weight ``w`` (1 runs only the conditional branch), or a
        :class:`~salad_core.sampling.Guidance` (weight, rescale, noise interval).
    num_steps : int
        Inference steps.
    progress : bool
        Show a tqdm bar.
    generator : torch.Generator, optional
        For stochastic schedulers' ``step``.
    callback : callable, optional
        ``callback(step_info, latents)`` after each step (:class:`~salad_core.sampling.StepInfo`, as
        every sampler of salad).
    text_sides : LongTensor ``(B, W)``, optional
        Side ids of the prompts' tokens (:func:`~salad_core.keymotion.sides.side_ids_of` of their
        TextBatch); required by a PST with ``config.side_cue``, an error for one without.

    Returns
    -------
    Tensor ``(B, Lz, Dz)``: the denoised latents in the keyframe VAE's space (a ``latent_norm`` PST's
    samples de-normalised; ``callback`` sees the normalised ones it diffuses).
    """
    if num_steps < 1:
        raise ValueError(f"num_steps must be >= 1, got {num_steps}")
    prediction = PSTPrediction(pst, text, text_mask, null_text, null_mask, guidance_scale, lengths, text_sides)
    z = denoise(pst, scheduler, latents=noise, num_steps=num_steps, prediction=prediction, callback=callback,
                progress=progress, generator=generator)
    return pst.denormalize_latents(z)


register_model("keymotion_pst", PSTConfig, ParallelSkipTransformer)
