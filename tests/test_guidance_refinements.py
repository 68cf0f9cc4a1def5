"""Projected guidance (APG, Sadat et al. 2025) and dynamic thresholding (Imagen, Saharia et al. 2022) of
:class:`salad_core.sampling.Guidance`: off they change nothing, on they do what the papers say, in numbers."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from salad_core.io import CheckpointError
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import (
    Guidance,
    GuidanceStep,
    GuidedPrediction,
    denoise,
    dynamic_threshold,
    guidance_step,
    make_scheduler,
    project_onto,
    training_target,
)
from _doubles import HashTextEncoder, tiny_keymotion

CFG = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=3, text_dim=12, max_len=256)

pytestmark = pytest.mark.usefixtures("single_thread")


def _setup(b=2, n=5, seed=0):
    """A tiny random SALAD denoiser, two texts, the null text, noise ``(b, n, P, Dz)`` and a frame mask
    with padding in the second sample."""
    torch.manual_seed(seed)
    model = Denoiser(CFG)
    g = torch.Generator().manual_seed(seed + 1)
    text = (torch.randn(b, 6, CFG.text_dim, generator=g), torch.ones(b, 6, dtype=torch.bool))
    null = (torch.randn(1, 2, CFG.text_dim, generator=g), torch.ones(1, 2, dtype=torch.bool))
    noise = torch.randn(b, n, CFG.num_parts, CFG.latent_dim, generator=g)
    frame_mask = torch.ones(b, n, dtype=torch.bool)
    frame_mask[1, 3:] = False
    return model, text, null, noise, frame_mask


def _branches(seed=0, shape=(3, 4, 7, 5)):
    g = torch.Generator().manual_seed(seed)
    return torch.randn(shape, generator=g), torch.randn(shape, generator=g) + 0.5, torch.randn(shape, generator=g)


class LiteralCFG(GuidedPrediction):
    """Eq. 9 written out, ``u + w (c - u)``, on the same batched forward as :class:`GuidedPrediction`."""

    def __call__(self, z, t, info=None):
        out = self.model(torch.cat([z, z]), t.reshape(1), frame_mask=self._both_masks, text_context=self.both)
        u, c = out.chunk(2)
        return u + self.guidance.scale * (c - u)


def _dot(a, b):
    return (a.double() * b.double()).flatten(1).sum(1)


# ------------------------------------------------------------------------------- off = as before
def test_off_is_bit_identical_to_eq_9():
    model, text, null, noise, fm = _setup()
    u, c, _ = _branches()
    for off in (Guidance(7.5), Guidance(7.5, threshold=None, projection=None, norm_cap=None, momentum=0.0)):
        assert torch.equal(off.combine(u, c), u + 7.5 * (c - u))
        out = denoise(model, make_scheduler(), text, null, noise, fm, guidance_scale=off, num_steps=6)
        literal = LiteralCFG(model, text, null, 7.5, fm, batch_size=noise.shape[0])
        ref = denoise(model, make_scheduler(), latents=noise, frame_mask=fm, prediction=literal, num_steps=6)
        assert torch.equal(out, ref)
    assert guidance_step() is None                                   # the loop leaves nothing published


# ----------------------------------------------------------------------- the clean-sample step
@pytest.mark.parametrize("kind", ["epsilon", "v_prediction", "sample"])
def test_guidance_step_converts_model_outputs_to_the_clean_sample_and_back(kind):
    sched = make_scheduler()
    x0, noise, _ = _branches(1)
    t = torch.full((x0.shape[0],), 600)
    xt = sched.add_noise(x0, noise, t)
    step = GuidanceStep(xt, float(sched.alphas_cumprod[600]), kind)
    target = training_target(sched, x0, noise, t, kind)              # what the model would predict exactly
    torch.testing.assert_close(step.to_x0(target), x0, atol=1e-4, rtol=1e-4)
    torch.testing.assert_close(step.from_x0(x0), target, atol=1e-4, rtol=1e-4)


def test_guidance_step_errors_name_the_problem():
    with pytest.raises(ValueError, match="prediction_type"):
        GuidanceStep(torch.zeros(2, 3), 0.5, "x0")
    with pytest.raises(ValueError, match="alpha_bar"):
        GuidanceStep(torch.zeros(2, 3), 0.0, "epsilon")
    with pytest.raises(ValueError, match="noisy sample of the same rows"):
        GuidanceStep(torch.zeros(2, 3), 0.5, "epsilon").shaped_as(torch.zeros(4, 3))
    u, c, _ = _branches()
    with pytest.raises(RuntimeError, match="inside denoise"):
        Guidance(7.5, threshold=0.99).combine(u, c)


# --------------------------------------------------------------------------- thresholding
def test_dynamic_threshold_clamps_at_the_per_sample_quantile_and_rescales():
    g = torch.Generator().manual_seed(2)
    x0 = torch.randn(3, 6, 7, 5, generator=g) * torch.tensor([3.0, 0.2, 1.5]).view(3, 1, 1, 1)
    out = dynamic_threshold(x0, 0.9)
    for i in range(3):
        s = max(float(np.quantile(x0[i].abs().numpy(), 0.9)), 1.0)
        ref = np.clip(x0[i].numpy(), -s, s) / s
        np.testing.assert_allclose(out[i].numpy(), ref, atol=1e-6)
    assert out.abs().max() <= 1.0 + 1e-6
    assert torch.equal(out[1], x0[1])                 # |x0| < 1 everywhere: Imagen's s = 1 leaves it as it is
    share = (out[0].abs() >= 1.0 - 1e-6).float().mean().item()
    assert 0.09 <= share <= 0.12                      # the top 10 % of |x0| are clamped to the bound
    # a wider bound b: the quantile maps to b, a sample inside it is left alone
    wide = dynamic_threshold(x0, 0.9, bound=2.0)
    s0 = float(np.quantile(x0[0].abs().numpy(), 0.9))
    np.testing.assert_allclose(wide[0].numpy(), np.clip(x0[0].numpy(), -s0, s0) * 2.0 / s0, atol=1e-6)
    assert wide.abs().max() <= 2.0 + 1e-6 and torch.equal(wide[1], x0[1])
    # padded frames do not enter the quantile
    keep = torch.ones(3, 6, 1, 1)
    keep[0, 4:] = 0
    padded = x0.clone()
    padded[0, 4:] = 100.0
    masked = dynamic_threshold(padded, 0.9, keep=keep)
    s = max(float(np.quantile(x0[0, :4].abs().numpy(), 0.9)), 1.0)
    np.testing.assert_allclose(masked[0, :4].numpy(), np.clip(x0[0, :4].numpy(), -s, s) / s, atol=1e-6)


def test_threshold_bounds_the_guided_clean_sample_prediction():
    u, c, xt = _branches(3)
    step = GuidanceStep(xt, 0.3, "epsilon")
    g = Guidance(7.5, threshold=0.95, threshold_bound=1.5)
    pred = g.combine(u, c, step=step)
    x0 = step.to_x0(pred)
    assert x0.abs().flatten(1).max(1).values.max() <= 1.5 + 1e-4
    plain_x0 = step.to_x0(Guidance(7.5).combine(u, c))
    assert plain_x0.abs().max() > 3.0                                 # there was something to bound
    torch.testing.assert_close(x0, dynamic_threshold(plain_x0, 0.95, 1.5), atol=1e-4, rtol=1e-4)


# ---------------------------------------------------------------------------- projection
def test_projection_eta_one_is_plain_cfg_and_eta_zero_is_orthogonal():
    u, c, xt = _branches(4)
    for kind in ("epsilon", "v_prediction", "sample"):
        step = GuidanceStep(xt, 0.4, kind)
        plain = Guidance(5.0).combine(u, c)
        torch.testing.assert_close(Guidance(5.0, projection=1.0).combine(u, c, step=step), plain,
                                   atol=1e-5, rtol=1e-5)
        x0_c = step.to_x0(c)
        update = step.to_x0(Guidance(5.0, projection=0.0).combine(u, c, step=step)) - x0_c
        cos = _dot(update, x0_c) / (update.flatten(1).norm(dim=1) * x0_c.flatten(1).norm(dim=1)).double()
        assert cos.abs().max() < 1e-5                                 # no part along the conditional x0
        plain_update = step.to_x0(plain) - x0_c
        plain_cos = _dot(plain_update, x0_c) / (plain_update.flatten(1).norm(dim=1)
                                               * x0_c.flatten(1).norm(dim=1)).double()
        assert plain_cos.abs().min() > 0.05                           # plain CFG's update has one
        # the update removed is exactly the parallel part of (w - 1) * d
        par, orth = project_onto(step.to_x0(c) - step.to_x0(u), x0_c)
        torch.testing.assert_close(update, 4.0 * orth, atol=1e-4, rtol=1e-4)
        torch.testing.assert_close(par + orth, step.to_x0(c) - step.to_x0(u), atol=1e-5, rtol=1e-5)


def test_projection_uses_valid_frames_only_and_caps_the_norm():
    u, c, xt = _branches(5)
    step = GuidanceStep(xt, 0.5, "v_prediction")
    keep = torch.ones(3, 4, 1, 1)
    keep[1, 2:] = 0
    x0_c = step.to_x0(c)
    update = step.to_x0(Guidance(5.0, projection=0.0).combine(u, c, keep=keep, step=step)) - x0_c
    w = keep.expand_as(update)
    assert _dot(update * w, x0_c * w).abs().max() < 1e-4            # orthogonal over the valid frames
    # norm cap r: the guided x0 moves at most (w - 1) r from the conditional one
    r = 0.5
    capped = step.to_x0(Guidance(5.0, projection=1.0, norm_cap=r).combine(u, c, step=step)) - x0_c
    norms = capped.flatten(1).norm(dim=1)
    d_norms = (x0_c - step.to_x0(u)).flatten(1).norm(dim=1)
    assert torch.all(d_norms > r)                                     # every sample was capped
    torch.testing.assert_close(norms, torch.full_like(norms, 4.0 * r), atol=1e-4, rtol=1e-4)


def test_projection_momentum_averages_the_updates_of_one_loop():
    (u1, c1, xt), (u2, c2, _) = _branches(6), _branches(7)
    step = GuidanceStep(xt, 1.0 - 1e-6, "sample", {})                 # sample prediction: x0 is the output
    g = Guidance(3.0, projection=1.0, momentum=-0.5)
    first = g.combine(u1, c1, step=step)
    torch.testing.assert_close(first, Guidance(3.0).combine(u1, c1), atol=1e-5, rtol=1e-5)   # nothing to average yet
    second = g.combine(u2, c2, step=step)
    torch.testing.assert_close(second, c2 + 2.0 * ((c2 - u2) - 0.5 * (c1 - u1)), atol=1e-5, rtol=1e-5)


# ---------------------------------------------------------------------------- validation
@pytest.mark.parametrize("kwargs, word", [
    (dict(threshold=0.0), "threshold"), (dict(threshold=1.5), "threshold"), (dict(threshold="0.9"), "threshold"),
    (dict(threshold=True), "threshold"), (dict(threshold=float("nan")), "threshold"),
    (dict(threshold=0.9, threshold_bound=0.0), "threshold_bound"), (dict(threshold_bound=2.0), "threshold_bound"),
    (dict(projection=-0.1), "projection"), (dict(projection=1.5), "projection"), (dict(projection="0"), "projection"),
    (dict(projection=0.0, norm_cap=0.0), "norm_cap"), (dict(norm_cap=2.0), "norm_cap"),
    (dict(projection=0.0, momentum=1.0), "momentum"), (dict(momentum=-0.5), "momentum"),
])
def test_refinement_validation_names_the_field(kwargs, word):
    with pytest.raises(ValueError, match=f"Guidance.{word}"):
        Guidance(7.5, **kwargs)


def test_json_entry_writes_the_refinements_only_when_set():
    from salad_core.pipeline import guidance_from_json

    assert Guidance(7.5, interval=(0.1, 0.9)).to_json_dict() == {"scale": 7.5, "rescale": 0.0, "interval": (0.1, 0.9)}
    g = Guidance(5.0, threshold=0.99, threshold_bound=3.0, projection=0.0, momentum=-0.5)
    assert g.to_json_dict() == {"scale": 5.0, "rescale": 0.0, "interval": None, "threshold": 0.99,
                                "threshold_bound": 3.0, "projection": 0.0, "momentum": -0.5}
    assert guidance_from_json(json.loads(json.dumps(g.to_json_dict())), "pipeline.json") == g


def test_describe_names_the_refinements():
    assert Guidance(7.5, threshold=0.995).describe() == "7.5 (threshold 0.995)"
    assert Guidance(7.5, projection=0.0).describe() == "7.5 (projection 0)"
    assert Guidance(5, projection=0.5, norm_cap=4, momentum=-0.5, threshold=0.99, threshold_bound=3).describe() == \
        "5 (projection 0.5 cap 4 momentum -0.5, threshold 0.99 bound 3)"


# ------------------------------------------------------------------------------ tiny models
def test_tiny_salad_denoiser_threshold_bounds_its_samples_and_projection_changes_them():
    model, text, null, noise, fm = _setup()
    plain = denoise(model, make_scheduler(), text, null, noise, fm, guidance_scale=7.5, num_steps=6)
    bound = 0.5
    assert plain.abs().max() > 2 * bound
    # DDIM's last step (to a_prev = 1) returns its clean-sample prediction: the thresholded one
    thr = denoise(model, make_scheduler(), text, null, noise, fm,
                  guidance_scale=Guidance(7.5, threshold=0.9, threshold_bound=bound), num_steps=6)
    assert thr.abs().max() <= bound + 1e-4 and torch.all(thr[1, 3:] == 0)
    proj = denoise(model, make_scheduler(), text, null, noise, fm, guidance_scale=Guidance(7.5, projection=0.0),
                   num_steps=6)
    assert (proj - plain).abs().max() > 1e-2
    one = denoise(model, make_scheduler(), text, null, noise, fm, guidance_scale=Guidance(7.5, projection=1.0),
                  num_steps=6)
    torch.testing.assert_close(one, plain, atol=1e-4, rtol=1e-4)
    # a sigma-parametrised solver (scaled model input, fractional timesteps) works too
    euler = denoise(model, make_scheduler(solver="euler"), text, null, noise, fm,
                    guidance_scale=Guidance(7.5, projection=1.0), num_steps=6)
    torch.testing.assert_close(euler, denoise(model, make_scheduler(solver="euler"), text, null, noise, fm,
                                              guidance_scale=7.5, num_steps=6), atol=1e-4, rtol=1e-4)


def test_tiny_keymotion_run_changes_with_the_refinements_and_a_folder_entry_loads_them(tmp_path):
    from salad_core.keymotion.pipeline import KeyMotionPipeline
    from salad_core.pipeline import guidance_from_json

    pipe = tiny_keymotion()
    kw = dict(lengths=[40, 48], seed=3, num_steps=5)
    prompts = ["a person jumps", "a person walks forward"]
    plain = pipe(prompts, **kw).latents
    bound = 0.5 * float(np.abs(plain).max())
    thr = pipe(prompts, guidance_scale=Guidance(7.5, threshold=0.9, threshold_bound=bound), **kw).latents
    assert np.abs(thr).max() <= bound + 1e-4 < np.abs(plain).max()       # the last DDIM step's x0, bounded
    proj = pipe(prompts, guidance_scale=Guidance(7.5, projection=0.0, norm_cap=1.0), **kw).latents
    assert np.abs(proj - plain).max() > 1e-2
    # a weight folder's "guidance" entry with the new keys
    chosen = Guidance(7.5, projection=0.5, norm_cap=1.0, threshold=0.9, threshold_bound=bound)
    pipe.guidance = chosen
    root = pipe.save_pretrained(tmp_path / "km")
    doc = json.loads((root / "keymotion.json").read_text())
    assert doc["guidance"]["projection"] == 0.5 and doc["guidance"]["threshold"] == 0.9
    loaded = KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder())
    assert loaded.guidance == chosen
    np.testing.assert_array_equal(loaded(prompts, **kw).latents, pipe(prompts, guidance_scale=chosen, **kw).latents)
    assert loaded.resolve_guidance(3.0) == Guidance(3.0, projection=0.5, norm_cap=1.0, threshold=0.9,
                                                    threshold_bound=bound)       # a number replaces the weight only
    # an entry written by hand, with some of the keys; a bad one names the field
    doc["guidance"] = {"scale": 7.5, "threshold": 0.995, "threshold_bound": 4.0}
    (root / "keymotion.json").write_text(json.dumps(doc))
    assert KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder()).guidance == \
        Guidance(7.5, threshold=0.995, threshold_bound=4.0)
    with pytest.raises(CheckpointError, match="threshold"):
        guidance_from_json({"scale": 7.5, "threshold": 2.0}, "keymotion.json")
    with pytest.raises(CheckpointError, match="norm_cap"):
        guidance_from_json({"scale": 7.5, "norm_cap": 3.0}, "keymotion.json")


def test_edit_and_invert_refuse_refined_guidance_with_a_clear_error(pipe):
    """Editing and inversion run the source and edited rows stacked: a threshold or projection is refused
    up front (naming the setting), while plain guidance with rescale still edits."""
    from salad_core.attention import Reweight

    refined = Guidance(7.5, threshold=0.99, threshold_bound=3.0)
    with pytest.raises(ValueError, match="threshold or projection"):
        pipe.edit("a person walks", edits=[Reweight("walks", 2.0)], lengths=40, num_steps=2,
                  guidance_scale=refined)
    motion = pipe("a person walks", lengths=40, num_steps=2).features[0]
    with pytest.raises(ValueError, match="threshold or projection"):
        pipe.invert(motion, "a person walks", num_steps=2, guidance_scale=Guidance(2.0, projection=0.0))
    out = pipe.edit("a person walks", edits=[Reweight("walks", 2.0)], lengths=40, num_steps=2,
                    guidance_scale=Guidance(7.5, rescale=0.5))
    assert out.edited.joints[0].shape == (40, 22, 3)
