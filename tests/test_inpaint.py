"""In-painting (issue 67): Inpaint's region, its notation, and regenerating parts / frames of generated and
inverted motions with the shipped weights (few steps, one thread)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.attention import Inpaint, Refine, Reweight, parse_inpaint
from salad_core.attention.edits import seeded_noise, validate_edits
from salad_core.attention.inpaint import MATCHED_MAX_RHO, NOISE_MODES, matched_noise, noise_statistics
from salad_core.skeleton import PART_NAMES, get_skeleton
from _weights import needs_weights

STEPS = 10
FRAMES = 48
SOURCE = "a person walks forward"



# ------------------------------------------------------------------------------ the spec
def test_parts_and_groups():
    assert Inpaint(parts="arms").parts == ("left arm", "right arm")
    assert Inpaint(parts="upper").parts == ("spine", "left arm", "right arm", "head")
    assert Inpaint(parts="lower").parts == ("root", "left leg", "right leg")
    assert Inpaint(parts=["head", "left_arm"]).parts == ("left arm", "head")
    assert Inpaint(parts="left-leg,head").parts == ("left leg", "head")


@pytest.mark.parametrize("kwargs, match", [
    (dict(parts="tail"), "unknown body part 'tail'"),
    (dict(parts=[]), "names no body part"),
    (dict(), "needs parts"),
    (dict(frames=(40, 40)), "empty span"),
    (dict(frames=(50, 40)), "empty span"),
    (dict(frames=(-4, 40)), "negative"),
    (dict(frames=(0, None)), "whole motion"),
    (dict(frames=(1, 2, 3)), "pair"),
    (dict(parts="all"), "keeps nothing"),
    (dict(parts="arms", blend=-1), "blend"),
])
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        Inpaint(**kwargs)


def test_one_inpaint_per_edit():
    with pytest.raises(ValueError, match="at most one in-painting"):
        validate_edits([Inpaint(parts="arms"), Inpaint(parts="legs")])
    assert len(validate_edits([Refine(), Inpaint(parts="arms"), Reweight("waves", 2.0)])) == 3


def test_span_outside_motion():
    with pytest.raises(ValueError, match="outside the motion of 48 frames"):
        Inpaint(frames=(40, 80)).latent_span(48)
    with pytest.raises(ValueError, match="outside the motion of 48 frames"):
        Inpaint(frames=(48, None)).latent_span(48)
    with pytest.raises(ValueError, match="nothing is kept"):
        Inpaint(frames=(0, 48)).latent_span(48)
    assert Inpaint(frames=(6, 30)).latent_span(48) == (1, 8)          # rounded outward to latent frames
    assert Inpaint(frames=(None, 20)).latent_span(48) == (0, 5)
    assert Inpaint(frames=(20, None)).latent_span(48) == (5, 12)


def test_mask():
    fm = torch.ones(2, 12, dtype=torch.bool)
    fm[1, 10:] = False                                                 # 40 frames
    m = Inpaint(parts="arms").mask(fm)
    assert m.shape == (2, 12, 7, 1)
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    assert m[0, :, arms].eq(1).all() and m[0].sum() == 12 * 2
    assert m[1, 10:].eq(0).all()                                       # padding is never regenerated
    hard = Inpaint(frames=(16, 32), blend=0).mask(fm)[0, :, 0, 0]
    assert hard.tolist() == [0, 0, 0, 0, 1, 1, 1, 1, 0, 0, 0, 0]
    soft = Inpaint(frames=(16, 32), blend=1).mask(fm)[0, :, 0, 0]
    assert soft.tolist() == [0, 0, 0, 0, 0.5, 1, 1, 0.5, 0, 0, 0, 0]
    suffix = Inpaint(frames=(32, None), blend=1).mask(fm)[0, :, 0, 0]     # no seam at the motion's end
    assert suffix.tolist() == [0] * 8 + [0.5, 1, 1, 1]
    both = Inpaint(parts="legs", frames=(None, 16), blend=0).mask(fm)[0, :, :, 0]
    assert both[:4, 1:3].eq(1).all() and both.sum() == 8


@pytest.mark.parametrize("spec, parts, frames", [
    ("arms", ("left arm", "right arm"), None),
    ("legs@40:80", ("left leg", "right leg"), (40, 80)),
    ("@40:80", None, (40, 80)),
    ("all@:40", None, (None, 40)),
    ("left_arm,head@80:", ("left arm", "head"), (80, None)),
    (" upper ", ("spine", "left arm", "right arm", "head"), None),
])
def test_parse_inpaint(spec, parts, frames):
    inp = parse_inpaint(spec)
    assert (inp.parts, inp.frames) == (parts, frames)
    assert parse_inpaint(inp.describe()) == inp


@pytest.mark.parametrize("spec, match", [
    ("", "empty"), ("@", "START:END"), ("arms@40", "START:END"), ("arms@a:b", "integers"),
    ("@:", "START and/or END"), ("wings", "unknown body part 'wings'"), ("arms@50:40", "empty span"),
])
def test_parse_inpaint_errors(spec, match):
    with pytest.raises(ValueError, match=match):
        parse_inpaint(spec)


# --------------------------------------------------------------------- with the shipped weights
@pytest.fixture(scope="module")
def pipe(single_thread):
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained()


def _dist_cm(a, b, frames=slice(None), joints=slice(None)) -> float:
    a, b = a - a[:, :1], b - b[:, :1]
    return float(np.linalg.norm(a[frames][:, joints] - b[frames][:, joints], axis=-1).mean() * 100)


@needs_weights
def test_regenerate_arms_of_a_generated_motion(pipe):
    out = pipe.edit(SOURCE, target="a man waves his right hand", edits=[Inpaint(parts="arms")], lengths=FRAMES,
                    seed=0, num_steps=STEPS)
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    kept = [p for p in range(7) if p not in arms]
    torch.testing.assert_close(out.edited.latents[:, :, kept], out.source.latents[:, :, kept], atol=0, rtol=0)
    jt = np.array(get_skeleton().joint_to_part)
    kept_j, arm_j = np.isin(jt, kept), np.isin(jt, arms)
    src, ed = out.source.joints[0], out.edited.joints[0]
    assert _dist_cm(src, ed, joints=kept_j) < 2.0                    # the other parts stay (decoder mixing only)
    assert _dist_cm(src, ed, joints=arm_j) > 5.0                     # the arms are regenerated


@needs_weights
def test_regenerate_frames_of_a_generated_motion(pipe):
    out = pipe.edit(SOURCE, target="a person jumps", edits=[Inpaint(frames=(24, None))], lengths=FRAMES, seed=0,
                    num_steps=STEPS)
    src, ed = out.source.joints[0], out.edited.joints[0]
    assert _dist_cm(src, ed, frames=slice(0, 20)) < 2.0              # the kept prefix (a latent frame off the seam)
    assert _dist_cm(src, ed, frames=slice(28, None)) > 5.0
    run_mask = out.edited.latents[0, :6] - out.source.latents[0, :6]
    assert run_mask.abs().max() == 0                                 # the kept latent frames are the source's


@needs_weights
def test_composes_with_reweight_and_refine(pipe):
    out = pipe.edit(SOURCE, edits=[Inpaint(parts="arms"), Reweight("walks", 2.0)], lengths=FRAMES, seed=0,
                    num_steps=STEPS)
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    assert not torch.equal(out.edited.latents[:, :, arms], out.source.latents[:, :, arms])
    out2 = pipe.edit(SOURCE, target="a person walks forward and waves", lengths=FRAMES, seed=0, num_steps=STEPS,
                     edits=[Refine(), Reweight("waves", 2.0), Inpaint(parts="arms", frames=(16, 40))])
    assert np.isfinite(out2.edited.joints[0]).all()
    assert _dist_cm(out2.source.joints[0], out2.edited.joints[0], frames=slice(0, 12)) < 2.0


@needs_weights
def test_span_outside_the_motion_is_refused(pipe):
    with pytest.raises(ValueError, match="outside the motion of 48 frames"):
        pipe.edit(SOURCE, target="a person jumps", edits=[Inpaint(frames=(40, 80))], lengths=FRAMES, num_steps=2)


@needs_weights
def test_inpaint_an_inverted_motion(pipe, sample_features):
    inv = pipe.invert(sample_features[:FRAMES], "a person walks forward and turns around", num_steps=STEPS)
    out = pipe.edit(inversion=inv, target="a person jumps", edits=[Inpaint(frames=(24, None))])
    rec, ed = out.source.joints[0], out.edited.joints[0]
    # the source branch is the inverted motion's reconstruction (exact up to the VAE)
    assert _dist_cm(inv.reconstruction.joints[0], rec) < 0.1
    assert _dist_cm(rec, ed, frames=slice(0, 20)) < 2.0
    assert _dist_cm(rec, ed, frames=slice(28, None)) > 3.0
    arms = pipe.edit(inversion=inv, target="a man waves his right hand", edits=[Inpaint(parts="arms")])
    jt = np.array(get_skeleton().joint_to_part)
    kept_j = ~np.isin(jt, [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")])
    assert _dist_cm(arms.source.joints[0], arms.edited.joints[0], joints=kept_j) < 2.0


# --------------------------------------------------------------------- the feature-space composite
def _edited_like(f: np.ndarray, seed: int = 0) -> np.ndarray:
    """A different motion of the same length: the features shifted in time plus noise on every channel but the
    contacts, and a turn of 0.05 (half-angle) per frame added to the root."""
    rng = np.random.default_rng(seed)
    g = np.roll(f, 7, axis=0).astype(np.float64)
    g[:, :-4] += rng.normal(scale=0.02, size=g[:, :-4].shape)
    g[:, 0] += 0.05
    return g


def test_composite_keeps_kept_parts_exactly_and_hangs_limbs_from_the_source(sample_features):
    from salad_core.attention.composite import composite_features, part_joint_weights
    from salad_core.motion import features_to_joints

    sk = get_skeleton()
    f = sample_features[:60].astype(np.float64)
    g = _edited_like(f)
    w = part_joint_weights(("left arm", "right arm"), sk)
    out = composite_features(f, g, w)
    jf, jg, jo = features_to_joints(f), features_to_joints(g), features_to_joints(out)
    arms = w > 0
    kept = ~arms
    # the kept joints are the source's to float precision (root included: heading and path)
    np.testing.assert_allclose(jo[:, kept], jf[:, kept], atol=1e-9)
    # the arms keep the edit's pose relative to their attachment (spine3), hung from the source's spine3
    chest = sk.joint_names.index("spine3")
    rel_g = (jg[:, arms] - jg[:, chest:chest + 1])
    rel_o = (jo[:, arms] - jo[:, chest:chest + 1])
    # compare in each motion's heading frame (the source's heading differs from the edit's)
    from salad_core.attention.composite import _ric

    ric = sk.feature_slices["ric"].start
    for j in np.flatnonzero(arms):
        np.testing.assert_allclose(out[:, ric + 3 * (j - 1): ric + 3 * j] - _ric(out, sk, chest),
                                   g[:, ric + 3 * (j - 1): ric + 3 * j] - _ric(g, sk, chest), atol=1e-9)
    assert np.abs(rel_o - rel_g).max() > 0.01          # ... which are not the same world offsets (other heading)
    # without re-joining the arms keep the edit's root-relative positions instead
    loose = composite_features(f, g, w, rejoin=False)
    assert np.abs(loose - out).max() > 1e-3


def test_composite_of_a_frame_span_keeps_the_kept_frames_in_place(sample_features):
    from salad_core.attention.composite import composite_features, frame_weights
    from salad_core.motion import features_to_joints

    f = sample_features[:80].astype(np.float64)
    g = _edited_like(f, 1)                              # the edit turns 0.05 rad (half-angle) a frame more
    fw = frame_weights(80, (24, 56), fade=4)
    np.testing.assert_allclose(fw[24:29], [0.2, 0.4, 0.6, 0.8, 1.0])
    np.testing.assert_allclose(fw[51:56], [1.0, 0.8, 0.6, 0.4, 0.2])
    assert fw[:24].sum() == 0 and fw[56:].sum() == 0
    w = np.repeat(fw[:, None], 22, 1)
    jf = features_to_joints(f)
    held = features_to_joints(composite_features(f, g, w, root="source"))
    free = features_to_joints(composite_features(f, g, w, root="edit"))
    # the kept frames: exactly the source's, before the span and (root="source") after it, in global position
    np.testing.assert_allclose(held[:24], jf[:24], atol=1e-9)
    np.testing.assert_allclose(held[57:], jf[57:], atol=1e-6)
    assert np.abs(held[30:50] - features_to_joints(g)[30:50]).max() > 0.05     # the span is the edit's
    # root="edit": after the span the kept poses follow the span's turn (root-aligned they differ)
    rel = lambda j: j - j[:, :1]
    assert np.linalg.norm(rel(free[57:]) - rel(jf[57:]), axis=-1).mean() > 0.05
    assert np.linalg.norm(rel(held[57:]) - rel(jf[57:]), axis=-1).mean() < 1e-6
    # a suffix span has nothing after it: both root modes agree
    sw = np.repeat(frame_weights(80, (56, 80), fade=4)[:, None], 22, 1)
    np.testing.assert_allclose(composite_features(f, g, sw, root="source"), composite_features(f, g, sw, root="edit"))


def _yaw_fit_residual(a: np.ndarray, b: np.ndarray) -> float:
    """Largest distance (m) left after the best rotation about the vertical plus translation maps joints ``a``
    ``(N, J, 3)`` onto ``b``: 0 when ``b`` is ``a`` turned and moved bodily."""
    pa, pb = a.reshape(-1, 3), b.reshape(-1, 3)
    ca, cb = pa.mean(0), pb.mean(0)
    x, y = pa - ca, pb - cb
    # rotation about y: maximise sum over points of (x_xz . R y_xz)
    sxx = (x[:, 0] * y[:, 0] + x[:, 2] * y[:, 2]).sum()
    sxz = (x[:, 0] * y[:, 2] - x[:, 2] * y[:, 0]).sum()
    t = np.arctan2(sxz, sxx)
    c, s = np.cos(t), np.sin(t)
    r = np.stack([c * x[:, 0] - s * x[:, 2], x[:, 1], s * x[:, 0] + c * x[:, 2]], -1)
    return float(np.linalg.norm(r - y, axis=-1).max())


def test_root_auto_follows_a_span_that_turned_and_holds_one_that_did_not(sample_features):
    """``root="auto"``: the kept frames after a span that turned on its own, more than TURN_FOLLOW_DEG and that much
    beyond the source, follow it (as ``"edit"``); after a span that did not (also one that stayed straight where the
    take turned) they keep the source's place (as ``"source"``); after two spans,
    the first turned and the second not, the last kept frames are the source's turned and moved bodily."""
    from salad_core.attention.composite import (TURN_FOLLOW_DEG, _turn_deg, composite_features, followed_turns,
                                                frame_weights, regenerated_runs)
    from salad_core.motion import features_to_joints

    f = sample_features[:80].astype(np.float64)
    assert -100 < _turn_deg(f, 24, 56) < -70             # the take turns right over [24, 56) (about 85 degrees)
    straight = f + np.random.default_rng(2).normal(scale=0.02, size=f.shape) * (np.arange(f.shape[1]) < f.shape[1] - 4)
    straight[:, 0] = f[:, 0] + 0.001                     # 0.002 rad a frame more: about 4 degrees over the span
    turned = straight.copy()
    turned[:, 0] = 0.05                                  # a steady left turn: 0.1 rad a frame, about 180 degrees
    flat = straight.copy()
    flat[:, 0] = 0.0                                     # no turn at all where the take turns: not followed
    w = np.repeat(frame_weights(80, (24, 56), fade=4)[:, None], 22, 1)
    assert regenerated_runs(w[:, 0]) == [(24, 56)]
    out_t = composite_features(f, turned, w, root="edit")
    assert followed_turns(out_t, f, w[:, 0]) == [(24, 56)]
    assert followed_turns(composite_features(f, straight, w, root="edit"), f, w[:, 0]) == []
    assert followed_turns(composite_features(f, flat, w, root="edit"), f, w[:, 0]) == []     # 85 beyond, 0 own
    np.testing.assert_allclose(composite_features(f, turned, w, root="auto"), out_t)
    np.testing.assert_allclose(composite_features(f, straight, w, root="auto"),
                               composite_features(f, straight, w, root="source"))
    with pytest.raises(ValueError, match="root"):
        composite_features(f, turned, w, root="follow")
    assert 0 < TURN_FOLLOW_DEG < 90
    # two spans: [16, 32) turns (followed), [48, 64) does not (corrected towards the turned source path)
    two = turned.copy()
    two[40:] = straight[40:]
    w2 = np.repeat(np.maximum(frame_weights(80, (16, 32), fade=4), frame_weights(80, (48, 64), fade=4))[:, None],
                   22, 1)
    out2 = composite_features(f, two, w2, root="auto")
    assert followed_turns(composite_features(f, two, w2, root="edit"), f, w2[:, 0]) == [(16, 32)]
    j_src, j_auto = features_to_joints(f), features_to_joints(out2)
    assert _yaw_fit_residual(j_src[64:], j_auto[64:]) < 1e-6          # the source's last frames, turned and moved
    assert _yaw_fit_residual(j_src[32:48], j_auto[32:48]) < 1e-6      # and the kept frames between the spans
    assert np.abs(j_src[64:] - j_auto[64:]).max() > 0.1               # ... which did move


