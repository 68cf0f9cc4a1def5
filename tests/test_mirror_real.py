"""Mirroring real takes (issue 67): MirrorTake's spec and latent plumbing (tiny pipeline), the side of a real
kneel before and after (shipped weights), and grounding of an edit's pelvis."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.attention import ExampleBased, Mirror
from salad_core.attention.edits import validate_edits
from salad_core.attention.grounding import (asks_to_leave_floor, ground_features, lower_body, pelvis_ceiling)
from salad_core.attention.mirror_take import (MirrorTake, invert_mirror, mirror_prompt, mirror_take_edits,
                                              mirror_take_mask)
from salad_core.motion import features_to_joints, mirror_features
from salad_core.skeleton import PART_NAMES, get_skeleton
from _weights import needs_weights

PIPE_SEED = 3
STEPS = 5
PROMPT = "a person kicks with the right leg"



# ------------------------------------------------------------------------------ the spec
def test_mirror_prompt_swaps_sides():
    assert mirror_prompt("A person waves the left hand, then turns right") == \
        "A person waves the right hand, then turns left"
    assert mirror_prompt("Left foot forward, spins clockwise") == "Right foot forward, spins counterclockwise"
    assert mirror_prompt("a person kicks") == "a person kicks"
    assert mirror_prompt(mirror_prompt("the left arm goes right")) == "the left arm goes right"


def test_mask_of_each_group():
    idx = {p: PART_NAMES.index(p) for p in PART_NAMES}
    legs = mirror_take_mask("legs")[0, 0, :, 0]
    assert legs.sum() == 2 and legs[idx["left leg"]] == legs[idx["right leg"]] == 1
    assert mirror_take_mask("limbs").sum() == 4 and mirror_take_mask("limbs")[0, 0, idx["root"], 0] == 0
    assert mirror_take_mask("all").sum() == len(PART_NAMES)


@pytest.fixture(scope="module")
def motion(sample_features):
    return sample_features[:48].astype(np.float32)


@pytest.fixture(scope="module")
def inversions(pipe, motion, single_thread):
    inv = pipe.invert(motion, PROMPT, num_steps=STEPS)
    return inv, invert_mirror(pipe, inv)


def test_spec_checks(pipe, inversions):
    inv, mirrored = inversions
    assert mirrored.prompts == inv.prompts
    assert invert_mirror(pipe, inv, swap_sides=True).prompts == ["a person kicks with the left leg"]
    np.testing.assert_array_equal(mirrored.features[0], mirror_features(inv.features[0]))
    with pytest.raises(ValueError, match="allowed"):
        MirrorTake("tail", mirrored)
    with pytest.raises(TypeError, match="Inversion of the take's mirror image"):
        MirrorTake("legs", None)
    with pytest.raises(ValueError, match="follow"):
        MirrorTake("legs", mirrored, follow=(0.5, 0.2))
    assert MirrorTake("lower", mirrored).parts == "legs"
    with pytest.raises(ValueError, match="at most one MirrorTake"):
        validate_edits([MirrorTake("legs", mirrored), MirrorTake("arms", mirrored)])
    with pytest.raises(ValueError, match="cannot be combined"):
        validate_edits([MirrorTake("legs", mirrored), ExampleBased(seed=2)])
    edits = mirror_take_edits("legs", mirrored)
    assert isinstance(edits[0], Mirror) and edits[0].parts == "legs" and isinstance(edits[1], MirrorTake)
    assert mirror_take_edits("limbs", mirrored)[0].parts == "all"
    assert len(mirror_take_edits("all", mirrored)) == 1


# ------------------------------------------------------------------------------ latent plumbing (tiny pipeline)
def test_all_parts_following_the_mirror_is_its_exact_mirror_image(pipe, inversions):
    """Every part following the mirror's trajectory to the end: the edited latents are the mirror's encoded
    latents (its inversion is exact), the source branch is the source's."""
    inv, mirrored = inversions
    out = pipe.edit(inversion=inv, edits=[MirrorTake("all", mirrored, follow=(0.0, 1.0), keep=None)])
    torch.testing.assert_close(out.edited.latents, mirrored.latents, atol=1e-4, rtol=0)
    torch.testing.assert_close(out.source.latents, inv.latents, atol=1e-4, rtol=0)
    # without following, the mirror's noise and exact corrections regenerate it as well (no map edit)
    free = pipe.edit(inversion=inv, edits=[MirrorTake("all", mirrored, follow=None, keep=None)])
    torch.testing.assert_close(free.edited.latents, mirrored.latents, atol=1e-3, rtol=0)


