"""Motion representation (salad_core.motion, salad_core.quaternion) checked on real HumanML3D data.

Sample 012314 (tests/data): ``new_joint_vecs`` are the official 263-d features of T-1 = 170 rows,
``new_joints`` = recover_from_ric(features), i.e. the processed positions of frames 0..T-2.
"""
from __future__ import annotations

import logging
import time

import numpy as np
import pytest
import torch

from salad_core.motion import (
    FEATURE_BLOCKS,
    check_features,
    check_joints,
    compute_mean_std,
    denormalize,
    features_to_joints,
    features_to_joints_rot,
    joints_to_features,
    mirror_features,
    mirror_joints,
    normalize,
    process_joints,
    recover_root,
    retarget_joints,
)
from salad_core.quaternion import (
    cont6d_to_matrix,
    matrix_to_cont6d,
    matrix_to_quat,
    qbetween,
    qinv,
    qmul,
    qnormalize,
    qrot,
    quat_from_axis_angle,
    quat_to_cont6d,
    quat_to_matrix,
)
from salad_core.skeleton import get_skeleton

HML = get_skeleton("humanml3d")
KIT = get_skeleton("kit")
SL = HML.feature_slices
J = HML.num_joints


# --------------------------------------------------------------------------- helpers
def _random_quats(rng, shape):
    return qnormalize(rng.normal(size=shape + (4,)))


def _synthetic_motion(sk, n=60, seed=0, length_scale=1.0):
    """A smooth, turning, walking-like motion ``(n, J, 3)`` on skeleton ``sk``.

    Bone directions are the raw rest directions wobbled by smooth per-bone rotations; bone lengths
    are random (not the target ones), the body walks forward while slowly turning.
    """
    rng = np.random.default_rng(seed)
    j = sk.num_joints
    lengths = rng.uniform(0.08, 0.4, size=j) * length_scale
    t = np.arange(n)[:, None]
    axes = rng.normal(size=(j, 3))
    amp = rng.uniform(0.1, 0.5, size=j)
    freq = rng.uniform(0.05, 0.2, size=j)
    wobble = quat_from_axis_angle(np.broadcast_to(axes, (n, j, 3)), amp * np.sin(freq * t))  # (n, j, 4)
    raw = np.asarray(sk.raw_offsets, dtype=np.float64)
    dirs = qrot(wobble, np.broadcast_to(raw, (n, j, 3)))
    pos = np.zeros((n, j, 3))
    pos[:, 0] = np.stack([0.02 * t[:, 0], 1.0 * length_scale + 0.03 * np.sin(0.3 * t[:, 0]), 0.03 * t[:, 0]], -1)
    for c in range(1, j):
        pos[:, c] = pos[:, sk.parents[c]] + lengths[c] * dirs[:, c]
    yaw = quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), 0.01 * t[:, 0] + 0.7)          # (n, 4)
    return qrot(yaw[:, None], pos)


def _bone_lengths(joints, sk):
    parents = np.asarray(sk.parents[1:])
    return np.linalg.norm(joints[..., 1:, :] - joints[..., parents, :], axis=-1)


def _reconstruct_full_clip(features, joints):
    """All T processed frames of the sample: ``new_joints`` plus the final frame recovered from the
    last row's local velocity (``lv = qrot(r_{T-2}, P_{T-1} - P_{T-2})``)."""
    r, _ = recover_root(features.astype(np.float64))
    lv = features[-1, SL["local_vel"]].reshape(J, 3)
    last = joints[-1] + qrot(qinv(r[-1]), lv)
    return np.concatenate([joints, last[None]], axis=0)


# --------------------------------------------------------------------------- quaternions
def test_quaternion_product_matches_matrix_product_and_rotation():
    rng = np.random.default_rng(0)
    a, b = _random_quats(rng, (50,)), _random_quats(rng, (50,))
    np.testing.assert_allclose(quat_to_matrix(qmul(a, b)), quat_to_matrix(a) @ quat_to_matrix(b), atol=1e-12)
    v = rng.normal(size=(50, 3))
    np.testing.assert_allclose(qrot(a, v), (quat_to_matrix(a) @ v[:, :, None])[..., 0], atol=1e-12)
    np.testing.assert_allclose(qrot(qinv(a), qrot(a, v)), v, atol=1e-12)
    # a quarter turn about +y sends +z to +x (right-handed, active)
    q = quat_from_axis_angle(np.array([0.0, 1.0, 0.0]), np.pi / 2)
    np.testing.assert_allclose(qrot(q, np.array([0.0, 0.0, 1.0])), [1.0, 0.0, 0.0], atol=1e-12)


