"""Schedulers, the CFG denoising loop and the training target."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from salad_core.models.attention import EagerProcessor, use_processors
from salad_core.models.denoiser import Denoiser, DenoiserConfig
from salad_core.sampling import (
    SOLVERS,
    DiffusionConfig,
    Guidance,
    StepInfo,
    denoise,
    make_scheduler,
    training_target,
)

CFG = DenoiserConfig(latent_dim=4, width=32, heads=4, ff_dim=48, layers=3, text_dim=12, max_len=256)


pytestmark = pytest.mark.usefixtures("single_thread")


def _setup(b=2, n=5, seed=0):
    torch.manual_seed(seed)
    model = Denoiser(CFG)
    g = torch.Generator().manual_seed(seed + 1)
    text = torch.randn(b, 6, CFG.text_dim, generator=g)
    mask = torch.ones(b, 6, dtype=torch.bool)
    mask[0, 4:] = False
    null = (torch.randn(1, 2, CFG.text_dim, generator=g), torch.ones(1, 2, dtype=torch.bool))
    noise = torch.randn(b, n, CFG.num_parts, CFG.latent_dim, generator=g)
    frame_mask = torch.ones(b, n, dtype=torch.bool)
    frame_mask[1, 3:] = False
    return model, (text, mask), null, noise, frame_mask


# ----------------------------------------------------------------------- schedulers
def test_ddim_timesteps_match_the_official_sampler():
    sched = make_scheduler(DiffusionConfig(), "ddim")
    sched.set_timesteps(50)
    assert sched.timesteps.tolist() == list(range(980, -1, -20))
    sched.set_timesteps(20)
    assert sched.timesteps.tolist() == list(range(950, -1, -50))
    c = sched.config
    assert (c.prediction_type, c.beta_schedule, c.clip_sample, c.set_alpha_to_one, c.steps_offset) == \
        ("v_prediction", "scaled_linear", False, True, 0)
    # supplement eq. 13: scaled-linear betas from 0.00085 to 0.012
    assert sched.betas[0].item() == pytest.approx(0.00085) and sched.betas[-1].item() == pytest.approx(0.012)


def test_solver_names_and_errors():
    for name in SOLVERS:
        sched = make_scheduler(DiffusionConfig(prediction_type="epsilon"), name)
        assert sched.config.prediction_type == "epsilon"
    dpm = make_scheduler(solver="DPM++")
    assert type(dpm).__name__ == "DPMSolverMultistepScheduler"
    assert dpm.config.algorithm_type == "dpmsolver++" and dpm.config.solver_order == 2
    with pytest.raises(ValueError, match="unknown solver 'plms'.*ddim.*dpm\\+\\+"):
        make_scheduler(solver="plms")
    with pytest.raises(ValueError, match="prediction_type"):
        DiffusionConfig(prediction_type="x0")
    with pytest.raises(ValueError, match="beta_start"):
        DiffusionConfig(beta_start=0.02, beta_end=0.01)


@pytest.mark.parametrize("prediction_type", ["v_prediction", "epsilon", "sample"])
@pytest.mark.parametrize("solver", ["ddim", "dpm++", "euler"])
def test_training_target_is_what_the_scheduler_inverts(prediction_type, solver):
    """An oracle that outputs the training target lets every solver recover x0 exactly."""
    config = DiffusionConfig(prediction_type=prediction_type)
    train = make_scheduler(config, "ddim")
    g = torch.Generator().manual_seed(0)
    x0 = torch.randn(2, 3, 7, 4, generator=g)
    # per-timestep consistency with the DDIM step's x0 estimate
    for t in (999, 500, 10):
        noise = torch.randn(x0.shape, generator=g)
        tt = torch.full((2,), t)
        xt = train.add_noise(x0, noise, tt)
        target = training_target(train, x0, noise, tt)
        train.set_timesteps(50)
        x0_hat = train.step(target, t, xt).pred_original_sample
        torch.testing.assert_close(x0_hat, x0, atol=2e-4, rtol=1e-4)
    # a full sampling run with the oracle lands on x0
    sched = make_scheduler(config, solver)
    sched.set_timesteps(10)
    z = torch.randn(x0.shape, generator=g) * sched.init_noise_sigma
    for t in sched.timesteps:
        abar = train.alphas_cumprod[int(t)]
        if solver == "euler":  # z is in sigma-space: x_t = z / sqrt(1 + sigma^2)
            xt = sched.scale_model_input(z, t)
        else:
            xt = z
        eps = (xt - abar.sqrt() * x0) / (1 - abar).sqrt()
        pred = training_target(train, x0, eps, torch.full((2,), int(t)))
        z = sched.step(pred, t, z).prev_sample
    torch.testing.assert_close(z, x0, atol=1e-3, rtol=1e-3)


def test_training_target_values():
    sched = make_scheduler()
    x0, eps, t = torch.ones(1, 1, 1, 1), torch.full((1, 1, 1, 1), 2.0), torch.tensor([300])
    abar = sched.alphas_cumprod[300]
    v = training_target(sched, x0, eps, t)
    assert v.item() == pytest.approx((abar.sqrt() * 2 - (1 - abar).sqrt()).item(), rel=1e-5)
    assert training_target(sched, x0, eps, t, "epsilon").item() == 2.0
    assert training_target(sched, x0, eps, t, "sample").item() == 1.0
    with pytest.raises(ValueError, match="prediction_type"):
        training_target(sched, x0, eps, t, "x0")


# -------------------------------------------------------------------------- the loop
def _two_pass_reference(model, sched, cond, uncond, noise, frame_mask, w, steps):
    """CFG with two separate forwards per step (the official ``cfg_step``)."""
    return _reference_with(model, sched, cond, uncond, noise, frame_mask, lambda u, c, t, keep: u + w * (c - u), steps)


def test_batched_cfg_equals_two_separate_passes():
    model, cond, null, noise, fm = _setup()
    ref = _two_pass_reference(model, make_scheduler(), cond, null, noise, fm, 7.5, 8)
    out = denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=7.5, num_steps=8)
    assert (out - ref).abs().max().item() < 1e-5
    assert torch.all(out[1, 3:] == 0)  # padded frames re-masked
    assert out[0].abs().sum() > 0


def test_denoise_is_deterministic_and_does_not_mutate_inputs():
    model, cond, null, noise, fm = _setup()
    noise_copy = noise.clone()
    a = denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=5)
    b = denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=5)
    assert torch.equal(a, b) and torch.equal(noise, noise_copy)
    other = torch.randn(noise.shape, generator=torch.Generator().manual_seed(99))
    assert not torch.allclose(a, denoise(model, make_scheduler(), cond, null, other, fm, num_steps=5))
    # stochastic solvers are reproducible through the generator
    anc = [denoise(model, make_scheduler(solver="euler_ancestral"), cond, null, noise, fm, num_steps=5,
                   generator=torch.Generator().manual_seed(3)) for _ in range(2)]
    assert torch.equal(anc[0], anc[1])


def test_guidance_scale_one_is_the_conditional_branch_and_uncond_required_otherwise():
    model, cond, null, noise, fm = _setup()
    only_cond = denoise(model, make_scheduler(), cond, None, noise, fm, guidance_scale=1.0, num_steps=4)
    with_null = denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=1.0, num_steps=4)
    torch.testing.assert_close(only_cond, with_null)
    ref = _two_pass_reference(model, make_scheduler(), cond, null, noise, fm, 1.0, 4)
    torch.testing.assert_close(only_cond, ref, atol=1e-5, rtol=1e-5)
    with pytest.raises(ValueError, match="uncond"):
        denoise(model, make_scheduler(), cond, None, noise, fm, guidance_scale=3.0)


def _reference_with(model, sched, cond, uncond, noise, frame_mask, combine, steps):
    """Two-pass CFG with a custom ``combine(u, c, t, keep) -> pred`` (reference for Guidance)."""
    model.eval()
    sched.set_timesteps(steps)
    keep = frame_mask[:, :, None, None].float()
    z = noise * keep
    b = noise.shape[0]
    with torch.no_grad():
        for t in sched.timesteps:
            u = model(z, t, uncond[0].expand(b, -1, -1), uncond[1].expand(b, -1), frame_mask)
            c = model(z, t, cond[0], cond[1], frame_mask)
            z = sched.step(combine(u, c, int(t), keep), t, z).prev_sample * keep
    return z


def test_guidance_rescale_matches_lin_et_al_on_valid_frames():
    model, cond, null, noise, fm = _setup()
    phi, w = 0.7, 7.5

    def rescaled(u, c, t, keep):
        pred = u + w * (c - u)
        out = torch.empty_like(pred)
        for i in range(pred.shape[0]):      # per sample, valid frames only, unbiased std
            valid = keep[i, :, 0, 0] > 0
            ratio = c[i, valid].std() / pred[i, valid].std()
            out[i] = phi * pred[i] * ratio + (1 - phi) * pred[i]
        return out

    ref = _reference_with(model, make_scheduler(), cond, null, noise, fm, rescaled, 6)
    out = denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=Guidance(w, rescale=phi),
                  num_steps=6)
    assert (out - ref).abs().max().item() < 1e-5
    plain = denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=w, num_steps=6)
    assert (out - plain).abs().max().item() > 1e-3          # the rescale changes the samples
    # rescale 1: the guided prediction has exactly the conditional prediction's std
    g = Guidance(w, rescale=1.0)
    u, c = torch.randn(2, 3, 4, 7, 5).unbind(0)
    pred = g.combine(u, c)
    torch.testing.assert_close(pred.flatten(1).std(1), c.flatten(1).std(1))


def test_guidance_interval_guides_only_inside_and_skips_the_unconditional_rows():
    model, cond, null, noise, fm = _setup()
    sched = make_scheduler()
    lo, hi = 0.3, 0.7
    inside = lambda t: lo <= t / 1000 <= hi                           # noqa: E731

    ref = _reference_with(model, make_scheduler(), cond, null, noise, fm,
                          lambda u, c, t, keep: u + 7.5 * (c - u) if inside(t) else c, 8)
    rows = []
    hook = model.register_forward_hook(lambda mod, args, kw_out: rows.append(args[0].shape[0]))
    try:
        out = denoise(model, sched, cond, null, noise, fm, guidance_scale=Guidance(7.5, interval=(lo, hi)),
                      num_steps=8)
    finally:
        hook.remove()
    assert (out - ref).abs().max().item() < 1e-5
    b = noise.shape[0]
    assert rows == [2 * b if inside(int(t)) else b for t in sched.timesteps]
    assert 0 < rows.count(2 * b) < len(rows)
    # an interval covering every step is plain CFG
    full = denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=Guidance(7.5, interval=(0, 1)),
                   num_steps=8)
    torch.testing.assert_close(full, denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=8))


@pytest.mark.parametrize("kwargs, word", [(dict(rescale=1.5), "rescale"), (dict(rescale=-0.1), "rescale"),
                                          (dict(interval=(0.8, 0.2)), "interval"), (dict(interval="x"), "interval"),
                                          (dict(scale=float("nan")), "scale"), (dict(scale="7.5"), "scale")])
def test_guidance_validation_names_the_field(kwargs, word):
    with pytest.raises(ValueError, match=word):
        Guidance(**kwargs)


def test_guidance_describe_names_only_the_refinements_in_use():
    assert Guidance(4.5).describe() == "4.5"
    assert Guidance(7.5, rescale=0.7).describe() == "7.5 (rescale 0.7)"
    assert Guidance(3, rescale=0.5, interval=(0.1, 0.9)).describe() == "3 (rescale 0.5, interval (0.1, 0.9))"


def test_pipeline_guidance_defaults_overrides_and_round_trip(make_tiny_pipeline, tmp_path):
    pipe = make_tiny_pipeline()
    assert pipe.guidance == Guidance(7.5)                             # no "guidance" entry: the paper's
    pipe.guidance = Guidance(4.0, rescale=0.5, interval=(0.1, 0.9))
    assert pipe.resolve_guidance(None) == pipe.guidance
    assert pipe.resolve_guidance(2.0) == Guidance(2.0, rescale=0.5, interval=(0.1, 0.9))   # weight only
    assert pipe.resolve_guidance(Guidance(7.5)) == Guidance(7.5)                          # as given
    out = pipe("a person walks forward", lengths=16, num_steps=3)
    assert out.settings["guidance_scale"] == 4.0 and out.settings["guidance_rescale"] == 0.5
    assert out.settings["guidance_interval"] == (0.1, 0.9)
    from salad_core.pipeline import SaladPipeline

    pipe.save_pretrained(tmp_path / "p")
    again = SaladPipeline.from_pretrained(tmp_path / "p", text_encoder=pipe.text_encoder)
    assert again.guidance == pipe.guidance
    torch.testing.assert_close(again("a person walks forward", lengths=16, num_steps=3).latents, out.latents)


def test_hooks_and_callback_see_every_step_and_mode_is_restored():
    model, cond, null, noise, fm = _setup()
    model.train()
    seen: list[StepInfo] = []
    after: list[tuple[int, torch.Tensor]] = []
    denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=4,
            controller_hooks=[seen.append], callback=lambda info, z: after.append((info.index, z.clone())))
    assert model.training  # restored
    assert [s.index for s in seen] == [0, 1, 2, 3]
    assert [s.timestep for s in seen] == [750.0, 500.0, 250.0, 0.0]
    assert [s.fraction for s in seen] == [0.0, 0.25, 0.5, 0.75]
    assert all(s.cfg and s.batch_size == 2 and s.cond_rows == slice(2, 4) for s in seen)
    assert [i for i, _ in after] == [0, 1, 2, 3] and all(torch.all(z[1, 3:] == 0) for _, z in after)


def test_hooks_let_a_controller_know_the_step():
    """A controller keyed on the hook's step records cross maps of the cond rows only."""
    model, cond, null, noise, fm = _setup()
    state = {"step": None}
    store: dict[tuple[int, str], torch.Tensor] = {}

    def controller(site, probs):
        if site.kind == "cross":
            rows = state["step"].cond_rows
            store[(state["step"].index, site.name)] = site.to_named(probs)[rows].clone()
        return probs

    with use_processors(model, EagerProcessor(controller)):
        out = denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=3,
                      controller_hooks=[lambda info: state.update(step=info)])
    plain = denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=3)
    assert (out - plain).abs().max() < 1e-5  # capture does not change the result
    assert sorted(store) == [(i, f"layers.{l}.cross") for i in range(3) for l in range(3)]
    m = store[(0, "layers.0.cross")]
    assert m.shape == (2, CFG.heads, 5, CFG.num_parts, 6)
    assert torch.all(m[0, ..., 4:] == 0)  # the cond prompt's padded tokens