def test_composite_seam_is_smoother_with_a_fade(sample_features):
    """Cross-fading a span's seams in feature space: the largest jerk near the seams falls as the fade widens."""
    from salad_core.attention.composite import composite_features, frame_weights
    from salad_core.motion import features_to_joints

    f = sample_features[:80].astype(np.float64)
    g = f.copy()
    g[:, 4:] = np.roll(f[:, 4:], 20, axis=0)            # another pose at every frame, the same root
    seam_jerk = []
    for fade in (0, 4, 8):
        w = np.repeat(frame_weights(80, (24, 56), fade)[:, None], 22, 1)
        j = features_to_joints(composite_features(f, g, w))
        d3 = j[3:] - 3 * j[2:-1] + 3 * j[1:-2] - j[:-3]
        seam_jerk.append(np.linalg.norm(d3, axis=-1).mean(-1)[18:30].max())
    assert seam_jerk[0] > seam_jerk[1] > seam_jerk[2]
    assert seam_jerk[0] > 3 * seam_jerk[2]


def test_inpaint_composite_options():
    sk = get_skeleton()
    w = Inpaint(parts="arms", frames=(8, 24), fade=2).joint_weights(40, sk)
    arms = [j for j, p in enumerate(sk.joint_to_part) if PART_NAMES[p] in ("left arm", "right arm")]
    assert w.shape == (40, 22) and w[:, [j for j in range(22) if j not in arms]].sum() == 0
    np.testing.assert_allclose(w[8:11, arms[0]], [1 / 3, 2 / 3, 1.0])
    legs = Inpaint(parts="legs").joint_weights(12, sk)
    assert (legs.sum(1) == 8).all()                      # every frame: the 8 leg joints (hips to feet)
    with pytest.raises(ValueError, match="Inpaint.noise"):
        Inpaint(parts="arms", noise="white")
    with pytest.raises(ValueError, match=r"Inpaint.root='world'; allowed: \('source', 'edit', 'auto'\)"):
        Inpaint(parts="arms", root="world")
    assert Inpaint(frames=(8, 24)).root == "auto"          # the kept frames follow a span that turned on its own
    with pytest.raises(ValueError, match="Inpaint.fade"):
        Inpaint(parts="arms", fade=-1)
    assert Inpaint(parts="arms").fresh_noise(True) and not Inpaint(parts="arms").fresh_noise(False)
    assert not Inpaint(parts="arms", noise="source").fresh_noise(True)
    assert Inpaint(parts="arms", noise="fresh").fresh_noise(False)


