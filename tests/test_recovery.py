"""Joint recovery (salad_core.recovery): known answers on synthetic rigid skeletons, fixed bones,
locked feet, the floor, shapes and errors.

The motions are built here from the skeleton's rest offsets and target bone lengths (no corpus, no
real data), so every bone has its exact target length and the features are exact.
"""
from __future__ import annotations

import time

import numpy as np
import pytest
import torch

from salad_core.motion import bone_lengths, features_to_joints, joints_to_features
from salad_core.recovery import (
    METHODS,
    RecoveryConfig,
    branch_joints,
    plant_feet,
    contact_lock_mask,
    fit_skeleton,
    lift_above_floor,
    lock_feet,
    recover_joints,
    two_bone_ik,
)
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
SL = SK.feature_slices
J = SK.num_joints
TARGET = np.asarray(SK.bone_lengths)
EXACT = RecoveryConfig(smooth_sigma=0.0, lock_contacts=False, floor=False)   # the bare fit


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _rigid_motion(n=60, turn=0.0, swing=0.5, crouch=0.0, speed=0.02):
    """Joints ``(n, J, 3)`` of the target skeleton: legs and arms swing, the body yaws by ``turn``
    radians over the clip and walks ``speed`` m/frame forward; ``crouch`` bends both knees (rad)."""
    t = np.arange(n)
    phase = np.sin(2 * np.pi * t / 20.0)
    theta = np.zeros((n, J))
    # hips swing the thighs, knees the shins, in opposition left/right; arms the other way
    for j, sign in ((4, 1), (5, -1), (16, -1), (17, 1), (18, -1), (19, 1)):
        theta[:, j] = sign * swing * phase
    theta[:, 4] += crouch
    theta[:, 5] += crouch
    theta[:, 7] -= 2 * crouch
    theta[:, 8] -= 2 * crouch
    yaw = np.linspace(0.0, turn, n)
    rot = _rot_y(yaw)[:, None] @ _rot_x(theta)                                  # (n, J, 3, 3)
    raw = np.asarray(SK.raw_offsets, dtype=np.float64)
    dirs = (rot @ raw[None, :, :, None])[..., 0]                                 # (n, J, 3)
    pos = np.zeros((n, J, 3))
    heading = (_rot_y(yaw) @ np.array([0.0, 0.0, 1.0]))
    pos[:, 0] = np.cumsum(heading * speed, axis=0) + np.array([0.0, 1.0, 0.0])
    for j in range(1, J):
        pos[:, j] = pos[:, SK.parents[j]] + TARGET[j] * dirs[:, j]
    return pos


@pytest.fixture(scope="module")
def walk_features():
    return joints_to_features(_rigid_motion()).astype(np.float64)


def _bone_error(joints):
    return np.abs(bone_lengths(joints, SK)[..., 1:] - TARGET[1:]).max()


# --------------------------------------------------------------------------- known answers
def test_positions_is_the_standard_recovery(walk_features):
    np.testing.assert_array_equal(recover_joints(walk_features, "positions"), features_to_joints(walk_features))


@pytest.mark.parametrize("method", ["fk", "fit"])
def test_exact_features_of_a_rigid_skeleton_give_the_joints_back(walk_features, method):
    truth = features_to_joints(walk_features)
    got = recover_joints(walk_features, method, config=EXACT)
    assert np.abs(got - truth).max() < 1e-3                                   # within a millimetre
    assert _bone_error(got) < 1e-9


def test_default_fit_barely_moves_good_motion(walk_features):
    truth = features_to_joints(walk_features)
    got = recover_joints(walk_features, "fit")
    err = np.linalg.norm(got - truth, axis=-1)
    assert err.mean() < 0.01, err.mean()                                       # under 1 cm on average
    assert _bone_error(got) < 1e-9