def test_kept_parts_are_the_sources_and_mirrored_parts_the_mirrors(pipe, inversions):
    inv, mirrored = inversions
    legs = [PART_NAMES.index("left leg"), PART_NAMES.index("right leg")]
    rest = [p for p in range(len(PART_NAMES)) if p not in legs]
    out = pipe.edit(inversion=inv, edits=[MirrorTake("legs", mirrored, follow=(0.0, 1.0))])
    torch.testing.assert_close(out.edited.latents[:, :, rest], inv.latents[:, :, rest], atol=1e-4, rtol=0)
    torch.testing.assert_close(out.edited.latents[:, :, legs], mirrored.latents[:, :, legs], atol=1e-4, rtol=0)
    # composes with the attention edit and with in-painting (which keeps the source outside its region)
    from salad_core.attention import Inpaint

    both = pipe.edit(inversion=inv, edits=mirror_take_edits("legs", mirrored) + [Inpaint(parts="arms")])
    torch.testing.assert_close(both.edited.latents[:, :, rest], inv.latents[:, :, rest], atol=1e-4, rtol=0)


def test_composite_takes_the_kept_parts_from_the_source_decoding(pipe, inversions):
    """MirrorTake's feature-space composite (default on): every feature column of the joints outside the legs is
    the source's decoding (root included), the legs' are the edit's hung from the source's pelvis; without it the
    decoder's mixing moves them; ``"all"`` composites nothing."""
    inv, mirrored = inversions
    sk = get_skeleton()
    n = inv.lengths[0]
    plain = pipe.edit(inversion=inv, edits=mirror_take_edits("legs", mirrored, composite=False), ground=False)
    out = pipe.edit(inversion=inv, edits=mirror_take_edits("legs", mirrored), ground=False)
    assert "composite" in out.settings and "composite" not in plain.settings
    torch.testing.assert_close(out.edited.latents, plain.edited.latents, atol=0, rtol=0)   # latents as sampled
    legs = {PART_NAMES.index("left leg"), PART_NAMES.index("right leg")}
    kept = [j for j, p in enumerate(sk.joint_to_part) if p not in legs]
    cols = [c for j in kept for c in sk.joint_feature_index[j]]
    src, ed, raw = out.source.features[0, :n], out.edited.features[0, :n], plain.edited.features[0, :n]
    np.testing.assert_allclose(ed[:, cols], src[:, cols], atol=1e-6)
    assert np.abs(raw[:, cols] - src[:, cols]).max() > 1e-3         # the tiny decoder mixes parts too
    # the legs: the edit's, shifted by the pelvis height difference
    leg_j = sorted(set(range(sk.num_joints)) - set(kept))
    ric = sk.feature_slices["ric"].start
    dy = src[:, 3] - raw[:, 3]
    for j in leg_j:
        np.testing.assert_allclose(ed[:, ric + 3 * (j - 1) + 1], raw[:, ric + 3 * (j - 1) + 1] + dy, atol=1e-5)
    # root-aligned, the kept joints are the source's (up to the skeleton fit)
    a, b = out.source.joints[0], out.edited.joints[0]
    moved = lambda x: np.linalg.norm((x - x[:, :1])[:, kept[1:]] - (a - a[:, :1])[:, kept[1:]], axis=-1).mean()
    assert moved(b) < moved(plain.edited.joints[0])
    every = pipe.edit(inversion=inv, edits=mirror_take_edits("all", mirrored), ground=False)
    assert "composite" not in every.settings


