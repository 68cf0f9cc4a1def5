"""The side check (salad_core.side_check): the prompt's side cues, the motion's measured side, and the
mirror decision, on the real HumanML3D sample clip 012314 and edits of it with a known side."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from salad_core.motion import mirror_joints
from salad_core.side_check import KINDS, cue_verdict, should_mirror, side_cues, side_measure

CLIP = Path(__file__).parent / "data" / "humanml3d_sample" / "new_joints" / "012314.npy"


@pytest.fixture(scope="module")
def clip():
    return np.load(CLIP).astype(np.float64)                       # (170, 22, 3) real motion capture


@pytest.mark.parametrize("prompt, want", [
    ("a man waves his left hand", [("arm", 1)]),
    ("someone punches forward with their right fist", [("arm", -1)]),
    ("a man punches with the left", [("arm", 1)]),
    ("a man kicks with his left leg", [("leg", 1)]),
    ("a person kicks with the right", [("leg", -1)]),
    ("a woman lifts her left knee", [("leg", 1)]),
    ("a person turns left", [("turn", 1)]),
    ("a man walks in a circle to the right", [("turn", -1)]),
    ("a man sidesteps to the left", [("lateral", 1)]),
    ("a person steps sideways to the right", [("lateral", -1)]),
    ("a man raises his left arm and kicks with his right leg", [("arm", 1), ("leg", -1)]),
    ("a man looks to the left", []),
    ("a person walks forward", []),
    ("the person is all right", []),
])
def test_side_cues_of_prompts(prompt, want):
    assert [(c.kind, c.side) for c in side_cues(prompt)] == want


@pytest.mark.parametrize("kind", KINDS)
def test_every_measure_changes_sign_under_mirroring(clip, kind):
    m, mm = side_measure(clip, kind), side_measure(mirror_joints(clip), kind)
    assert mm == pytest.approx(-m, abs=1e-6 + 1e-6 * abs(m))


def _wave(clip, side):
    """The clip with one arm waving: elbow and wrist circle 15 and 30 cm at 1 Hz relative to the body."""
    x = clip.copy()
    t = np.arange(len(x)) / 20.0
    circle = 0.3 * np.stack([np.cos(2 * np.pi * t), np.sin(2 * np.pi * t), np.zeros_like(t)], -1)
    elbow, wrist = (18, 20) if side == "left" else (19, 21)
    x[:, elbow] += 0.5 * circle
    x[:, wrist] += circle
    return x


def test_a_left_wave_measures_left_and_is_mirrored_only_for_a_right_prompt(clip):
    x = _wave(clip, "left")
    assert side_measure(x, "arm") > 1.0
    assert not should_mirror("a man waves his left hand", x)
    assert should_mirror("a man waves his right hand", x)
    assert not should_mirror("a man waves his right hand", mirror_joints(x))
    assert not should_mirror("a person walks forward", x)                          # no cue: never
    # a kept cue is never given up for another: mirroring would break it
    both = "a man waves his left hand and kicks with his right leg"
    assert [cue_verdict(c, x) for c in side_cues(both)][0] == 1
    assert not should_mirror(both, x)


def test_a_turn_measures_its_direction(clip):
    """The clip turned progressively by +90 degrees about +Y (towards its left) measures about +90."""
    x = clip - clip[:1, :1] * np.array([1.0, 0.0, 1.0])
    yaw = np.linspace(0.0, np.pi / 2, len(x)) + 0.0
    base = np.degrees(side_measure(clip, "turn"))                  # the clip's own turn, whatever it is
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.zeros((len(x), 3, 3))
    rot[:, 0, 0], rot[:, 0, 2], rot[:, 1, 1], rot[:, 2, 0], rot[:, 2, 2] = c, s, 1.0, -s, c
    turned = np.einsum("nij,nkj->nki", rot, x)
    assert side_measure(turned, "turn") - side_measure(clip, "turn") == pytest.approx(90.0, abs=3.0)
    assert np.isfinite(base)


def test_bad_inputs(clip):
    with pytest.raises(ValueError, match="kind must be one of"):
        side_measure(clip, "head")
    with pytest.raises(ValueError, match=r"joints must have shape"):
        side_measure(clip[:, :5], "arm")
    with pytest.raises(TypeError, match="prompt must be a string"):
        side_cues(None)


# ------------------------------------------------------------------------------ KeyMotion's side check
@pytest.mark.usefixtures("single_thread")
def test_keymotion_pipeline_mirrors_exactly_the_motions_that_break_their_side():
    from salad_core.keymotion.pipeline import DEFAULT_WEIGHTS_DIR, KeyMotionPipeline
    from salad_core.motion import mirror_features

    if not (DEFAULT_WEIGHTS_DIR / "keymotion.json").is_file():
        pytest.skip("needs the shipped KeyMotion weights")
    km = KeyMotionPipeline.from_pretrained()
    assert km.side_check is True
    prompts = ["a man kicks with his left leg", "a person kicks his right leg forward", "a person walks forward"]
    seen = {True: 0, False: 0}
    for seed in (0, 1):
        plain = km(prompts, lengths=60, seed=seed, num_steps=10, side_check=False)
        checked = km(prompts, lengths=60, seed=seed, num_steps=10)
        assert plain.mirrored == [False] * 3 and checked.settings["side_check"] is True
        assert checked.mirrored[2] is False                       # no side named: never mirrored
        for i, p in enumerate(prompts):
            f0, f1 = plain.features[i, :60], checked.features[i, :60]
            if checked.mirrored[i]:
                assert should_mirror(p, plain.joints[i])
                np.testing.assert_allclose(f1, mirror_features(f0), atol=1e-6)
                assert not should_mirror(p, checked.joints[i])   # the mirror image keeps the side
            else:
                assert not should_mirror(p, plain.joints[i])
                np.testing.assert_array_equal(f1, f0)
            seen[checked.mirrored[i]] += 1
    assert seen[True] >= 1                                        # KeyMotion 0.2 gets some sides wrong