def test_fk_follows_the_positions_heading_after_a_half_turn():
    # turning past 180 degrees flips the sign of the stored yaw step (arcsin of a w<0 quaternion):
    # the rotation features then disagree with the positions by a yaw of the whole body
    # (the official code's quirk, which joints_to_features reproduces with official_heading=True)
    motion = _rigid_motion(n=60, turn=2 * np.pi, swing=0.3)
    feats = joints_to_features(motion, official_heading=True).astype(np.float64)
    truth = features_to_joints(feats)
    raw_fk = recover_joints(feats, "fk", config=RecoveryConfig(align_heading=False))
    aligned = recover_joints(feats, "fk")
    assert np.linalg.norm(raw_fk - truth, axis=-1).max() > 0.05
    assert np.linalg.norm(aligned - truth, axis=-1).max() < 1e-3
    # salad's own features store the right yaw step: rotations and positions agree without alignment
    fixed = joints_to_features(motion).astype(np.float64)
    plain_fk = recover_joints(fixed, "fk", config=RecoveryConfig(align_heading=False))
    assert np.linalg.norm(plain_fk - features_to_joints(fixed), axis=-1).max() < 1e-3


def test_motion_lengths_are_the_median_of_the_positions(walk_features):
    scaled = walk_features.copy()
    scaled[:, SL["ric"]] *= 1.1                                   # every joint 10 % further from the root axis
    got = recover_joints(scaled, "fk", config=RecoveryConfig(lengths="motion"))
    pos = features_to_joints(scaled)
    want = np.median(bone_lengths(pos, SK), axis=0)
    np.testing.assert_allclose(bone_lengths(got, SK), np.broadcast_to(want, got.shape[:2]), atol=1e-9)


# --------------------------------------------------------------------------- fixed bones under noise
@pytest.mark.parametrize("method", ["fk", "fit"])
def test_bone_lengths_exactly_fixed_on_noisy_features(walk_features, method):
    rng = np.random.default_rng(0)
    noisy = walk_features + rng.normal(scale=0.05, size=walk_features.shape)
    pos_err = _bone_error(recover_joints(noisy, "positions"))
    got = recover_joints(noisy, method)
    assert pos_err > 0.02                                          # the noise does stretch the raw bones
    assert _bone_error(got) < 1e-9


def test_fit_skeleton_aims_each_bone_at_its_predicted_child():
    p = _rigid_motion(n=5)
    stretched = p.copy()
    stretched[:, 20] += 0.3 * (p[:, 20] - p[:, 18])                # left wrist 30 % further out
    q = fit_skeleton(stretched, TARGET, SK)
    np.testing.assert_allclose(q[:, :20], p[:, :20], atol=1e-12)   # nothing before the wrist moves
    np.testing.assert_allclose(q[:, 20], p[:, 20], atol=1e-12)     # same direction, target length


# --------------------------------------------------------------------------- feet and floor
def _sliding_stance(n=40, slide=0.01, on=slice(None)):
    """A crouched stance whose left ankle and toe slide ``slide`` m/frame in x in the features."""
    feats = joints_to_features(_rigid_motion(n=n + 1, swing=0.0, crouch=0.3, speed=0.0)).astype(np.float64)
    drift = slide * (np.arange(n) - n / 2)
    for jnt in SK.fid_l:                                           # ankle, toe
        feats[:, SL["ric"].start + 3 * (jnt - 1)] += drift
    contacts = feats[:, SL["contacts"]]
    contacts[:] = 0.0
    contacts[on] = 1.0
    return feats


def test_a_foot_in_contact_stays_put():
    feats = _sliding_stance(slide=0.002)                           # the raw foot slides 7.8 cm over the run
    raw = recover_joints(feats, "positions")
    got = recover_joints(feats, "fit")
    ankle, toe = SK.fid_l
    assert np.ptp(raw[:, ankle, 0]) > 0.075
    for jnt in (ankle, toe):
        assert np.ptp(got[:, jnt, 0]) < 1e-3 and np.ptp(got[:, jnt, 2]) < 1e-3
    assert _bone_error(got) < 1e-9