def test_a_mismatched_mirror_is_refused(pipe, inversions, sample_features):
    inv, _ = inversions
    other = pipe.invert(sample_features[:32].astype(np.float32), PROMPT, num_steps=STEPS, reconstruct=False)
    with pytest.raises(ValueError, match="invert the mirror of the same takes"):
        pipe.edit(inversion=inv, edits=[MirrorTake("legs", other)])


# ------------------------------------------------------------------------------ grounding
def test_lower_body_keeps_the_pose(sample_features):
    f = sample_features[:40].astype(np.float64)
    drop = np.linspace(0.0, 0.3, len(f))
    j0, j1 = features_to_joints(f), features_to_joints(lower_body(f, drop))
    np.testing.assert_allclose(j0[..., 1] - j1[..., 1], np.repeat(drop[:, None], j0.shape[1], 1), atol=1e-9)
    np.testing.assert_allclose(j0[..., [0, 2]], j1[..., [0, 2]], atol=1e-9)


def test_ground_features_clamps_the_pelvis(sample_features):
    sk = get_skeleton()
    f = sample_features[:40].astype(np.float64).copy()
    f[10:20, sk.feature_slices["root_y"]] += 0.5                       # a lifted stretch
    ceiling = pelvis_ceiling(sample_features[:40, 3], margin=0.10)
    g, drop = ground_features(f, ceiling)
    assert g[:, 3].max() == pytest.approx(ceiling) and (drop > 0).sum() >= 10
    np.testing.assert_array_equal(g[:9], f[:9])        # frames below the ceiling untouched (frame 9: its velocity)
    assert pelvis_ceiling(np.array([0.9, 1.0]), margin=0.1, corpus_max=1.05) == pytest.approx(1.05)
    assert pelvis_ceiling(np.array([0.9, 1.2]), margin=0.1, corpus_max=1.05) == pytest.approx(1.2)


def test_ground_edit_lowers_a_lifted_edit(pipe, inversions):
    """An edit whose pelvis floats 50 cm above the source's comes back to 10 cm above it; with a jump in the target
    prompt it is left alone."""
    import dataclasses

    from salad_core.attention import Reweight
    from salad_core.attention.grounding import ground_edit
    from salad_core.recovery import recover_joints

    inv, _ = inversions
    out = pipe.edit(inversion=inv, edits=[Reweight("kicks", 0.5)])
    n = out.edited.lengths[0]
    f = out.edited.features.copy()
    f[0, :n] = lower_body(f[0, :n], np.full(n, -0.5))                # lift the whole body by 50 cm
    lifted = dataclasses.replace(out, edited=dataclasses.replace(
        out.edited, features=f, joints=[recover_joints(f[0, :n], pipe.recovery)]))
    top = out.source.joints[0][:, 0, 1].max()
    assert lifted.edited.joints[0][:, 0, 1].max() - top > 0.3
    grounded = ground_edit(pipe, lifted)
    assert grounded.edited.joints[0][:, 0, 1].max() - top <= 0.10 + 1e-3
    assert grounded.settings["grounding"]["motions"][0]["frames"] > 0
    assert lifted.edited.joints[0][:, 0, 1].max() - top > 0.3             # the input is not changed
    jump = dataclasses.replace(lifted, edited=dataclasses.replace(lifted.edited, texts=["a person jumps"]))
    np.testing.assert_array_equal(ground_edit(pipe, jump).edited.features, jump.edited.features)


