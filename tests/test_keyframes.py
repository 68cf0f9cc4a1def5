"""Keyframe selection: exact DPs checked against brute force, invariants, errors."""
from itertools import combinations

import numpy as np
import pytest

from salad_core.keymotion import interpolation_errors, select_keyframes


def _brute(x, k, score, maximise):
    n = len(x)
    best, best_idx = None, None
    for mid in combinations(range(1, n - 1), k - 2):
        idx = (0, *mid, n - 1)
        s = sum(score(x, a, b) for a, b in zip(idx[:-1], idx[1:]))
        if best is None or (s > best + 1e-12 if maximise else s < best - 1e-12):
            best, best_idx = s, idx
    return best, np.array(best_idx)


def _dist(x, a, b):
    return float(np.linalg.norm(x[a] - x[b]))


def _interp_err(x, a, b):
    t = np.arange(a, b + 1)
    w = ((t - a) / (b - a))[:, None]
    return float((((1 - w) * x[a] + w * x[b] - x[a:b + 1]) ** 2).sum())


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("k", [2, 3, 4, 5])
def test_mdo_matches_brute_force(seed, k):
    x = np.random.default_rng(seed).normal(size=(9, 4))
    idx = select_keyframes(x, k, "mdo")
    best, _ = _brute(x, k, _dist, maximise=True)
    got = sum(_dist(x, a, b) for a, b in zip(idx[:-1], idx[1:]))
    assert got == pytest.approx(best, abs=1e-9)
    assert idx[0] == 0 and idx[-1] == 8 and len(idx) == k and np.all(np.diff(idx) > 0)


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("k", [2, 3, 4, 5])
def test_mieo_matches_brute_force(seed, k):
    x = np.cumsum(np.random.default_rng(seed).normal(size=(9, 3)), 0)
    idx = select_keyframes(x, k, "mieo")
    best, _ = _brute(x, k, _interp_err, maximise=False)
    got = sum(_interp_err(x, a, b) for a, b in zip(idx[:-1], idx[1:]))
    assert got == pytest.approx(best, abs=1e-8)


def test_interpolation_error_matrix_matches_direct_sum():
    x = np.random.default_rng(3).normal(size=(12, 5))
    e = interpolation_errors(x)
    for a in range(12):
        for b in range(a + 1, 12):
            assert e[a, b] == pytest.approx(_interp_err(x, a, b), abs=1e-9)
    assert np.all(np.tril(e) == 0)


def test_mieo_exact_on_piecewise_linear_motion():
    # a piecewise-linear path with corners at 0, 7, 15, 20: MIEO with k=4 finds zero error there
    corners = {0: [0.0, 0.0], 7: [7.0, 1.0], 15: [3.0, 9.0], 20: [10.0, 10.0]}
    keys = sorted(corners)
    x = np.zeros((21, 2))
    for a, b in zip(keys[:-1], keys[1:]):
        for t in range(a, b + 1):
            w = (t - a) / (b - a)
            x[t] = (1 - w) * np.array(corners[a]) + w * np.array(corners[b])
    assert list(select_keyframes(x, 4, "mieo")) == keys


def test_uniform_and_real_motion(sample_features):
    idx = select_keyframes(sample_features, 20, "uniform")
    assert len(idx) == 20 and idx[0] == 0 and idx[-1] == len(sample_features) - 1
    for method in ("mdo", "mieo"):
        sel = select_keyframes(sample_features, 20, method)
        assert len(np.unique(sel)) == 20 and sel[0] == 0 and sel[-1] == len(sample_features) - 1
    # MDO spreads keyframes in feature space at least as far as uniform spacing does
    def total(ix):
        return np.linalg.norm(np.diff(sample_features[ix], axis=0), axis=1).sum()
    assert total(select_keyframes(sample_features, 20, "mdo")) >= total(idx) - 1e-6


@pytest.mark.parametrize("bad, msg", [
    (dict(k=1), "k must be"), (dict(k=50), "only 10 frames"), (dict(method="best"), "unknown keyframe method"),
])
def test_errors(bad, msg):
    kw = dict(k=3, method="mdo") | bad
    with pytest.raises(ValueError, match=msg):
        select_keyframes(np.zeros((10, 3)), **kw)


def test_nan_rejected():
    x = np.zeros((10, 3)); x[4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        select_keyframes(x, 3)


def test_feature_distances_and_optimal_path_are_mdo_and_take_any_pair_score():
    from salad_core.keymotion.selection import feature_distances, mdo_keyframes, optimal_keyframe_path

    x = np.random.default_rng(7).normal(size=(9, 4))
    d = feature_distances(x)
    assert d.shape == (9, 9) and np.allclose(d, d.T) and np.allclose(np.diag(d), 0.0, atol=1e-6)
    assert d[2, 5] == pytest.approx(_dist(x, 2, 5), abs=1e-9)
    np.testing.assert_array_equal(optimal_keyframe_path(d, 4), mdo_keyframes(x, 4))
    # a per-frame bonus on the chosen frame j: brute force over the same total
    bonus = np.zeros(9); bonus[3] = 10.0
    got = optimal_keyframe_path(d + bonus[None, :], 4)
    best, best_idx = _brute(x, 4, lambda x_, a, b: _dist(x_, a, b) + bonus[b], maximise=True)
    np.testing.assert_array_equal(got, best_idx)
    assert 3 in got
    # minimising reads the same DP: the smallest interpolation error is MIEO's
    np.testing.assert_array_equal(optimal_keyframe_path(interpolation_errors(x), 4, maximise=False),
                                  select_keyframes(x, 4, "mieo"))


@pytest.mark.parametrize("score, k, msg", [
    (np.zeros((4, 3)), 2, "square"), (np.full((4, 4), np.nan), 2, "NaN"), (np.zeros((4, 4)), 5, "only 4 frames"),
    (np.zeros((4, 4)), 1, "k must be"),
])
def test_optimal_keyframe_path_errors(score, k, msg):
    from salad_core.keymotion.selection import optimal_keyframe_path

    with pytest.raises(ValueError, match=msg):
        optimal_keyframe_path(score, k)