def test_matrix_and_cont6d_round_trips_including_half_turns():
    rng = np.random.default_rng(1)
    q = _random_quats(rng, (200,))
    # include rotations by ~pi, where the naive w-based formula is ill-conditioned
    q[:5] = quat_from_axis_angle(rng.normal(size=(5, 3)), np.full(5, np.pi - 1e-9))
    q = q * np.where(q[:, :1] < 0, -1.0, 1.0)
    back = matrix_to_quat(quat_to_matrix(q))
    # same rotation: q and -q agree; compare matrices and |dot|
    np.testing.assert_allclose(np.abs((back * q).sum(-1)), 1.0, atol=1e-9)
    R = quat_to_matrix(q)
    c6 = matrix_to_cont6d(R)
    assert c6.shape == (200, 6)
    np.testing.assert_allclose(c6[:, :3], R[:, :, 0])   # first column = (R00, R10, R20)
    np.testing.assert_allclose(cont6d_to_matrix(c6), R, atol=1e-12)
    np.testing.assert_allclose(quat_to_cont6d(q), c6, atol=1e-12)
    # Gram-Schmidt accepts non-orthonormal input and returns a proper rotation
    Rn = cont6d_to_matrix(c6 * 3.0 + rng.normal(scale=0.05, size=c6.shape))
    np.testing.assert_allclose(Rn @ np.swapaxes(Rn, -1, -2), np.broadcast_to(np.eye(3), Rn.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(Rn), 1.0, atol=1e-12)


def test_qbetween_maps_direction_and_handles_opposite_vectors():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(100, 3)), rng.normal(size=(100, 3))
    q = qbetween(a, b)
    assert (q[:, 0] >= 0).all()
    got = qrot(q, a / np.linalg.norm(a, axis=-1, keepdims=True))
    np.testing.assert_allclose(got, b / np.linalg.norm(b, axis=-1, keepdims=True), atol=1e-12)
    opp = qbetween(np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]), np.array([[0.0, 2.0, 0.0], [-3.0, 0.0, 0.0]]))
    assert np.isfinite(opp).all()
    np.testing.assert_allclose(qrot(opp, np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])),
                               [[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]], atol=1e-12)


def test_quaternion_helpers_torch_match_numpy():
    rng = np.random.default_rng(3)
    a, b = _random_quats(rng, (20,)), _random_quats(rng, (20,))
    v = rng.normal(size=(20, 3))
    ta, tb, tv = (torch.tensor(x) for x in (a, b, v))
    np.testing.assert_allclose(qmul(ta, tb).numpy(), qmul(a, b), atol=1e-12)
    np.testing.assert_allclose(qrot(ta, tv).numpy(), qrot(a, v), atol=1e-12)
    np.testing.assert_allclose(matrix_to_quat(quat_to_matrix(ta)).numpy(), matrix_to_quat(quat_to_matrix(a)), atol=1e-12)
    np.testing.assert_allclose(cont6d_to_matrix(quat_to_cont6d(ta)).numpy(), quat_to_matrix(a), atol=1e-12)
    np.testing.assert_allclose(qbetween(tv, tv.flip(0)).numpy(), qbetween(v, v[::-1]), atol=1e-12)
    with pytest.raises(ValueError, match="last axis of size 4"):
        qmul(a[:, :3], b)


# --------------------------------------------------------------------------- recovery on real data
def test_features_to_joints_reproduces_reference_joints(sample_features, sample_joints):
    got = features_to_joints(sample_features)
    assert got.shape == sample_joints.shape and got.dtype == np.float32
    assert np.abs(got - sample_joints).max() < 1e-4   # measured 2.4e-7


def test_features_to_joints_rot_reproduces_reference_joints(sample_features, sample_joints):
    got = features_to_joints_rot(sample_features, "humanml3d")
    # FK of the swing rotations with the 5-decimal target bone lengths; measured 1.2e-5 m
    assert np.abs(got - sample_joints).max() < 5e-5
    np.testing.assert_allclose(_bone_lengths(got, HML), np.broadcast_to(HML.bone_lengths[1:], (len(got), J - 1)),
                               atol=1e-5)


