"""Activation patching: all cross outputs at every step give the clean run, nothing gives the
corrupt run, partial patches land in between and are measured per body part."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.attention import PatchingResult, patch_activations
from salad_core.attention.patching import MIN_GAP
from salad_core.part_activity import part_activity
from salad_core.skeleton import NUM_PARTS, PART_NAMES

CLEAN = "a man waves his left hand"
CORRUPT = "a man kicks with his right leg"
RUN = dict(seed=1, lengths=40, num_steps=6)

pytestmark = pytest.mark.usefixtures("single_thread")


@pytest.fixture(scope="module")
def pipe(make_tiny_pipeline):
    return make_tiny_pipeline(seed=0)


@pytest.fixture(scope="module")
def everything(pipe) -> PatchingResult:
    return patch_activations(pipe, CLEAN, CORRUPT, site="layers.*.cross.out", steps=(0.0, 1.0), **RUN)


def test_patching_every_cross_output_at_every_step_gives_the_clean_run(pipe, everything):
    res = everything
    assert res.points == ("layers.0.cross.out", "layers.1.cross.out", "layers.2.cross.out")
    assert res.steps == tuple(range(6))
    clean, corrupt, patched = (res.outputs[k] for k in ("clean", "corrupt", "patched"))
    assert torch.equal(patched.latents, clean.latents) and np.array_equal(patched.features, clean.features)
    assert not torch.equal(corrupt.latents, clean.latents)
    # the clean run of the patching is the plain generation of the clean prompt
    assert torch.equal(clean.latents, pipe(CLEAN, **RUN).latents)
    np.testing.assert_array_equal(res.patched, res.clean)
    ok = ~np.isnan(res.recovered)
    assert ok.sum() >= 4 and np.allclose(res.recovered[ok], 1.0)
    assert res.recovered_total == pytest.approx(1.0)


def test_patching_nothing_gives_the_corrupt_run(pipe, everything):
    res = patch_activations(pipe, CLEAN, CORRUPT, site=(), **RUN)
    assert res.points == () and res.steps == ()
    assert torch.equal(res.outputs["patched"].latents, everything.outputs["corrupt"].latents)
    assert torch.equal(res.outputs["corrupt"].latents, everything.outputs["corrupt"].latents)
    np.testing.assert_array_equal(res.change, np.zeros(NUM_PARTS))
    assert res.recovered_total == 0.0


def test_a_partial_patch_is_measured_per_body_part(pipe, everything):
    res = patch_activations(pipe, CLEAN, CORRUPT, site="layers.1.cross.out", steps=(0.0, 0.5), **RUN)
    assert res.points == ("layers.1.cross.out",) and res.steps == (0, 1, 2)
    patched = res.outputs["patched"]
    assert not torch.equal(patched.latents, everything.outputs["clean"].latents)
    assert not torch.equal(patched.latents, everything.outputs["corrupt"].latents)
    # the measurements are part_activity of the three motions, parts in PART_NAMES order
    np.testing.assert_allclose(res.patched, part_activity(patched.joints[0]))
    np.testing.assert_allclose(res.corrupt, everything.corrupt)
    np.testing.assert_allclose(res.change, res.patched - res.corrupt)
    gap = res.clean - res.corrupt
    ok = np.abs(gap) >= MIN_GAP
    np.testing.assert_allclose(res.recovered[ok], res.change[ok] / gap[ok])
    assert res.recovered_total == pytest.approx(float(res.change @ gap / (gap @ gap)))
    rows = res.table()
    assert [r["part"] for r in rows] == list(PART_NAMES) and rows[2]["change"] == pytest.approx(res.change[2])


def test_probabilities_patch_between_prompts_of_one_token_count(pipe):
    clean, corrupt = "a man walks forward", "a man runs forward"
    widths = [len(t) for t in pipe.text_encoder.encode([clean, corrupt]).tokens]
    assert widths[0] == widths[1]
    res = patch_activations(pipe, clean, corrupt, site="layers.*.cross", **RUN)
    assert res.points == ("layers.0.cross", "layers.1.cross", "layers.2.cross")
    # the corrupt run's values mixed by the clean maps: neither run
    assert not torch.equal(res.outputs["patched"].latents, res.outputs["corrupt"].latents)
    with pytest.raises(ValueError, match="same token count"):
        patch_activations(pipe, CLEAN, CORRUPT, site="layers.0.cross", **RUN)


def test_bad_arguments(pipe):
    with pytest.raises(TypeError, match="clean_prompt must be one prompt"):
        patch_activations(pipe, [CLEAN], CORRUPT, **RUN)
    with pytest.raises(ValueError, match="q, k and v are read-only"):
        patch_activations(pipe, CLEAN, CORRUPT, site="layers.0.cross.q", **RUN)
    with pytest.raises(KeyError, match="no hook point matches 'layers.4.cross.out'"):
        patch_activations(pipe, CLEAN, CORRUPT, site="layers.4.cross.out", **RUN)