@needs_weights
def test_inverted_take_regions_start_from_fresh_noise_and_kept_parts_are_composited(pipe, sample_features):
    """Editing an inversion, the regenerated region starts from white noise (the inverted noise holds the take's own
    motion there) and the kept parts are the source's decoding: root-aligned they move less than 1 cm (the skeleton
    fit), and less than with the latent in-painting alone."""
    inv = pipe.invert(sample_features[:FRAMES], "a person walks forward and turns around", num_steps=STEPS)
    target = "a man waves his right hand"
    out = pipe.edit(inversion=inv, target=target, edits=[Inpaint(parts="arms")], ground=False)
    old = pipe.edit(inversion=inv, target=target, edits=[Inpaint(parts="arms", noise="source", composite=False,
                                                                  prior="none")], ground=False)
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    kept = [p for p in range(7) if p not in arms]
    z, z_old = out.edited.noise, old.edited.noise
    torch.testing.assert_close(z[:, :, kept], inv.noise[:, :, kept], atol=0, rtol=0)
    assert (z[:, :, arms] - inv.noise[:, :, arms]).abs().min() > 0          # fresh noise on every arm token
    assert 0.8 < float(z[:, :, arms].std()) < 1.2
    torch.testing.assert_close(z_old, inv.noise, atol=0, rtol=0)
    torch.testing.assert_close(out.edited.latents[:, :, kept], out.source.latents[:, :, kept], atol=1e-5, rtol=0)
    jt = np.array(get_skeleton().joint_to_part)
    kept_j = ~np.isin(jt, arms)
    moved = _dist_cm(out.source.joints[0], out.edited.joints[0], joints=kept_j)
    moved_old = _dist_cm(old.source.joints[0], old.edited.joints[0], joints=kept_j)
    assert moved < 1.0 and moved < moved_old
    # what is left is the pipeline's skeleton fit (fixed bone lengths): the features' own joints are the source's
    from salad_core.motion import features_to_joints

    n = out.edited.lengths[0]
    a, b = (features_to_joints(o.features[0, :n]) for o in (out.source, out.edited))
    assert _dist_cm(a, b, joints=kept_j) < 1e-3
    assert _dist_cm(out.source.joints[0], out.edited.joints[0], joints=~kept_j) > 5.0