def test_edit_of_a_take_is_grounded_by_default_and_not_when_asked(pipe, inversions):
    """``pipe.edit(inversion=...)`` grounds the edited motion unless ``ground=False``; a generated source is not
    grounded unless ``ground=True``; grounding never lifts: the edited pelvis ends at most 10 cm above the source's
    range, and where it was below that the motion is unchanged."""
    from salad_core.attention import Reweight

    inv, _ = inversions
    grounded = pipe.edit(inversion=inv, edits=[Reweight("kicks", -1.0)])
    plain = pipe.edit(inversion=inv, edits=[Reweight("kicks", -1.0)], ground=False)
    assert "grounding" in grounded.settings and "grounding" not in plain.settings
    top = grounded.source.joints[0][:, 0, 1].max()
    assert grounded.edited.joints[0][:, 0, 1].max() - top <= 0.10 + 1e-3
    record = grounded.settings["grounding"]["motions"][0]
    if record["frames"] == 0:
        np.testing.assert_array_equal(grounded.edited.features, plain.edited.features)
    else:
        assert plain.edited.joints[0][:, 0, 1].max() - top > 0.10
    generated = pipe.edit(PROMPT, edits=[Reweight("kicks", -1.0)], lengths=48, num_steps=STEPS)
    assert "grounding" not in generated.settings
    forced = pipe.edit(PROMPT, edits=[Reweight("kicks", -1.0)], lengths=48, num_steps=STEPS, ground=True)
    assert "grounding" in forced.settings


def test_lift_words():
    assert asks_to_leave_floor("a person jumps forward")
    assert asks_to_leave_floor("someone hops on one leg") and asks_to_leave_floor("a man climbs the stairs")
    assert not asks_to_leave_floor("a person walks and turns left")
    assert not asks_to_leave_floor("a person kneels down on one knee and stands up")


# ------------------------------------------------------------------------------ the shipped weights
@pytest.fixture(scope="module")
def shipped(single_thread):
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained()


@pytest.mark.slow
@needs_weights
def test_mirror_take_puts_the_other_knee_down(shipped):
    """bvhtoolbox's MocapBank kneel (right knee down; frames 64-256): Mirror alone keeps the right knee down,
    MirrorTake of the legs puts the left one down and leaves the other parts within 3 cm (root-aligned)."""
    from pathlib import Path

    from salad_core.bvh import import_bvh

    feats = import_bvh(Path(__file__).parent / "data" / "bvh" / "mocapbank.bvh").features()[64:256]
    inv = shipped.invert(feats.astype(np.float32), "a person kneels down on one knee and stands up", num_steps=20)
    mirrored = invert_mirror(shipped, inv)
    plain = shipped.edit(inversion=inv, edits=[Mirror("legs")])
    out = shipped.edit(inversion=inv, edits=mirror_take_edits("legs", mirrored))
    src = out.source.joints[0]
    assert _kneel_side(src) > 0.1                                   # the right knee is down
    assert _kneel_side(plain.edited.joints[0]) > 0                  # Mirror alone: still the right knee
    assert _kneel_side(out.edited.joints[0]) < -0.1                 # MirrorTake: the left knee
    sk = get_skeleton()
    legs = {PART_NAMES.index("left leg"), PART_NAMES.index("right leg")}
    rest = [j for j, p in enumerate(sk.joint_to_part) if p not in legs and j != 0]
    a, b = src - src[:, :1], out.edited.joints[0] - out.edited.joints[0][:, :1]
    assert np.linalg.norm(a[:, rest] - b[:, rest], axis=-1).mean() < 0.03


def _kneel_side(joints: np.ndarray) -> float:
    """Mean left-minus-right knee height (m) over the frames whose lower knee is within 25 cm of the floor
    (positive: the right knee is down)."""
    sk = get_skeleton()
    lk, rk = joints[:, sk.joint_names.index("left_knee"), 1], joints[:, sk.joint_names.index("right_knee"), 1]
    down = np.minimum(lk, rk) - joints[..., 1].min() < 0.25
    return float((lk - rk)[down].mean()) if down.any() else float("nan")