def test_text_context_is_projected_once_per_call(monkeypatch):
    model, cond, null, noise, fm = _setup()
    calls = []
    original = Denoiser.text_kv

    def counting(self, ctx):
        calls.append(ctx.batch_size)
        return original(self, ctx)

    monkeypatch.setattr(Denoiser, "text_kv", counting)
    denoise(model, make_scheduler(), cond, null, noise, fm, num_steps=6)
    assert calls == [4]  # one projection of the stacked [uncond, cond] batch for all 6 steps


# ------------------------------------------------------------------ the one loop
class _Zero:
    """A strategy that predicts zeros: one DDIM step is then ``z <- alpha_i z`` (v-prediction)."""

    desc = "zero"

    def __init__(self, model, b):
        self.model, self.batch_size, self.steps = model, b, []

    def session(self, timesteps, num_train_timesteps):
        from contextlib import nullcontext

        return nullcontext()

    def guided(self, timestep):
        return False

    def __call__(self, z, t, info):
        assert not torch.is_grad_enabled() and not self.model.training
        self.steps.append(info.index)
        return torch.zeros_like(z)


def test_denoise_takes_a_prediction_strategy_and_owns_the_loop():
    from salad_core.attention.inversion import ddim_schedule, ddim_step_coefficients
    from salad_core.sampling import GuidedPrediction, Prediction

    model, cond, null, noise, fm = _setup()
    text_path = denoise(model, make_scheduler(), cond, null, noise, fm, guidance_scale=Guidance(5.0, rescale=0.5),
                        num_steps=4)
    strategy = GuidedPrediction(model, cond, null, Guidance(5.0, rescale=0.5), fm)
    assert isinstance(strategy, Prediction)
    assert torch.equal(denoise(model, make_scheduler(), latents=noise, frame_mask=fm, num_steps=4,
                               prediction=strategy), text_path)
    # the loop: init, prediction, scheduler step, correction, re-masking, callback, in that order
    model.train()
    zero = _Zero(model, 2)
    corrections = torch.randn(3, *noise.shape, generator=torch.Generator().manual_seed(7))
    seen = []
    out = denoise(model, make_scheduler(), latents=noise, frame_mask=fm, num_steps=3, prediction=zero,
                  corrections=corrections, callback=lambda info, z: seen.append((info, z.clone())))
    assert model.training and zero.steps == [0, 1, 2]                 # mode restored
    keep = fm[:, :, None, None].float()
    z = noise * keep
    for i, (t, a_t, a_next) in enumerate(ddim_schedule(make_scheduler(), 3)):
        alpha, _ = ddim_step_coefficients(a_t, a_next, "v_prediction")
        z = (alpha * z + corrections[i]) * keep
        torch.testing.assert_close(seen[i][1], z)
        assert seen[i][0].index == i and seen[i][0].timestep == float(t) and not seen[i][0].cfg
    torch.testing.assert_close(out, z)
    with pytest.raises(ValueError, match="not both"):
        denoise(model, make_scheduler(), cond, latents=noise, prediction=zero)
    with pytest.raises(ValueError, match="not the denoiser given"):
        denoise(Denoiser(CFG), make_scheduler(), latents=noise, prediction=zero)
    with pytest.raises(ValueError, match="corrections must have shape"):
        denoise(model, make_scheduler(), latents=noise, num_steps=3, prediction=zero, corrections=corrections[:2])
    with pytest.raises(ValueError, match="frame_mask must be"):
        denoise(model, make_scheduler(), latents=noise, frame_mask=fm[:1], prediction=zero)


