"""The VAE training step's speed work (issue 19): the skeleto-temporal product with its hand-written
backward (``models.vae_kernels``) and the opt-in bf16 autocast of the trainers (``TrainConfig.autocast``)."""
from __future__ import annotations

import json

import pytest
import torch

from salad_core.models.layers import STConv
from salad_core.models.vae_kernels import st_conv_product
from salad_core.train import VAETrainConfig, train_vae
from salad_core.train.common import autocast_context
from _doubles import make_fake_corpus


def _two_branch(conv: STConv, x: torch.Tensor) -> torch.Tensor:
    """Paper eq. 1 as written: Conv1d over each joint's time series plus the graph convolution."""
    b, n, j, c = x.shape
    t = conv.temp_conv(x.permute(0, 2, 3, 1).reshape(b * j, c, n)).reshape(b, j, c, n).permute(0, 3, 1, 2)
    return t if conv.graph_conv is None else t + conv.graph_conv(x, conv.adj_matrix)


@pytest.mark.parametrize("frames, kernel", [(1, 3), (2, 5), (3, 5)])
def test_own_backward_handles_clips_shorter_than_the_kernel(frames, kernel):
    # taps that fall wholly outside the clip (|shift| >= N) are zero in value and gradient
    torch.manual_seed(1)
    conv = STConv(4, [(0, 1), (1, 2)], 3, kernel_size=kernel).double()
    x = torch.randn(2, frames, 3, 4, dtype=torch.float64, requires_grad=True)
    out, ref = conv(x), _two_branch(conv, x)
    torch.testing.assert_close(out, ref, rtol=1e-12, atol=1e-12)
    params = [x] + [p for p in conv.parameters() if p.requires_grad]
    w = torch.randn_like(out)
    for g, r in zip(torch.autograd.grad((out * w).sum(), params), torch.autograd.grad((ref * w).sum(), params)):
        torch.testing.assert_close(g, r, rtol=1e-10, atol=1e-12)


def test_own_backward_passes_gradcheck_on_a_non_contiguous_input():
    # the decoder feeds STConv the permuted output of STUnpool: strides must not matter
    torch.manual_seed(2)
    conv = STConv(3, [(0, 1), (1, 2), (2, 3)], 4, kernel_size=3).double()
    base = torch.randn(2, 4, 3, 5, dtype=torch.float64, requires_grad=True)   # (B, J, C, N)

    def f(b: torch.Tensor) -> torch.Tensor:
        x = b.permute(0, 3, 1, 2)                                # (B, N, J, C), not contiguous
        assert not x.is_contiguous()
        return conv(x)

    assert torch.autograd.gradcheck(f, (base,))


def test_product_bias_gradient_sums_over_batch_and_frames():
    # d/d bias of sum(out) is the count of (batch, frame) rows: per joint with a (J, C) bias, summed over
    # joints too with a (C,) bias
    x = torch.randn(3, 5, 2, 4)
    weight = torch.randn(6, 3 * 4)
    for shape, expect in (((2, 6), 15.0), ((6,), 30.0)):
        bias = torch.zeros(shape, requires_grad=True)
        st_conv_product(x, weight, bias, None, 3).sum().backward()
        assert bias.grad.shape == shape
        torch.testing.assert_close(bias.grad, torch.full(shape, expect))


def test_autocast_runs_the_product_in_bf16_with_float32_gradients():
    torch.manual_seed(3)
    conv = STConv(16, [(0, 1), (1, 2)], 3, kernel_size=3)
    x = torch.randn(4, 8, 3, 16, requires_grad=True)
    ref = conv(x)
    (g_ref,) = torch.autograd.grad(ref.square().sum(), x)
    with torch.autocast("cpu", dtype=torch.bfloat16):
        out = conv(x)
    assert out.dtype == torch.bfloat16                      # like nn.Linear under autocast
    (g,) = torch.autograd.grad(out.float().square().sum(), x)
    assert g.dtype == torch.float32
    # bf16 keeps 8 bits of mantissa: about 2-3 significant digits, not more
    rel = (out.float() - ref).norm() / ref.norm()
    grel = (g - g_ref).norm() / g_ref.norm()
    assert 0 < rel < 1e-2 and 0 < grel < 2e-2, (float(rel), float(grel))