def test_a_gliding_foot_is_held_only_within_the_leash():
    """A foot the model glides 39 cm is not pinned 20 cm from where the model put it: it stays within
    ``max_foot_shift`` of its own track (and slides the rest), the leg is never straighter than the
    model made it plus ``reach_slack``, and the other joints barely move."""
    feats = _sliding_stance()
    raw = recover_joints(feats, "fit", config=RecoveryConfig(lock_contacts=False, floor=False))  # bones fitted, nothing planted
    cfg = RecoveryConfig()
    got = recover_joints(feats, "fit")
    ankle, toe = SK.fid_l
    hip = SK.parents[SK.parents[ankle]]
    assert np.ptp(raw[:, ankle, 0]) > 0.3
    off = np.linalg.norm((got - raw)[:, [ankle, toe]][..., [0, 2]], axis=-1)
    assert off.max() <= cfg.max_foot_shift + 0.01, off.max()
    assert np.ptp(got[:, ankle, 0]) < np.ptp(raw[:, ankle, 0]) - 2 * cfg.max_foot_shift + 0.02   # held back by the leash
    ext_raw = np.linalg.norm(raw[:, ankle] - raw[:, hip], axis=-1)
    ext_got = np.linalg.norm(got[:, ankle] - got[:, hip], axis=-1)
    assert (ext_got <= ext_raw + cfg.reach_slack + 1e-6).all()
    others = [j for j in range(J) if j not in (ankle, toe, SK.parents[ankle])]
    assert np.linalg.norm(got[:, others] - raw[:, others], axis=-1).max() < 0.02
    assert _bone_error(got) < 1e-9
    # without the leash the old lock pins the foot at the run's median: 19 cm from the model's foot
    pinned = recover_joints(feats, "fit", config=RecoveryConfig(max_foot_shift=None))
    assert np.linalg.norm((pinned - raw)[:, ankle][:, [0, 2]], axis=-1).max() > 0.15


def test_a_planted_foot_out_of_the_legs_reach_moves_the_body_not_the_leg():
    """Straight legs, the left foot planted all along, and the model glides the whole body 5 cm forward
    halfway: the foot's anchor (the run's median) is out of a straight leg's reach in both halves, so
    the body (root and all) moves towards the foot instead of the leg stretching."""
    n = 40
    j = _rigid_motion(n=n, swing=0.0, speed=0.0)                   # straight legs, standing still
    j[..., 1] -= j[..., 1].min()
    j[20:, :, 2] += 0.05                                           # second half: everything 5 cm forward
    ankle, toe = SK.fid_l
    lock = np.zeros((n, 4), bool)
    lock[:, :2] = True
    out = plant_feet(j, lock, SK, max_foot_shift=0.06, reach_slack=0.0, root_sigma=0.0, move_root=True)
    held = plant_feet(j, lock, SK, max_foot_shift=0.06, reach_slack=0.0, root_sigma=0.0)
    hip = SK.parents[SK.parents[ankle]]
    ext_in = np.linalg.norm(j[:, ankle] - j[:, hip], axis=-1)
    ext_out = np.linalg.norm(out[:, ankle] - out[:, hip], axis=-1)
    assert (ext_out <= ext_in + 1e-6).all()                        # never straighter
    # the anchor is 2.5 cm from the model's foot in each half; the body follows the foot most of the way
    assert np.ptp(out[:, 0, 2]) < 0.03 and np.abs(out[:, ankle, 2] - 0.025 - j[0, ankle, 2]).max() < 0.01
    assert _bone_error(out) < 1e-9
    # without moving the root (the default) the body stays where the model put it and the foot, out of
    # reach, stays with the straight leg: the leg is still never straighter than the model made it
    np.testing.assert_allclose(held[:, :4], j[:, :4], atol=1e-12)
    ext_held = np.linalg.norm(held[:, ankle] - held[:, hip], axis=-1)
    assert (ext_held <= ext_in + 1e-6).all()
    assert np.abs(held[:, ankle] - j[:, ankle]).max() < 0.03                  # tilted towards the anchor, 2.5 cm


def test_rigid_branches_keep_the_rigs_rest_geometry():
    """With rigid branches the pelvis's and spine3's children keep one geometry (their offsets' pairwise dot
    products) in every frame, even on noisy predictions; without, they do not."""
    rng = np.random.default_rng(0)
    p = _rigid_motion(n=20) + rng.normal(scale=0.02, size=(20, J, 3))
    rigid = fit_skeleton(p, TARGET, SK, rigid_branches=True)
    loose = fit_skeleton(p, TARGET, SK)
    for par, kids in branch_joints(SK).items():
        for q, ok in ((rigid, True), (loose, False)):
            off = q[:, list(kids)] - q[:, par:par + 1]
            gram = np.einsum("nci,ndi->ncd", off, off)             # pairwise dot products: rotation invariant
            err = np.abs(gram - gram[:1]).max()
            assert (err < 1e-9) if ok else (err > 1e-4), (par, err)
    assert _bone_error(rigid) < 1e-9


