"""salad_core.eval.denoising_error: a denoiser's estimate of the clean latent per timestep."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from salad_core.eval.batches import RealBatch
from salad_core.eval.denoising_error import denoising_error, paired_difference, x0_estimate
from salad_core.sampling import DiffusionConfig, make_scheduler, training_target

PIPE_SEED = 3


@pytest.mark.parametrize("kind", ["sample", "epsilon", "v_prediction"])
def test_x0_estimate_inverts_each_training_target(kind):
    """Given the exact target of x_t = add_noise(x0, eps, t), the estimate is x0 again, at every t."""
    scheduler = make_scheduler(DiffusionConfig(prediction_type=kind), "ddim")
    g = torch.Generator().manual_seed(0)
    x0, eps = torch.randn(5, 6, 7, 4, generator=g), torch.randn(5, 6, 7, 4, generator=g)
    t = torch.tensor([0, 10, 400, 900, 999])
    x_t = scheduler.add_noise(x0, eps, t)
    target = training_target(scheduler, x0, eps, t, kind)
    est = x0_estimate(target, x_t, scheduler.alphas_cumprod[t], kind)
    torch.testing.assert_close(est, x0, atol=2e-3 if kind == "epsilon" else 1e-5, rtol=1e-4)
    with pytest.raises(ValueError, match="prediction_type 'x'"):
        x0_estimate(target, x_t, scheduler.alphas_cumprod[t], "x")


def _batches(sample_features, lengths=((40, 64), (48,))) -> list[RealBatch]:
    out = []
    for i, group in enumerate(lengths):
        motions = np.zeros((len(group), max(group), sample_features.shape[1]), np.float32)
        for j, n in enumerate(group):
            motions[j, :n] = sample_features[8 * j: 8 * j + n]
        out.append(RealBatch([f"a person walks forward {i}{j}" for j in range(len(group))], [[]] * len(group),
                             np.asarray(group), motions, [f"clip{i}{j}" for j in range(len(group))]))
    return out


def test_a_denoiser_that_predicts_no_noise_errs_by_the_noise_it_leaves(pipe, sample_features, monkeypatch):
    """An epsilon denoiser that always answers 0 estimates x0 = x_t / sqrt(a): its latent error is (1 - a) / a
    times the noise's mean square, close to (1 - a) / a; with CFG the answer is 0 too, so guided == cond."""
    monkeypatch.setattr(pipe, "diffusion", DiffusionConfig(prediction_type="epsilon"))
    monkeypatch.setattr(pipe.denoiser, "forward", lambda x, *a, **k: torch.zeros_like(x))
    batches = _batches(sample_features)
    r = denoising_error(pipe, batches, timesteps=(0, 500, 999), guidance_scale=7.5, decode=False)
    alphas = make_scheduler(pipe.diffusion, "ddim").alphas_cumprod
    assert r.clips == ["clip00", "clip01", "clip10"] and r.prediction_type == "epsilon"
    for t in (0, 500, 999):
        a = float(alphas[t])
        got = r.latent["cond"][t]
        assert got.shape == (3,)
        # each clip's noise mean square is near 1 (a few thousand elements)
        np.testing.assert_allclose(got / ((1 - a) / a), 1.0, rtol=0.15)
        np.testing.assert_array_equal(r.latent["guided"][t], got)
    assert r.joints == {}


def test_the_same_denoiser_measured_twice_is_paired_exactly_and_guidance_1_is_the_conditional(pipe, sample_features):
    batches = _batches(sample_features)
    a = denoising_error(pipe, batches, timesteps=(10, 700), guidance_scale=1.0)
    b = denoising_error(pipe, batches, timesteps=(10, 700), guidance_scale=1.0)
    for metric in ("latent", "joints"):
        for t in (10, 700):
            first, second = getattr(a, metric)["cond"][t], getattr(b, metric)["cond"][t]
            np.testing.assert_array_equal(first, second)
            np.testing.assert_allclose(getattr(a, metric)["guided"][t], first, rtol=1e-5, atol=1e-7)
            assert paired_difference(first, second) == (0.0, 0.0)
            assert (first > 0).all()
    # more noise, a worse estimate (a random denoiser cannot beat the signal x_t still carries at t=10)
    assert a.latent["cond"][700].mean() > a.latent["cond"][10].mean()
    # another noise seed is another measurement
    c = denoising_error(pipe, batches, timesteps=(700,), guidance_scale=None, noise_seed=1, decode=False)
    assert not np.array_equal(c.latent["cond"][700], a.latent["cond"][700]) and set(c.latent) == {"cond"}


