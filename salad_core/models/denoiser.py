"""The skeleto-temporal denoiser of SALAD (paper §3.2, Fig. 3, supplement A.2; fact sheet §2.1).

Input and output are latents ``(B, N', P, Dz)`` (``N'`` latent frames, ``P`` body parts). One
layer (:class:`STTransformerLayer`) is, with pre-LayerNorm and a timestep FiLM on every
sublayer output before its residual add (paper eqs. 4-6, 10-12)::

    z <- z + FiLM(TempAttn(LN(z)))            # each part attends over frames (padded keys masked)
    z <- z + FiLM(SkelAttn(LN(z)))            # each frame attends over its P parts (full P x P)
    z <- z + FiLM(CrossAttn(LN(z), LN(E c)))  # every (frame, part) token attends to the words
    z <- z + FiLM(FFN(LN(z)))

``L`` (odd) layers are stacked U-Net style (:class:`SkipTransformer`): ``(L-1)/2`` input
blocks whose outputs are kept, a middle block, and ``(L-1)/2`` output blocks each preceded by
``Linear(concat(z, skip))``. Module names reproduce the official state dict, so official
checkpoints (without ``clip_model.*`` keys) load strictly: see
:meth:`Denoiser.from_official_state_dict`.

Ablations (paper Tab. 3 and supplement C.4): ``cross_attention=False`` replaces the cross
attention by self-attention over ``[sentence token; N'*P motion tokens]`` (queries: the motion
tokens; the sentence token is ``word_emb`` of the pooled sentence feature, normalised per layer
by ``cross_tgt_norm``, and is the same at every layer); ``film=False`` drops the FiLMs and adds
the timestep embedding to the input tokens instead.

This file is the architecture. What sampling reuses across steps (the text keys and values of a
:class:`TextContext`, the folded cross-attention, every timestep's FiLMs, the stacked Q/K/V) lives
in :mod:`salad_core.models.inference`, and the CPU attention kernels in
:mod:`salad_core.models.kernels`: the forward asks them for its text and timestep inputs
(:func:`~salad_core.models.inference.text_inputs`, :func:`~salad_core.models.inference.timestep_inputs`),
which are cached when gradients are off and computed afresh when training.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, replace
from typing import Any, Mapping, Sequence

import torch
from torch import nn

from salad_core.io import CheckpointError, load_state_into, register_model
from salad_core.models.attention import Attention, AttnProcessorMixin, CallDims, site_names
from salad_core.models.embeddings import PositionalEmbedding, TimestepEmbedding
from salad_core.models.gemm import Linear, linear
from salad_core.models.inference import TextContext, text_inputs, timestep_inputs, timestep_table
from salad_core.models.kernels import FoldedText
from salad_core.skeleton import NUM_PARTS

__all__ = ["DenoiserConfig", "TextContext", "FiLM", "STTransformerLayer", "SkipTransformer", "Denoiser"]

log = logging.getLogger(__name__)

_ACTIVATIONS = {"gelu": nn.GELU, "relu": nn.ReLU}

#: ``axis`` of :meth:`Attention.attend_within` for the two self-attentions of a layer.
_FRAMES, _PARTS = 1, 2


@dataclass(frozen=True)
class DenoiserConfig:
    """Hyper-parameters of :class:`Denoiser` (defaults = the paper / official release)."""

    latent_dim: int = 32          # Dz, VAE latent channels per part
    num_parts: int = NUM_PARTS    # P, latent body parts (1 for the pose-vector VAE ablation)
    width: int = 256              # w, transformer width
    heads: int = 8                # H, attention heads (w divisible by H)
    ff_dim: int = 1024            # hidden width of the FFN
    layers: int = 5               # L, transformer layers (odd: input blocks, middle, output blocks)
    dropout: float = 0.1          # dropout after pos-emb, on attention probs and on sublayer outputs
    text_dim: int = 512           # C, text-encoder token channels (CLIP B/32 512, MiniLM 384)
    activation: str = "gelu"      # FFN activation: "gelu" or "relu"
    max_len: int = 5000           # longest flattened sequence N' * P (rows of pos_emb.pe)
    cross_attention: bool = True  # False: ablation "w/o CrossAttn" (sentence token + self-attention)
    film: bool = True             # False: ablation "w/o FiLM" (timestep embedding added to the input)

    def __post_init__(self) -> None:
        for name in ("latent_dim", "num_parts", "width", "heads", "ff_dim", "layers", "text_dim", "max_len"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"DenoiserConfig.{name} must be a positive int, got {value!r}")
        if self.width % self.heads:
            raise ValueError(f"DenoiserConfig.width ({self.width}) must be divisible by heads ({self.heads})")
        if self.width % 2:
            raise ValueError(f"DenoiserConfig.width must be even (sin/cos embeddings), got {self.width}")
        if self.layers % 2 != 1:
            raise ValueError(f"DenoiserConfig.layers must be odd (U-Net skips pair input/output blocks), got {self.layers}")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"DenoiserConfig.dropout must be in [0, 1), got {self.dropout!r}")
        if self.activation not in _ACTIVATIONS:
            raise ValueError(f"DenoiserConfig.activation must be one of {sorted(_ACTIVATIONS)}, got {self.activation!r}")
        if self.max_len < self.num_parts:
            raise ValueError(f"DenoiserConfig.max_len ({self.max_len}) must hold at least one frame of {self.num_parts} parts")


class FiLM(nn.Module):
    """Timestep FiLM (official ``DenseFiLM``): ``SiLU -> Linear(w, 2w)`` -> (scale, shift).

    Applied as ``out * (1 + scale) + shift`` (supplement eq. 10 with gamma = 1 + scale) by
    :meth:`residual`.
    """

    def __init__(self, width: int) -> None:
        super().__init__()
        self.linear = nn.Sequential(nn.SiLU(), Linear(width, 2 * width))

    def forward(self, temb: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``temb`` ``(B, w)`` -> ``scale, shift`` each ``(B, 1, 1, w)``."""
        scale, shift = self.linear(temb)[:, None, None, :].chunk(2, dim=-1)
        return scale, shift

    @staticmethod
    def residual(x: torch.Tensor, out: torch.Tensor,
                 film: tuple[torch.Tensor, torch.Tensor] | None) -> torch.Tensor:
        """Residual update ``x + out * (1 + scale) + shift`` (``x + out`` without FiLM).

        One fused ``addcmul`` and an in-place add on its fresh result instead of three new tensors:
        at batch 32 each new activation costs an allocation of tens of MB, and the three-op form took
        26 ms against 11 ms per residual of the paper model on this machine.
        """
        if film is None:
            return x + out
        scale, shift = film
        return torch.addcmul(x, out, 1 + scale).add_(shift)


