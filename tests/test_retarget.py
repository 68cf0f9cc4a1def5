"""salad_core.retarget: moving a motion onto another rig's rigid torso geometry with every limb kept
(issue 21), and the DeepMimic converter that uses it (HumanML3D's torso by default)."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core import retarget as R
from salad_core.data import deepmimic
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
J = SK.num_joints
IX = {n: i for i, n in enumerate(SK.joint_names)}
needs_pybullet = pytest.mark.skipif(not deepmimic.pybullet_available(), reason="pybullet (extra 'deepmimic') is not installed")


def _rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def _hip_angle(x: np.ndarray) -> np.ndarray:
    """Degrees between the left hip bone and the line from the right hip to the left, per frame."""
    bone, across = x[:, IX["left_hip"]] - x[:, 0], x[:, IX["left_hip"]] - x[:, IX["right_hip"]]
    cos = (bone * across).sum(-1) / np.linalg.norm(bone, axis=-1) / np.linalg.norm(across, axis=-1)
    return np.degrees(np.arccos(np.clip(cos, -1, 1)))


# ----------------------------------------------------------------------------- rig geometry
def _rig_pose(dirs, rots, rng):
    """Joints of a pose whose torso segments are the rest rig ``dirs`` turned by ``rots`` (pelvis, chest)
    and whose other bones point anywhere (limbs)."""
    seg_of = {IX[n]: seg for seg, (_, emit) in R.SEGMENTS.items() for n in emit}
    d = np.zeros((J, 3))
    for c in range(1, J):
        if c in seg_of:
            d[c] = rots[seg_of[c]] @ dirs[c]
        elif c == IX["head"]:
            d[c] = rots["chest"] @ dirs[c]
        else:
            v = rng.normal(size=3)
            d[c] = v / np.linalg.norm(v)
    out = np.zeros((J, 3))
    out[0] = rng.normal(size=3)
    for c in range(1, J):
        out[c] = out[SK.parents[c]] + d[c] * SK.bone_lengths[c]
    return out


def _flat_rig():
    """A DeepMimic-like rig: hips level with the pelvis, spine, neck and head straight up."""
    dirs = R.smpl_rest_directions().copy()
    for n, v in {"left_hip": (1, 0, 0), "right_hip": (-1, 0, 0), "spine1": (0, 1, 0), "spine2": (0, 1, 0),
                 "spine3": (0, 1, 0), "neck": (0, 1, 0), "head": (0, 1, 0)}.items():
        dirs[IX[n]] = v
    return dirs


def test_kabsch_and_swing_recover_rotations():
    rng = np.random.default_rng(4)
    q = np.stack([_rotation(rng) for _ in range(5)])
    src = rng.normal(size=(4, 3))
    np.testing.assert_allclose(R.kabsch(src, np.einsum("nij,kj->nki", q, src)), q, atol=1e-9)
    a, b = R._unit(rng.normal(size=(5, 3))), R._unit(rng.normal(size=(5, 3)))
    r = R.swing(a, b)
    np.testing.assert_allclose(np.einsum("nij,nj->ni", r, a), b, atol=1e-9)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(3), r.shape), atol=1e-9)


def test_rerig_onto_the_same_rig_is_the_identity_and_onto_another_moves_only_the_torso():
    rng = np.random.default_rng(5)
    smpl, flat = R.smpl_rest_directions(), _flat_rig()
    frames = [_rig_pose(smpl, {"pelvis": _rotation(rng), "chest": _rotation(rng)}, rng) for _ in range(4)]
    x = np.stack(frames)
    np.testing.assert_allclose(R.rerig(x, smpl, smpl), x, atol=1e-9)
    y = R.rerig(x, smpl, flat)
    lengths = np.linalg.norm(y[:, 1:] - y[:, list(SK.parents[1:])], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(SK.bone_lengths[1:], lengths.shape), atol=1e-9)
    d_x, d_y = R.bone_directions(x), R.bone_directions(y)
    torso = {IX[n] for _, emit in R.SEGMENTS.values() for n in emit} | {IX["head"]}
    limbs = [c for c in range(1, J) if c not in torso]
    np.testing.assert_allclose(d_y[:, limbs], d_x[:, limbs], atol=1e-9)       # every limb keeps its direction
    np.testing.assert_allclose(_hip_angle(y), 0.0, atol=1e-5)                  # the flat rig's hips: level
    assert (_hip_angle(x) > 50).all()                                          # the SMPL rig's: well below
    np.testing.assert_allclose(R.rerig(y, flat, smpl), x, atol=1e-9)           # and back
    q = _rotation(rng)                                                          # equivariant
    np.testing.assert_allclose(R.rerig(x @ q.T, smpl, flat), y @ q.T, atol=1e-9)


@pytest.mark.skipif(not deepmimic.pybullet_available(), reason="pybullet (extra 'deepmimic') is not installed")
def test_deepmimic_rest_rig_has_level_hips_and_a_straight_spine():
    dm = deepmimic.humanoid_rest_directions()
    assert dm.shape == (J, 3)
    np.testing.assert_allclose(dm[IX["left_hip"]], [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(dm[IX["right_hip"]], [-1, 0, 0], atol=1e-6)
    for n in ("spine1", "spine2", "spine3", "neck", "head"):
        np.testing.assert_allclose(dm[IX[n]], [0, 1, 0], atol=1e-6)


def test_rerig_refuses_shapes_that_do_not_fit():
    smpl = R.smpl_rest_directions()
    with pytest.raises(ValueError, match="joints must be"):
        R.rerig(np.zeros((4, 21, 3)), smpl, smpl)
    with pytest.raises(ValueError, match="dst_dirs must be"):
        R.rerig(np.zeros((4, J, 3)), smpl, smpl[:5])
    with pytest.raises(ValueError, match="rest_pose must be"):
        R.rest_directions(np.zeros((2, J, 3)))


@needs_pybullet
def test_deepmimic_clips_come_on_humanml3d_torso_with_every_limb_kept():
    """The converter's default re-poses a clip on HumanML3D's torso: the hips hang as in every HumanML3D clip
    (about 58 degrees below the hip line), while every limb bone points as in the humanoid-rig conversion."""
    smpl, human = deepmimic.load_clip("walk"), deepmimic.load_clip("walk", rig="deepmimic")
    assert (smpl.rig, human.rig) == ("smpl", "deepmimic") and smpl.joints.shape == human.joints.shape
    x, y = smpl.joints.astype(np.float64), human.joints.astype(np.float64)
    rest = R.smpl_rest_directions() * np.asarray(SK.bone_lengths)[:, None]     # pelvis-relative rest hips
    rest_angle = _hip_angle(np.stack([np.zeros(3) if c == 0 else rest[c] for c in range(J)])[None])[0]
    assert 55 < rest_angle < 60                                                # HumanML3D's 58 degrees
    np.testing.assert_allclose(_hip_angle(x), rest_angle, atol=1.0)
    np.testing.assert_allclose(_hip_angle(y), 0.0, atol=1.0)
    np.testing.assert_allclose(x[:, 0], y[:, 0], atol=1e-5)                                 # the root stays
    torso = {IX[n] for _, emit in R.SEGMENTS.values() for n in emit} | {IX["head"]}
    limbs = [c for c in range(1, J) if c not in torso]
    dx, dy = R.bone_directions(x), R.bone_directions(y)
    np.testing.assert_allclose(dx[:, limbs], dy[:, limbs], atol=1e-5)
    lengths = np.linalg.norm(x[:, 1:] - x[:, list(SK.parents[1:])], axis=-1)
    np.testing.assert_allclose(lengths, np.broadcast_to(SK.bone_lengths[1:], lengths.shape), atol=1e-5)
    with pytest.raises(ValueError, match="rig="):
        deepmimic.load_clip("walk", rig="cmu")