@needs_weights
def test_inverted_take_span_keeps_the_frames_after_it_in_place(pipe, sample_features):
    """A regenerated middle span of a take that turns: with ``root="source"`` (and ``"auto"``, the default, for a
    span that does not turn on its own) the frames after the span keep their global place and facing; the seams are
    cross-faded; the edited branch's guidance is settable."""
    inv = pipe.invert(sample_features[:FRAMES], "a person walks forward and turns around", num_steps=STEPS)
    out = pipe.edit(inversion=inv, target="a person jumps", ground=False,
                    edits=[Inpaint(frames=(16, 32), guidance=7.5, candidates=1)])
    free = pipe.edit(inversion=inv, target="a person jumps", ground=False,
                     edits=[Inpaint(frames=(16, 32), guidance=7.5, root="edit", candidates=1)])
    src, ed = out.source.joints[0], out.edited.joints[0]
    glob = lambda a, b, fr: float(np.linalg.norm(a[fr] - b[fr], axis=-1).mean() * 100)
    assert glob(src, ed, slice(0, 16)) < 1.0 and glob(src, ed, slice(33, None)) < 1.0      # global, not aligned
    assert _dist_cm(src, ed, frames=slice(20, 28)) > 3.0
    assert glob(src, free.edited.joints[0], slice(33, None)) > glob(src, ed, slice(33, None))
    with pytest.raises(ValueError, match="Inpaint.guidance"):
        Inpaint(frames=(16, 32), guidance=0.5)


