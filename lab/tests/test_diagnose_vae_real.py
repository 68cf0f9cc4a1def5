"""The pure functions of lab/scripts/vae/diagnose_vae_real.py (issue 21's diagnosis of real-clip reconstruction):
nearest neighbours, aggregation, correlations, resampling and the torso re-rigging, on small synthetic
inputs with known answers. Not the shipped VAE's figures (the script prints those)."""
from __future__ import annotations

import numpy as np
import pytest

from _lab import load_script
from salad_core.data import deepmimic
from salad_core.motion import features_to_joints, joints_to_features
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
J = SK.num_joints

pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def D():
    return load_script("diagnose_vae_real")


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


# ----------------------------------------------------------------------------- nearest neighbours
def test_nearest_neighbour_finds_the_shifted_pose_at_its_known_distance(D):
    rng = np.random.default_rng(0)
    bank = rng.normal(size=(50, J, 3)).astype(np.float32)
    query = bank[[7, 31]].copy()
    query[0, 5] += [0.03, 0.0, 0.04]            # one joint moved by 5 cm: mean joint distance 5 / 22 cm
    dist, idx, per_joint = D.nearest_neighbours(query, bank, k=4, chunk=1)
    assert idx.tolist() == [7, 31]
    np.testing.assert_allclose(dist, [0.05 / J, 0.0], atol=1e-6)
    np.testing.assert_allclose(per_joint[0, 5], 0.05, atol=1e-6)
    assert per_joint[0].sum() == pytest.approx(0.05, abs=1e-6) and np.allclose(per_joint[1], 0.0)


def test_nearest_neighbour_equals_brute_force_when_every_pose_is_a_candidate(D):
    rng = np.random.default_rng(1)
    bank = rng.normal(size=(40, J, 3)).astype(np.float32)
    query = rng.normal(size=(9, J, 3)).astype(np.float32)
    brute = np.linalg.norm(query[:, None] - bank[None], axis=-1).mean(-1)        # (Q, B)
    dist, idx, _ = D.nearest_neighbours(query, bank, k=len(bank), chunk=4)
    np.testing.assert_array_equal(idx, brute.argmin(1))
    np.testing.assert_allclose(dist, brute.min(1), rtol=1e-5)
    with pytest.raises(ValueError, match="must be"):
        D.nearest_neighbours(query[:, :5], bank)


# ----------------------------------------------------------------------------- aggregation
def test_per_joint_error_is_root_aligned_and_parts_average_their_joints(D):
    rng = np.random.default_rng(2)
    gt = rng.normal(size=(6, J, 3))
    pred = gt + rng.normal(scale=0.05, size=gt.shape)
    err = D.per_joint_error(pred + [1.0, 2.0, 3.0], gt)                     # a global shift changes nothing
    np.testing.assert_allclose(err, D.per_joint_error(pred, gt))
    assert np.allclose(err[:, 0], 0.0) and err.shape == (6, J)
    parts = D.part_means(err)
    part_of = np.asarray(SK.joint_to_part)
    counts = np.bincount(part_of)
    # each part is the mean of its joints: counts-weighted part means sum to the sum over joints
    total = sum(parts[name] * counts[k] for k, name in enumerate(SK.part_names))
    assert total == pytest.approx(err.mean(0).sum())
    assert parts["root"] == 0.0
    # the library's per-part error (root part left out) agrees
    from salad_core.eval.reconstruction import part_errors

    for name, value in part_errors(pred, gt).items():
        assert parts[name] == pytest.approx(value)
    one_hot = np.zeros(J)
    one_hot[SK.joint_names.index("head")] = 1.0
    head_part = D.part_means(one_hot)["head"]
    assert head_part == pytest.approx(1.0 / counts[SK.part_names.index("head")])


def test_pose_descriptor_is_the_root_relative_pose(D, sample_features):
    desc = D.pose_descriptor(sample_features)
    joints = features_to_joints(sample_features.astype(np.float64))
    assert desc.shape == (len(sample_features), J, 3) and np.all(desc[:, 0] == 0)
    # heading-aligned root-relative positions: same distances from the root, same heights above it
    np.testing.assert_allclose(np.linalg.norm(desc, axis=-1), np.linalg.norm(joints - joints[:, :1], axis=-1),
                               atol=1e-5)
    np.testing.assert_allclose(desc[..., 1], joints[..., 1] - joints[:, :1, 1], atol=1e-5)


def test_swap_columns(D):
    a, b = np.zeros((3, 10)), np.ones((3, 10))
    out = D.swap_columns(a, b, slice(0, 4))
    assert out[:, :4].all() and not out[:, 4:].any() and not a.any()


# ----------------------------------------------------------------------------- statistics
def test_rank_correlations(D):
    rng = np.random.default_rng(3)
    x = rng.normal(size=400)
    assert D.spearman(x, np.exp(x)) == pytest.approx(1.0)
    assert D.spearman(x, -x ** 3) == pytest.approx(-1.0)
    assert np.isnan(D.spearman(x, np.ones_like(x)))
    z = rng.normal(size=4000)
    a, b = z + 0.3 * rng.normal(size=z.size), z + 0.3 * rng.normal(size=z.size)
    assert D.spearman(a, b) > 0.8                                    # both follow z ...
    assert abs(D.partial_spearman(a, b, z)) < 0.1                    # ... and nothing else
    with pytest.raises(ValueError):
        D.spearman([1, 2], [1, 2])


def test_binned_counts_and_means(D):
    rows = D.binned([0.5, 1.5, 1.7, 5.0], [1.0, 2.0, 4.0, 9.0], [0, 1, 2, 3])
    assert rows[0] == (0.0, 1.0, 1, 1.0) and rows[1] == (1.0, 2.0, 2, 3.0)
    assert rows[2][2] == 0 and np.isnan(rows[2][3])


def test_speed_and_resampling(D):
    n = 11
    joints = np.zeros((n, J, 3))
    joints[..., 0] = np.arange(n)[:, None] * 0.1                    # every joint 0.1 m per frame along x
    np.testing.assert_allclose(D.frame_speed(joints, fps=20.0), 2.0)
    np.testing.assert_allclose(D.resample_joints(joints, 1.0), joints)
    slow = D.resample_joints(joints, 0.5)
    assert len(slow) == 2 * (n - 1) + 1
    np.testing.assert_allclose(D.frame_speed(slow, fps=20.0), 1.0)
    fast = D.resample_joints(joints, 2.0)
    np.testing.assert_allclose(fast, joints[::2])
    with pytest.raises(ValueError):
        D.resample_joints(joints, 0.0)


def test_rerigged_features_round_trip(D, sample_features):
    smpl = D.smpl_rest_directions()
    f = D.rerig_features(sample_features[:40], smpl, smpl)
    assert f.shape == (39, 263) and np.isfinite(f).all()
    again = features_to_joints(joints_to_features(features_to_joints(f.astype(np.float64))).astype(np.float64))
    assert np.isfinite(again).all()
