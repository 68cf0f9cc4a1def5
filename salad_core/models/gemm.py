"""Dense layers on the fastest CPU matrix-multiply library PyTorch ships: oneDNN when it helps.

PyTorch's CPU ``F.linear`` for float32 calls MKL's ``sgemm``. MKL picks its kernels by CPU vendor,
and on AMD processors it stays on a path that reaches about half of what the cores can do: on the
2-core AMD EPYC (AVX-512) this project is developed on, MKL ran the denoiser's GEMM shapes
(686 x 256 x 256, 686 x 256 x 1024, 686 x 1024 x 256) at 188-195 GFLOP/s, oneDNN (MKL-DNN, bundled
with every PyTorch CPU build, dispatched by instruction set rather than vendor) at 356-397 GFLOP/s,
on one thread 90 against 190. ``salad bench`` measures both on the machine at hand.

:func:`linear` routes inference-time products (gradients disabled, float32 CPU tensors, at least
:data:`MIN_ROWS` rows) through ``torch.ops.mkldnn._linear_pointwise``, optionally with the GELU
fused into the same call; everything else, and all training, goes through ``F.linear``. Both give
the same values up to float rounding (the probe below checks this before the fast route is used).
:class:`Linear` is ``nn.Linear`` with that forward: same parameters, same state-dict keys.

The route is chosen by the environment variable ``SALAD_GEMM`` (``auto``, the default: oneDNN if
the probe passes; ``aten``: always ``F.linear``) or at run time with :func:`set_backend` /
:func:`use_backend`.
"""
from __future__ import annotations

import logging
import os
from contextlib import contextmanager
from typing import Iterator

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["BACKENDS", "MIN_ROWS", "Linear", "linear", "backend", "set_backend", "use_backend", "onednn_available"]

log = logging.getLogger(__name__)

#: Accepted backend names: ``auto`` (oneDNN when available, else aten), ``onednn``, ``aten``.
BACKENDS: tuple[str, ...] = ("auto", "onednn", "aten")

#: Products with fewer rows (e.g. the FiLM projections of a 2-row timestep embedding) stay on
#: ``F.linear``: oneDNN's per-call set-up costs more than the multiply there (28 vs 20 us).
MIN_ROWS = 64

_ACTIVATIONS = ("none", "gelu")
# torch.compiler.is_compiling exists from torch 2.3 on (the package allows 2.1)
_is_compiling = getattr(getattr(torch, "compiler", None), "is_compiling", None) or (lambda: False)
_state: dict[str, object] = {"backend": None, "probe": None, "resolved": None}


def _probe() -> tuple[bool, str]:
    """Whether ``torch.ops.mkldnn._linear_pointwise`` exists, runs, and agrees with ``F.linear``."""
    try:
        if not torch.backends.mkldnn.is_available():
            return False, "this PyTorch build has no oneDNN (MKL-DNN)"
        op = torch.ops.mkldnn._linear_pointwise
        g = torch.Generator().manual_seed(0)
        x = torch.randn(2, MIN_ROWS, 48, generator=g)
        w = torch.randn(40, 48, generator=g) / 7.0
        b = torch.randn(40, generator=g)
        with torch.no_grad():
            for act, ref in (("none", F.linear(x, w, b)), ("gelu", F.gelu(F.linear(x, w, b)))):
                out = op(x, w, b, act, [], "none" if act == "gelu" else "")
                if out.shape != ref.shape or not torch.allclose(out, ref, rtol=1e-4, atol=1e-4):
                    return False, f"oneDNN linear ({act}) disagrees with F.linear"
    except Exception as exc:  # missing op, unsupported CPU, ...: fall back cleanly
        return False, f"oneDNN linear unavailable: {type(exc).__name__}: {exc}"
    return True, "ok"


def onednn_available() -> bool:
    """True if the oneDNN route exists on this build and passed the agreement probe (cached)."""
    if _state["probe"] is None:
        ok, why = _probe()
        _state["probe"] = ok
        if not ok:
            log.info("salad: dense layers use F.linear (%s)", why)
    return bool(_state["probe"])


