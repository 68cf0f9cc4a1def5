"""Skeleto-temporal building blocks of the SALAD VAE (paper §3.1, supplement A.1).

Every module here works on motion hidden states laid out as ``(B, N, J, C)``: batch, frames,
joints (or pooled body nodes), channels. Graph operations mix the ``J`` axis, temporal
operations mix the ``N`` axis, and all weights except :class:`MultiLinear` are shared across
joints, as in the official implementation (fact sheet §1.3, gotcha 9).

The fixed skeleton matrices (adjacency, pooling, unpooling) are stored as *frozen*
``nn.Parameter`` objects rather than buffers because the official checkpoints store them
under parameter names (``adj_matrix``, ``skeleton_pool``, ``skeleton_unpool``); keeping the same
kind and name lets those checkpoints load strictly.
"""
from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from .vae_kernels import st_conv

__all__ = [
    "ACTIVATIONS",
    "NORMS",
    "get_activation",
    "get_norm",
    "adjacency_with_self_loops",
    "MultiLinear",
    "GraphConv",
    "STConv",
    "ResSTConv",
    "STPool",
    "STUnpool",
]

#: Activation names accepted by :func:`get_activation` (the official choices).
ACTIVATIONS: tuple[str, ...] = ("relu", "silu", "gelu")
#: Normalisation names accepted by :func:`get_norm` (the official choices).
NORMS: tuple[str, ...] = ("none", "batch", "layer")


def get_activation(name: str) -> nn.Module:
    """A fresh activation module by name (``"relu"``, ``"silu"`` or ``"gelu"``)."""
    table = {"relu": nn.ReLU, "silu": nn.SiLU, "gelu": nn.GELU}
    if name not in table:
        raise ValueError(f"activation={name!r} is not supported; choose one of {ACTIVATIONS}")
    return table[name]()


class ChannelBatchNorm(nn.BatchNorm1d):
    """Batch normalisation over the last (channel) axis of a ``(..., C)`` tensor.

    Statistics are taken over every other axis (batch, frames and joints). Subclassing
    ``BatchNorm1d`` keeps the state-dict keys (``weight``, ``running_mean``, ...) at the module's
    own level, as a plain batch-norm layer would have them.
    """

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        shape = x.shape
        # (..., C) -> (M, C): BatchNorm1d normalises each channel over the M rows
        return super().forward(x.reshape(-1, shape[-1])).reshape(shape)


def get_norm(name: str, channels: int) -> nn.Module:
    """A normalisation over the channel axis of ``(B, N, J, C)``; ``"none"`` is an ``Identity``."""
    if name == "none":
        return nn.Identity()
    if name == "layer":
        return nn.LayerNorm(channels)
    if name == "batch":
        return ChannelBatchNorm(channels)
    raise ValueError(f"norm={name!r} is not supported; choose one of {NORMS}")


def _frozen(value: np.ndarray | torch.Tensor) -> nn.Parameter:
    """A float32 parameter that the optimiser never updates (it still appears in state dicts)."""
    # always a private copy: a view of a caller's (or another layer's) array must not be shared
    param = nn.Parameter(torch.tensor(np.array(value, dtype=np.float32)), requires_grad=False)
    param.salad_constant = True         # structure, not weights: num_parameters(trainable_only) skips it
    return param


def _frozen_matrix(value, name: str, axes: str) -> nn.Parameter:
    """:func:`_frozen` of a 2-D matrix ``value`` (the argument ``name``, axes ``axes`` in messages)."""
    mat = np.asarray(value, dtype=np.float32)
    if mat.ndim != 2:
        raise ValueError(f"{name} must be 2-D {axes}, got shape {mat.shape}")
    return _frozen(mat)


def _check_nodes(j: int, matrix: torch.Tensor, layer: str, nodes: str) -> None:
    """An input ``(B, N, J, C)`` with ``J = j`` must have the nodes the ``(J_out, J)`` matrix maps from."""
    if j != matrix.shape[1]:
        raise ValueError(f"{layer} expects {matrix.shape[1]} {nodes} on axis 2, got {j}")


def adjacency_with_self_loops(edges, num_nodes: int) -> np.ndarray:
    """``(J, J)`` float 0/1 adjacency of undirected ``edges`` plus the identity (self loops).

    Parameters
    ----------
    edges : iterable of (int, int)
        Undirected edges, e.g. ``Skeleton.level_edges[level]``.
    num_nodes : int
        Number of graph nodes ``J``.
    """
    if num_nodes < 1:
        raise ValueError(f"num_nodes must be >= 1, got {num_nodes}")
    adj = np.eye(num_nodes, dtype=np.float32)
    for a, b in edges:
        if not (0 <= a < num_nodes and 0 <= b < num_nodes):
            raise ValueError(f"edge ({a}, {b}) is out of range for a graph of {num_nodes} nodes")
        adj[a, b] = adj[b, a] = 1.0
    return adj


