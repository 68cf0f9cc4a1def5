"""Positional and diffusion-timestep embeddings of the skeleto-temporal denoiser.

Both follow the official SALAD code (fact sheet §2.1):

* the positional embedding is a 1-D sinusoidal table (sin on even channels, cos on odd ones,
  base 10000) over the *flattened* (frame, part) index ``t * P + j`` (supplement A.2: a
  ``(T*J, D)`` table reshaped to ``(T, J, D)``), stored as the persistent buffer ``pe`` so that
  official checkpoints load strictly;
* the timestep embedding is the GLIDE sinusoid laid out ``[cos, sin]`` followed by an MLP
  ``Linear -> SiLU -> Linear``.
"""
from __future__ import annotations

import math

import torch
from torch import nn

__all__ = ["sinusoidal_table", "timestep_sinusoid", "PositionalEmbedding", "TimestepEmbedding"]


def sinusoidal_table(length: int, dim: int, base: float = 10000.0) -> torch.Tensor:
    """Transformer sinusoidal table ``(length, dim)``: ``sin`` on even, ``cos`` on odd channels.

    Parameters
    ----------
    length : int
        Number of positions.
    dim : int
        Channels (even).
    base : float
        Wavelength base (10000 as in Vaswani et al.).
    """
    if dim % 2:
        raise ValueError(f"dim must be even for a sin/cos table, got {dim}")
    pos = torch.arange(length, dtype=torch.float64)[:, None]
    div = torch.exp(torch.arange(0, dim, 2, dtype=torch.float64) * (-math.log(base) / dim))
    table = torch.zeros(length, dim, dtype=torch.float64)
    table[:, 0::2] = torch.sin(pos * div)
    table[:, 1::2] = torch.cos(pos * div)
    return table.float()


def timestep_sinusoid(timesteps: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    """GLIDE timestep features ``(B, dim)`` laid out ``[cos, sin]`` (official ``TimestepEmbedding``).

    Parameters
    ----------
    timesteps : torch.Tensor
        ``(B,)`` diffusion timesteps (int or float).
    dim : int
        Output channels; an odd ``dim`` gets a trailing zero channel.
    """
    half = dim // 2
    freqs = torch.exp(
        -math.log(max_period) * torch.arange(half, dtype=torch.float32, device=timesteps.device) / half
    )
    args = timesteps.float()[:, None] * freqs[None]
    emb = torch.cat([torch.cos(args), torch.sin(args)], dim=-1)
    if dim % 2:
        emb = torch.cat([emb, torch.zeros_like(emb[:, :1])], dim=-1)
    return emb


class PositionalEmbedding(nn.Module):
    """Adds the sinusoidal table over a flattened token axis, then dropout.

    Parameters
    ----------
    width : int
        Token channels ``w``.
    max_len : int
        Longest flattened sequence ``N' * P`` supported (rows of the buffer ``pe``).
    dropout : float
        Dropout applied after the addition (official: 0.1).
    """

    def __init__(self, width: int, max_len: int = 5000, dropout: float = 0.1) -> None:
        super().__init__()
        self.register_buffer("pe", sinusoidal_table(max_len, width)[None], persistent=True)  # (1, max_len, w)
        self.dropout = nn.Dropout(dropout)

    @property
    def max_len(self) -> int:
        return self.pe.shape[1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``x`` ``(B, L, w)`` -> ``(B, L, w)`` with ``pe[:, :L]`` added."""
        length = x.shape[1]
        if length > self.max_len:
            raise ValueError(
                f"sequence of {length} tokens (frames x parts) exceeds max_len={self.max_len}; "
                "build the denoiser with a larger max_len or use shorter motions"
            )
        return self.dropout(x + self.pe[:, :length])


class TimestepEmbedding(nn.Module):
    """Timestep -> ``(B, w)`` conditioning vector: GLIDE sinusoid then ``Linear-SiLU-Linear``.

    The module names (``mlp.0``, ``mlp.2``) match the official state dict.
    """

    def __init__(self, width: int, max_period: float = 10000.0) -> None:
        super().__init__()
        self.width = width
        self.max_period = max_period
        self.mlp = nn.Sequential(nn.Linear(width, width), nn.SiLU(), nn.Linear(width, width))

    def forward(self, timesteps: torch.Tensor) -> torch.Tensor:
        """``timesteps`` ``(B,)`` -> ``(B, w)``."""
        emb = timestep_sinusoid(timesteps, self.width, self.max_period)
        return self.mlp(emb.to(self.mlp[0].weight.dtype))