def test_features_to_joints_torch_matches_numpy_batched_and_differentiable(sample_features, sample_joints):
    x = torch.tensor(np.stack([sample_features, mirror_features(sample_features)]), requires_grad=True)
    out = features_to_joints(x)
    assert isinstance(out, torch.Tensor) and out.shape == (2, len(sample_features), J, 3)
    np.testing.assert_allclose(out[0].detach().numpy(), sample_joints, atol=1e-4)
    np.testing.assert_allclose(out[1].detach().numpy(), features_to_joints(mirror_features(sample_features)),
                               atol=1e-4)
    out[..., -1, 0, 0].sum().backward()   # final root x depends on every earlier velocity row
    g = x.grad
    assert torch.isfinite(g).all()
    assert g[:, :-1, SL["root_lin_vel"]].abs().sum() > 0 and g[:, :-1, SL["root_rot_vel"]].abs().sum() > 0
    # rotation path (recover_from_rot) agrees between backends too
    np.testing.assert_allclose(features_to_joints_rot(torch.tensor(sample_features)).numpy(),
                               features_to_joints_rot(sample_features), atol=1e-4)


# --------------------------------------------------------------------------- extraction on real data
def test_joints_to_features_reproduces_reference_features_exactly_on_the_full_clip(sample_features,
                                                                                  sample_joints):
    """With all T frames (the last one recovered from the features), extraction matches every slice
    including the rotations: this pins the IK quirks (hip sign, sigma-20 heading, frame-0 identity,
    arms restarting from the root)."""
    full = _reconstruct_full_clip(sample_features, sample_joints)
    feats = joints_to_features(full)
    assert feats.shape == sample_features.shape and feats.dtype == np.float32
    for name in ("root", "ric", "rot", "local_vel", "contacts"):
        err = np.abs(feats[:, SL[name]] - sample_features[:, SL[name]]).max()
        assert err < 2e-4, (name, err)   # measured <= 9.1e-5 (rot), float32 input


def test_joints_to_features_on_reference_joints(sample_features, sample_joints):
    """``new_joints`` lacks the clip's final frame, so the output has T-2 = 169 rows. Contacts
    depend only on positions and match exactly. The heading is Gaussian-smoothed (sigma 20,
    'nearest'); with the last frame missing, the padding repeats frame T-2 instead of T-1, which
    changes the heading in roughly the last 2 sigma frames. Frame 0's forced identity is the
    same in both, so row 0 matches. Measured maxima over all 169 rows: root 3.0e-4, local
    velocity 4.1e-4, ric 6.8e-3 (row 168: a heading change of ~0.3 deg times up to ~1 m arm's
    length), rot 1.3e-2. Rows that end 40 or more frames before the end: ric 2.6e-4, rot 4.7e-4."""
    feats = joints_to_features(sample_joints)
    n = len(sample_joints) - 1
    assert feats.shape == (n, HML.feature_dim)
    ref = sample_features[:n]
    err = {k: np.abs(feats[:, SL[k]] - ref[:, SL[k]]).max() for k in SL}
    for name in ("root", "local_vel", "contacts"):
        assert err[name] < 1e-3, (name, err[name])
    assert err["contacts"] == 0.0
    assert err["ric"] < 1e-2 and err["rot"] < 2e-2
    early = slice(0, n - 40)
    for name in ("ric", "rot"):
        assert np.abs(feats[early, SL[name]] - ref[early, SL[name]]).max() < 1e-3, name
    # the end effect is real: the last rows differ by more than the early ones
    assert np.abs(feats[-1, SL["ric"]] - ref[n - 1, SL["ric"]]).max() > 1e-3


def test_sample_rotation_velocity_row0_is_the_frame0_identity_quirk(sample_features, sample_joints):
    # Frame 0's heading is forced to identity, frame 1 uses the smoothed heading, so row 0's yaw
    # velocity is not small in the reference (0.106 rad half angle) and we must reproduce it.
    feats = joints_to_features(sample_joints)
    assert abs(sample_features[0, 0]) > 0.05
    assert abs(feats[0, 0] - sample_features[0, 0]) < 1e-4