class MultiLinear(nn.Module):
    """A separate linear map per joint (or body part): ``y_p = x_p W_p + b_p``.

    Used for the per-part latent head (``dist``, 7 experts 32 -> 64).

    Parameters
    ----------
    num_experts : int
        Number of joints/parts ``P``, each with its own weights.
    in_features, out_features : int
        Channel sizes.

    Shapes
    ------
    ``x (..., P, in_features) -> (..., P, out_features)``; weight ``(P, in, out)``, bias ``(P, out)``.
    """

    def __init__(self, num_experts: int, in_features: int, out_features: int) -> None:
        super().__init__()
        for arg, val in (("num_experts", num_experts), ("in_features", in_features), ("out_features", out_features)):
            if val < 1:
                raise ValueError(f"MultiLinear {arg} must be >= 1, got {val}")
        self.num_experts = num_experts
        self.in_features = in_features
        self.out_features = out_features
        self.weight = nn.Parameter(torch.empty(num_experts, in_features, out_features))
        self.bias = nn.Parameter(torch.empty(num_experts, out_features))
        self.reset_parameters()

    def reset_parameters(self) -> None:
        # the same U(-1/sqrt(in), 1/sqrt(in)) range as nn.Linear's default, per expert
        bound = 1.0 / math.sqrt(self.in_features)
        nn.init.uniform_(self.weight, -bound, bound)
        nn.init.uniform_(self.bias, -bound, bound)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if x.shape[-2:] != (self.num_experts, self.in_features):
            raise ValueError(
                f"MultiLinear expects x (..., {self.num_experts}, {self.in_features}), got {tuple(x.shape)}"
            )
        return torch.einsum("...pi,pio->...po", x, self.weight) + self.bias

    def extra_repr(self) -> str:
        return f"num_experts={self.num_experts}, in_features={self.in_features}, out_features={self.out_features}"


class GraphConv(nn.Module):
    """Skeletal graph convolution with weights shared by all joints (official ``GraphConv``).

    ``out_j = W1 x_j + b1 + mean_{k in N(j) ∪ {j}} (W2 x_k + b2)``

    The supplement (eq. in A.1) writes the mean over ``N(j)`` only; the official code adds self
    loops to the adjacency, so a joint enters twice: through ``linear1`` and inside the mean.
    The normaliser is ``|N(j)| + 1 + 1e-6`` as in the official code.

    The adjacency is passed to :meth:`forward` rather than stored here: in the official
    checkpoints ``adj_matrix`` is a sibling of ``graph_conv`` inside :class:`STConv`
    (``...layers.2.adj_matrix`` next to ``...layers.2.graph_conv.linear1.weight``).

    Parameters
    ----------
    in_channels, out_channels : int
        Channel sizes ``C_in -> C_out``.
    """

    def __init__(self, in_channels: int, out_channels: int) -> None:
        super().__init__()
        self.linear1 = nn.Linear(in_channels, out_channels)
        self.linear2 = nn.Linear(in_channels, out_channels)

    def forward(self, x: torch.Tensor, adj_matrix: torch.Tensor) -> torch.Tensor:
        """Apply the graph convolution.

        Parameters
        ----------
        x : Tensor ``(B, N, J, C_in)``
        adj_matrix : Tensor ``(J, J)``
            0/1 adjacency **including** self loops (see :func:`adjacency_with_self_loops`).

        Returns
        -------
        Tensor ``(B, N, J, C_out)``
        """
        j = adj_matrix.shape[0]
        if x.shape[-2] != j:
            raise ValueError(f"GraphConv: x has {x.shape[-2]} joints on axis -2 but adj_matrix is {tuple(adj_matrix.shape)}")
        norm = adj_matrix / (adj_matrix.sum(dim=1, keepdim=True) + 1e-6)  # (J, J), rows = neighbourhood mean
        # (J, K) x (B, N, K, C) -> (B, N, J, C): mean of W2 x_k + b2 over k in N(j) ∪ {j}
        neighbour_mean = torch.einsum("jk,bnkc->bnjc", norm, self.linear2(x))
        return self.linear1(x) + neighbour_mean