# ------------------------------------------------------------- a tiny trained model
def test_tiny_trained_denoiser_with_cfg_moves_samples_to_the_class_mean():
    """Train on a 2-class latent toy problem with v-prediction and condition dropout, then sample."""
    torch.manual_seed(0)
    cfg = DenoiserConfig(latent_dim=2, num_parts=2, width=32, heads=2, ff_dim=64, layers=1, text_dim=4,
                         dropout=0.0, max_len=64)
    model = Denoiser(cfg)
    sched = make_scheduler(DiffusionConfig())
    n = 4
    means = torch.stack([torch.full((n, 2, 2), 0.8), torch.full((n, 2, 2), -0.8)])
    null_token = torch.tensor([0.0, 0.0, 0.0, 1.0])

    def text_for(labels):
        text = torch.zeros(len(labels), 2, 4)
        text[torch.arange(len(labels)), 0, labels] = 1.0   # class word
        text[:, 1, 2] = 1.0                                 # a shared word
        return text, torch.ones(len(labels), 2, dtype=torch.bool)

    opt = torch.optim.AdamW(model.parameters(), lr=2e-3)
    for _ in range(200):
        labels = torch.randint(0, 2, (64,))
        x0 = means[labels] + 0.1 * torch.randn(64, n, 2, 2)
        text, mask = text_for(labels)
        drop = torch.rand(64) < 0.1   # p_uncond (official cond_drop_prob 0.1)
        text[drop] = torch.stack([null_token, torch.zeros(4)])
        mask[drop] = torch.tensor([True, False])
        noise = torch.randn_like(x0)
        t = torch.randint(0, sched.config.num_train_timesteps, (64,))
        pred = model(sched.add_noise(x0, noise, t), t, text, mask)
        loss = (pred - training_target(sched, x0, noise, t)).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()

    labels = torch.tensor([0] * 6 + [1] * 6)
    null = (null_token[None, None], torch.ones(1, 1, dtype=torch.bool))
    start = torch.randn(12, n, 2, 2, generator=torch.Generator().manual_seed(1))
    z = denoise(model, sched, text_for(labels), null, start, guidance_scale=2.5, num_steps=20)
    d_right = (z - means[labels]).flatten(1).norm(dim=1)
    d_wrong = (z - means[1 - labels]).flatten(1).norm(dim=1)
    assert torch.all(d_right < d_wrong)
    assert torch.all(d_right < 0.5 * (means[0] - means[1]).norm())