# --------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("seed", [0, 1])
def test_round_trip_joints_features_joints(seed):
    joints = _synthetic_motion(HML, n=50, seed=seed)
    feats = joints_to_features(joints)
    assert feats.shape == (49, 263)
    processed = process_joints(joints)
    back = features_to_joints(feats)
    np.testing.assert_allclose(back, processed[:-1], atol=1e-5)
    # bone lengths equal the target lengths (the input's were random)
    assert np.abs(_bone_lengths(joints, HML) - np.asarray(HML.bone_lengths[1:])).max() > 0.05
    np.testing.assert_allclose(_bone_lengths(back, HML), np.broadcast_to(HML.bone_lengths[1:], (49, J - 1)),
                               atol=1e-5)
    # on the floor, frame-0 root at the origin in x and z, facing +Z (hips: left at +x)
    assert abs(processed[..., 1].min()) < 1e-6
    np.testing.assert_allclose(processed[0, 0, [0, 2]], 0.0, atol=1e-6)
    r_hip, l_hip, sdr_r, sdr_l = HML.face_joint_indx
    across = processed[0, r_hip] - processed[0, l_hip] + processed[0, sdr_r] - processed[0, sdr_l]
    forward = np.cross([0.0, 1.0, 0.0], across)
    np.testing.assert_allclose(forward / np.linalg.norm(forward), [0.0, 0.0, 1.0], atol=1e-6)
    # the rotation path reproduces the same joints up to what swing rotations cannot store
    np.testing.assert_allclose(features_to_joints_rot(feats), back, atol=1e-4)
    # contacts are binary
    assert set(np.unique(feats[:, SL["contacts"]])) <= {0.0, 1.0}


def test_retarget_keeps_directions_and_scales_root():
    joints = _synthetic_motion(HML, n=10, seed=4)
    out = retarget_joints(joints, HML)
    parents = np.asarray(HML.parents[1:])
    d_in = joints[:, 1:] - joints[:, parents]
    d_out = out[:, 1:] - out[:, parents]
    cos = (d_in * d_out).sum(-1) / np.linalg.norm(d_in, axis=-1) / np.linalg.norm(d_out, axis=-1)
    np.testing.assert_allclose(cos, 1.0, atol=1e-12)
    l1, l2 = HML.leg_bones
    src = np.linalg.norm(d_in[0], axis=-1)
    scale = (HML.bone_lengths[l1] + HML.bone_lengths[l2]) / (src[l1 - 1] + src[l2 - 1])
    np.testing.assert_allclose(out[:, 0], scale * joints[:, 0], atol=1e-12)
    with pytest.raises(ValueError, match="no target bone lengths"):
        retarget_joints(_synthetic_motion(KIT, n=5), KIT)


def test_contacts_threshold_on_squared_displacement():
    joints = _synthetic_motion(HML, n=30, seed=5)
    f_default = joints_to_features(joints)
    p = process_joints(joints)
    cj = list(HML.contact_joints)
    disp2 = ((p[1:, cj] - p[:-1, cj]) ** 2).sum(-1)
    np.testing.assert_array_equal(f_default[:, SL["contacts"]], (disp2 < HML.foot_threshold).astype(np.float32))
    big = joints_to_features(joints, feet_threshold=1e3)
    assert (big[:, SL["contacts"]] == 1).all()
    with pytest.raises(ValueError, match="feet_threshold must be positive"):
        joints_to_features(joints, feet_threshold=0.0)


def test_kit_features_have_251_dims_and_round_trip():
    joints = _synthetic_motion(KIT, n=40, seed=6, length_scale=1000.0)   # KIT is ~mm
    feats = joints_to_features(joints, "kit")
    assert feats.shape == (39, 251)
    processed = process_joints(joints, "kit")
    np.testing.assert_allclose(features_to_joints(feats, "kit"), processed[:-1], atol=1e-2)  # float32 at ~1e3
    # no retargeting for KIT: the bone lengths are the input's
    np.testing.assert_allclose(_bone_lengths(processed, KIT), _bone_lengths(joints, KIT), rtol=1e-5)
    with pytest.raises(ValueError, match="no target bone lengths"):
        features_to_joints_rot(feats, "kit")
    fk = features_to_joints_rot(feats, "kit", offsets=np.asarray(KIT.raw_offsets) * np.r_[0, _bone_lengths(joints, KIT)[0]][:, None])
    np.testing.assert_allclose(fk, processed[:-1], atol=0.05)