def test_contact_on_and_off_blends_without_a_pop():
    feats = _sliding_stance(n=60, slide=0.003, on=slice(20, 40))
    got = recover_joints(feats, "fit", config=RecoveryConfig(smooth_sigma=0.0))
    raw = recover_joints(feats, "positions")
    ankle = SK.fid_l[0]
    step = np.linalg.norm(np.diff(got[:, ankle], axis=0), axis=-1)
    raw_step = np.linalg.norm(np.diff(raw[:, ankle], axis=0), axis=-1)
    assert np.ptp(got[20:40, ankle, 0]) < 1e-3                     # locked inside the run
    # leaving the run, the foot must catch up the 2.85 cm it was held back (anchor: the run's median);
    # the smoothstep over blend + 1 frames moves at most 1.5 / (blend + 1) of that per frame on top of
    # the slide (without the blend it would jump by all of it in one frame)
    blend = RecoveryConfig().blend_frames
    jump = abs(got[39, ankle, 0] - raw[39, ankle, 0])
    assert 0.025 < jump < 0.03
    assert step.max() <= 1.02 * (raw_step.max() + 1.5 * jump / (blend + 1))
    free = recover_joints(feats, "fit", config=RecoveryConfig(smooth_sigma=0.0, lock_contacts=False))
    np.testing.assert_allclose(got[:20 - blend], free[:20 - blend], atol=1e-12)   # beyond the blend: the unlocked fit
    np.testing.assert_allclose(got[40 + blend:], free[40 + blend:], atol=1e-12)
    assert np.abs(got[20 - blend:20] - free[20 - blend:20]).max() > 1e-3          # inside it: blended


def test_lock_mask_gates_on_channel_height_and_speed():
    feats = _sliding_stance(n=30)
    lock = contact_lock_mask(feats)
    assert lock.shape == (30, 4) and lock.all()
    high = feats.copy()
    high[:, SL["ric"].start + 3 * (SK.fid_l[0] - 1) + 1] += 0.5    # left ankle 50 cm up
    assert not contact_lock_mask(high)[:, 0].any() and contact_lock_mask(high)[:, 2].all()
    fast = feats.copy()
    fast[:, SL["local_vel"].start + 3 * SK.fid_r[0]] = 0.05         # right ankle 1 m/s in the velocity channel
    assert not contact_lock_mask(fast)[:, 2].any()
    assert contact_lock_mask(fast, config=RecoveryConfig(contact_speed=None))[:, 2].all()
    short = feats.copy()
    short[:, SL["contacts"]] = 0.0
    short[5:7, SL["contacts"]] = 1.0                                # a 2-frame flicker
    assert not contact_lock_mask(short).any()


def test_nothing_below_the_floor():
    feats = joints_to_features(_rigid_motion(n=41)).astype(np.float64)
    feats[:, SL["root_y"]] -= 0.1
    feats[:, SL["ric"].start + 1:SL["ric"].stop:3] -= 0.1           # whole body 10 cm down
    assert recover_joints(feats, "positions")[..., 1].min() < -0.09
    got = recover_joints(feats, "fit")
    assert got[..., 1].min() >= -1e-9
    assert _bone_error(got) < 1e-9


def test_lift_above_floor_moves_whole_frames():
    j = _rigid_motion(n=4)
    j[..., 1] -= j[..., 1].min(-1, keepdims=True) + np.array([0.0, 0.1, 0.0, 0.2])[:, None]
    out = lift_above_floor(j)
    np.testing.assert_allclose(out[..., 1].min(-1), [0.0, 0.0, 0.0, 0.0], atol=1e-12)
    want = np.zeros_like(j)
    want[..., 1] = np.array([0.0, 0.1, 0.0, 0.2])[:, None]         # only the sunken frames, by their depth
    np.testing.assert_allclose(out - j, want, atol=1e-12)


