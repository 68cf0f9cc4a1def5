"""salad_core.models.gemm: the oneDNN route gives F.linear's values, is taken only where it should
be, and the backend switch validates and restores."""
from __future__ import annotations

import pytest
import torch
import torch.nn.functional as F
from torch import nn
from torch.utils.flop_counter import FlopCounterMode

from salad_core.models import gemm

needs_onednn = pytest.mark.skipif(not gemm.onednn_available(), reason="no oneDNN linear in this torch build")


def _counted_flops(fn) -> int:
    """FLOPs torch's counter sees: aten matmuls are counted, the oneDNN op is not."""
    with FlopCounterMode(display=False) as counter:
        fn()
    return counter.get_total_flops()


@pytest.mark.parametrize("shape", [(100, 48), (2, 7, 9, 48)])
@pytest.mark.parametrize("activation", ["none", "gelu"])
@pytest.mark.parametrize("name", ["onednn", "aten"])
def test_linear_equals_f_linear(shape, activation, name):
    if name == "onednn" and not gemm.onednn_available():
        pytest.skip("no oneDNN linear")
    g = torch.Generator().manual_seed(0)
    x, w, b = torch.randn(*shape, generator=g), torch.randn(40, 48, generator=g) / 7, torch.randn(40, generator=g)
    ref = F.linear(x, w, b)
    ref = F.gelu(ref) if activation == "gelu" else ref
    with torch.inference_mode(), gemm.use_backend(name):
        out = gemm.linear(x, w, b, activation)
        no_bias = gemm.linear(x, w, None)
    assert out.shape == (*shape[:-1], 40)
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(no_bias, F.linear(x, w), rtol=1e-5, atol=1e-5)


@needs_onednn
def test_routing_onednn_only_without_gradients_and_for_enough_rows():
    x, w, b = torch.randn(gemm.MIN_ROWS, 32), torch.randn(16, 32), torch.randn(16)
    flops = 2 * gemm.MIN_ROWS * 32 * 16
    with gemm.use_backend("onednn"):
        with torch.no_grad():
            assert _counted_flops(lambda: gemm.linear(x, w, b)) == 0            # oneDNN: not an aten matmul
            assert _counted_flops(lambda: gemm.linear(x[:-1], w, b)) == flops * (gemm.MIN_ROWS - 1) // gemm.MIN_ROWS
            assert _counted_flops(lambda: gemm.linear(x.double(), w.double(), b.double())) == flops  # float64: aten
        with gemm.use_backend("aten"), torch.no_grad():
            assert _counted_flops(lambda: gemm.linear(x, w, b)) == flops
        # training: a weight that needs its gradient keeps autograd's F.linear
        wg = w.clone().requires_grad_()
        out = gemm.linear(x, wg, b, "gelu")
        out.sum().backward()
        wr = w.clone().requires_grad_()
        F.gelu(F.linear(x, wr, b)).sum().backward()
        torch.testing.assert_close(wg.grad, wr.grad)


def test_linear_module_keeps_nn_linear_parameters_and_state_dict():
    torch.manual_seed(0)
    ours, plain = gemm.Linear(12, 5), nn.Linear(12, 5)
    assert list(ours.state_dict()) == list(plain.state_dict()) == ["weight", "bias"]
    plain.load_state_dict(ours.state_dict())
    x = torch.randn(3, 70, 12)
    with torch.inference_mode():
        torch.testing.assert_close(ours(x), plain(x), rtol=1e-5, atol=1e-5)


def test_backend_switch_validates_and_restores(monkeypatch):
    before = gemm.backend()
    with pytest.raises(ValueError, match="backend must be one of"):
        gemm.set_backend("mkl")
    with gemm.use_backend("aten"):
        assert gemm.backend() == "aten"
    assert gemm.backend() == before
    with pytest.raises(ValueError, match="activation must be one of"):
        gemm.linear(torch.randn(2, 3), torch.randn(4, 3), activation="relu")
    monkeypatch.setenv("SALAD_GEMM", "aten")
    assert gemm.backend() == before                  # the environment is read once ...
    gemm.set_backend(None)                           # ... and again after set_backend(None)
    assert gemm.backend() == "aten"
    monkeypatch.setenv("SALAD_GEMM", "fastest")
    gemm.set_backend(None)
    with pytest.raises(ValueError, match="SALAD_GEMM must be one of"):
        gemm.backend()
    monkeypatch.delenv("SALAD_GEMM")
    gemm.set_backend(None)
    assert gemm.backend() == before