def test_joints_to_features_is_fast():
    joints = _synthetic_motion(HML, n=200, seed=7)
    joints_to_features(joints)
    best = min(_time(joints_to_features, joints) for _ in range(5))
    print(f"joints_to_features: {best * 1e3:.2f} ms per 200-frame clip")
    assert best < 0.02


def _time(fn, *args):
    t0 = time.perf_counter()
    fn(*args)
    return time.perf_counter() - t0


# --------------------------------------------------------------------------- mirroring
def test_mirror_joints_swaps_sides_and_is_an_involution(sample_joints):
    m = mirror_joints(sample_joints)
    for left, right in HML.mirror_pairs:
        np.testing.assert_array_equal(m[:, left, 0], -sample_joints[:, right, 0])
        np.testing.assert_array_equal(m[:, left, 1:], sample_joints[:, right, 1:])
    np.testing.assert_array_equal(mirror_joints(m), sample_joints)
    t = torch.tensor(sample_joints)
    np.testing.assert_array_equal(mirror_joints(t).numpy(), m)


def test_mirror_features_twice_is_identity_numpy_and_torch(sample_features):
    np.testing.assert_array_equal(mirror_features(mirror_features(sample_features)), sample_features)
    t = torch.tensor(sample_features)
    assert torch.equal(mirror_features(mirror_features(t)), t)
    np.testing.assert_array_equal(mirror_features(t).numpy(), mirror_features(sample_features))
    m = mirror_features(sample_features)
    assert not np.allclose(m, sample_features)
    # left contacts become right contacts
    c = SL["contacts"].start
    np.testing.assert_array_equal(m[:, c:c + 2], sample_features[:, c + 2:c + 4])


def test_mirror_features_commutes_with_recovery(sample_features):
    """features_to_joints(mirror_features(f)) == mirror_joints(features_to_joints(f))."""
    np.testing.assert_allclose(features_to_joints(mirror_features(sample_features)),
                               mirror_joints(features_to_joints(sample_features)), atol=1e-5)
    np.testing.assert_allclose(features_to_joints_rot(mirror_features(sample_features), offsets=_mirror_offsets()),
                               mirror_joints(features_to_joints_rot(sample_features)), atol=1e-5)


def _mirror_offsets():
    # mirrored motions keep the original bone lengths on the swapped side
    lengths = np.asarray(HML.bone_lengths)[list(HML.mirror_map)]
    return np.asarray(HML.raw_offsets) * lengths[:, None]


def test_mirror_features_agrees_with_mirroring_joints(sample_joints):
    """Without retargeting, extraction is exactly mirror-equivariant (heading smoothing, the IK hip
    quirk and the frame-0 identity all commute with x -> -x): every slice agrees (measured 0.0).
    With retargeting (HumanML3D's pipeline) they cannot agree exactly: the target skeleton is
    asymmetric (e.g. left hip 0.103 m vs right 0.110 m, left leg 0.826 m vs right 0.816 m), so the
    mirrored clip is re-lengthened and its root path scaled by the right-leg ratio (0.988 here).
    Measured on 012314 (169 rows): root_y 4.9e-3, ric 7.8e-2, rot 1.2e-1, local_vel 4.0e-2,
    rot-vel 4.1e-2 (rows 22-25, a fast spin where the smoothed heading is ill-conditioned; row 0
    differs by 9.4e-3 because the face-+Z step and the IK heading weigh the re-lengthened hips
    differently), 1 of 676 contact labels flips; the means are 1e-3 to 4e-3 per slice."""
    feats = joints_to_features(sample_joints, retarget=False)
    direct = mirror_features(feats)
    via_joints = joints_to_features(mirror_joints(sample_joints), retarget=False)
    assert np.abs(direct - via_joints).max() < 1e-5

    feats_rt = joints_to_features(sample_joints)
    direct_rt = mirror_features(feats_rt)
    via_rt = joints_to_features(mirror_joints(sample_joints))
    err = {k: np.abs(direct_rt[:, SL[k]] - via_rt[:, SL[k]]).max() for k in SL}
    assert err["root_y"] < 1e-2 and err["ric"] < 0.1 and err["rot"] < 0.2
    assert np.mean(direct_rt[:, SL["contacts"]] != via_rt[:, SL["contacts"]]) < 0.01
    mean_err = {k: np.abs(direct_rt[:, SL[k]] - via_rt[:, SL[k]]).mean() for k in SL}
    # measured means: root 1.3e-3, ric 3.6e-3, rot 4.2e-3, local_vel 5.6e-4
    assert mean_err["root"] < 5e-3 and mean_err["local_vel"] < 2e-3
    assert mean_err["ric"] < 1e-2 and mean_err["rot"] < 1e-2


