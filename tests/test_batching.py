"""Length-bucketed batches: determinism, exact resume, DDP shares, padding, and the loss weighting."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.train.batching import LengthBucketBatchSampler, expected_latent_frames, padding_ratio


def skewed_lengths(n: int = 300, seed: int = 0) -> np.ndarray:
    """Like the procedural corpus: most clips short, a long tail up to 196 frames."""
    rng = np.random.default_rng(seed)
    return np.clip(40 + rng.exponential(40.0, n), 40, 196).astype(np.int64)


def test_batches_are_a_function_of_seed_and_epoch():
    lengths = skewed_lengths()
    a = LengthBucketBatchSampler(lengths, 16, seed=5, pool_batches=4)
    b = LengthBucketBatchSampler(lengths, 16, seed=5, pool_batches=4)
    for epoch in range(3):
        a.set_epoch(epoch)
        b.set_epoch(epoch)
        assert list(a) == list(b)
    a.set_epoch(0)
    b.set_epoch(1)
    assert list(a) != list(b)
    c = LengthBucketBatchSampler(lengths, 16, seed=6, pool_batches=4)
    assert list(c) != list(a)


def test_an_epoch_uses_disjoint_full_batches_sorted_by_length():
    lengths = skewed_lengths(301)
    s = LengthBucketBatchSampler(lengths, 16, seed=1, pool_batches=4)
    batches = list(s)
    assert len(batches) == len(s) == 301 // 16
    flat = np.concatenate(batches)
    assert len(flat) == len(set(flat.tolist())) == (301 // 16) * 16
    for b in batches:
        assert len(b) == 16 and np.all(np.diff(lengths[b]) >= 0)
    # the dropped remainder is random: over epochs every item is used
    seen = set()
    for epoch in range(20):
        s.set_epoch(epoch)
        seen |= {i for b in s for i in b}
    assert seen == set(range(301))


def test_buckets_cut_the_padding_of_random_batches():
    lengths = skewed_lengths(640)
    rng = np.random.default_rng(0)
    random_batches = np.split(rng.permutation(640), 40)
    s = LengthBucketBatchSampler(lengths, 16, seed=0, pool_batches=16)
    bucketed = s.global_batches(0)
    r_random, r_bucket = padding_ratio(lengths, random_batches), padding_ratio(lengths, bucketed)
    assert r_random > 1.5 and r_bucket < 1.1
    one = LengthBucketBatchSampler(lengths, 16, seed=0, pool_batches=1)   # pools of one batch: random batches
    assert padding_ratio(lengths, one.global_batches(0)) > 1.5


def test_resume_mid_epoch_yields_the_rest_of_the_epoch():
    lengths = skewed_lengths()
    full = LengthBucketBatchSampler(lengths, 8, seed=3)
    full.set_epoch(2)
    whole = list(full)
    part = LengthBucketBatchSampler(lengths, 8, seed=3, start=7)
    part.set_epoch(2)
    assert list(part) == whole[7:] and len(part) == len(whole) - 7


@pytest.mark.parametrize("world", [2, 4])
def test_ranks_get_disjoint_equal_shares_of_the_global_batch(world):
    lengths = skewed_lengths(203)
    single = LengthBucketBatchSampler(lengths, 8, seed=9)
    ranks = [LengthBucketBatchSampler(lengths, 8, rank=r, world_size=world, seed=9) for r in range(world)]
    for epoch in (0, 1):
        for s in (single, *ranks):
            s.set_epoch(epoch)
        per_rank = [list(s) for s in ranks]
        assert len({len(p) for p in per_rank}) == 1 and len(per_rank[0]) == len(single)
        for step, global_batch in enumerate(single):
            shares = [p[step] for p in per_rank]
            assert all(len(s) == 8 // world for s in shares)
            union = sorted(i for s in shares for i in s)
            assert union == sorted(global_batch)                       # disjoint and complete


def test_invalid_arguments_name_the_argument():
    with pytest.raises(ValueError, match="batch_size=6 is not divisible by world_size=4"):
        LengthBucketBatchSampler([50] * 10, 6, world_size=4)
    with pytest.raises(ValueError, match="rank=2"):
        LengthBucketBatchSampler([50] * 10, 4, rank=2, world_size=2)
    with pytest.raises(ValueError, match="pool_batches=0"):
        LengthBucketBatchSampler([50] * 10, 4, pool_batches=0)
    with pytest.raises(ValueError, match="non-empty"):
        LengthBucketBatchSampler([], 4)


def test_expected_latent_frames_matches_the_random_crop(tmp_path):
    from salad_core.data.dataset import MotionTextDataset
    from _doubles import make_fake_corpus

    root = make_fake_corpus(tmp_path / "c", n_train=12, lengths=(40, 120))
    ds = MotionTextDataset(root, "train", max_length=120, random_crop=True, seed=0)
    want = expected_latent_frames(ds.lengths, 4)
    got = np.mean([ds[i]["length"] // 4 for e in range(300) if not ds.set_epoch(e) for i in range(len(ds))])
    assert got == pytest.approx(want, abs=0.05)
    assert expected_latent_frames([40, 43], 4) == pytest.approx(10 - 1 / 3)


def test_fixed_normaliser_makes_the_epoch_objective_independent_of_grouping():
    """With a per-batch mean, grouping short clips together up-weights them; with the constant
    normaliser (batch x expected frames) the sum over an epoch is the same whatever the grouping."""
    from salad_core.train.denoiser_trainer import DenoiserObjective

    class Zero(torch.nn.Module):
        def forward(self, x, *args):
            return torch.zeros_like(x)

    rng = np.random.default_rng(0)
    lengths = skewed_lengths(64) // 4
    err = torch.from_numpy(rng.uniform(0.5, 2.0, 64)).float()           # per-item error level
    n = int(lengths.max())
    target = err[:, None, None, None].expand(64, n, 1, 1).sqrt().clone()
    mask = torch.arange(n)[None] < torch.from_numpy(lengths)[:, None]
    objective = DenoiserObjective(Zero())
    norm = float(lengths.mean())

    def epoch(batches, fixed: bool) -> float:
        total = 0.0
        for b in batches:
            b = torch.as_tensor(np.asarray(b))
            denom = torch.tensor(len(b) * norm) if fixed else mask[b].sum().float()
            total += float(objective(torch.zeros_like(target[b]), None, None, None, mask[b], target[b], denom)["loss"])
        return total / len(batches)

    random_batches = np.split(rng.permutation(64), 8)
    sorted_batches = np.split(np.argsort(lengths, kind="stable"), 8)
    per_frame = float((err[:, None] * mask).sum() / mask.sum())       # the corpus's per-frame mean
    assert epoch(random_batches, True) == pytest.approx(epoch(sorted_batches, True), rel=1e-6)
    assert epoch(sorted_batches, True) == pytest.approx(per_frame, rel=1e-5)
    # the per-batch mean over sorted batches is a different (per-clip) weighting
    assert abs(epoch(sorted_batches, False) - per_frame) > 1e-3


# ----------------------------------------------------------------- equal valid frames per batch
def test_equal_frame_batches_hold_about_the_same_frames_and_cover_the_epoch():
    lengths = skewed_lengths(640, seed=3)
    s = LengthBucketBatchSampler(lengths, 16, seed=2, pool_batches=8, equal_frames=True)
    batches = s.global_batches(0)
    flat = np.concatenate(batches)
    assert sorted(flat.tolist()) == list(range(640))            # every item once, none dropped
    frames = np.array([lengths[b].sum() for b in batches], dtype=float)
    target = 16 * lengths.mean()
    assert abs(len(batches) - 640 / 16) <= 2                     # about as many steps per epoch as fixed batches
    assert np.all(np.abs(frames / target - 1) < 0.25)           # each batch close to batch x mean length
    sizes = np.array([len(b) for b in batches])
    assert sizes.max() > 16 > sizes.min()                        # short clips come in bigger batches
    for b in batches:
        assert np.all(np.diff(lengths[b]) >= 0)
    assert padding_ratio(lengths, batches) < 1.15


def test_equal_frame_batches_are_deterministic_and_resume_exactly():
    lengths = skewed_lengths(400, seed=4)
    a = LengthBucketBatchSampler(lengths, 16, seed=9, pool_batches=4, equal_frames=True)
    a.set_epoch(2)
    full = list(a)
    assert len(full) == a.batches_per_epoch
    b = LengthBucketBatchSampler(lengths, 16, seed=9, pool_batches=4, equal_frames=True, start=5)
    b.set_epoch(2)
    assert list(b) == full[5:]
    a.set_epoch(3)
    assert list(a) != full


@pytest.mark.parametrize("world", [2, 4])
def test_equal_frame_batches_split_into_equal_disjoint_rank_shares(world):
    lengths = skewed_lengths(300, seed=5)
    single = LengthBucketBatchSampler(lengths, 16, seed=1, pool_batches=4, equal_frames=True, world_size=world)
    ranks = [LengthBucketBatchSampler(lengths, 16, seed=1, pool_batches=4, equal_frames=True,
                                      rank=r, world_size=world) for r in range(world)]
    shares = [list(r) for r in ranks]
    assert len({len(s) for s in shares}) == 1
    for step, global_batch in enumerate(single.global_batches(0)):
        parts = [shares[r][step] for r in range(world)]
        assert len({len(p) for p in parts}) == 1                 # every rank the same number of items
        assert sorted(sum(parts, [])) == sorted(global_batch.tolist())