@needs_weights
def test_root_auto_records_the_followed_turns_and_equals_its_choice(pipe, sample_features):
    """``Inpaint(root="auto")`` through ``pipe.edit``: the composite records, per motion, the spans whose turn the
    kept frames follow, and the edit equals the one made with the root mode that record implies."""
    inv = pipe.invert(sample_features[:FRAMES], "a person walks forward and turns around", num_steps=STEPS)
    outs = {root: pipe.edit(inversion=inv, target="a person turns left", ground=False,
                            edits=[Inpaint(frames=(16, 32), guidance=7.5, root=root, candidates=1, prior="none")])
            for root in ("auto", "source", "edit")}
    rec = outs["auto"].settings["composite"]
    assert "followed_turns" in rec and len(rec["followed_turns"]) == 1
    assert "followed_turns" not in outs["source"].settings["composite"]
    same = "edit" if rec["followed_turns"][0] else "source"
    np.testing.assert_allclose(outs["auto"].edited.joints[0], outs[same].edited.joints[0], atol=1e-5)
    for span in rec["followed_turns"][0]:
        assert 16 <= span[0] < span[1] <= 32


# --------------------------------------------------------------------- seam smoothing, resampling, span guidance
def _third_difference(x: np.ndarray) -> np.ndarray:
    return x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]


def test_smooth_columns_lowers_the_seam_jerk_of_a_step_and_keeps_fixed_frames():
    from salad_core.attention.composite import smooth_columns

    n = 40
    y = np.zeros((n, 2))
    y[20:, 0] = 1.0                                     # a step at the seam 19 | 20
    y[20:, 1] = np.linspace(1.0, 2.0, n - 20)           # a step and a slope
    free = np.zeros(n, bool)
    free[20:28] = True                                  # the regenerated frames next to the seam
    out = smooth_columns(y, free, order=3, strength=100.0)
    np.testing.assert_array_equal(out[~free], y[~free])                 # every fixed frame exactly
    before, after = np.abs(_third_difference(y)[14:26]).max(0), np.abs(_third_difference(out)[14:26]).max(0)
    assert (after < 0.25 * before).all()
    # a stronger penalty smooths more; none leaves the signal as it is
    strong = smooth_columns(y, free, order=3, strength=1000.0)
    assert np.abs(_third_difference(strong)[14:26]).max() < np.abs(_third_difference(out)[14:26]).max()
    np.testing.assert_array_equal(smooth_columns(y, free, order=3, strength=0.0), y)
    # a smooth signal (a cubic, third difference constant) is left almost as it is
    t = np.arange(n, dtype=float)[:, None] / n
    cubic = t ** 3
    np.testing.assert_allclose(smooth_columns(cubic, free, order=3, strength=100.0), cubic, atol=1e-3)


def test_seams():
    from salad_core.attention.composite import seams

    assert seams(np.array([0, 0, 1, 1, 1, 0], bool)) == [2, 5]
    assert seams(np.array([1, 1, 0, 0], bool)) == [2]
    assert seams(np.ones(5, bool)) == [] and seams(np.zeros(5, bool)) == []


def test_seam_smoothing_of_a_composite_lowers_the_seam_jerk_and_keeps_the_rest(sample_features):
    """A regenerated span (another pose at every frame, the same root): smoothing moves only the span's frames within
    the window of each seam, keeps the kept frames (global place too) and lowers the seam's jerk."""
    from salad_core.attention.composite import composite_features, frame_weights, smooth_seam_features
    from salad_core.motion import features_to_joints

    f = sample_features[:80].astype(np.float64)
    g = f.copy()
    g[:, 4:] = np.roll(f[:, 4:], 20, axis=0)
    w = np.repeat(frame_weights(80, (24, 56), 4)[:, None], 22, 1)
    plain = composite_features(f, g, w)
    smooth = smooth_seam_features(plain, w, window=8, strength=100.0)
    moved = np.abs(smooth - plain).max(1) > 0
    assert moved[24:32].all() and moved[48:56].all()                # the span's frames next to the seams
    assert not moved[:24].any() and not moved[32:48].any() and not moved[56:].any()
    contacts = get_skeleton().feature_slices["contacts"]
    np.testing.assert_array_equal(smooth[:, contacts], plain[:, contacts])
    seam_jerk = lambda x: np.linalg.norm(_third_difference(features_to_joints(x)), axis=-1).mean(-1)
    for b in (24, 56):
        assert seam_jerk(smooth)[b - 5:b + 3].max() < 0.7 * seam_jerk(plain)[b - 5:b + 3].max()
    # through composite_features, with a span that also turns: the kept frames keep their global place
    g2 = _edited_like(f, 1)
    held = composite_features(f, g2, w, smooth=100.0, smooth_window=8)
    jf, jh = features_to_joints(f), features_to_joints(held)
    np.testing.assert_allclose(jh[:24], jf[:24], atol=1e-9)
    np.testing.assert_allclose(jh[57:], jf[57:], atol=1e-6)
    assert np.abs(held - composite_features(f, g2, w)).max() > 1e-3
    # parts without a span have no seam: nothing to smooth
    from salad_core.attention.composite import part_joint_weights

    pw = np.repeat(part_joint_weights(("left arm", "right arm"))[None], 80, 0)
    np.testing.assert_array_equal(composite_features(f, g, pw, smooth=100.0, smooth_window=8),
                                  composite_features(f, g, pw))


