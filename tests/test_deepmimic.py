"""DeepMimic clips (optional extra 'deepmimic': pybullet) converted to the HumanML3D skeleton."""
from __future__ import annotations

import sys

import numpy as np
import pytest

from salad_core.data import deepmimic
from salad_core.data.procedural.checks import bone_length_error
from salad_core.motion import features_to_joints
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")
J = {name: i for i, name in enumerate(SK.joint_names)}
needs_pybullet = pytest.mark.skipif(not deepmimic.pybullet_available(),
                                    reason="pybullet (the optional extra 'deepmimic') is not installed")


def test_without_pybullet_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pybullet", None)          # makes `import pybullet` fail
    monkeypatch.setitem(sys.modules, "pybullet_data", None)
    assert not deepmimic.pybullet_available()
    with pytest.raises(ImportError, match=r"optional extra 'deepmimic'.*pip install 'salad\[deepmimic\]'"):
        deepmimic.load_clip("walk")
    with pytest.raises(ImportError, match="deepmimic"):
        deepmimic.available_clips()


@pytest.fixture(scope="module")
def walk():
    return deepmimic.load_clip("walk")


@needs_pybullet
def test_the_humanoid_clips_are_listed():
    names = deepmimic.available_clips()
    assert len(names) == 20 and {"walk", "run", "backflip", "cartwheel", "walker/turn_left0"} <= set(names)
    assert "laikago_walk" not in names and set(names) <= set(deepmimic.CLIP_PROMPTS)
    with pytest.raises(ValueError, match="unknown DeepMimic clip 'moonwalk'.*'backflip'"):
        deepmimic.load_clip("moonwalk")


@needs_pybullet
def test_walk_is_an_upright_forward_walk_on_the_humanml3d_skeleton(walk):
    j = walk.joints
    # 39 frames at 30 fps (1.27 s) resampled to 20 fps
    assert walk.fps == SK.fps and walk.source_fps == pytest.approx(30.0, rel=1e-3) and j.shape == (26, SK.num_joints, 3)
    assert walk.loop and walk.prompt == "a person walks forward"
    # rigid forward kinematics: every bone keeps its length
    assert bone_length_error(j)["max_std"] < 1e-4
    # upright (Y up): head above neck above pelvis above knees above ankles
    for a, b in (("head", "neck"), ("neck", "pelvis"), ("pelvis", "left_knee"), ("left_knee", "left_ankle")):
        assert (j[:, J[a], 1] > j[:, J[b], 1]).all()
    # facing +Z with the left side at +X (HumanML3D's convention), walking ~1.1 m forward
    assert (j[:, J["left_hip"], 0] > j[:, J["right_hip"], 0]).all()
    assert (j[:, J["left_shoulder"], 0] > j[:, J["right_shoulder"], 0]).all()
    disp = j[-1, 0] - j[0, 0]
    assert 0.9 < disp[2] < 1.4 and abs(disp[0]) < 0.2
    # the toes are ahead of the ankles, and the stance foot is still on the floor
    fwd = (j[:, J["left_foot"]] - j[:, J["left_ankle"]])[:, 2]
    assert (fwd > 0.05).mean() > 0.8
    foot_y = j[:, [J["left_foot"], J["right_foot"]], 1].min(1)
    assert foot_y.max() - foot_y.min() < 0.06


@needs_pybullet
def test_cycles_and_features(walk):
    three = deepmimic.load_clip("walk", cycles=3)
    assert three.num_frames == 76 and three.cycles == 3
    # identical up to the cycle's last frame, which the repetition replaces by the next cycle's
    # first (the clip's end pose is a few degrees of heading off its start)
    np.testing.assert_allclose(three.joints[:25], walk.joints[:25], atol=1e-5)
    np.testing.assert_allclose(three.joints[25], walk.joints[25], atol=0.05)
    disp1 = walk.joints[-1, 0, 2] - walk.joints[0, 0, 2]
    assert three.joints[-1, 0, 2] - three.joints[0, 0, 2] == pytest.approx(3 * disp1, rel=0.02)
    feats = three.features()
    assert feats.shape == (75, SK.feature_dim) and np.isfinite(feats).all()
    # the features encode the same motion: root path length and heights agree after retargeting
    rec = features_to_joints(feats)
    path = lambda x: np.linalg.norm(np.diff(x[:, 0, [0, 2]], axis=0), axis=-1).sum()  # noqa: E731
    assert path(rec) == pytest.approx(path(three.joints[:-1]), rel=0.1)
    with pytest.raises(ValueError, match="does not loop"):
        deepmimic.load_clip("kick", cycles=2)


@needs_pybullet
def test_other_frame_rates_resample_to_20_fps():
    jump = deepmimic.load_clip("jump")                      # 107 frames at 60 fps
    assert jump.source_fps == pytest.approx(60.0, rel=1e-3)
    assert jump.num_frames == int(106 / 60 * 20) + 1
    flip = deepmimic.load_clip("backflip")                  # 29 frames at 16 fps: up-sampled
    assert flip.num_frames == int(28 / 16 * 20) + 1
    # a backflip turns the body upside down at some point
    up = flip.joints[:, J["head"], 1] - flip.joints[:, J["pelvis"], 1]
    assert up.min() < 0 < up.max()