@pytest.mark.parametrize("solver", ["ddim", "dpm++"])
def test_pipeline_denoises_large_batches_in_chunks_with_the_same_motions(make_tiny_pipeline, single_thread, solver,
                                                                         monkeypatch):
    pipe = make_tiny_pipeline(seed=0)
    prompts = [f"a person walks {w}" for w in ("forward", "back", "left", "right", "fast")]
    lengths = [40, 16, 28, 40, 8]
    pipe.max_batch = 100
    whole = pipe(prompts, lengths=lengths, seed=3, num_steps=4, solver=solver)
    import salad_core.pipeline as P

    calls, real = [], P.denoise

    def counting(*args, **kwargs):
        calls.append(args[4].shape)                    # the chunk's noise (B, N', P, Dz)
        return real(*args, **kwargs)

    monkeypatch.setattr(P, "denoise", counting)
    pipe.max_batch = 2
    chunked = pipe(prompts, lengths=lengths, seed=3, num_steps=4, solver=solver)
    # chunks of 2, 2 and 1 motions, each denoised at its own longest length (10, 10, 2 latent frames)
    assert [tuple(s[:2]) for s in calls] == [(2, 10), (2, 10), (1, 2)]
    assert torch.equal(chunked.noise, whole.noise)
    torch.testing.assert_close(chunked.latents, whole.latents, rtol=1e-4, atol=1e-4)
    for b, n in enumerate(lengths):
        assert torch.count_nonzero(chunked.latents[b, n // 4:]) == 0
        np.testing.assert_allclose(chunked.features[b, :n], whole.features[b, :n], rtol=1e-3, atol=1e-3)


def test_chunk_size_follows_max_batch_or_the_allocator(make_tiny_pipeline, monkeypatch):
    import salad_core.allocator as allocator

    pipe = make_tiny_pipeline(seed=0)
    assert pipe.max_batch is None
    monkeypatch.setitem(allocator._state, "tuned", False)
    assert pipe.chunk_size() == 8                      # glibc's default allocator: small chunks pay
    monkeypatch.setitem(allocator._state, "tuned", True)
    assert pipe.chunk_size() == 32                     # freed memory reused: one large batch pays
    pipe.max_batch = 3
    assert pipe.chunk_size() == 3
    for bad in (0, 2.5, True):
        pipe.max_batch = bad
        with pytest.raises(ValueError, match="max_batch must be a positive int or None"):
            pipe.chunk_size()


def test_pipeline_joints_are_the_fixed_bone_fit_and_raw_joints_the_position_features(make_tiny_pipeline):
    from salad_core.motion import features_to_joints
    from salad_core.skeleton import get_skeleton

    pipe = make_tiny_pipeline()
    assert pipe.recovery == "fit"                                      # HumanML3D has target bone lengths
    out = pipe(["a person walks forward", "a person jumps"], lengths=[16, 24], num_steps=3)
    sk = get_skeleton("humanml3d")
    parents = list(sk.parents[1:])
    for joints, raw, n, feats in zip(out.joints, out.raw_joints, out.lengths, out.features):
        assert joints.shape == raw.shape == (n, 22, 3)
        lengths = np.linalg.norm(joints[:, 1:] - joints[:, parents], axis=-1)
        np.testing.assert_allclose(lengths, np.broadcast_to(sk.bone_lengths[1:], lengths.shape), atol=1e-4)
        np.testing.assert_array_equal(raw, features_to_joints(feats[:n], sk).astype(np.float32))
        assert joints[..., 1].min() >= -1e-4                           # nothing below the floor
    assert out.settings["recovery"] == "fit"
    pipe.recovery = "positions"
    plain = pipe(["a person walks forward", "a person jumps"], lengths=[16, 24], num_steps=3)
    for a, b in zip(plain.joints, out.raw_joints):
        np.testing.assert_allclose(a, b, atol=1e-6)
    pipe.recovery = "spline"
    with pytest.raises(ValueError, match="recovery"):
        pipe("a person walks forward", lengths=16, num_steps=2)


def test_pipeline_latent_normalisation_round_trips_and_is_stored(make_tiny_pipeline, sample_features, tmp_path):
    from salad_core.pipeline import SaladPipeline

    pipe = make_tiny_pipeline()
    feats = sample_features[:40]
    plain_z = pipe.encode_motion(feats)                                 # (1, 10, P, Dz) VAE space
    plain_feats, _ = pipe.decode(plain_z, [40])
    p, dz = pipe.latent_shape
    mean, std = torch.linspace(-1, 1, p * dz).reshape(p, dz), torch.linspace(0.5, 2, p * dz).reshape(p, dz)
    pipe.latent_stats = (mean, std)
    z = pipe.encode_motion(feats)                                       # diffusion space
    torch.testing.assert_close(z, (plain_z - mean) / std)
    torch.testing.assert_close(pipe.from_diffusion(pipe.to_diffusion(plain_z)), plain_z)
    norm_feats, _ = pipe.decode(z, [40])                                # decode undoes the normalisation
    np.testing.assert_allclose(norm_feats, plain_feats, atol=1e-4)
    pipe.save_pretrained(tmp_path / "p")
    again = SaladPipeline.from_pretrained(tmp_path / "p", text_encoder=pipe.text_encoder)
    torch.testing.assert_close(again.latent_stats[0], mean)
    torch.testing.assert_close(again.latent_stats[1], std)
    with pytest.raises(ValueError, match="positive std"):
        SaladPipeline(pipe.vae, pipe.denoiser, pipe.text_encoder, pipe.mean, pipe.std,
                      latent_stats=(mean, torch.zeros(p, dz)))
