"""salad_core.part_activity: each body part's speed is measured in its own frame, so moving or turning
the whole body counts for the root only, and a moving hand counts for its arm only."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.part_activity import YAW_LEVER, chest_frames, heading_frames, part_activity, part_speeds
from salad_core.skeleton import PART_NAMES, get_skeleton
from salad_viz.synthetic import synthetic_motion

SK = get_skeleton("humanml3d")
N = 21


def _still() -> np.ndarray:
    """A mid-stride pose held still, ``(N, J, 3)``, with the shoulder girdle 6 cm above spine3 as in
    real bodies (the synthetic skeleton's collars sit level with spine3: no chest up axis)."""
    pose = synthetic_motion(SK, 12)[7].copy()
    girdle = [SK.joint_names.index(f"{side}_{j}") for side in ("left", "right")
              for j in ("collar", "shoulder", "elbow", "wrist")]
    pose[girdle, 1] += 0.06
    return np.repeat(pose[None], N, axis=0)


def _yaw(angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def test_a_still_body_has_no_activity():
    assert np.array_equal(part_speeds(_still()), np.zeros((N - 1, len(PART_NAMES))))


def test_walking_the_whole_body_counts_for_the_root_only():
    j = _still()
    j += np.arange(N)[:, None, None] * np.array([0.05, 0.0, 0.03])     # per frame, at 20 fps
    s = part_speeds(j)
    np.testing.assert_allclose(s[:, 0], 20 * np.hypot(0.05, 0.03))
    np.testing.assert_allclose(s[:, 1:], 0.0, atol=1e-6)


def test_turning_on_the_spot_counts_as_root_motion_through_the_lever():
    rate = 0.05                                                         # rad per frame
    pose = _still()[0] - _still()[0, :1] * np.array([1.0, 0.0, 1.0])    # pelvis on the vertical axis
    j = np.stack([pose @ _yaw(rate * n).T for n in range(N)])
    s = part_speeds(j)
    np.testing.assert_allclose(s[:, 0], YAW_LEVER * rate * SK.fps, rtol=1e-9)
    np.testing.assert_allclose(s[:, 1:], 0.0, atol=1e-6)
    # the heading and chest frames turn with the body and stay orthonormal
    for frames in (heading_frames(j), chest_frames(j)):
        np.testing.assert_allclose(frames @ frames.transpose(0, 2, 1), np.broadcast_to(np.eye(3), (N, 3, 3)),
                                   atol=1e-9)
    np.testing.assert_allclose(heading_frames(j)[5, 2], _yaw(5 * rate) @ heading_frames(j)[0, 2], atol=1e-9)


def test_a_waving_hand_counts_for_its_arm_only():
    j = _still()
    wrist = SK.joint_names.index("left_wrist")
    j[:, wrist, 1] += 0.1 * np.sin(np.arange(N) / 2.0)
    s = part_speeds(j)
    left_arm = PART_NAMES.index("left arm")
    assert s[:, left_arm].max() > 0.5
    np.testing.assert_allclose(np.delete(s, left_arm, axis=1), 0.0, atol=1e-6)
    act = part_activity(j)
    np.testing.assert_allclose(act, s.mean(0))
    np.testing.assert_allclose(part_activity(None, (2, 6), speeds=s), s[2:6].mean(0))
    assert np.array_equal(part_activity(None, (6, 6), speeds=s), np.zeros(len(PART_NAMES)))


def test_bad_joints_are_refused_with_their_shape():
    with pytest.raises(ValueError, match=r"joints must be \(N >= 2, 22, 3\).*got shape \(1, 22, 3\)"):
        part_speeds(_still()[:1])
    with pytest.raises(ValueError, match=r"got shape \(21, 21, 3\)"):
        part_speeds(_still()[:, :21])