def test_autocast_option_is_validated_and_opt_in():
    assert VAETrainConfig().autocast is None
    assert VAETrainConfig(autocast="bf16").autocast == "bf16"
    with pytest.raises(ValueError, match="autocast"):
        VAETrainConfig(autocast="fp16")
    with autocast_context(VAETrainConfig(autocast="bf16"), "cpu"):
        assert torch.is_autocast_enabled("cpu")
        assert torch.get_autocast_dtype("cpu") == torch.bfloat16
    with autocast_context(VAETrainConfig(), "cpu"):
        assert not torch.is_autocast_enabled("cpu")


def test_native_bf16_cpu_reads_the_cpu_flags(tmp_path):
    from salad_core.train.common import native_bf16_cpu

    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu sse2 avx2 avx512f avx512bw\n\nprocessor\t: 1\n"
                    "flags\t\t: fpu sse2 avx2 avx512f avx512bw\n")
    assert native_bf16_cpu(info) is False                       # avx512f alone: bf16 is emulated
    info.write_text("flags\t\t: fpu avx512f avx512_bf16 avx512_vnni\n")
    assert native_bf16_cpu(info) is True
    info.write_text("flags\t\t: fpu amx_tile amx_bf16\n")
    assert native_bf16_cpu(info) is True
    info.write_text("model name\t: some CPU\n")                 # no flags line: unknown
    assert native_bf16_cpu(info) is None
    assert native_bf16_cpu(tmp_path / "missing") is None


def test_bf16_vae_training_follows_the_float32_run(tmp_path):
    from salad_core.models.vae import VAEConfig

    corpus = make_fake_corpus(tmp_path / "corpus")
    model = VAEConfig(latent_dim=8, n_extra_layers=0, dropout=0.0)
    base = dict(batch_size=8, max_steps=12, lr=3e-3, warmup_steps=0, milestones=(), window=64, val_every=0,
                ckpt_every=0, log_every=1, num_threads=1, progress=False, seed=5)
    curves = {}
    for mode in (None, "bf16"):
        out = tmp_path / str(mode)
        train_vae(corpus, out, model, VAETrainConfig(**base, autocast=mode))
        curves[mode] = [json.loads(l)["loss"] for l in (out / "log.jsonl").read_text().splitlines()]
        runtime = json.loads((out / "config.json").read_text())["runtime"]
        assert runtime["autocast"] == mode                 # the run records its numerics
    f32, b16 = torch.tensor(curves[None]), torch.tensor(curves["bf16"])
    assert not torch.equal(f32, b16)                         # the option did change the arithmetic
    assert b16[-1] < 0.9 * b16[0]                            # and it still learns
    torch.testing.assert_close(b16, f32, rtol=3e-2, atol=0.0)  # step for step within bf16 rounding


def test_denoiser_trains_and_validates_under_bf16_autocast(tmp_path):
    # the option lives on TrainConfig: the denoiser (measured for speed: no) must at least run with it
    from salad_core.models.denoiser import DenoiserConfig
    from salad_core.models.vae import VAEConfig
    from salad_core.train import DenoiserTrainConfig, train_denoiser
    from _doubles import HashTextEncoder

    corpus = make_fake_corpus(tmp_path / "corpus")
    vae_run = tmp_path / "vae"
    train_vae(corpus, vae_run, VAEConfig(latent_dim=8, n_extra_layers=0),
              VAETrainConfig(batch_size=8, max_steps=0, window=64, val_every=0, ckpt_every=0, num_threads=1,
                             progress=False))
    cfg = DenoiserTrainConfig(batch_size=4, max_steps=3, lr=2e-3, warmup_steps=1, max_length=72, val_every=3,
                              ckpt_every=0, log_every=1, num_threads=1, progress=False, seed=11, autocast="bf16")
    res = train_denoiser(corpus, tmp_path / "den", vae_run,
                         DenoiserConfig(latent_dim=8, width=16, heads=2, ff_dim=32, layers=1, text_dim=16), cfg,
                         HashTextEncoder())
    rows = [json.loads(l) for l in (tmp_path / "den" / "log.jsonl").read_text().splitlines()]
    assert res.step == 3 and res.best_val is not None and torch.isfinite(torch.tensor(res.best_val))
    assert all(torch.isfinite(torch.tensor(r["loss"])) for r in rows if "loss" in r)


def test_product_rejects_a_weight_of_the_wrong_width():
    with pytest.raises(ValueError, match="weight must be"):
        st_conv_product(torch.randn(1, 4, 2, 3), torch.randn(5, 9), torch.zeros(5), torch.eye(2), 3)  # needs 12
    with pytest.raises(ValueError, match="kernel_size"):
        st_conv_product(torch.randn(1, 4, 2, 3), torch.randn(5, 6), torch.zeros(5), None, 2)
