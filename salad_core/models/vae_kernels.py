"""The skeleto-temporal convolution as one matrix product (the training and inference kernel of
:class:`~salad_core.models.layers.STConv`).

``STConv(h) = TempConv(h) + SkelConv(h)`` (paper eq. 1) with, per joint ``j`` and frame ``t``,

* ``TempConv(h)[t, j] = sum_i W_t[:, :, i] h[t + i - k//2, j] + b_t`` (a ``Conv1d`` shared by all joints,
  zero padding at the clip's ends), and
* ``SkelConv(h)[t, j] = W_1 h[t, j] + b_1 + sum_k A[j, k] (W_2 h[t, k] + b_2)``
  (:class:`~salad_core.models.layers.GraphConv`, ``A`` the row-normalised adjacency with self loops).

Both are linear in ``h``, so the sum is one product of the stacked inputs
``[h[t-1], h[t], h[t+1], (A h)[t]]`` (``(k + 1) C`` channels per joint and frame) with the stacked
weights ``[W_t[..., 0], W_t[..., 1] + W_1, W_t[..., 2], W_2]``, plus a per-joint bias
``b_t + b_1 + b_2 * rowsum(A)``. The weights are assembled from the module's own parameters at
every call (cheap: ``C x (k + 1) C``), so checkpoints keep the official layout and gradients flow to
the original parameters. In the layout the model already uses, ``(B, N, J, C)`` channels-last, the
product needs no transposes, where ``Conv1d`` needs ``(B J, C, N)`` and two layout copies each way;
on this project's 2-core CPU machines ``Conv1d``'s backward and those copies were the largest items
of the VAE's training step. The result equals the two-branch form up to float rounding
(``tests/test_vae.py``).

Measured (``bench/bench_vae_step.py``, v2 VAE config, batch 64 x 40 frames, one thread, forward +
backward + AdamW, the two forms interleaved in one process, on a loaded machine): 863 -> 768 and
814 -> 763 ms per step in two runs (1.12x, 1.07x).
Tried and not kept: the 22 per-joint input/output MLPs as two batched products over a joint axis
(exact, but no faster: 791 ms), and ``torch.compile`` of the whole objective (1.08x more, after a
98 s compilation).
"""
from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["st_conv"]


def st_conv(x: torch.Tensor, temp_conv: nn.Conv1d, graph_conv: nn.Module | None,
            adj_matrix: torch.Tensor | None) -> torch.Tensor:
    """``TempConv(x) + SkelConv(x)`` as one matrix product.

    Parameters
    ----------
    x : Tensor ``(B, N, J, C)``
        Hidden states: batch, frames, joints, channels.
    temp_conv : nn.Conv1d
        ``C -> C``, odd kernel ``k``, stride 1, padding ``k // 2``.
    graph_conv : GraphConv or None
        Its ``linear1`` and ``linear2`` (``C -> C``); ``None``: no skeletal term.
    adj_matrix : Tensor ``(J, J)`` or None
        0/1 adjacency with self loops (normalised here as :class:`GraphConv` does).

    Returns
    -------
    Tensor ``(B, N, J, C)``
    """
    b, n, j, c = x.shape
    w_t = temp_conv.weight                                   # (C_out, C_in, k)
    k = w_t.shape[-1]
    pad = k // 2
    xp = F.pad(x, (0, 0, 0, 0, pad, pad))                    # zeros before and after the clip on N
    taps = [xp[:, i: i + n] for i in range(k)]               # k x (B, N, J, C): h[t + i - k//2]
    weights = [w_t[:, :, i] for i in range(k)]               # k x (C_out, C_in)
    bias = temp_conv.bias
    if graph_conv is not None:
        norm = adj_matrix / (adj_matrix.sum(dim=1, keepdim=True) + 1e-6)      # (J, J), as GraphConv
        taps.append(torch.matmul(norm, x))                   # (B, N, J, C): neighbourhood means
        weights[pad] = weights[pad] + graph_conv.linear1.weight
        weights.append(graph_conv.linear2.weight)
        # b_t + b_1 + b_2 * rowsum(norm): a bias per joint, (J, C_out)
        bias = (bias + graph_conv.linear1.bias)[None, :] + norm.sum(dim=1)[:, None] * graph_conv.linear2.bias[None, :]
    stacked = torch.cat(taps, dim=-1)                        # (B, N, J, (k [+1]) C)
    out = stacked @ torch.cat(weights, dim=1).t()            # (B, N, J, C_out)
    return out + bias