# --------------------------------------------------------------------------- normalisation
def test_compute_mean_std_block_structure_matches_humanml3d_std(sample_features, sample_dir):
    chunks = [sample_features[:50], sample_features[50:120], sample_features[120:]]
    mean, std = compute_mean_std(chunks, "humanml3d")
    assert mean.shape == std.shape == (263,) and mean.dtype == np.float32
    np.testing.assert_allclose(mean, sample_features.astype(np.float64).mean(0), atol=1e-6)
    per_dim = sample_features.astype(np.float64).std(0)
    ref_std = np.load(sample_dir / "Std.npy")
    for block in FEATURE_BLOCKS:
        sl = SL[block]
        np.testing.assert_allclose(std[sl], per_dim[sl].mean(), rtol=1e-5)
        # the real dataset Std.npy has the same block structure (constant within our slices)
        assert np.ptp(ref_std[sl]) < 1e-6 * max(1.0, ref_std[sl].max()), block
    boundaries = [SL[b].start for b in FEATURE_BLOCKS[1:]]
    assert all(ref_std[i] != ref_std[i - 1] for i in boundaries)


def test_compute_mean_std_guards_zero_std_and_skips_nan(caplog):
    rng = np.random.default_rng(8)
    a = rng.normal(size=(30, 263)).astype(np.float32)
    a[:, SL["contacts"]] = 1.0
    bad = a.copy()
    bad[3, 7] = np.nan
    with caplog.at_level(logging.WARNING, logger="salad_core.motion"):
        mean, std = compute_mean_std([a, bad], min_std=1e-4)
    assert np.all(std[SL["contacts"]] == np.float32(1e-4))
    np.testing.assert_allclose(mean, a.mean(0), atol=1e-6)   # the NaN array was skipped
    assert "contacts" in caplog.text and "skipped 1" in caplog.text
    with pytest.raises(ValueError, match="no finite frame"):
        compute_mean_std([bad])
    with pytest.raises(ValueError, match=r"feature_arrays\[0\] must have shape \(\.\.\., 263\)"):
        compute_mean_std([a[:, :100]])


def test_normalize_denormalize_round_trip_numpy_and_torch(sample_features, sample_dir):
    mean, std = np.load(sample_dir / "Mean.npy"), np.load(sample_dir / "Std.npy")
    z = normalize(sample_features, mean, std)
    np.testing.assert_allclose(z, (sample_features - mean) / std, rtol=1e-6)
    np.testing.assert_allclose(denormalize(z, mean, std), sample_features, atol=1e-5)
    t = torch.tensor(sample_features)[None]                      # (B, N, D)
    zt = normalize(t, mean, std)
    assert isinstance(zt, torch.Tensor) and zt.dtype == torch.float32
    np.testing.assert_allclose(zt[0].numpy(), z, atol=1e-5)
    np.testing.assert_allclose(denormalize(zt, torch.tensor(mean), torch.tensor(std))[0].numpy(),
                               sample_features, atol=1e-5)
    with pytest.raises(ValueError, match=r"mean must have shape \(263,\).*got shape \(251,\)"):
        normalize(sample_features, mean[:251], std)