def backend() -> str:
    """The route in effect: ``"onednn"`` or ``"aten"`` (resolving ``auto`` and ``SALAD_GEMM``).

    The answer is kept until :func:`set_backend` / :func:`use_backend` change the choice (every dense
    layer asks, and reading ``os.environ`` each time cost about 0.5 ms per paper-model forward), so
    ``SALAD_GEMM`` is read at the first use and again after ``set_backend(None)``.
    """
    resolved = _state["resolved"]
    if resolved is None:
        resolved = _state["resolved"] = _resolve()
    return resolved


def _resolve() -> str:
    name = _state["backend"]
    if name is None:
        name = os.environ.get("SALAD_GEMM", "auto").strip().lower() or "auto"
        if name not in BACKENDS:
            raise ValueError(f"SALAD_GEMM must be one of {BACKENDS}, got {name!r}")
    if name == "aten":
        return "aten"
    if onednn_available():
        return "onednn"
    if name == "onednn":
        raise RuntimeError("SALAD_GEMM=onednn was asked for, but oneDNN linear is not usable here; "
                           "use 'auto' or 'aten'")
    return "aten"


def set_backend(name: str | None) -> None:
    """Choose the route for dense layers (``None`` = back to ``SALAD_GEMM`` / ``auto``)."""
    if name is not None and name not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS} or None, got {name!r}")
    _state["backend"], _state["resolved"] = name, None
    if name == "onednn" and not onednn_available():
        _state["backend"] = None
        raise RuntimeError("oneDNN linear is not usable in this PyTorch build / on this CPU")


@contextmanager
def use_backend(name: str | None) -> Iterator[None]:
    """Use ``name`` for the dense layers inside the block; the previous choice is restored after."""
    previous = _state["backend"]
    set_backend(name)
    try:
        yield
    finally:
        _state["backend"], _state["resolved"] = previous, None


def _fast_ok(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None) -> bool:
    if _is_compiling():                      # torch.compile lowers F.linear itself (inductor rejects the op)
        return False
    if torch.is_grad_enabled() and (x.requires_grad or weight.requires_grad
                                    or (bias is not None and bias.requires_grad)):
        return False
    if x.device.type != "cpu" or x.dtype != torch.float32 or weight.dtype != torch.float32:
        return False
    if bias is not None and bias.dtype != torch.float32:
        return False
    if x.dim() < 2 or x.numel() < MIN_ROWS * x.shape[-1] or not weight.is_contiguous():
        return False
    return backend() == "onednn"


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None = None,
           activation: str = "none") -> torch.Tensor:
    """``activation(x @ weight.T + bias)`` on the fastest route (see module docstring).

    Parameters
    ----------
    x : torch.Tensor
        ``(..., in)``.
    weight : torch.Tensor
        ``(out, in)``.
    bias : torch.Tensor, optional
        ``(out,)``.
    activation : {"none", "gelu"}
        ``"gelu"`` is the exact (erf) GELU of ``nn.GELU()``, fused into the product on oneDNN.

    Returns
    -------
    torch.Tensor
        ``(..., out)``.
    """
    if activation not in _ACTIVATIONS:
        raise ValueError(f"activation must be one of {_ACTIVATIONS}, got {activation!r}")
    if _fast_ok(x, weight, bias):
        if activation == "gelu":
            return torch.ops.mkldnn._linear_pointwise(x, weight, bias, "gelu", [], "none")
        return torch.ops.mkldnn._linear_pointwise(x, weight, bias, "none", [], "")
    out = F.linear(x, weight, bias)
    return F.gelu(out) if activation == "gelu" else out


class Linear(nn.Linear):
    """``nn.Linear`` whose forward uses :func:`linear` (same parameters and state-dict keys)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # noqa: D102 - as nn.Linear
        return linear(x, self.weight, self.bias)