def test_inpaint_new_options():
    from salad_core.attention.inpaint import SPAN_GUIDANCE

    assert Inpaint(frames=(8, 24), guidance="auto").edited_guidance == SPAN_GUIDANCE
    assert Inpaint(frames=(8, 24)).edited_guidance == SPAN_GUIDANCE and Inpaint(parts="arms").edited_guidance is None
    assert Inpaint(parts="arms", guidance="auto").edited_guidance is None
    assert Inpaint(parts="arms", frames=(8, 24), guidance="auto").edited_guidance == SPAN_GUIDANCE
    assert Inpaint(parts="arms", guidance=6).edited_guidance == 6.0
    assert Inpaint(frames=(8, 24), guidance=None).edited_guidance is None
    for kwargs, match in [(dict(guidance="strong"), "Inpaint.guidance"), (dict(smooth=-1.0), "Inpaint.smooth"),
                          (dict(smooth=float("nan")), "Inpaint.smooth"), (dict(smooth_window=-2), "smooth_window"),
                          (dict(resample=0), "Inpaint.resample"), (dict(jump=0), "Inpaint.jump"),
                          (dict(resample=1.5), "Inpaint.resample")]:
        with pytest.raises(ValueError, match=match):
            Inpaint(frames=(8, 24), **kwargs)
    # resampling after the steps that end a jump, never after the last step, only in the replacement's window
    r = Inpaint(frames=(8, 24), resample=2, jump=3)
    assert [i for i in range(10) if r.resampling(i / 10, i, 10, r.passes_for(False))] == [2, 5, 8]
    every = Inpaint(frames=(8, 24), resample=2, jump=1)
    assert [i for i in range(10) if every.resampling(i / 10, i, 10, 2)] == list(range(9))
    # resample="auto" (default): PARTS_RESAMPLE passes of jumps of 5 steps for body parts alone of an inverted
    # motion; none for a span or a generated source; a number is used as it is
    from salad_core.attention.inpaint import PARTS_RESAMPLE

    arms = Inpaint(parts="arms", prior="none")
    assert arms.passes_for(True) == PARTS_RESAMPLE > 1 and arms.passes_for(False) == 1
    assert Inpaint(parts="arms").passes_for(True) == 1          # the default pastes a prior there instead
    assert Inpaint(frames=(8, 24)).passes_for(True) == 1 and Inpaint(parts="arms", frames=(8, 24)).passes_for(True) == 1
    assert Inpaint(parts="arms", resample=1).passes_for(True) == 1 and r.passes_for(True) == r.passes_for(False) == 2
    assert [i for i in range(10) if arms.resampling(i / 10, i, 10, arms.passes_for(True))] == [4]
    assert not any(arms.resampling(i / 10, i, 10, arms.passes_for(False)) for i in range(10))
    late = Inpaint(frames=(8, 24), resample=2, jump=1, steps=(0.0, 0.5))
    assert [i for i in range(10) if late.resampling(i / 10, i, 10, 2)] == [0, 1, 2, 3, 4]


@needs_weights
def test_resampling_changes_the_region_and_not_the_kept_latents(pipe):
    kw = dict(target="a person jumps", lengths=FRAMES, seed=0, num_steps=6)
    plain = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), composite=False, guidance=None)], **kw)
    again = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), composite=False, guidance=None, resample=2, jump=1)],
                      **kw)
    jumps = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), composite=False, guidance=None, resample=3,
                                             jump=2)], **kw)
    region = plain.edited.latents.new_zeros(plain.edited.latents.shape[:2], dtype=torch.bool)
    region[:, 4:8] = True
    for out in (again, jumps):
        # the source branch is never touched; the kept latents are the source's exactly
        torch.testing.assert_close(out.source.latents, plain.source.latents, atol=0, rtol=0)
        torch.testing.assert_close(out.edited.latents[~region], out.source.latents[~region], atol=0, rtol=0)
        assert (out.edited.latents[region] - plain.edited.latents[region]).abs().mean() > 0.05
    # the extra passes are counted, 4 forward rows each (two branches, each with its unconditional row):
    # resample=2 runs steps 0..4 once more (never the last), resample=3 jump=2 the jumps 0-1 and 2-3 twice more
    rows = plain.settings["forward_rows"]
    assert again.settings["forward_rows"] - rows == 5 * 4
    assert jumps.settings["forward_rows"] - rows == 2 * 2 * 2 * 4
    with pytest.raises(ValueError, match="needs the DDIM sampler"):
        pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), resample=2)], solver="dpm++", **kw)
    # resample="auto" on body parts: a generated source is sampled once (with DDIM too, and with other solvers);
    # an inverted motion is resampled
    arms = dict(target="a man waves his right hand", lengths=FRAMES, seed=0, num_steps=6)
    auto = pipe.edit(SOURCE, edits=[Inpaint(parts="arms", composite=False)], **arms)
    once = pipe.edit(SOURCE, edits=[Inpaint(parts="arms", composite=False, resample=1)], **arms)
    assert auto.settings["forward_rows"] == once.settings["forward_rows"]
    np.testing.assert_array_equal(auto.edited.features, once.edited.features)
    fast = pipe.edit(SOURCE, edits=[Inpaint(parts="arms", composite=False)], solver="dpm++", **arms)
    fast_once = pipe.edit(SOURCE, edits=[Inpaint(parts="arms", composite=False, resample=1)], solver="dpm++", **arms)
    np.testing.assert_array_equal(fast.edited.features, fast_once.edited.features)
    from salad_core.attention.inpaint import PARTS_RESAMPLE

    inv = pipe.invert(plain.source.features[0, :FRAMES], SOURCE, num_steps=6)
    take = dict(target="a man waves his right hand", inversion=inv, ground=False)
    auto = pipe.edit(edits=[Inpaint(parts="arms", composite=False, prior="none")], **take)
    once = pipe.edit(edits=[Inpaint(parts="arms", composite=False, resample=1, prior="none")], **take)
    assert auto.settings["forward_rows"] == once.settings["forward_rows"] + 4 * (PARTS_RESAMPLE - 1) * 5
    # with the default pasted prior (prior="auto") an inverted take's parts are not resampled
    pasted = pipe.edit(edits=[Inpaint(parts="arms", composite=False)], **take)
    assert pasted.settings["forward_rows"] == once.settings["forward_rows"]
    assert pasted.settings["inpaint_prior"]["mode"] == "prompt"


