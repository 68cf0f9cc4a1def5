"""Rest padding (salad_core/keymotion/rest_padding.py): whole clips held still before and after, at a longer length."""
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.data.dataset import read_texts
from salad_core.keymotion.rest_padding import RestPaddedDataset, hold_features
from salad_core.skeleton import get_skeleton

pytestmark = pytest.mark.usefixtures("single_thread")

SK = get_skeleton("humanml3d")
VELOCITY = [SK.feature_slices[g] for g in ("root_rot_vel", "root_lin_vel", "local_vel")]
POSE = [SK.feature_slices[g] for g in ("root_y", "ric", "rot", "contacts")]


@pytest.fixture(scope="module")
def fake_corpus(tmp_path_factory) -> Path:
    from _doubles import make_fake_corpus

    return make_fake_corpus(tmp_path_factory.mktemp("fake_rest"), n_train=6, n_val=2, lengths=(44, 90))


def _base(root: Path, **kw):
    from salad_core.data.dataset import MotionTextDataset

    return MotionTextDataset(root, "train", max_length=96, random_crop=True, seed=0, **kw)


def test_hold_features_repeats_the_end_poses_with_zero_velocities(sample_features):
    x = sample_features[:50]
    out = hold_features(x, 3, 5)
    assert out.shape == (58, SK.feature_dim)
    np.testing.assert_array_equal(out[3:53], x)                          # the clip itself is untouched
    for held, src in ((out[:3], x[0]), (out[53:], x[-1])):
        for sl in POSE:
            np.testing.assert_array_equal(held[:, sl], np.broadcast_to(src[sl], held[:, sl].shape))
        for sl in VELOCITY:
            assert np.all(held[:, sl] == 0)
    assert np.abs(x[-1, SK.feature_slices["local_vel"]]).max() > 0      # the sample's last frame does move
    np.testing.assert_array_equal(hold_features(x, 0, 0), x)


@pytest.mark.parametrize("args, message", [((np.zeros((4, 10)), 1, 1), "features must be"),
                                           ((np.zeros((4, 263)), -1, 0), "before=-1"),
                                           ((np.zeros((4, 263)), 0, 1.5), "after=1.5")])
def test_hold_features_rejects_bad_input(args, message):
    with pytest.raises(ValueError, match=message):
        hold_features(*args)


def test_padded_windows_are_whole_clips_held_still_at_a_longer_length(fake_corpus):
    base = _base(fake_corpus)
    ds = RestPaddedDataset(base, share=0.5, seed=3)
    assert ds.num_padded == min(len(base), round(0.5 / 0.5 * len(base)))
    assert len(ds) == len(base) + ds.num_padded
    assert len(ds.lengths) == len(ds)
    real_keys = set(base.crops())
    padded_keys = ds.crops()[len(base.crops()):]
    assert len(padded_keys) == ds.num_padded and not real_keys & set(padded_keys)
    for i in range(len(base), len(ds)):
        item = ds[i]
        n, before = item["length"], -item["offset"]
        mid = item["motion_id"]
        clip_frames = base.clip_length(mid) // base.unit_length * base.unit_length
        assert n % base.unit_length == 0 and clip_frames < n <= 96 and 0 <= before <= n - clip_frames
        raw = item["motion"][:n] * base.std + base.mean                      # de-normalised window
        clip = base.crop_features(mid, 0, clip_frames) * base.std + base.mean
        np.testing.assert_allclose(raw[before:before + clip_frames], clip, atol=1e-4)
        held = np.concatenate([raw[:before], raw[before + clip_frames:]])
        for sl in VELOCITY:
            np.testing.assert_allclose(held[:, sl], 0, atol=1e-4)
        assert np.all(item["motion"][n:] == 0)
        assert item["caption"] in {t.caption for t in read_texts(fake_corpus, mid)}
        np.testing.assert_array_equal(ds.crop_features(mid, item["offset"], n), item["motion"][:n])
    # the same seed gives the same windows across epochs and instances; another seed other ones
    ds.set_epoch(5)
    assert ds.crops() == RestPaddedDataset(_base(fake_corpus), share=0.5, seed=3).crops()
    assert ds.crops() != RestPaddedDataset(_base(fake_corpus), share=0.5, seed=4).crops()
    assert RestPaddedDataset(base, share=0.0).num_padded == 0


@pytest.mark.parametrize("share", [-0.1, 0.95, True, "0.2"])
def test_bad_share_is_refused(fake_corpus, share):
    with pytest.raises(ValueError, match="share="):
        RestPaddedDataset(_base(fake_corpus), share=share)


def test_train_config_pads_only_the_training_split_and_feeds_the_latent_cache(fake_corpus, tmp_path):
    from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig
    from salad_core.keymotion.train import KeyMotionTrainConfig, _datasets, kf_vae_latent_cache
    from salad_core.train.distributed import DistEnv

    with pytest.raises(ValueError, match="rest_padding"):
        KeyMotionTrainConfig(rest_padding=0.95)
    cfg = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, rest_padding=0.3, seed=0)
    train, val = _datasets(fake_corpus, "humanml3d", 8, cfg)
    assert isinstance(train.base, RestPaddedDataset) and train.base.num_padded > 0
    assert not isinstance(val.base, RestPaddedDataset)
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, max_length=96, frame_dim=32, latent_dim=16, num_layers=1,
                                        ff_dim=64)).eval()
    vae.set_normalization(train.mean, train.std)
    cache = kf_vae_latent_cache(vae, [train, val], tmp_path, DistEnv())
    assert len(cache) == len(train.base.crops()) + len(val.base.crops())
    item = train[len(train) - 1]                                           # a padded window, keyframes included
    key = (item["motion_id"], int(item["offset"]), int(item["length"]))
    assert key[1] <= 0 and item["keyframes"][-1] == item["length"] - 1
    mu, _ = cache.lookup([key])
    from salad_core.keymotion.kf_vae import gather_keyframes, indices_to_positions

    idx = torch.as_tensor(item["keyframes"])[None]
    frames = gather_keyframes(torch.as_tensor(item["motion"][: item["length"]])[None], idx)
    with torch.no_grad():
        enc = vae.encode(frames, indices_to_positions(idx, torch.tensor([item["length"]])), sample=False)
    torch.testing.assert_close(mu, enc.mu, rtol=1e-4, atol=1e-5)
