"""Latent normalisation for KeyMotion's PST (issue 22): statistics, training inputs, sampling, checkpoints."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig, gather_keyframes, indices_to_positions
from salad_core.keymotion.pst import PST_DIFFUSION, ParallelSkipTransformer, PSTConfig, sample_latents
from salad_core.keymotion.train import KeyMotionTrainConfig, kf_latent_stats, kf_vae_latent_cache, prepare_pst_batch
from salad_core.sampling import make_scheduler
from salad_core.train.common import StepContext
from salad_core.train.distributed import DistEnv, GlobalBatchRandom
from _doubles import make_fake_corpus

TEXT_DIM = 16
pytestmark = pytest.mark.usefixtures("single_thread")


def tiny_pst(**kw) -> ParallelSkipTransformer:
    base = dict(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4, ff_dim=64,
                num_cond_layers=1, num_cross_layers=2, dropout=0.0, max_length=96)
    base.update(kw)
    return ParallelSkipTransformer(PSTConfig(**base)).eval()


@pytest.fixture(scope="module")
def keyframe_sets(tmp_path_factory):
    from salad_core.data.dataset import MotionTextDataset
    from salad_core.keymotion.train import KeyframeDataset

    root = make_fake_corpus(tmp_path_factory.mktemp("pst_norm"), n_train=6, n_val=2, lengths=(44, 90))
    train = MotionTextDataset(root, "train", max_length=96, random_crop=True, seed=0)
    val = MotionTextDataset(root, "val", max_length=96, mean=train.mean, std=train.std, random_crop=False)
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, max_length=96, frame_dim=32, latent_dim=16, num_layers=1,
                                        ff_dim=64, dropout=0.0)).eval()
    vae.set_normalization(train.mean, train.std)
    return KeyframeDataset(train, 8, "uniform"), KeyframeDataset(val, 8, "uniform"), vae


def test_normalisation_round_trips_is_saved_and_checks_its_statistics():
    pst = tiny_pst(latent_norm=True)
    assert {"latent_mean", "latent_std"} <= set(pst.state_dict())                 # saved with the weights
    z = torch.randn(3, 2, 16)
    assert torch.equal(pst.normalize_latents(z), z)                               # identity until set
    mean, std = torch.randn(2, 16), torch.rand(2, 16) + 0.5
    pst.set_latent_stats(mean, std)
    torch.testing.assert_close(pst.normalize_latents(z), (z - mean) / std)
    torch.testing.assert_close(pst.denormalize_latents(pst.normalize_latents(z)), z)
    with pytest.raises(ValueError, match="must be \\(2, 16\\)"):
        pst.set_latent_stats(torch.zeros(16), torch.ones(16))
    with pytest.raises(ValueError, match="> 0"):
        pst.set_latent_stats(mean, torch.zeros(2, 16))
    plain = tiny_pst()
    assert "latent_mean" not in plain.state_dict() and torch.equal(plain.denormalize_latents(z), z)
    with pytest.raises(ValueError, match="latent_norm=False"):
        plain.set_latent_stats(mean, std)


def test_sample_latents_returns_the_vae_space():
    """The same network with and without normalisation: the normalised PST's samples are the plain one's
    ``* std + mean`` (it diffuses in the normalised space and maps back at the end)."""
    torch.manual_seed(1)
    plain = tiny_pst()
    normed = tiny_pst(latent_norm=True)
    missing, unexpected = normed.load_state_dict(plain.state_dict(), strict=False)
    assert sorted(missing) == ["latent_mean", "latent_std"] and not unexpected
    mean, std = torch.randn(2, 16), torch.rand(2, 16) + 0.5
    normed.set_latent_stats(mean, std)
    text, mask = torch.randn(2, 3, TEXT_DIM), torch.ones(2, 3, dtype=torch.bool)
    noise, lengths = torch.randn(2, 2, 16), torch.tensor([40, 80])
    kw = dict(lengths=lengths, guidance_scale=1.0, num_steps=4)
    a = sample_latents(plain, make_scheduler(PST_DIFFUSION, "ddim"), text, mask, None, None, noise, **kw)
    b = sample_latents(normed, make_scheduler(PST_DIFFUSION, "ddim"), text, mask, None, None, noise, **kw)
    torch.testing.assert_close(b, a * std + mean, rtol=1e-5, atol=1e-5)


def test_kf_latent_stats_are_the_sampled_training_latents_spread(keyframe_sets, tmp_path):
    train, val, vae = keyframe_sets
    mus, variances = [], []
    for key in train.base.crops():                                   # every training window, one at a time
        idx = torch.from_numpy(train.keyframes_of(key))[None]
        frames = torch.from_numpy(train.base.crop_features(*key))[None]
        with torch.no_grad():
            enc = vae.encode(gather_keyframes(frames, idx), indices_to_positions(idx, torch.tensor([key[2]])),
                             sample=False)
        mus.append(enc.mu[0].double()); variances.append(enc.logvar[0].double().exp())
    mus, variances = torch.stack(mus), torch.stack(variances)
    want_std = (mus.var(0, unbiased=False) + variances.mean(0)).sqrt()
    mean, std = kf_latent_stats(vae, train, batch_size=3)
    torch.testing.assert_close(mean.double(), mus.mean(0), rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(std.double(), want_std, rtol=1e-5, atol=1e-6)
    cache = kf_vae_latent_cache(vae, [train, val], tmp_path, DistEnv())
    cached = kf_latent_stats(vae, train, cache)                      # the cache gives the same numbers
    torch.testing.assert_close(cached[0], mean, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(cached[1], std, rtol=1e-5, atol=1e-6)


def test_prepare_diffuses_the_normalised_latent(keyframe_sets):
    """With ``latent_stats = (m, 1)`` the noised input moves by ``-sqrt(alpha_bar_t) m`` and nothing else."""
    from salad_core.keymotion.train import collate_keyframes

    train, _, vae = keyframe_sets
    batch = collate_keyframes([train[i] for i in range(3)])

    class Text:
        def encode(self, captions):
            return torch.ones(len(captions), 3, TEXT_DIM), torch.ones(len(captions), 3, dtype=torch.bool)

    env = DistEnv()
    scheduler = make_scheduler(PST_DIFFUSION, "ddim")
    kw = dict(vae=vae, text=Text(), scheduler=scheduler, config=KeyMotionTrainConfig(max_length=96, progress=False),
              latent_shape=vae.latent_shape)
    shift = torch.full((2, 16), 1.5)
    out = {}
    for name, stats in (("plain", None), ("shifted", (shift, torch.ones(2, 16)))):
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(4), env), env, train=True, step=0)
        out[name] = prepare_pst_batch(batch, ctx, latent_stats=stats, **kw)
    t = out["plain"]["timesteps"]
    assert torch.equal(t, out["shifted"]["timesteps"]) and torch.equal(out["plain"]["target"], out["shifted"]["target"])
    a = scheduler.alphas_cumprod[t].sqrt().float()[:, None, None]
    torch.testing.assert_close(out["plain"]["noisy"] - out["shifted"]["noisy"], (a * shift).expand(3, -1, -1),
                               rtol=1e-5, atol=1e-5)


def test_pst_task_sets_the_statistics_and_init_from_needs_the_same_choice(keyframe_sets, tmp_path):
    from salad_core.io import save_checkpoint
    from salad_core.keymotion.train import build_pst_task, load_pst_init
    from _doubles import HashTextEncoder

    train, _, vae = keyframe_sets
    (tmp_path / "vae").mkdir()
    save_checkpoint(tmp_path / "vae" / "best", vae, model_type="keymotion_kf_vae", config=vae.config)
    enc = HashTextEncoder()
    cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, keyframe_method="uniform",
                               latent_cache=False)
    model = PSTConfig(latent_size=2, latent_dim=16, text_dim=enc.dim, width=32, num_heads=4, ff_dim=64,
                      num_cond_layers=1, num_cross_layers=2, dropout=0.0, max_length=96, latent_norm=True)
    task = build_pst_task(train.base.root, tmp_path / "vae", model, cfg, DistEnv(), enc)
    mean, std = kf_latent_stats(vae, task.train_set)
    torch.testing.assert_close(task.model.latent_mean, mean)
    torch.testing.assert_close(task.model.latent_std, std)
    assert float(std.min()) > 0
    save_checkpoint(tmp_path / "pst", task.model, model_type="keymotion_pst", config=model)
    plain = tiny_pst(text_dim=enc.dim)
    with pytest.raises(ValueError, match="latent_norm"):          # a normalised PST is another latent space
        load_pst_init(plain, tmp_path / "pst")