# --------------------------------------------------------------------------- validation errors
def test_errors_name_expected_and_found(sample_features, sample_joints):
    with pytest.raises(ValueError, match=r"features must have shape \(\.\.\., N, 263\).*got shape \(170, 251\)"):
        features_to_joints(sample_features[:, :251])
    with pytest.raises(ValueError, match=r"\(\.\.\., N, 251\) for skeleton 'kit'"):
        features_to_joints(sample_features, "kit")
    bad = sample_features.copy()
    bad[5, 10] = np.inf
    with pytest.raises(ValueError, match=r"1 non-finite values.*index \(5, 10\)"):
        features_to_joints(bad)
    with pytest.raises(ValueError, match=r"joints must have shape \(\.\.\., N, 22, 3\).*got shape \(170, 21, 3\)"):
        joints_to_features(sample_joints[:, :21])
    with pytest.raises(ValueError, match="at least 2 frame"):
        joints_to_features(sample_joints[:1])
    nan_j = sample_joints.copy()
    nan_j[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        joints_to_features(nan_j)
    with pytest.raises(ValueError, match="unknown skeleton 'smpl'"):
        joints_to_features(sample_joints, "smpl")
    assert check_features(sample_features.tolist()).shape == sample_features.shape   # array-likes accepted
    with pytest.raises(ValueError, match="one motion"):
        joints_to_features(sample_joints[None])
    with pytest.raises(ValueError, match=r"joints must have shape \(\.\.\., 22, 3\)"):
        mirror_joints(sample_joints[..., :2])
    check_joints(sample_joints)   # valid input passes


def test_recover_root_matches_recovered_pelvis(sample_features):
    r, root = recover_root(sample_features)
    assert r.shape == (len(sample_features), 4) and root.shape == (len(sample_features), 3)
    np.testing.assert_array_equal(r[0], [1.0, 0.0, 0.0, 0.0])            # frame 0 heading = identity
    np.testing.assert_allclose(root, features_to_joints(sample_features)[:, 0], atol=1e-6)
    np.testing.assert_allclose(root[:, 1], sample_features[:, SL["root_y"].start])
    # the stored yaw velocity is the half angle: 2 * arcsin(y) steps of the heading
    half = np.arctan2(r[:, 2], r[:, 0])
    np.testing.assert_allclose(np.diff(half), sample_features[:-1, 0], atol=1e-5)
    rt, roott = recover_root(torch.tensor(sample_features))
    np.testing.assert_allclose(roott.numpy(), root, atol=1e-4)


def test_bone_lengths_of_a_processed_clip_are_the_target_skeleton(sample_joints):
    from salad_core.motion import bone_lengths

    sk = get_skeleton("humanml3d")
    lengths = bone_lengths(sample_joints)
    assert lengths.shape == sample_joints.shape[:2]
    assert np.all(lengths[:, 0] == 0.0)                       # the root has no bone
    np.testing.assert_allclose(lengths, np.broadcast_to(sk.bone_lengths, lengths.shape), atol=1e-4)
    # torch gives the same; stretching the motion by 2 doubles every bone
    t = bone_lengths(torch.from_numpy(2.0 * sample_joints))
    np.testing.assert_allclose(t.numpy(), 2.0 * lengths, rtol=1e-5, atol=1e-6)
    with pytest.raises(ValueError, match="joints must have shape"):
        bone_lengths(sample_joints[:, :21])


SAMPLE = __import__("pathlib").Path(__file__).parent / "data" / "humanml3d_sample"


def _turning_walk(turns: float = 2.0, frames: int = 120) -> np.ndarray:
    """The real sample's first pose carried round a circle while turning ``turns`` times (N, 22, 3)."""
    pose = np.load(SAMPLE / "new_joints" / "012314.npy")[0].astype(np.float64)
    pose = pose - np.array([pose[0, 0], 0.0, pose[0, 2]])
    out = []
    for a in np.linspace(0.0, 2 * np.pi * turns, frames):
        rot = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        out.append(pose @ rot.T + np.array([0.5 * np.sin(a), 0.0, 0.5 * np.cos(a)]))
    return np.stack(out)


def test_heading_velocity_is_right_when_the_motion_turns_around():
    joints = _turning_walk()
    fixed = features_to_joints(joints_to_features(joints))
    official = features_to_joints(joints_to_features(joints, official_heading=True))
    err_fixed = np.linalg.norm(fixed - process_joints(joints)[:-1], axis=-1).max()
    err_official = np.linalg.norm(official - process_joints(joints)[:-1], axis=-1).max()
    assert err_fixed < 0.01                       # metres: the round trip holds through 720 degrees
    assert err_official > 0.2                     # the official arcsin quirk: a wrong turn, then drift
    # the two agree on motions that never turn around, e.g. the real sample
    real = np.load(SAMPLE / "new_joints" / "012314.npy")
    np.testing.assert_array_equal(joints_to_features(real), joints_to_features(real, official_heading=True))