def test_the_unconditional_mode_is_guidance_at_weight_0(pipe, sample_features):
    """``unconditional=True`` adds the empty prompt's estimate: what guidance at w = 0 gives, and not the caption's
    (the tiny test denoiser still reads its text)."""
    batches = _batches(sample_features)
    r = denoising_error(pipe, batches, timesteps=(300,), guidance_scale=2.0, unconditional=True, decode=False)
    w0 = denoising_error(pipe, batches, timesteps=(300,), guidance_scale=0.0, decode=False)
    assert set(r.latent) == {"cond", "uncond", "guided"}
    np.testing.assert_allclose(r.latent["uncond"][300], w0.latent["guided"][300], rtol=1e-5, atol=1e-8)
    np.testing.assert_array_equal(r.latent["cond"][300], w0.latent["cond"][300])
    assert not np.allclose(r.latent["uncond"][300], r.latent["cond"][300])
    alone = denoising_error(pipe, batches, timesteps=(300,), guidance_scale=None, unconditional=True, decode=False)
    assert set(alone.latent) == {"cond", "uncond"}
    np.testing.assert_allclose(alone.latent["uncond"][300], r.latent["uncond"][300], rtol=1e-5, atol=1e-8)


def test_bad_input_is_refused_with_what_is_wrong(pipe, sample_features):
    batches = _batches(sample_features)
    with pytest.raises(ValueError, match=r"must be in \[0, 1000\)"):
        denoising_error(pipe, batches, timesteps=(1000,), decode=False)
    odd = [dataclasses.replace(batches[1], lengths=np.asarray([46]))]
    with pytest.raises(ValueError, match="multiples of 4"):
        denoising_error(pipe, odd, timesteps=(10,), decode=False)
    with pytest.raises(ValueError, match="two equal 1-d arrays"):
        paired_difference(np.ones(3), np.ones(2))


def test_the_fid_of_a_one_step_estimate_is_the_clean_latents_at_t0_and_grows_with_the_noise(sample_features,
                                                                                           monkeypatch):
    """With the zero-noise epsilon denoiser, x0_hat = x0 + sqrt((1 - a) / a) eps: at t = 0 (a = 0.99915) almost the
    clean latent, so its FID is that of the decoded clean latents; at t = 999 the estimate is noise blown up.
    (A trained VAE, the shipped ablation study's, so that the decoded clean latents are motions.)"""
    from salad_core.ablation_models import load_ablation_pipeline
    from salad_core.eval.train_evaluator import load_packaged_evaluator

    pipe = load_ablation_pipeline("full")

    monkeypatch.setattr(pipe, "diffusion", DiffusionConfig(prediction_type="epsilon"))
    monkeypatch.setattr(pipe.denoiser, "forward", lambda x, *a, **k: torch.zeros_like(x))
    batches = _batches(sample_features, lengths=((40, 48, 56, 64), (64, 60, 52, 44)))
    evaluator = load_packaged_evaluator()[0]
    r = denoising_error(pipe, batches, timesteps=(0, 999), guidance_scale=None, evaluator=evaluator)
    assert r.fid_clean is not None and r.fid_clean >= 0 and set(r.fid) == {"cond"}
    assert r.fid["cond"][0] == pytest.approx(r.fid_clean, rel=0.1, abs=0.5)
    assert r.fid["cond"][999] > 10 * r.fid_clean + 1
    assert r.means()["fid"]["cond"][0] == r.fid["cond"][0]
    with pytest.raises(ValueError, match="decode=True"):
        denoising_error(pipe, batches, timesteps=(0,), evaluator=evaluator, decode=False)