@dataclass
class _Masks:
    """Key masks of one call (None = all valid), built once and shared by the layers."""

    temporal: torch.Tensor | None   # (B*P, N')
    text: torch.Tensor | None       # (B, W)
    sentence: torch.Tensor | None   # (B, 1 + N'*P)


@dataclass
class LayerInputs:
    """What one layer gets besides the tokens in one call: the call's key masks and sizes, this
    layer's text keys and values ``(B, H, W, dh)``, and, when sampling, its four FiLM
    ``(scale, shift)`` from the timestep table and its folded text (else None)."""

    masks: _Masks
    dims: CallDims
    text_kv: tuple[torch.Tensor, torch.Tensor]
    films: Sequence[tuple[torch.Tensor, torch.Tensor]] | None = None
    fold: FoldedText | None = None


class STTransformerLayer(nn.Module):
    """One skeleto-temporal layer: TempAttn -> SkelAttn -> CrossAttn -> FFN (see module docstring)."""

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        w, h, p = config.width, config.heads, config.dropout
        self.use_film = config.film
        self.cross_attention = config.cross_attention
        self.temp_norm = nn.LayerNorm(w)
        self.temp_attn = Attention(w, h, p, "temporal")
        self.temp_dropout = nn.Dropout(p)
        self.skel_norm = nn.LayerNorm(w)
        self.skel_attn = Attention(w, h, p, "skeletal")
        self.skel_dropout = nn.Dropout(p)
        self.cross_src_norm = nn.LayerNorm(w)
        self.cross_tgt_norm = nn.LayerNorm(w)
        self.cross_attn = Attention(w, h, p, "cross" if config.cross_attention else "sentence")
        self.cross_dropout = nn.Dropout(p)
        self.ffn_norm = nn.LayerNorm(w)
        self.ffn_linear1 = Linear(w, config.ff_dim)
        self.ffn_activation = _ACTIVATIONS[config.activation]()
        self.ffn_fused_gelu = config.activation == "gelu"      # GELU fused into ffn_linear1 on oneDNN
        self.ffn_linear2 = Linear(config.ff_dim, w)
        self.ffn_dropout = nn.Dropout(p)
        if config.film:
            self.temp_film = FiLM(w)
            self.skel_film = FiLM(w)
            self.cross_film = FiLM(w)
            self.ffn_film = FiLM(w)

    def text_kv(self, memory: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """This layer's text keys/values ``(B, H, W, dh)`` from projected tokens ``(B, W, w)``."""
        return self.cross_attn.project_kv(self.cross_tgt_norm(memory))

    @property
    def films(self) -> tuple[FiLM, ...]:
        """The four FiLMs in application order (temporal, skeletal, cross, FFN); empty without FiLM."""
        return (self.temp_film, self.skel_film, self.cross_film, self.ffn_film) if self.use_film else ()

    def feed_forward(self, h: torch.Tensor) -> torch.Tensor:
        """``FFN(h) = W2 act(W1 h + b1) + b2`` per token (GELU fused into the first product on oneDNN)."""
        if self.ffn_fused_gelu:
            h = linear(h, self.ffn_linear1.weight, self.ffn_linear1.bias, activation="gelu")
        else:
            h = self.ffn_activation(self.ffn_linear1(h))
        return self.ffn_linear2(h)

    def forward(self, x: torch.Tensor, temb: torch.Tensor, inputs: LayerInputs) -> torch.Tensor:
        """``x`` ``(B, N', P, w)`` -> ``(B, N', P, w)``; ``temb`` ``(B, w)`` (FiLMs computed from it
        unless ``inputs.films`` holds them already)."""
        b, n, p, w = x.shape
        masks, dims = inputs.masks, inputs.dims
        if not self.use_film:
            films = (None,) * 4
        else:
            films = inputs.films if inputs.films is not None else tuple(film(temb) for film in self.films)

        # temporal attention: every part is a sequence over frames, rows ordered (batch, part)
        h = self.temp_attn.attend_within(self.temp_norm(x), _FRAMES, key_mask=masks.temporal, dims=dims)
        x = FiLM.residual(x, self.temp_dropout(h), films[0])

        # skeletal attention: every frame is a sequence over its parts (no skeleton mask, as official)
        h = self.skel_attn.attend_within(self.skel_norm(x), _PARTS, dims=dims)
        x = FiLM.residual(x, self.skel_dropout(h), films[1])

        # cross attention over words (query index t * P + j), or the ablation's sentence token
        q = self.cross_src_norm(x.reshape(b, n * p, w))
        if self.cross_attention:
            h = self.cross_attn(q, kv=inputs.text_kv, key_mask=masks.text, fold=inputs.fold, dims=dims)
        else:
            kx, vx = self.cross_attn.project_kv(q)
            kv = (torch.cat([inputs.text_kv[0], kx], dim=2), torch.cat([inputs.text_kv[1], vx], dim=2))
            h = self.cross_attn(q, kv=kv, key_mask=masks.sentence, dims=dims)
        x = FiLM.residual(x, self.cross_dropout(h.view(b, n, p, w)), films[2])

        h = self.feed_forward(self.ffn_norm(x))
        return FiLM.residual(x, self.ffn_dropout(h), films[3])


class SkipTransformer(nn.Module):
    """U-Net stack of ``L`` layers: input blocks, middle block, output blocks with skip merges."""

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        half = config.layers // 2
        self.input_blocks = nn.ModuleList([STTransformerLayer(config) for _ in range(half)])
        self.middle_block = STTransformerLayer(config)
        self.output_blocks = nn.ModuleList([STTransformerLayer(config) for _ in range(half)])
        self.skip_blocks = nn.ModuleList([Linear(2 * config.width, config.width) for _ in range(half)])

    @property
    def layers(self) -> list[STTransformerLayer]:
        """Layers in execution order (index = the layer index of the attention sites)."""
        return [*self.input_blocks, self.middle_block, *self.output_blocks]

    def forward(self, x: torch.Tensor, temb: torch.Tensor, inputs: Sequence[LayerInputs]) -> torch.Tensor:
        """``x`` ``(B, N', P, w)``; ``inputs``: per layer (execution order) its :class:`LayerInputs`."""
        half = len(self.input_blocks)
        skips = []
        for i, block in enumerate(self.input_blocks):
            x = block(x, temb, inputs[i])
            skips.append(x)
        x = self.middle_block(x, temb, inputs[half])
        for i, (block, merge) in enumerate(zip(self.output_blocks, self.skip_blocks)):
            # the last input block's output pairs with the first output block (U-Net symmetry)
            x = merge(torch.cat([x, skips.pop()], dim=-1))
            x = block(x, temb, inputs[half + 1 + i])
        return x


class InputProcess(nn.Module):
    """``Linear(Dz, w) -> ReLU -> Linear(w, w)`` per (frame, part) token."""

    def __init__(self, latent_dim: int, width: int) -> None:
        super().__init__()
        self.layers = nn.Sequential(Linear(latent_dim, width), nn.ReLU(), Linear(width, width))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.layers(x)


class OutputProcess(nn.Module):
    """``LayerNorm -> Linear(w, w) -> ReLU -> Linear(w, Dz)`` per token."""

    def __init__(self, width: int, latent_dim: int) -> None:
        super().__init__()
        self.layers = nn.Sequential(nn.LayerNorm(width), Linear(width, width), nn.ReLU(),
                                    Linear(width, latent_dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.layers(x)


class Denoiser(AttnProcessorMixin, nn.Module):
    """SALAD's skeleton-aware denoiser ``(z_t, t, text) -> prediction`` (v, eps or x0).

    Parameters
    ----------
    config : DenoiserConfig
        Architecture; the defaults give the paper model (9,894,176 parameters at ``text_dim=512``).

    Notes
    -----
    Attention sites are named ``layers.{i}.temporal|skeletal|cross`` (``sentence`` instead of
    ``cross`` in the "w/o CrossAttn" ablation), ``i`` in execution order; see
    :mod:`salad_core.models.attention` for processors and controllers. Outputs at padded frames
    are not zeroed (as in the official code); the sampler re-masks them.
    """

    def __init__(self, config: DenoiserConfig | None = None) -> None:
        super().__init__()
        self.config = config = config or DenoiserConfig()
        self.input_process = InputProcess(config.latent_dim, config.width)
        self.pos_emb = PositionalEmbedding(config.width, config.max_len, config.dropout)
        self.timestep_emb = TimestepEmbedding(config.width)
        self.word_emb = Linear(config.text_dim, config.width)
        self.transformer = SkipTransformer(config)
        self.output_process = OutputProcess(config.width, config.latent_dim)
        names = site_names(config.layers, config.cross_attention)
        self._sites: dict[str, Attention] = {}
        for i, layer in enumerate(self.transformer.layers):
            for mod in (layer.temp_attn, layer.skel_attn, layer.cross_attn):
                name = f"layers.{i}.{mod.kind}"
                mod.bind_site(name, i, config.layers)
                self._sites[name] = mod
        assert list(self._sites) == names

    # ------------------------------------------------------------ attention sites
    @property
    def attention_sites(self) -> dict[str, Attention]:
        """Attention modules by stable site name, in execution order."""
        return dict(self._sites)

    # ----------------------------------------------------------------------- text
    def prepare_text(self, text: torch.Tensor, text_mask: torch.Tensor,
                     pooled: torch.Tensor | None = None) -> TextContext:
        """Wrap token features for repeated use (sampling): see :class:`TextContext`.

        Parameters
        ----------
        text : torch.Tensor
            ``(B, W, C)`` token features, ``C = config.text_dim``.
        text_mask : torch.Tensor
            ``(B, W)`` bool, True = valid token.
        pooled : torch.Tensor, optional
            ``(B, C)`` sentence feature (only used when ``cross_attention=False``).
        """
        if text.dim() != 3 or text.shape[-1] != self.config.text_dim:
            raise ValueError(f"text must be (B, W, C={self.config.text_dim}) token features, got {tuple(text.shape)}")
        return TextContext(text, text_mask, pooled)

    def text_kv(self, text: TextContext) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Per layer (execution order) the text keys and values ``(B, H, W, dh)``: the words
        ``E c`` (``word_emb``; the pooled sentence token ``(B, 1, w)`` in the "w/o CrossAttn"
        ablation), normalised by the layer's ``cross_tgt_norm`` and projected by its ``Wk``, ``Wv``.
        :class:`TextContext` caches them for sampling."""
        dtype = self.word_emb.weight.dtype
        if self.config.cross_attention:
            memory = self.word_emb(text.text.to(dtype))               # (B, W, w)
        else:
            memory = self.word_emb(text.pooled.to(dtype))[:, None]    # (B, 1, w): the sentence token
        return [layer.text_kv(memory) for layer in self.transformer.layers]

    # ------------------------------------------------------------------- timestep
    def prepare_timesteps(self, timesteps: torch.Tensor) -> None:
        """Compute every FiLM of the timesteps ``(S,)`` of a schedule in one product and keep them
        (:class:`~salad_core.models.inference.TimestepTable`); a no-op with gradients enabled or
        without FiLM."""
        if not torch.is_grad_enabled() and self.config.film:
            timestep_table(self).fill(self, timesteps)

    def timestep_conditioning(self, timesteps: torch.Tensor) -> tuple[torch.Tensor, list]:
        """Timestep embedding ``(R, w)`` and every layer's four FiLM ``(scale, shift)``, each
        ``(R, 1, 1, w)``, for ``timesteps`` ``(R,)`` (``R = 1`` broadcasts over the batch): from the
        cached table when gradients are off, computed afresh otherwise."""
        if not self.config.film:
            raise ValueError("this denoiser has no FiLM (config.film=False)")
        if torch.is_grad_enabled():
            temb = self.timestep_emb(timesteps)
            return temb, [tuple(f(temb) for f in layer.films) for layer in self.transformer.layers]
        return timestep_table(self).conditioning(self, timesteps)

    # -------------------------------------------------------------------- forward
    def forward(self, x: torch.Tensor, timesteps: torch.Tensor | int | float,
                text: torch.Tensor | None = None, text_mask: torch.Tensor | None = None,
                frame_mask: torch.Tensor | None = None, *,
                text_context: TextContext | None = None) -> torch.Tensor:
        """Predict the diffusion target for noisy latents (paper Fig. 3).

        Parameters
        ----------
        x : torch.Tensor
            ``(B, N', P, Dz)`` noisy latents.
        timesteps : torch.Tensor or number
            ``(B,)`` diffusion timesteps (a scalar or ``(1,)`` is broadcast).
        text, text_mask : torch.Tensor
            ``(B, W, C)`` token features and ``(B, W)`` bool validity; omit when ``text_context``
            is given.
        frame_mask : torch.Tensor, optional
            ``(B, N')`` bool, True = valid latent frame; padded frames are masked as temporal
            keys (and as keys of the ablation's sentence attention).
        text_context : TextContext, optional
            From :meth:`prepare_text`; reuses the cached text projections.

        Returns
        -------
        torch.Tensor
            ``(B, N', P, Dz)``.
        """
        cfg = self.config
        if x.dim() != 4 or x.shape[2] != cfg.num_parts or x.shape[3] != cfg.latent_dim:
            raise ValueError(f"x must be (B, N', P={cfg.num_parts}, Dz={cfg.latent_dim}), got {tuple(x.shape)}")
        b, n, p, _ = x.shape
        text_context = self._text_context(text, text_mask, text_context, b)
        timesteps = self._timesteps(timesteps, b, x.device)      # (1,) or (B,)

        # the conditions: text keys/values per layer (E c), the timestep embedding and FiLMs
        text_kv, folds = text_inputs(self, text_context)
        temb, films = timestep_inputs(self, timesteps, b)
        masks = self._masks(frame_mask, text_context.mask, b, n, p)
        dims = CallDims(b, n, p, text_context.num_tokens if cfg.cross_attention else 1 + n * p)
        inputs = [LayerInputs(masks, dims, text_kv[i], None if films is None else films[i],
                              None if folds is None else folds[i]) for i in range(cfg.layers)]

        # tokens: every (frame, part) latent embedded, plus the positional embedding of its flattened
        # index t * P + j (supplement A.2)
        h = self.input_process(x).reshape(b, n * p, cfg.width)
        h = self.pos_emb(h).view(b, n, p, cfg.width)
        if not cfg.film:
            # "w/o FiLM" ablation (supplement C.4): timestep embedding added to the input
            h = h + temb[:, None, None, :]
        h = self.transformer(h, temb, inputs)
        return self.output_process(h)

    def _text_context(self, text: torch.Tensor | None, text_mask: torch.Tensor | None,
                      text_context: TextContext | None, batch: int) -> TextContext:
        """The call's text as a :class:`TextContext`, checked against the latent batch."""
        if text_context is None:
            if text is None or text_mask is None:
                raise ValueError("pass either text and text_mask, or text_context")
            text_context = self.prepare_text(text, text_mask)
        elif text is not None:
            raise ValueError("pass either text/text_mask or text_context, not both")
        if text_context.batch_size != batch:
            raise ValueError(f"text batch ({text_context.batch_size}) must equal the latent batch ({batch})")
        if text_context.text_dim != self.config.text_dim:
            raise ValueError(f"text features have C={text_context.text_dim}, the denoiser expects "
                             f"{self.config.text_dim}")
        return text_context

    @staticmethod
    def _timesteps(timesteps, batch: int, device) -> torch.Tensor:
        t = torch.as_tensor(timesteps, device=device)
        if t.dim() == 0:
            t = t[None]
        if t.dim() != 1 or t.shape[0] not in (1, batch):
            raise ValueError(f"timesteps must be a scalar, (1,) or (B={batch},), got shape {tuple(t.shape)}")
        return t

    def _masks(self, frame_mask, text_mask, b: int, n: int, p: int) -> _Masks:
        text = None if bool(text_mask.all()) else text_mask
        if frame_mask is None:
            return _Masks(None, text, None)
        if frame_mask.shape != (b, n):
            raise ValueError(f"frame_mask must be (B, N') = {(b, n)}, got {tuple(frame_mask.shape)}")
        frame_mask = frame_mask.to(dtype=torch.bool)
        if not bool(frame_mask.any(dim=1).all()):
            raise ValueError("frame_mask has a sample with no valid frame; every motion needs >= 1 latent frame")
        if bool(frame_mask.all()):
            return _Masks(None, text, None)
        temporal = frame_mask[:, None, :].expand(b, p, n).reshape(b * p, n)
        sentence = None
        if not self.config.cross_attention:
            sentence = torch.cat([frame_mask.new_ones(b, 1), frame_mask.repeat_interleave(p, dim=1)], dim=1)
        return _Masks(temporal, text, sentence)

    # ---------------------------------------------------- official checkpoint I/O
    def official_state_dict(self) -> dict[str, torch.Tensor]:
        """State dict in the official layout (251 keys at L = 5; no ``clip_model.*`` keys)."""
        if not (self.config.film and self.config.cross_attention):
            raise ValueError("only the full model (film=True, cross_attention=True) has an official layout; "
                             f"this one has film={self.config.film}, cross_attention={self.config.cross_attention}")
        return {k: v.detach().clone() for k, v in self.state_dict().items()}

    @classmethod
    def from_official_state_dict(cls, state_dict: Mapping[str, torch.Tensor],
                                 config: DenoiserConfig | None = None, **overrides: Any) -> "Denoiser":
        """Build a denoiser from an official SALAD denoiser state dict, loading it strictly.

        Sizes that the weights determine (``latent_dim``, ``width``, ``ff_dim``, ``layers``,
        ``text_dim``, ``max_len``) are inferred unless ``config`` is given; ``heads`` and
        ``num_parts`` cannot be read from weights and default to the paper values (8, 7), or
        pass them in ``overrides``. ``clip_model.*`` and ``*_cache_*`` keys (the frozen text
        encoder, excluded from official best checkpoints) are dropped.

        Raises
        ------
        salad_core.io.CheckpointError
            On missing, unexpected or wrongly shaped keys (the message names them).
        """
        sd = {k: v for k, v in state_dict.items() if not k.startswith("clip_model.") and "_cache_" not in k}
        if len(sd) != len(state_dict):
            log.info("ignored %d clip_model/_cache_ keys of the text encoder", len(state_dict) - len(sd))
        if config is None:
            config = cls._infer_config(sd)
        if overrides:
            config = replace(config, **overrides)
        model = cls(config)
        load_state_into(model, sd, source="official denoiser state dict")
        return model

    @staticmethod
    def _infer_config(sd: Mapping[str, torch.Tensor]) -> DenoiserConfig:
        need = ("input_process.layers.0.weight", "word_emb.weight", "pos_emb.pe",
                "transformer.middle_block.ffn_linear1.weight")
        missing = [k for k in need if k not in sd]
        if missing:
            raise CheckpointError(f"official denoiser state dict lacks {missing}; is this a SALAD denoiser?")
        width, latent_dim = sd["input_process.layers.0.weight"].shape
        half = len({k.split(".")[2] for k in sd if k.startswith("transformer.input_blocks.")})
        return DenoiserConfig(
            latent_dim=int(latent_dim), width=int(width),
            ff_dim=int(sd["transformer.middle_block.ffn_linear1.weight"].shape[0]),
            layers=2 * half + 1, text_dim=int(sd["word_emb.weight"].shape[1]),
            max_len=int(sd["pos_emb.pe"].shape[1]),
        )


register_model("denoiser", DenoiserConfig, Denoiser)
