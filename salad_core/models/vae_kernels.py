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

The product has its own backward (:class:`_STConvProduct`): autograd's backward of the stacked form
(pad, ``k`` slices, ``cat``) built a zero-filled gradient of the padded input per tap and summed them;
here the input gradient is one product ``g @ W`` read back as shifted slices, and the stacked input is
written once (no padded copy), in the compute dtype. Under ``torch.autocast`` (``TrainConfig.autocast``)
that dtype is bfloat16: the stacked input, the products and the result are bf16 (as ``nn.Linear``'s
would be), the weight and bias gradients come back in the parameters' dtype.

Measured (``bench/bench_vae_step.py``, batch 64 x 40 frames, one thread, forward + backward + AdamW,
the forms interleaved in one process, on a loaded machine): the one product against ``Conv1d`` + graph
convolution 863 -> 768 and 814 -> 763 ms per step (1.12x, 1.07x; v2 config); the hand-written backward
against autograd's: 4090 -> 3607, 5089 -> 4944 ms (default config) and 9762 -> 9306 ms (v2) at load
8-15 (1.03-1.13x); the same under bf16 autocast: 2238, 3169 and 6115 ms (1.60-1.83x against autograd's
fp32 form; docs/performance.md).
Tried and not kept: the 22 per-joint input/output MLPs as two batched products over a joint axis
(exact, but no faster: 791 ms), and ``torch.compile`` of the whole objective (1.08x more, after a
98 s compilation).
"""
from __future__ import annotations

import torch
from torch import nn

__all__ = ["st_conv", "st_conv_product"]


def _compute_dtype(x: torch.Tensor) -> torch.dtype:
    """The dtype of the products: the CPU autocast dtype when autocast is on, else ``x.dtype``."""
    if x.device.type == "cpu" and torch.is_autocast_enabled("cpu"):
        return torch.get_autocast_dtype("cpu")
    if x.device.type == "cuda" and torch.is_autocast_enabled("cuda"):
        return torch.get_autocast_dtype("cuda")
    return x.dtype


def _shifted_copy(dst: torch.Tensor, x: torch.Tensor, shift: int) -> None:
    """``dst[:, t] = x[:, t + shift]`` where ``0 <= t + shift < N``, zeros elsewhere (``(B, N, ...)``)."""
    n = x.shape[1]
    if shift == 0:
        dst.copy_(x)
    elif abs(shift) >= n:
        dst.zero_()
    elif shift > 0:
        dst[:, : n - shift].copy_(x[:, shift:])
        dst[:, n - shift:].zero_()
    else:
        dst[:, -shift:].copy_(x[:, : n + shift])
        dst[:, :-shift].zero_()


class _STConvProduct(torch.autograd.Function):
    """``out = [x[t-p], ..., x[t+p], (A x)[t]] @ W^T + bias`` with a hand-written backward.

    Autograd's own backward of the stacked-input form (pad, k slices, ``cat``) builds a zero-filled
    gradient of the padded input per tap and adds them up; here the input gradient is one product
    ``g @ W`` read back as shifted slices, and the stacked input is written once, in the compute
    dtype, without the padded copy.
    """

    @staticmethod
    def forward(ctx, x, weight, bias, norm, kernel_size: int, dtype: torch.dtype):  # noqa: ANN001
        b, n, j, c = x.shape
        k, pad = kernel_size, kernel_size // 2
        slots = k + (norm is not None)
        with torch.autocast(x.device.type, enabled=False):
            stacked = torch.empty((b, n, j, slots * c), dtype=dtype, device=x.device)
            for i in range(k):
                _shifted_copy(stacked[..., i * c: (i + 1) * c], x, i - pad)
            if norm is not None:
                stacked[..., k * c:].copy_(torch.matmul(norm.to(x.dtype), x))   # neighbourhood means
            w = weight.to(dtype)
            out = torch.matmul(stacked.view(-1, slots * c), w.t()).view(b, n, j, -1)
            # under autocast the result stays in the lower precision, as nn.Linear's does: the GELU and
            # dropout after it then run in bf16 too (the residual sum promotes back to float32)
            out = out.add_(bias.to(dtype))
        ctx.save_for_backward(stacked, w, norm)
        ctx.kernel_size, ctx.x_dtype, ctx.w_dtype = k, x.dtype, weight.dtype
        ctx.bias_shape, ctx.b_dtype = bias.shape, bias.dtype
        return out

    @staticmethod
    def backward(ctx, grad):  # noqa: ANN001
        stacked, w, norm = ctx.saved_tensors
        k, pad = ctx.kernel_size, ctx.kernel_size // 2
        b, n, j, width = stacked.shape
        c = width // (k + (norm is not None))
        grad = grad.contiguous()
        g2 = grad.view(-1, grad.shape[-1])
        gc = g2.to(stacked.dtype)
        grad_x = grad_w = grad_b = None
        with torch.autocast(grad.device.type, enabled=False):
            if ctx.needs_input_grad[1]:
                grad_w = torch.matmul(gc.t(), stacked.view(-1, width)).to(ctx.w_dtype)     # (C_out, slots C)
            if ctx.needs_input_grad[2]:
                acc = torch.promote_types(grad.dtype, torch.float32)            # bf16 gradients summed in fp32
                grad_b = grad.sum(dim=(0, 1), dtype=acc).sum_to_size(ctx.bias_shape).to(ctx.b_dtype)  # (J, C_out)
            if ctx.needs_input_grad[0]:
                gs = torch.matmul(gc, w).view(b, n, j, width)                   # d loss / d stacked
                grad_x = torch.empty((b, n, j, c), dtype=ctx.x_dtype, device=grad.device)
                grad_x.copy_(gs[..., pad * c: (pad + 1) * c])
                for i in range(k):
                    s = i - pad                    # tap i reads x[t + s]: x[u] gets the tap's gradient at u - s
                    if s == 0 or abs(s) >= n:
                        continue
                    tap = gs[..., i * c: (i + 1) * c]
                    if s > 0:
                        grad_x[:, s:].add_(tap[:, : n - s])
                    else:
                        grad_x[:, : n + s].add_(tap[:, -s:])
                if norm is not None:
                    grad_x.add_(torch.matmul(norm.t().to(gs.dtype), gs[..., k * c:]))
        return grad_x, grad_w, grad_b, None, None, None


def st_conv_product(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor, norm: torch.Tensor | None,
                    kernel_size: int) -> torch.Tensor:
    """The stacked product of :func:`st_conv` with its hand-written backward.

    Parameters
    ----------
    x : Tensor ``(B, N, J, C)``
    weight : Tensor ``(C_out, S C)``
        ``S = kernel_size`` temporal taps (oldest first), plus one slot for the neighbourhood means
        when ``norm`` is given.
    bias : Tensor ``(J, C_out)`` or ``(C_out,)``
    norm : Tensor ``(J, J)`` or None
        Row-normalised adjacency.
    kernel_size : int
        Odd number of temporal taps.

    Returns
    -------
    Tensor ``(B, N, J, C_out)``: in the autocast dtype when CPU (or CUDA) autocast is on (the products
    run in it, as ``nn.Linear``'s do), else in ``x.dtype``.
    """
    if x.ndim != 4:
        raise ValueError(f"x must be (B, N, J, C), got shape {tuple(x.shape)}")
    if kernel_size < 1 or kernel_size % 2 == 0:
        raise ValueError(f"kernel_size must be a positive odd number, got {kernel_size}")
    slots = kernel_size + (norm is not None)
    if weight.ndim != 2 or weight.shape[1] != slots * x.shape[-1]:
        raise ValueError(f"weight must be (C_out, {slots} x C = {slots * x.shape[-1]}) for kernel_size={kernel_size}"
                         f"{' and a graph' if norm is not None else ''}, got shape {tuple(weight.shape)}")
    return _STConvProduct.apply(x.contiguous(), weight, bias, norm, kernel_size, _compute_dtype(x))


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
    w_t = temp_conv.weight                                   # (C_out, C_in, k)
    k = w_t.shape[-1]
    pad = k // 2
    weights = [w_t[:, :, i] for i in range(k)]               # k x (C_out, C_in): tap i reads h[t + i - k//2]
    bias = temp_conv.bias
    norm = None
    if graph_conv is not None:
        norm = adj_matrix / (adj_matrix.sum(dim=1, keepdim=True) + 1e-6)      # (J, J), as GraphConv
        weights[pad] = weights[pad] + graph_conv.linear1.weight
        weights.append(graph_conv.linear2.weight)            # applied to the neighbourhood means
        # b_t + b_1 + b_2 * rowsum(norm): a bias per joint, (J, C_out)
        bias = (bias + graph_conv.linear1.bias)[None, :] + norm.sum(dim=1)[:, None] * graph_conv.linear2.bias[None, :]
    return st_conv_product(x, torch.cat(weights, dim=1), bias, norm, k)
