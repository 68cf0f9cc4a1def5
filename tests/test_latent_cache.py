"""The latent cache: signatures (VAE weights, corpus files), numerical equivalence with on-the-fly
encoding, and the denoiser's batch preparation with and without it."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.data.dataset import MotionTextDataset
from salad_core.train.config import DenoiserTrainConfig
from salad_core.train.distributed import DistEnv
from salad_core.train.latent_cache import LatentCache, corpus_digest, module_digest
from _doubles import make_fake_corpus

MAX = 72


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    return make_fake_corpus(tmp_path_factory.mktemp("corpus"), n_train=6, n_val=2, lengths=(44, 72))


@pytest.fixture(scope="module")
def vae():
    from salad_core.models.vae import MotionVAE, VAEConfig

    torch.manual_seed(0)
    model = MotionVAE(VAEConfig(latent_dim=8, n_extra_layers=0)).eval()
    for p in model.parameters():
        p.requires_grad_(False)
    return model


def train_set(root: Path) -> MotionTextDataset:
    return MotionTextDataset(root, "train", max_length=MAX, random_crop=True, seed=0)


def config(**kw) -> DenoiserTrainConfig:
    return DenoiserTrainConfig(max_length=MAX, num_threads=1, progress=False, **kw)


def build(vae, datasets, tmp: Path, **kw):
    from salad_core.train.denoiser_trainer import denoiser_latent_cache

    return denoiser_latent_cache(vae, datasets, config(**kw), tmp, DistEnv())


def test_module_digest_changes_with_one_weight(vae):
    import copy

    other = copy.deepcopy(vae)
    assert module_digest(other) == module_digest(vae)
    with torch.no_grad():
        next(other.parameters()).view(-1)[3] += 1e-6
    assert module_digest(other) != module_digest(vae)


def test_corpus_digest_changes_when_a_clip_file_is_touched(tmp_path):
    root = make_fake_corpus(tmp_path / "c", n_train=4, n_val=1)
    before = corpus_digest(train_set(root))
    assert corpus_digest(train_set(root)) == before
    clip = root / "new_joint_vecs" / "000000.npy"                   # a train clip
    st = clip.stat()
    os.utime(clip, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000))
    assert corpus_digest(train_set(root)) != before


@pytest.mark.parametrize("pad", [False, True])
def test_cached_posteriors_equal_encoding_the_window(vae, corpus, tmp_path, pad):
    ds = train_set(corpus)
    cache = build(vae, [ds], tmp_path, vae_pad_to_max=pad)
    keys = ds.crops()
    assert len(cache) == len(keys) and len(keys) > 6 * len(ds)       # 6-12 windows per item
    for key in keys[:: max(1, len(keys) // 25)]:
        mid, off, n = key
        x = torch.zeros(1, MAX if pad else n, 263)
        x[0, :n] = torch.from_numpy(ds.crop_features(mid, off, n))
        enc = vae.encode(x, sample=False)
        mu, logvar = cache.rows(key)
        assert mu.shape == (n // 4, vae.num_parts, vae.latent_dim)
        torch.testing.assert_close(torch.from_numpy(np.array(mu)), enc.mu[0, : n // 4], rtol=1e-5, atol=1e-6)
        torch.testing.assert_close(torch.from_numpy(np.array(logvar)), enc.logvar[0, : n // 4], rtol=1e-5, atol=1e-6)


def test_every_item_is_in_the_cache_and_lookup_pads_with_zeros(vae, corpus, tmp_path):
    ds = train_set(corpus)
    cache = build(vae, [ds], tmp_path)
    keys = []
    for epoch in range(30):
        ds.set_epoch(epoch)
        keys += [(it["motion_id"], it["offset"], it["length"]) for it in (ds[i] for i in range(len(ds)))]
    assert all(k in cache for k in keys)
    mu, logvar = cache.lookup(keys[:4], rows=MAX // 4)
    assert mu.shape == (4, MAX // 4, vae.num_parts, vae.latent_dim)
    for i, k in enumerate(keys[:4]):
        assert torch.all(mu[i, k[2] // 4:] == 0) and torch.all(logvar[i, k[2] // 4:] == 0)
        assert torch.equal(mu[i, : k[2] // 4], torch.from_numpy(np.array(cache.rows(k)[0])))


def test_signature_reuses_and_invalidates(vae, corpus, tmp_path):
    import copy

    ds = train_set(corpus)
    first = build(vae, [ds], tmp_path)
    again = build(vae, [ds], tmp_path)
    assert again.folder == first.folder and again.signature == first.signature
    changed = copy.deepcopy(vae)
    with torch.no_grad():
        next(changed.parameters()).view(-1)[0] += 1e-3
    other = build(changed, [ds], tmp_path)
    assert other.folder != first.folder
    assert not torch.equal(other.lookup(ds.crops()[:2])[0], first.lookup(ds.crops()[:2])[0])
    half = build(vae, [ds], tmp_path, latent_cache_dtype="float16")
    a, b = half.lookup(ds.crops()[:8])[0], first.lookup(ds.crops()[:8])[0]
    assert half.folder != first.folder and torch.allclose(a, b, rtol=1e-3, atol=1e-3) and not torch.equal(a, b)


def test_prune_removes_caches_of_other_weights(vae, corpus, tmp_path):
    import copy

    from salad_core.train.denoiser_trainer import denoiser_latent_cache

    ds = train_set(corpus)
    first = build(vae, [ds], tmp_path)
    changed = copy.deepcopy(vae)
    with torch.no_grad():
        next(changed.parameters()).view(-1)[0] += 1e-3
    second = denoiser_latent_cache(changed, [ds], config(), tmp_path, DistEnv(), prune=True)
    assert second.folder.is_dir() and not first.folder.exists()
    assert LatentCache(second.folder).signature == second.signature


@pytest.mark.skipif(os.name != "posix", reason="the build lock is POSIX flock")
def test_callers_sharing_a_cache_folder_build_it_once(vae, corpus, tmp_path, monkeypatch):
    """Two callers (the ablation study's denoisers on one VAE, in two processes) opening the same missing
    cache at once: the second waits for the first's build and reuses it instead of encoding every window
    again. Threads stand in for the processes: each opens the lock file itself, and ``flock`` locks
    belong to the open file, so they exclude each other as two processes would."""
    import threading
    import time

    import salad_core.train.latent_cache as lc
    from salad_core.train.denoiser_trainer import denoiser_latent_cache

    builds = []
    real_build = lc.build_latent_cache

    def slow_counting_build(*args, **kwargs):
        builds.append(threading.get_ident())
        time.sleep(1.0)                           # long enough for the other caller to ask meanwhile
        return real_build(*args, **kwargs)

    monkeypatch.setattr(lc, "build_latent_cache", slow_counting_build)
    ds = train_set(corpus)
    shared = tmp_path / "shared"
    folders, errors = [], []

    def worker():
        try:
            folders.append(denoiser_latent_cache(vae, [ds], config(), shared, DistEnv()).folder)
        except Exception as exc:                  # surfaced by the assertion below
            errors.append(exc)

    threads = [threading.Thread(target=worker) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors and len(folders) == 2
    assert len(builds) == 1 and folders[0] == folders[1]
    assert len(LatentCache(folders[0])) == len(ds.crops())


def test_prepare_with_the_cache_equals_encoding_on_the_fly(vae, corpus, tmp_path):
    """vae_pad_to_max: the cached batch preparation gives the on-the-fly latents, noise and targets."""
    from salad_core.data.dataset import collate_motion_text
    from salad_core.sampling import DiffusionConfig, make_scheduler
    from salad_core.train.common import StepContext
    from salad_core.train.denoiser_trainer import prepare_denoiser_batch
    from salad_core.train.distributed import GlobalBatchRandom

    class Text:
        def encode(self, captions):
            return torch.ones(len(captions), 3, 4), torch.ones(len(captions), 3, dtype=torch.bool)

    ds = train_set(corpus)
    cfg = config(vae_pad_to_max=True)
    cache = build(vae, [ds], tmp_path, vae_pad_to_max=True)
    batch = collate_motion_text([ds[i] for i in range(4)], trim=False)
    kw = dict(vae=vae, text=Text(), scheduler=make_scheduler(DiffusionConfig(), "ddim"), config=cfg,
              prediction_type="v_prediction", latent_shape=(MAX // 4, vae.num_parts, vae.latent_dim))
    env = DistEnv()
    out = {}
    for name, latents in (("fly", None), ("cache", cache)):
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(4), env), env, train=True, step=0)
        out[name] = prepare_denoiser_batch(batch, ctx, latents=latents, **kw)
    for k in ("noisy", "target"):
        torch.testing.assert_close(out["cache"][k], out["fly"][k], rtol=1e-5, atol=1e-6)
    assert torch.equal(out["cache"]["frame_mask"], out["fly"]["frame_mask"])
    assert torch.equal(out["cache"]["denom"], out["fly"]["denom"])
