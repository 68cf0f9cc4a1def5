"""In-painting (issue 67): Inpaint's region, its notation, and regenerating parts / frames of generated and
inverted motions with the shipped weights (few steps, one thread)."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.attention import Inpaint, Refine, Reweight, parse_inpaint
from salad_core.attention.edits import validate_edits
from salad_core.pipeline import default_weights_dir
from salad_core.skeleton import PART_NAMES, get_skeleton

STEPS = 10
FRAMES = 48
SOURCE = "a person walks forward"

needs_weights = pytest.mark.skipif(not (default_weights_dir() / "pipeline.json").is_file(),
                                   reason="needs the shipped SALAD weights (salad_core/weights/salad)")


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
