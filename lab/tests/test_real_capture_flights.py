"""lab/scripts/physics/real_capture_flights.py: flight segments of real capture under the benchmark's contact rule
and with one resting level per foot joint."""
from __future__ import annotations

import numpy as np
import pytest

from _doubles import rest_pose
from _lab import load_script
from salad_core.eval.physics import GRAVITY, PhysicsConfig
from salad_core.skeleton import get_skeleton

rf = load_script("real_capture_flights")
SK = get_skeleton("humanml3d")


def jump(toe_raise: float = 0.0) -> np.ndarray:
    """60 frames standing, a 0.5 s ballistic flight (frames 25-34) of the whole body, standing again; ``toe_raise``
    lifts one toe joint by that much (m) in every frame, as a converted rig whose toe joint rests high."""
    fps = SK.fps
    pose = rest_pose()
    y = np.zeros(60)
    t = (np.arange(10) + 1) / fps                       # frames 25..34 in the air, take-off speed for 0.55 s
    v0 = GRAVITY * 11 / fps / 2
    y[25:35] = v0 * t - 0.5 * GRAVITY * t ** 2
    x = np.repeat(pose[None], 60, axis=0)
    x[:, :, 1] += y[:, None]
    x[:, SK.contact_joints[3], 1] += toe_raise
    return x


def test_segments_keeps_runs_at_least_min_frames():
    f = np.zeros(20, bool)
    f[2:4] = True
    f[6:12] = True
    f[17:] = True
    assert rf.segments(f, 3) == [(6, 12), (17, 20)]
    assert rf.segments(f, 2) == [(2, 4), (6, 12), (17, 20)]


def test_a_ballistic_flight_reads_gravity_under_both_rules():
    res = rf.clip_flights(jump(), SK)
    for kind in ("benchmark", "per_joint"):
        (seg,) = res[kind]
        a, b = seg["frames"]
        assert 25 <= a <= 27 and 33 <= b <= 35
        assert seg["accel_ms2"] == pytest.approx(-GRAVITY, rel=1e-6)
        assert seg["clearance_cm"] > 20
    want = 100 * (rest_pose()[list(SK.contact_joints), 1] - rest_pose()[list(SK.contact_joints), 1].min())
    np.testing.assert_allclose(res["rest_height_cm"], np.round(want, 1), atol=0.051)


def test_feet_resting_high_are_flight_to_the_benchmark_and_not_to_their_own_levels():
    """Toe joints resting 5 cm and ankles 9 cm above the floor (a converted rig whose foot joints sit higher
    than the benchmark's 3.5 / 8 cm thresholds): measured from the floor every frame is "flight"; measured from
    each joint's own resting height only the jump is."""
    x = jump()
    for joint, lift in zip(SK.contact_joints, (0.09, 0.05, 0.09, 0.05)):
        x[:, joint, 1] += lift
    cfg = PhysicsConfig(contact_reference="floor")
    assert rf.segments(rf.ph.flight_frames(x, SK, cfg), 3) == [(0, 60)]
    (seg,) = rf.segments(rf.per_joint_flight(x, SK, cfg), 3)
    assert 25 <= seg[0] <= 27 and 33 <= seg[1] <= 35