@needs_weights
def test_span_guidance_and_smoothing_reach_the_edit(pipe):
    """``guidance="auto"`` guides a span's edited branch with SPAN_GUIDANCE (the same edit as giving it), and the
    seam smoothing changes only the span's frames next to the seams of the decoded edit."""
    from salad_core.attention.inpaint import SPAN_GUIDANCE

    kw = dict(target="a person jumps", lengths=FRAMES, seed=0, num_steps=5)
    auto = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), guidance="auto", smooth=0.0)], **kw)
    given = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), guidance=SPAN_GUIDANCE, smooth=0.0)], **kw)
    motion = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), guidance=None, smooth=0.0)], **kw)
    np.testing.assert_array_equal(auto.edited.features, given.edited.features)
    assert np.abs(auto.edited.features - motion.edited.features).max() > 1e-3
    smooth = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), guidance="auto", smooth=100.0, smooth_window=4)],
                       **kw)
    d = np.abs(smooth.edited.features[0, :FRAMES] - auto.edited.features[0, :FRAMES]).max(1)
    assert smooth.settings["composite"]["seam_smoothing"] == ["smoothed"]
    assert d[16:20].max() > 1e-4 and d[28:32].max() > 1e-4
    assert d[:16].max() == 0 and d[32:].max() == 0          # the kept frames are the source's


@needs_weights
def test_seam_smoothing_is_dropped_where_it_would_raise_the_seams_jerk(pipe, monkeypatch):
    """The composite keeps the smoothed seams only if the recovered joints' seam jerk does not rise: a smoothing that
    shakes the frames next to the seams is dropped (the edit is the plain composite)."""
    from salad_core.attention import composite

    def shaky(features, weights, window, strength, skeleton="humanml3d"):
        out = np.array(features, np.float64)
        out[16:20, 4:67] += 0.05 * np.array([1.0, -1.0, 1.0, -1.0])[:, None]        # positions jump every frame
        return out

    kw = dict(target="a person jumps", lengths=FRAMES, seed=0, num_steps=5)
    plain = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), smooth=0.0)], **kw)
    monkeypatch.setattr(composite, "smooth_seam_features", shaky)
    shaken = pipe.edit(SOURCE, edits=[Inpaint(frames=(16, 32), smooth=100.0)], **kw)
    assert shaken.settings["composite"]["seam_smoothing"] == ["plain"]
    np.testing.assert_array_equal(shaken.edited.features, plain.edited.features)
    assert "seam_smoothing" not in plain.settings["composite"]


# --------------------------------------------------------------------- matched region noise
def _lag1_and_std(x: np.ndarray) -> tuple[float, float]:
    """``(N', P, Dz)`` -> (correlation of neighbouring frames pooled over parts and channels, std), computed here."""
    x = np.asarray(x, np.float64)
    return float(np.corrcoef(x[1:].ravel(), x[:-1].ravel())[0, 1]), float(x.std())


def _ar1_reference(rho: float, std: float, n: int, seed: int) -> torch.Tensor:
    """``(n, 7, 32)`` a stationary AR(1) sequence along the frames with lag-1 correlation ``rho`` and std ``std``."""
    e = np.random.default_rng(seed).standard_normal((n, 7, 32))
    x = np.empty_like(e)
    x[0] = e[0]
    for t in range(1, n):
        x[t] = rho * x[t - 1] + np.sqrt(1 - rho ** 2) * e[t]
    return torch.from_numpy(std * x).float()