class STConv(nn.Module):
    """Skeleto-temporal convolution, ``STConv(h) = SkelConv(h) + TempConv(h)`` (paper eq. 1).

    ``TempConv`` is one ``Conv1d`` (kernel ``k``, stride 1, padding ``k // 2``) shared by all
    joints. With ``edges=None`` the skeletal term is dropped and the block is a plain temporal
    convolution (used by the one-vector "pose" VAE, whose single node has no graph).

    Parameters
    ----------
    channels : int
        Channel size ``C`` (input and output).
    edges : iterable of (int, int) or None
        Undirected graph edges of this resolution; ``None`` for no skeletal term.
    num_nodes : int
        Number of joints/nodes ``J``.
    kernel_size : int
        Odd temporal kernel size.

    Shapes
    ------
    ``(B, N, J, C) -> (B, N, J, C)``
    """

    def __init__(self, channels: int, edges, num_nodes: int, kernel_size: int = 3) -> None:
        super().__init__()
        if kernel_size < 1 or kernel_size % 2 == 0:
            raise ValueError(f"kernel_size must be a positive odd number (length-preserving), got {kernel_size}")
        self.num_nodes = num_nodes
        if edges is not None:
            self.adj_matrix = _frozen(adjacency_with_self_loops(edges, num_nodes))
            self.graph_conv = GraphConv(channels, channels)
        else:
            self.adj_matrix = None
            self.graph_conv = None
        self.temp_conv = nn.Conv1d(channels, channels, kernel_size, stride=1, padding=kernel_size // 2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        # TempConv(x) + SkelConv(x), computed as one matrix product over channels-last inputs
        # (salad_core.models.vae_kernels.st_conv: the same sum, without the Conv1d layout copies)
        return st_conv(x, self.temp_conv, self.graph_conv, self.adj_matrix)


class ResSTConv(nn.Module):
    """Pre-activation residual block ``x + Dropout(STConv(act(norm(STConv(act(norm(x)))))))``.

    ``layers`` is a ``Sequential`` whose indices match the official checkpoints:
    0 norm, 1 act, 2 STConv, 3 norm, 4 act, 5 STConv, 6 Dropout.

    Shapes
    ------
    ``(B, N, J, C) -> (B, N, J, C)``
    """

    def __init__(self, channels: int, edges, num_nodes: int, kernel_size: int = 3,
                 activation: str = "gelu", norm: str = "none", dropout: float = 0.1) -> None:
        super().__init__()
        self.layers = nn.Sequential(
            get_norm(norm, channels),
            get_activation(activation),
            STConv(channels, edges, num_nodes, kernel_size),
            get_norm(norm, channels),
            get_activation(activation),
            STConv(channels, edges, num_nodes, kernel_size),
            nn.Dropout(dropout),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.layers(x)


class STPool(nn.Module):
    """Skeleto-temporal pooling, ``STPool(h) = TempPool(SkelPool(h))`` (paper eq. 2).

    ``SkelPool`` multiplies by the fixed mean matrix ``skeleton_pool (J_out, J_in)`` (each row
    averages one group of adjacent joints); ``TempPool`` averages non-overlapping pairs of frames
    (``AvgPool1d(kernel=2, stride=2)``; an odd last frame is dropped, as AvgPool1d does).

    Parameters
    ----------
    pool_matrix : array ``(J_out, J_in)``
        e.g. ``Skeleton.pool_matrix(level)``.

    Shapes
    ------
    ``(B, N, J_in, C) -> (B, N // 2, J_out, C)``
    """

    def __init__(self, pool_matrix) -> None:
        super().__init__()
        self.skeleton_pool = _frozen_matrix(pool_matrix, "pool_matrix", "(J_out, J_in)")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, j, c = x.shape
        _check_nodes(j, self.skeleton_pool, "STPool", "joints")
        # (J_out, J_in) x (B, N, J_in, C) -> (B, N, J_out, C)
        x = torch.einsum("oj,bnjc->bnoc", self.skeleton_pool, x)
        half = n // 2
        # (B, 2*half, J_out, C) -> (B, half, 2, J_out, C) -> mean over the frame pair
        return x[:, : 2 * half].reshape(b, half, 2, x.shape[2], c).mean(dim=2)


class STUnpool(nn.Module):
    """Skeleto-temporal unpooling, the inverse pattern of :class:`STPool` (supplement A.1).

    ``skeleton_unpool (J_fine, J_coarse)`` is the binary group membership, **not** normalised:
    a fine joint that belongs to several groups receives the *sum* of their features (as in the
    official code). Time is upsampled ×2 by linear interpolation (``align_corners=False``).

    Parameters
    ----------
    unpool_matrix : array ``(J_fine, J_coarse)``
        e.g. ``Skeleton.unpool_matrix(level)``.

    Shapes
    ------
    ``(B, N', J_coarse, C) -> (B, 2 N', J_fine, C)``
    """

    def __init__(self, unpool_matrix) -> None:
        super().__init__()
        self.skeleton_unpool = _frozen_matrix(unpool_matrix, "unpool_matrix", "(J_fine, J_coarse)")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        b, n, j, c = x.shape
        _check_nodes(j, self.skeleton_unpool, "STUnpool", "nodes")
        # (J_fine, J_coarse) x (B, N', J_coarse, C) -> (B, N', J_fine, C)
        x = torch.einsum("jo,bnoc->bnjc", self.skeleton_unpool, x)
        jf = x.shape[2]
        # (B, N', J, C) -> (B, J, C, N') -> (B, J*C, N'): interpolate along the last (time) axis
        t = x.permute(0, 2, 3, 1).reshape(b, jf * c, n)
        t = F.interpolate(t, scale_factor=2, mode="linear", align_corners=False)
        # (B, J*C, 2N') -> (B, J, C, 2N') -> (B, 2N', J, C)
        return t.reshape(b, jf, c, 2 * n).permute(0, 3, 1, 2)
