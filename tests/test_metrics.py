"""Metrics of salad_core.eval.metrics on embeddings with known answers."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.eval.metrics import (
    activation_statistics,
    diversity,
    euclidean_distance_matrix,
    fid,
    frechet_distance,
    matching_score,
    mean_ci,
    mpjpe,
    multimodality,
    r_precision,
)


# --------------------------------------------------------------------------- distances
def test_distance_matrix_matches_direct_norms():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(5, 7)), rng.normal(size=(4, 7))
    direct = np.linalg.norm(a[:, None] - b[None], axis=-1)
    np.testing.assert_allclose(euclidean_distance_matrix(a, b), direct, atol=1e-10)
    self_dist = euclidean_distance_matrix(a, a).diagonal()
    assert np.isfinite(self_dist).all() and self_dist.max() < 1e-6  # negative round-off clipped, not NaN


# --------------------------------------------------------------------------- R-precision
def test_r_precision_of_matched_pairs_is_one():
    rng = np.random.default_rng(1)
    e = rng.normal(size=(96, 16))
    assert r_precision(e, e) == (1.0, 1.0, 1.0)


def test_r_precision_of_random_pairs_is_chance_level():
    rng = np.random.default_rng(2)
    n = 32 * 600
    top = r_precision(rng.normal(size=(n, 8)), rng.normal(size=(n, 8)), top_k=3)
    # chance: k / 32; binomial std of top-3 over 19200 rows is 0.0021
    np.testing.assert_allclose(top, [1 / 32, 2 / 32, 3 / 32], atol=0.008)
    assert top[0] <= top[1] <= top[2]


def test_r_precision_known_ranks_per_batch():
    # text i sits at distance 0 from motion i except texts 0..3 of the batch, whose own motion
    # is pushed far away, so they rank it last (rank 31): 28/32 hits at every k
    e = np.eye(32) * 10.0
    m = e.copy()
    m[:4] += 100.0
    top = r_precision(e, m, top_k=2)
    assert top == (28 / 32, 28 / 32)


def test_r_precision_drops_incomplete_batch_and_validates():
    rng = np.random.default_rng(3)
    e = rng.normal(size=(40, 4))
    other = rng.normal(size=(40, 4))
    # the last 8 rows are matched perfectly but dropped; the first 32 are compared to themselves
    t = np.concatenate([e[:32], other[32:]])
    assert r_precision(t, np.concatenate([e[:32], other[32:]]))[0] == 1.0
    with pytest.raises(ValueError, match="drop_last"):
        r_precision(e, e, drop_last=False)
    with pytest.raises(ValueError, match="at least batch_size=32"):
        r_precision(e[:31], e[:31])
    with pytest.raises(ValueError, match="same shape"):
        r_precision(e, e[:, :3])
    with pytest.raises(ValueError, match="top_k"):
        r_precision(e, e, top_k=0)


# --------------------------------------------------------------------------- MM-Dist
def test_matching_score_identical_is_zero_and_known_shift():
    rng = np.random.default_rng(4)
    e = rng.normal(size=(50, 6))
    assert matching_score(e, e) == 0.0
    shift = np.zeros(6)
    shift[2] = 3.0
    assert matching_score(e, e + shift) == pytest.approx(3.0)


# --------------------------------------------------------------------------- FID
def test_fid_identical_sets_is_zero():
    rng = np.random.default_rng(5)
    e = rng.normal(size=(400, 12)) @ rng.normal(size=(12, 12))
    assert abs(fid(e, e)) < 1e-6


def test_fid_of_mean_shift_is_squared_shift():
    rng = np.random.default_rng(6)
    d, n = 8, 40000
    a = rng.normal(size=(n, d))
    b = rng.normal(size=(n, d)) + np.array([1.5, 0, 0, 0, 0, 0, 0, -0.5])
    # |shift|^2 = 2.5; the covariance term is O(d^2 / n)
    assert fid(a, b) == pytest.approx(2.5, abs=0.02)


def test_frechet_distance_closed_form_for_diagonal_covariances():
    # for commuting covariances the trace term is sum (sqrt(s1) - sqrt(s2))^2
    s1, s2 = np.array([1.0, 4.0, 9.0]), np.array([4.0, 4.0, 1.0])
    expected = 1.0 + ((np.sqrt(s1) - np.sqrt(s2)) ** 2).sum()
    got = frechet_distance(np.zeros(3), np.diag(s1), np.array([1.0, 0, 0]), np.diag(s2))
    assert got == pytest.approx(expected)  # 1 + 1 + 0 + 4


def test_fid_singular_covariances_stay_finite():
    # both sets live on a 1-D line in 3-D: singular covariances whose product is 0
    rng = np.random.default_rng(7)
    t = rng.normal(size=(200, 1))
    a = t @ np.array([[1.0, 0.0, 0.0]])
    b = t @ np.array([[0.0, 1.0, 0.0]])
    mu_a, s_a = activation_statistics(a)
    mu_b, s_b = activation_statistics(b)
    val = frechet_distance(mu_a, s_a, mu_b, s_b)
    # orthogonal lines of variance v: |mu diff|^2 + 2 v (sqrtm of the product is 0)
    assert val == pytest.approx(((mu_a - mu_b) ** 2).sum() + s_a[0, 0] + s_b[1, 1], abs=1e-9)


def test_fid_retries_with_eps_when_sqrtm_is_not_finite(monkeypatch):
    from salad_core.eval import metrics

    real_sqrtm = metrics.linalg.sqrtm
    seen = []

    def flaky_sqrtm(m):
        seen.append(np.array(m))
        return np.full_like(m, np.inf) if len(seen) == 1 else real_sqrtm(m)

    monkeypatch.setattr(metrics.linalg, "sqrtm", flaky_sqrtm)
    s = np.diag([1.0, 4.0])
    val = frechet_distance(np.zeros(2), s, np.zeros(2), s, eps=1e-2)
    assert len(seen) == 2
    np.testing.assert_allclose(seen[1], (s + 0.01 * np.eye(2)) @ (s + 0.01 * np.eye(2)))
    # sqrtm((s + eps)^2) = s + eps, so the value is 2 tr(s) - 2 tr(s + eps) = -2 * 2 * eps
    assert val == pytest.approx(-0.04)


def test_fid_validates():
    with pytest.raises(ValueError, match="at least 2"):
        fid(np.zeros((1, 3)), np.zeros((5, 3)))
    with pytest.raises(ValueError, match="same width"):
        fid(np.zeros((4, 3)), np.zeros((5, 2)))


# --------------------------------------------------------------------------- Diversity
def test_diversity_of_a_regular_simplex():
    # N points, every distinct pair exactly d apart; a drawn pair that repeats an index adds 0
    n, d = 400, 2.0
    e = np.eye(n) * d / np.sqrt(2.0)
    got = diversity(e, n_pairs=300, rng=np.random.default_rng(8))
    replay = np.random.default_rng(8)
    first = replay.choice(n, 300, replace=False)
    second = replay.choice(n, 300, replace=False)
    assert got == pytest.approx(d * np.mean(first != second))
    assert got == pytest.approx(d, abs=0.03)  # P(repeat) = 1/400 per pair


def test_diversity_of_two_clusters_is_deterministic_given_seed():
    # half the points at 0, half at 5 on one axis: each pair adds 0 or 5
    e = np.zeros((500, 3))
    e[250:, 0] = 5.0
    a = diversity(e, rng=123)
    assert a == diversity(e, rng=123)
    assert a == pytest.approx(2.5, abs=0.5)   # 5 * P(clusters differ) = 5 * 1/2
    assert (a / 5.0 * 300) == pytest.approx(round(a / 5.0 * 300))  # a multiple of 5/300


def test_diversity_needs_more_samples_than_pairs():
    with pytest.raises(ValueError, match="more than n_pairs=300"):
        diversity(np.zeros((300, 4)))
    with pytest.raises(TypeError, match="rng"):
        diversity(np.zeros((10, 2)), n_pairs=3, rng="seed")


# --------------------------------------------------------------------------- MultiModality
def test_multimodality_identical_repeats_is_zero():
    rng = np.random.default_rng(9)
    base = rng.normal(size=(20, 1, 16))
    assert multimodality(np.repeat(base, 30, axis=1), rng=0) == 0.0


def test_multimodality_known_value():
    # repeat r of every text sits at r along one axis: a pair (i, j) adds |i - j|
    e = np.zeros((4, 30, 2))
    e[:, :, 0] = np.arange(30)
    got = multimodality(e, n_pairs=10, rng=np.random.default_rng(10))
    replay = np.random.default_rng(10)
    first = replay.choice(30, 10, replace=False)
    second = replay.choice(30, 10, replace=False)
    assert got == pytest.approx(np.abs(first - second).mean())
    with pytest.raises(ValueError, match="n_repeats > n_pairs"):
        multimodality(e[:, :10], n_pairs=10)
    with pytest.raises(ValueError, match=r"\(n_texts, n_repeats, C\)"):
        multimodality(e[0])


# --------------------------------------------------------------------------- MPJPE
def test_mpjpe_translated_copy_is_zero_with_root_alignment(sample_joints):
    shifted = sample_joints + np.array([0.7, -0.2, 3.0], dtype=np.float32)
    assert mpjpe(shifted, sample_joints) == pytest.approx(0.0, abs=1e-6)
    # without alignment the error is the translation's length at every joint
    unaligned = mpjpe(shifted, sample_joints, root_aligned=False)
    assert unaligned == pytest.approx(np.linalg.norm([0.7, -0.2, 3.0]), rel=1e-5)


def test_mpjpe_known_value_and_mask():
    gt = np.zeros((2, 3, 4, 3))         # (B, N, J, 3)
    pred = gt.copy()
    pred[0, :, 1:, 0] = 0.3             # batch 0: joints 1..3 off by 0.3 -> per pose 0.225
    pred[1, 2, 1:, 1] = 1.0             # batch 1, frame 2 only: per pose 0.75
    assert mpjpe(pred, gt) == pytest.approx((3 * 0.225 + 0.75) / 6)
    mask = np.array([[True, True, True], [True, True, False]])   # frame 2 of batch 1 is padding
    assert mpjpe(pred, gt, mask=mask) == pytest.approx(3 * 0.225 / 5)
    with pytest.raises(ValueError, match="mask must have"):
        mpjpe(pred, gt, mask=mask[0])
    with pytest.raises(ValueError, match="same shape"):
        mpjpe(pred, gt[:1])


# --------------------------------------------------------------------------- mean ± CI
def test_mean_ci_uses_population_std():
    mean, half = mean_ci([1.0, 2.0, 3.0, 4.0])
    assert mean == pytest.approx(2.5)
    assert half == pytest.approx(1.96 * np.sqrt(1.25) / 2.0)  # np.std ddof=0 = sqrt(1.25)
    means, halves = mean_ci(np.array([[1.0, 10.0], [3.0, 10.0]]))
    np.testing.assert_allclose(means, [2.0, 10.0])
    np.testing.assert_allclose(halves, [1.96 * 1.0 / np.sqrt(2), 0.0])
    with pytest.raises(ValueError, match="NaN"):
        mean_ci([1.0, np.nan])