def _corr(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(np.corrcoef(a.flatten().numpy(), b.flatten().numpy())[0, 1])


def test_matched_noise_takes_the_references_frame_correlation_and_std():
    n = 1500
    ref = torch.stack([_ar1_reference(0.6, 1.3, n, 1), _ar1_reference(0.3, 0.6, n, 2)])
    white = torch.randn(2, n, 7, 32, generator=torch.Generator().manual_seed(3))
    out = matched_noise(white, ref, torch.ones(2, n, dtype=torch.bool))
    assert out.shape == white.shape and out.dtype == white.dtype
    for i, (rho, std) in enumerate([(0.6, 1.3), (0.3, 0.6)]):
        lag1, s = _lag1_and_std(out[i].numpy())
        assert abs(lag1 - rho) < 0.02 and abs(s / std - 1) < 0.02
        assert abs(_corr(out[i], ref[i])) < 0.01                       # new noise, not the reference
    # the correlation is clipped to [0, MATCHED_MAX_RHO]: an anti-correlated reference gives white noise of its std
    anti = _ar1_reference(-0.5, 0.7, n, 4)[None]
    std, rho = noise_statistics(anti, torch.ones(1, n, dtype=torch.bool))
    assert rho.item() < -0.45
    torch.testing.assert_close(matched_noise(white[:1], anti, torch.ones(1, n, dtype=torch.bool)),
                               white[:1] * float(std), atol=1e-5, rtol=0)
    hot = _ar1_reference(0.99, 1.0, n, 5)[None]
    lag1, _ = _lag1_and_std(matched_noise(white[:1], hot, torch.ones(1, n, dtype=torch.bool))[0].numpy())
    assert abs(lag1 - MATCHED_MAX_RHO) < 0.01


def test_matched_noise_ignores_frames_past_each_motions_length():
    n, valid = 40, 25
    ref = torch.stack([_ar1_reference(0.5, 0.8, n, 6)] * 2)
    ref[1, valid:] = 50.0 * torch.randn(n - valid, 7, 32, generator=torch.Generator().manual_seed(7))
    fm = torch.ones(2, n, dtype=torch.bool)
    fm[1, valid:] = False
    std, rho = noise_statistics(ref, fm)
    lag1, s = _lag1_and_std(ref[1, :valid].numpy())                     # the valid frames alone
    assert abs(rho[1].item() - lag1) < 1e-6 and abs(std[1].item() - s) < 1e-6
    lag1_all, s_all = _lag1_and_std(ref[0].numpy())                    # motion 0: all its frames are valid
    assert abs(rho[0].item() - lag1_all) < 1e-6 and abs(std[0].item() - s_all) < 1e-6
    white = torch.randn(2, n, 7, 32, generator=torch.Generator().manual_seed(8))
    other = ref.clone()
    other[1, valid:] = -7.0                                            # other padding: the same noise
    torch.testing.assert_close(matched_noise(white, ref, fm), matched_noise(white, other, fm), atol=0, rtol=0)
    counted = matched_noise(white, ref, torch.ones(2, n, dtype=torch.bool))
    assert counted[1].std() > 5 * matched_noise(white, ref, fm)[1].std()   # counted, the padding would dominate


def test_matched_noise_bad_input():
    fm = torch.ones(1, 12, dtype=torch.bool)
    with pytest.raises(ValueError, match="same shape"):
        matched_noise(torch.randn(1, 12, 7, 32), torch.randn(1, 10, 7, 32), fm)
    with pytest.raises(ValueError, match="frame_mask must be"):
        noise_statistics(torch.randn(1, 12, 7, 32), torch.ones(1, 10, dtype=torch.bool))
    with pytest.raises(ValueError, match=r"\(B, N', P, Dz\)"):
        noise_statistics(torch.randn(12, 7, 32), fm)
    with pytest.raises(ValueError, match="motion 0 of the batch has no valid latent frame"):
        noise_statistics(torch.randn(1, 12, 7, 32), torch.zeros(1, 12, dtype=torch.bool))
    with pytest.raises(ValueError, match="Inpaint.noise='white'; allowed: .*'matched'"):
        Inpaint(parts="arms", noise="white")
    assert "matched" in NOISE_MODES


def test_matched_region_noise_is_seeded_and_about_fresh_for_white_source_noise():
    shape = (2, 12, 7, 32)
    src, fm = seeded_noise(5, shape), torch.ones(2, 12, dtype=torch.bool)
    matched = Inpaint(parts="arms", noise="matched", seed=3)
    assert matched.fresh_noise(True) and matched.fresh_noise(False)
    a, b = matched.region_noise(src, fm), matched.region_noise(src, fm)
    torch.testing.assert_close(a, b, atol=0, rtol=0)                    # deterministic for a seed
    other = Inpaint(parts="arms", noise="matched", seed=4).region_noise(src, fm)
    assert _corr(a, other) < 0.1
    fresh = Inpaint(parts="arms", noise="fresh", seed=3).region_noise(src, fm)
    torch.testing.assert_close(fresh, seeded_noise(3, shape), atol=0, rtol=0)
    assert _corr(a, fresh) > 0.99 and 0.95 < float(a.std() / fresh.std()) < 1.05
    # a hotter, frame-correlated source (as an inverted real take's): the same draw, shaped
    take = torch.stack([_ar1_reference(0.5, 1.3, 12, 9), _ar1_reference(0.5, 1.3, 12, 10)])
    shaped = matched.region_noise(take, fm)
    assert 0.5 < _corr(shaped, fresh) < 0.95 and 1.1 < float(shaped.std()) < 1.5


@needs_weights
def test_matched_noise_on_a_generated_source_changes_only_the_region(pipe):
    kw = dict(target="a man waves his right hand", lengths=FRAMES, seed=0, num_steps=STEPS)
    out = pipe.edit(SOURCE, edits=[Inpaint(parts="arms", noise="matched", composite=False)], **kw)
    fresh = pipe.edit(SOURCE, edits=[Inpaint(parts="arms", noise="fresh", composite=False)], **kw)
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    kept = [p for p in range(7) if p not in arms]
    z, z_src = out.edited.noise, out.source.noise
    torch.testing.assert_close(z[:, :, kept], z_src[:, :, kept], atol=0, rtol=0)
    torch.testing.assert_close(out.edited.latents[:, :, kept], out.source.latents[:, :, kept], atol=0, rtol=0)
    fm = torch.ones(1, FRAMES // 4, dtype=torch.bool)
    want = Inpaint(parts="arms", noise="matched").region_noise(z_src, fm)
    torch.testing.assert_close(z[:, :, arms], want[:, :, arms], atol=0, rtol=0)
    assert (z[:, :, arms] - z_src[:, :, arms]).abs().min() > 0          # new noise on every arm token
    assert _corr(z[:, :, arms], fresh.edited.noise[:, :, arms]) > 0.95   # white source noise: about "fresh"
    assert (out.edited.latents[:, :, arms] - out.source.latents[:, :, arms]).abs().mean() > 0.05


@needs_weights
def test_matched_noise_of_an_inverted_take_follows_the_takes_noise(pipe, sample_features):
    inv = pipe.invert(sample_features[:FRAMES], "a person walks forward and turns around", num_steps=STEPS)
    out = pipe.edit(inversion=inv, target="a man waves his right hand",
                    edits=[Inpaint(parts="arms", noise="matched", resample=1, prior="none")],
                    ground=False)
    arms = [PART_NAMES.index("left arm"), PART_NAMES.index("right arm")]
    kept = [p for p in range(7) if p not in arms]
    z = out.edited.noise
    torch.testing.assert_close(z[:, :, kept], inv.noise[:, :, kept], atol=0, rtol=0)
    fm = torch.ones(1, FRAMES // 4, dtype=torch.bool)
    want = matched_noise(seeded_noise(0, z.shape), inv.noise, fm)
    torch.testing.assert_close(z[:, :, arms], want[:, :, arms], atol=0, rtol=0)
    std, _ = noise_statistics(inv.noise, fm)
    assert 0.8 < float(z[:, :, arms].std()) / std.item() < 1.25
    torch.testing.assert_close(out.edited.latents[:, :, kept], out.source.latents[:, :, kept], atol=1e-5, rtol=0)
