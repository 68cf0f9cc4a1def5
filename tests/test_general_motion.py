"""General (uncaptioned) motion for VAE training: generator, files, mixture dataset (issue 21)."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core.data.dataset import MotionWindowDataset
from salad_core.data.general_dataset import MixtureWindowDataset, general_windows, mixture_mean_std
from salad_core.data.procedural.checks import bone_length_error, joint_angles
from salad_core.data.procedural.corpus import corpus_digest
from salad_core.data.procedural.general import (MODES, GeneralConfig, generate_general, sample_general,
                                                smooth_track)
from salad_core.data.procedural.general_body import (DOF_INDEX, DOFS, flesh_radii, forward_kinematics,
                                                     limits_array, rest_dofs)
from salad_core.data.procedural.general_build import build_general
from salad_core.data.procedural.general_root import plant_feet, solve_root
from salad_core.eval.physics import foot_skating
from salad_core.motion import features_to_joints, joints_to_features, process_joints
from salad_core.skeleton import get_skeleton

SK = get_skeleton("humanml3d")


@pytest.fixture(scope="module")
def clips():
    """Four clips of every mode, from fixed seeds."""
    out = []
    for mode in MODES:
        rng = np.random.default_rng([11, len(mode)])
        out += [sample_general(rng, mode=mode) for _ in range(4)]
    return out


# ----------------------------------------------------------------------------- generator
def test_same_seed_same_clip_and_different_index_differs():
    a, b = generate_general(0, 5), generate_general(0, 5)
    assert np.array_equal(a.joints, b.joints) and a.mode == b.mode
    c = generate_general(0, 6)
    assert a.joints.shape != c.joints.shape or not np.allclose(a.joints, c.joints)


def test_shapes_frames_bones_and_floor(clips):
    for c in clips:
        n = c.num_frames
        assert 41 <= n <= 197 and c.joints.shape == (n, 22, 3) and np.isfinite(c.joints).all()
        assert bone_length_error(c.joints)["max_error"] < 1e-9, c.mode
        # nothing below the floor; something touches it (the lowest joint rests on it)
        assert c.joints[..., 1].min() >= -1e-9, c.mode
        assert c.joints[..., 1].min() < 0.05, c.mode


def test_joint_angles_stay_in_their_limits(clips):
    lo, hi = limits_array()
    for c in clips:
        assert (c.dofs[:, 4:] >= lo[4:] - 1e-9).all() and (c.dofs[:, 4:] <= hi[4:] + 1e-9).all(), c.mode
        ang = joint_angles(c.joints)
        # knee/elbow flexion measured on the joints: 0..150 deg, and knees never bend backwards
        assert ang["knee"].max() <= 150.5 and ang["elbow"].max() <= 150.5, c.mode
        # knees never bend backwards (knee_bend is measured about the horizontal heading's left
        # axis, so only frames with an upright trunk are meaningful)
        spine = c.joints[:, SK.joint_names.index("spine1")] - c.joints[:, 0]
        upright = spine[:, 1] / np.linalg.norm(spine, axis=-1) > np.cos(np.radians(25))
        if upright.any():
            assert ang["knee_bend"][upright].min() > -0.02, c.mode


def test_coverage_of_orientations_and_speeds():
    """Bodies far from upright, inverted bodies, fast root paths and flights are all present."""
    tilt, inverted, frames, fast, flights = 0, 0, 0, 0, 0
    for i in range(40):
        c = generate_general(1, i)
        spine = c.joints[:, SK.joint_names.index("spine3")] - c.joints[:, 0]
        cos = spine[:, 1] / np.linalg.norm(spine, axis=-1)
        tilt += int((cos < np.cos(np.radians(60))).sum())
        inverted += int((cos < np.cos(np.radians(120))).sum())
        frames += c.num_frames
        speed = np.linalg.norm(np.diff(c.joints[:, 0, [0, 2]], axis=0), axis=1) * 20
        fast += int(speed.max() > 2.5)
        flights += int(c.flight.any())
    assert tilt / frames > 0.15          # share of frames with the spine > 60 deg from vertical
    assert inverted / frames > 0.02      # upside down
    assert fast >= 4 and flights >= 4


def test_smooth_track_stays_between_keys():
    t = np.linspace(0, 3, 200)
    keys = np.array([0.0, 1.0, -0.5, -0.4, 2.0])
    v = smooth_track(t, np.array([0.0, 0.7, 1.5, 2.2, 3.0]), keys)
    assert v.min() >= keys.min() - 1e-12 and v.max() <= keys.max() + 1e-12
    assert v[0] == keys[0] and abs(v[-1] - keys[-1]) < 1e-12
    with pytest.raises(ValueError, match="increase"):
        smooth_track(t, np.array([0.0, 0.0]), np.zeros(2))


def test_root_solver_rests_the_lowest_joint_and_pins_the_support():
    # a body turning on one foot with the other leg lifted: the lowest joint (flesh included)
    # rests on the floor every frame and the standing foot does not slide
    n = 40
    d = np.repeat(rest_dofs()[None], n, 0)
    d[:, DOF_INDEX["l_hip_flex"]] = np.radians(60)
    d[:, DOF_INDEX["l_knee"]] = np.radians(90)
    d[:, DOF_INDEX["r_knee"]] = np.radians(20) * np.sin(np.linspace(0, np.pi, n))   # bob on the standing leg
    d[:, DOF_INDEX["heading"]] = np.radians(90) * np.linspace(0, 1, n)
    rel = forward_kinematics(d)
    root = solve_root(rel)
    j = rel + root[:, None]
    gap = j[..., 1] - flesh_radii()[None]                            # joint height above its flesh
    assert np.abs(gap.min(axis=1)).max() < 1e-9
    # the foot pivots about its support (ankle, toe or between them): one of them stays put
    drift = [np.linalg.norm(j[:, k, [0, 2]] - j[0, k, [0, 2]], axis=-1).max()
             for k in (SK.joint_names.index("right_ankle"), SK.joint_names.index("right_foot"))]
    assert min(drift) < 0.02, drift
    # without the support pinning the pelvis would stay put and the foot would sweep round it
    assert np.linalg.norm(root[-1, [0, 2]]) > 0.03


def _joint(name):
    return SK.joint_names.index(name)


def test_plant_feet_holds_a_flat_foot_and_pivots_a_rolling_one():
    # a standing body turning 90 degrees in place: the feet turn with it (as the joint angles say)
    # unless they are planted; planted, both ends of the flat right foot stay put, bones stay exact
    n = 30
    d = np.repeat(rest_dofs()[None], n, 0)
    d[:, DOF_INDEX["heading"]] = np.radians(90) * np.linspace(0, 1, n)
    rel = forward_kinematics(d)
    j = rel + solve_root(rel)[:, None]
    heel, toe = _joint("right_ankle"), _joint("right_foot")
    before = max(np.linalg.norm(j[:, k, [0, 2]] - j[0, k, [0, 2]], axis=-1).max() for k in (heel, toe))
    out = plant_feet(j)
    after = max(np.linalg.norm(out[:, k, [0, 2]] - out[0, k, [0, 2]], axis=-1).max() for k in (heel, toe))
    assert before > 0.05 and after < 0.005, (before, after)
    assert bone_length_error(out)["max_error"] < 1e-9
    legs = [_joint(f"{s}_{p}") for s in ("left", "right") for p in ("knee", "ankle", "foot")]
    rest = [k for k in range(22) if k not in legs]
    assert np.array_equal(out[:, rest], j[:, rest])                  # only knees, ankles and toes move
    # heel rising while the toe stays down (toe-off): the toe is held, the heel may travel
    d = np.repeat(rest_dofs()[None], n, 0)
    d[:, DOF_INDEX["r_knee"]] = np.radians(40) * np.linspace(0, 1, n)
    d[:, DOF_INDEX["r_hip_flex"]] = np.radians(15) * np.linspace(0, 1, n)
    rel = forward_kinematics(d)
    j = rel + solve_root(rel)[:, None]
    out = plant_feet(j)
    down = out[:, toe, 1] - flesh_radii()[toe] < 0.01
    assert down.sum() > 5
    assert np.linalg.norm(out[down, toe][:, [0, 2]] - out[0, toe, [0, 2]], axis=-1).max() < 0.005


def test_general_feet_do_not_skate_like_the_old_generator():
    # generator 1.0's walking and running feet slid 0.36 m/s on the physics measure (its stance feet
    # turned and slid with the body); 1.1 pins heel and toe: measured over 12 locomotion clips
    speeds = [foot_skating(sample_general(np.random.default_rng([5, i, 1]), mode="locomotion").joints)
              for i in range(12)]
    s = np.concatenate(speeds)
    assert s.mean() < 0.2 and (s > 0.10).mean() < 0.25, (s.mean(), (s > 0.10).mean())


def test_config_is_validated():
    with pytest.raises(ValueError, match="unknown modes"):
        GeneralConfig(modes={"swim": 1.0})
    with pytest.raises(ValueError, match="max_frames"):
        GeneralConfig(min_frames=50, max_frames=45)
    with pytest.raises(ValueError, match="mode="):
        sample_general(np.random.default_rng(0), mode="swim")
    c = sample_general(np.random.default_rng(0), GeneralConfig(min_frames=20, max_frames=24))
    assert 20 <= c.num_frames <= 24


def test_dofs_layout():
    assert len(DOFS) == len(set(DOFS)) == len(DOF_INDEX)
    with pytest.raises(ValueError, match="shape"):
        forward_kinematics(np.zeros((3, 5)))


# ----------------------------------------------------------------------------- representation
def test_round_trip_through_the_humanml3d_features(clips):
    """features_to_joints(joints_to_features(j)) gives back the processed joints, lying and
    inverted bodies included, except where the smoothed heading crosses +-180 deg (HumanML3D's
    arcsin half-angle velocity flips sign there): most clips are exact, all are bounded."""
    errs = []
    for c in clips:
        rec = features_to_joints(joints_to_features(c.joints))
        ref = process_joints(c.joints)[:-1]
        errs.append(float(np.linalg.norm(rec - ref, axis=-1).max()))
    errs = np.array(errs)
    assert np.median(errs) < 1e-4
    assert (errs < 0.01).mean() >= 0.7
    floor = [c for c, e in zip(clips, errs) if c.mode == "floor"]
    assert floor and all(e < 0.05 for c, e in zip(clips, errs) if c.mode == "floor")


# ----------------------------------------------------------------------------- files
@pytest.fixture(scope="module")
def general_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("general")
    build_general(root / "a", n=24, seed=2, workers=1, progress=False)
    return root


def test_build_layout_and_determinism(general_dir):
    a = general_dir / "a"
    build_general(general_dir / "b", n=24, seed=2, workers=2, progress=False)
    assert corpus_digest(a) == corpus_digest(general_dir / "b")         # workers do not matter
    ids = {s: (a / f"{s}.txt").read_text().split() for s in ("train", "val", "test", "all")}
    assert sorted(ids["train"] + ids["val"] + ids["test"]) == sorted(ids["all"]) and len(ids["all"]) == 24
    assert not (a / "texts").exists()
    for i in ids["all"][:5]:
        f = np.load(a / "new_joint_vecs" / f"{i}.npy")
        j = np.load(a / "new_joints" / f"{i}.npy")
        assert f.shape[1] == 263 and 40 <= len(f) <= 196 and j.shape == (len(f), 22, 3)
        assert np.allclose(features_to_joints(f), j, atol=1e-5)
    with pytest.raises(FileExistsError):
        build_general(a, n=24, seed=2, progress=False)
    with pytest.raises(ValueError, match="n="):
        build_general(general_dir / "c", n=5)


# ----------------------------------------------------------------------------- mixture
def test_mixture_ratio_determinism_and_item_format(general_dir):
    a = general_dir / "a"
    corpus = MotionWindowDataset(a, "train", window=16)          # any window set stands in for the corpus
    gen = general_windows(a, "test", window=16, mean=corpus.mean, std=corpus.std)
    mix = MixtureWindowDataset(corpus, gen, ratio=0.3, seed=4)
    assert len(mix) == round(len(corpus) / 0.7)
    src = [mix.locate(i)[0] for i in range(len(mix))]
    assert src.count("secondary") == round(0.3 * len(mix))
    item = mix[0]
    assert list(item) == ["motion"] and item["motion"].shape == (16, 263) and item["motion"].dtype == np.float32
    which, k = mix.locate(3)
    assert np.array_equal(mix[3]["motion"], (gen if which == "secondary" else corpus)[k]["motion"])
    # the primary's windows are each drawn once per epoch
    prim = sorted(k for i in range(len(mix)) for w, k in [mix.locate(i)] if w == "primary")
    assert prim == list(range(len(corpus)))
    # same (seed, epoch): same items; another epoch: another draw; back again: the same
    first = [mix.locate(i) for i in range(len(mix))]
    again = MixtureWindowDataset(corpus, gen, ratio=0.3, seed=4)
    assert [again.locate(i) for i in range(len(mix))] == first
    mix.set_epoch(1)
    assert [mix.locate(i) for i in range(len(mix))] != first
    mix.set_epoch(0)
    assert [mix.locate(i) for i in range(len(mix))] == first
    assert mix.mean is corpus.mean and mix.std is corpus.std


def test_mixture_rejects_bad_arguments(general_dir):
    a = general_dir / "a"
    corpus = MotionWindowDataset(a, "train", window=16)
    gen = general_windows(a, "test", window=16, mean=corpus.mean, std=corpus.std)
    with pytest.raises(ValueError, match="ratio"):
        MixtureWindowDataset(corpus, gen, ratio=1.0)
    other = MotionWindowDataset(a, "test", window=16, mean=corpus.mean + 1.0, std=corpus.std)
    with pytest.raises(ValueError, match="normalisation"):
        MixtureWindowDataset(corpus, other, ratio=0.5)
    with pytest.raises(ValueError, match="mean and std"):
        general_windows(a, "test", window=16, mean=None, std=None)


def test_mixture_statistics_weigh_the_general_share(general_dir, tmp_path):
    a = general_dir / "a"
    # a "corpus" of the same clips with every feature doubled: its share moves the mean
    (tmp_path / "new_joint_vecs").mkdir()
    ids = (a / "train.txt").read_text().split()
    for i in ids:
        np.save(tmp_path / "new_joint_vecs" / f"{i}.npy", 2.0 * np.load(a / "new_joint_vecs" / f"{i}.npy"))
    (tmp_path / "train.txt").write_text("\n".join(ids) + "\n")
    m0, s0 = mixture_mean_std(tmp_path, a, ratio=0.0)
    m5, s5 = mixture_mean_std(tmp_path, a, ratio=0.5)
    assert m0.shape == s0.shape == (263,) and (s5 > 0).all()
    half = np.concatenate([np.load(a / "new_joint_vecs" / f"{i}.npy") for i in ids]).mean(0)
    assert np.allclose(m0, 2 * half, atol=1e-4)                        # corpus only
    assert np.allclose(m5, 1.5 * half, atol=1e-3 + 1e-3 * np.abs(half).max())   # equal shares