def test_two_bone_ik_reaches_and_keeps_lengths():
    rng = np.random.default_rng(1)
    root = rng.normal(size=(50, 3))
    mid = root + rng.normal(size=(50, 3))
    goal = root + 0.6 * rng.normal(size=(50, 3))
    l1, l2 = 0.4, 0.43
    new_mid, end = two_bone_ik(root, mid, goal, l1, l2)
    dist = np.linalg.norm(goal - root, axis=-1)
    reach = (dist < l1 + l2) & (dist > abs(l1 - l2))
    np.testing.assert_allclose(np.linalg.norm(new_mid - root, axis=-1), l1, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(end - new_mid, axis=-1), l2, atol=1e-9)
    np.testing.assert_allclose(end[reach], goal[reach], atol=1e-5)
    far = dist > l1 + l2                                            # out of reach: fully stretched towards the goal
    along = (end[far] - root[far]) / np.linalg.norm(end[far] - root[far], axis=-1, keepdims=True)
    np.testing.assert_allclose(along, (goal[far] - root[far]) / dist[far, None], atol=1e-6)
    # the bend stays in the plane of the old middle joint
    normal = np.cross(mid - root, goal - root)
    np.testing.assert_allclose((normal * (new_mid - root)).sum(-1)[reach], 0.0, atol=1e-9)


def test_lock_feet_validates_its_arrays():
    j = _rigid_motion(n=5)
    with pytest.raises(ValueError, match=r"lock must have shape \(5, 4\)"):
        lock_feet(j, np.ones((5, 3), bool))


# --------------------------------------------------------------------------- shapes and inputs
@pytest.mark.parametrize("method", METHODS)
def test_shapes_batches_and_torch(walk_features, method):
    single = recover_joints(walk_features, method)
    assert single.shape == (walk_features.shape[0], J, 3) and single.dtype == np.float64
    batch = np.stack([walk_features, walk_features[::-1].copy()])
    got = recover_joints(batch, method)
    assert got.shape == (2, walk_features.shape[0], J, 3)
    np.testing.assert_allclose(got[0], single, atol=1e-12)
    np.testing.assert_allclose(got[1], recover_joints(batch[1], method), atol=1e-12)
    t = recover_joints(torch.from_numpy(walk_features.astype(np.float32)), method)
    assert isinstance(t, np.ndarray) and t.dtype == np.float32
    np.testing.assert_allclose(t, single, atol=1e-3)


def test_bad_inputs_give_clear_errors(walk_features):
    with pytest.raises(ValueError, match=r"\(\.\.\., N, 263\)"):
        recover_joints(walk_features[:, :200], "fit")
    bad = walk_features.copy()
    bad[3, 10] = np.nan
    with pytest.raises(ValueError, match="non-finite"):
        recover_joints(bad, "fk")
    with pytest.raises(ValueError, match="method must be one of"):
        recover_joints(walk_features, "ik")
    with pytest.raises(TypeError, match="RecoveryConfig"):
        recover_joints(walk_features, "fit", config={"lengths": "motion"})
    with pytest.raises(ValueError, match="no target bone lengths"):
        recover_joints(np.zeros((10, 251)), "fit", skeleton="kit")


@pytest.mark.parametrize("kwargs, match", [
    ({"lengths": "median"}, "lengths must be"),
    ({"rotation_weight": 1.5}, "rotation_weight"),
    ({"smooth_sigma": -1.0}, "smooth_sigma"),
    ({"contact_threshold": 1.0}, "contact_threshold"),
    ({"contact_heights": (0.1,)}, "contact_heights"),
    ({"contact_speed": 0.0}, "contact_speed"),
    ({"min_contact_frames": 0}, "min_contact_frames"),
    ({"blend_frames": 1.5}, "blend_frames"),
])
def test_config_is_validated(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RecoveryConfig(**kwargs)


def test_fit_is_fast_enough():
    feats = joints_to_features(_rigid_motion(n=197)).astype(np.float32)     # 196 rows
    recover_joints(feats, "fit")
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        recover_joints(feats, "fit")
        times.append(time.perf_counter() - t0)
    assert min(times) < 0.05, times
