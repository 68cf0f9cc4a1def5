"""KeyMotion models: keyframe VAE, Parallel Skip Transformer, MMAE, their losses, training and the pipeline.

Tiny seeded models, one CPU thread, the real HumanML3D sample 012314 for the overfit tests, and a
deterministic hashing text encoder (``HashTextEncoder``) instead of MiniLM so that the file stays
fast; the trainers and the pipeline take any object with the text-encoder interface.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.keymotion import select_keyframes
from salad_core.keymotion.kf_vae import (
    KeyframeVAE,
    KeyframeVAEConfig,
    gather_keyframes,
    indices_to_positions,
    positions_to_indices,
)
from salad_core.keymotion.mmae import MMAEConfig, MotionMaskedAutoencoder, keyframe_lerp, scatter_keyframes
from salad_core.keymotion.models import bone_length_loss, bone_lengths, pose_joints, velocity_loss
from salad_core.keymotion.pipeline import KeyMotionOutput, KeyMotionPipeline, decode_keyframes
from salad_core.keymotion.pst import PST_DIFFUSION, ParallelSkipTransformer, PSTConfig
from salad_core.motion import features_to_joints
from salad_core.skeleton import get_skeleton
from _doubles import HashTextEncoder

SK = get_skeleton("humanml3d")
D = SK.feature_dim
TEXT_DIM = 16
K = 8


pytestmark = pytest.mark.usefixtures("single_thread")


# ------------------------------------------------------------------------------ helpers
def tiny_vae_config(**kw) -> KeyframeVAEConfig:
    base = dict(num_keyframes=K, frame_dim=56, index_dim=8, latent_size=2, latent_dim=16, num_layers=1,
                num_heads=4, ff_dim=128, dropout=0.0)
    base.update(kw)
    return KeyframeVAEConfig(**base)


def tiny_pst_config(**kw) -> PSTConfig:
    base = dict(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4, ff_dim=64,
                num_cond_layers=1, num_cross_layers=4, dropout=0.0)
    base.update(kw)
    return PSTConfig(**base)


def tiny_mmae_config(**kw) -> MMAEConfig:
    base = dict(text_dim=TEXT_DIM, width=64, num_layers=2, num_heads=4, ff_dim=128, dropout=0.0)
    base.update(kw)
    return MMAEConfig(**base)


@pytest.fixture(scope="module")
def normalised(sample_features, sample_dir):
    mean = np.load(sample_dir / "Mean.npy")
    std = np.load(sample_dir / "Std.npy")
    return ((sample_features - mean) / std).astype(np.float32), mean, std


@pytest.fixture(scope="module")
def procedural_normalised():
    """Procedural motion 0 of seed 0 (generator 2.5: 191 frames), normalised with its own
    per-channel mean and std (floored at 0.01, as a corpus's statistics would be). The tests that train
    (overfit) tiny models use it, never the real sample, which is evaluation data."""
    import io

    from salad_core.data.procedural.corpus import make_motion

    x = np.load(io.BytesIO(make_motion(0, 0)["000000"]["new_joint_vecs"])).astype(np.float32)
    mean, std = x.mean(0), np.maximum(x.std(0), 0.01)
    return ((x - mean) / std).astype(np.float32), mean, std


@pytest.fixture(scope="module")
def two_clips(procedural_normalised):
    """Two crops of a procedural walk (60 and 80 frames), padded to 80, with their MDO keyframes."""
    x, mean, std = procedural_normalised
    assert len(x) >= 110
    clips = [x[:60], x[30:110]]
    n = max(len(c) for c in clips)
    motion = torch.zeros(2, n, D)
    for i, c in enumerate(clips):
        motion[i, : len(c)] = torch.from_numpy(c)
    lengths = torch.tensor([len(c) for c in clips])
    idx = torch.from_numpy(np.stack([select_keyframes(c, K) for c in clips]))
    return motion, lengths, idx, mean, std


def tiny_pipeline(seed: int = 0) -> KeyMotionPipeline:
    torch.manual_seed(seed)
    vae = KeyframeVAE(tiny_vae_config())
    pst = ParallelSkipTransformer(tiny_pst_config())
    mmae = MotionMaskedAutoencoder(tiny_mmae_config())
    return KeyMotionPipeline(vae, pst, mmae, HashTextEncoder(), default_length=40)


# --------------------------------------------------------------------------- index helpers
def test_positions_to_indices_round_trip_and_repairs_bad_positions():
    lengths = torch.tensor([8, 40, 196])
    idx = torch.stack([torch.arange(8), torch.tensor([0, 3, 4, 10, 20, 21, 30, 39]),
                       torch.tensor([0, 1, 50, 51, 52, 100, 190, 195])])
    assert torch.equal(positions_to_indices(indices_to_positions(idx, lengths), lengths), idx)

    gen = torch.Generator().manual_seed(0)
    raw = torch.randn(64, 8, generator=gen) * 0.8 + 0.5        # unsorted, duplicates, outside [0, 1]
    lens = torch.randint(8, 197, (64,), generator=gen)
    out = positions_to_indices(raw, lens)
    assert out.dtype == torch.long and out.shape == (64, 8)
    assert torch.all(out[:, 0] == 0) and torch.all(out[:, -1] == lens - 1)
    assert torch.all(out[:, 1:] > out[:, :-1])                  # strictly increasing
    assert torch.all(out >= 0) and torch.all(out <= (lens - 1)[:, None])
    # L == K leaves exactly one choice
    assert torch.equal(positions_to_indices(raw[:1], torch.tensor([8])), torch.arange(8)[None])
    with pytest.raises(ValueError, match=r"lengths must all be >= 8 \(the number of keyframes\)"):
        positions_to_indices(raw[:1], torch.tensor([7]))


def test_decode_keyframes_keeps_features_with_their_positions():
    torch.manual_seed(0)
    vae = KeyframeVAE(tiny_vae_config()).eval()
    z = torch.randn(3, 2, 16)
    dec = vae.decode(z)
    kf, idx = decode_keyframes(vae, z, torch.tensor([50, 60, 196]))
    # decoded positions are increasing from exactly 0 to 1, so keyframes keep the decoder's order
    assert torch.all(dec.positions[:, 0] == 0) and torch.allclose(dec.positions[:, -1], torch.ones(3))
    assert torch.all(dec.positions[:, 1:] > dec.positions[:, :-1])
    torch.testing.assert_close(kf, dec.keyframes)
    assert torch.all(idx[:, 1:] > idx[:, :-1])
    assert idx[:, -1].tolist() == [49, 59, 195]


# ------------------------------------------------------------------------------- losses
def test_kinematic_losses_zero_for_true_joints_and_exact_otherwise(sample_joints, normalised):
    j = torch.from_numpy(sample_joints[:30]).float()[None]                     # (1, 30, 22, 3)
    assert float(bone_length_loss(j, j, SK)) == 0.0
    assert float(velocity_loss(j, j)) == 0.0
    # scaling a pose about the root scales every bone: the loss is the mean length change
    scaled = j * 1.1
    want = float((0.1 * bone_lengths(j, SK)).mean())
    assert float(bone_length_loss(scaled, j, SK)) == pytest.approx(want, rel=1e-5)
    # a constant offset leaves velocities alone; a drift of 1 cm per frame in x costs 1 cm / 3 axes
    assert float(velocity_loss(j + 0.3, j)) == pytest.approx(0.0, abs=1e-6)
    drift = j.clone()
    drift[..., 0] += 0.01 * torch.arange(30.0)[None, :, None]
    assert float(velocity_loss(drift, j)) == pytest.approx(0.01 / 3, rel=1e-4)
    # each keyframe pose alone has the skeleton's target bone lengths (HumanML3D data is retargeted)
    x, mean, std = normalised
    poses = pose_joints(torch.from_numpy(x[:20] * std + mean).float()[None], SK)  # (1, 20, 22, 3)
    np.testing.assert_allclose(bone_lengths(poses, SK)[0].numpy(),
                               np.broadcast_to(np.asarray(SK.bone_lengths[1:]), (20, SK.num_joints - 1)), atol=2e-3)


def test_model_losses_vanish_on_perfect_reconstructions(two_clips):
    motion, lengths, idx, mean, std = two_clips
    vae = KeyframeVAE(tiny_vae_config())
    vae.set_normalization(mean, std)
    kf = gather_keyframes(motion, idx)
    u = indices_to_positions(idx, lengths)
    from salad_core.keymotion.kf_vae import KeyframeDecoding

    zero = torch.zeros(2, 2, 16)
    out = vae.loss(kf, u, KeyframeDecoding(kf.clone(), u.clone()), zero, zero)
    assert {k: float(v) for k, v in out.items()} == {"loss": 0.0, "rec": 0.0, "kl": 0.0, "bone": 0.0, "index": 0.0}
    mmae = MotionMaskedAutoencoder(tiny_mmae_config())
    mmae.set_normalization(mean, std)
    frame_mask = torch.arange(motion.shape[1])[None] < lengths[:, None]
    out = mmae.loss(motion, motion.clone(), frame_mask)
    assert all(float(v) == 0.0 for v in out.values())
    # garbage in the padded frames of the prediction costs nothing
    noisy = motion.clone()
    noisy[0, 60:] += 5.0
    assert float(mmae.loss(noisy, motion, frame_mask)["loss"]) == 0.0
    noisy[0, 10] += 1.0
    out = mmae.loss(noisy, motion, frame_mask)
    assert float(out["rec"]) > 0 and float(out["bone"]) > 0 and float(out["vel"]) > 0


# --------------------------------------------------------------------------- keyframe VAE
def test_kf_vae_shapes_and_config_errors():
    torch.manual_seed(0)
    vae = KeyframeVAE(tiny_vae_config())
    kf = torch.randn(3, K, D)
    u = torch.sort(torch.rand(3, K), 1).values
    enc = vae.encode(kf, u)
    assert enc.z.shape == enc.mu.shape == enc.logvar.shape == (3, 2, 16)
    dec = vae.decode(enc.z)
    assert dec.keyframes.shape == (3, K, D) and dec.positions.shape == (3, K)
    g1, g2 = torch.Generator().manual_seed(5), torch.Generator().manual_seed(5)
    vae.eval()
    torch.testing.assert_close(vae.encode(kf, u, generator=g1).z, vae.encode(kf, u, generator=g2).z)
    with pytest.raises(ValueError, match=r"keyframes must be \(B, 8, 263\)"):
        vae.encode(torch.randn(3, K + 1, D), torch.rand(3, K + 1))
    with pytest.raises(ValueError, match="index_dim=7"):
        KeyframeVAEConfig(index_dim=7)
    with pytest.raises(ValueError, match="num_keyframes=1"):
        KeyframeVAEConfig(num_keyframes=1)
    with pytest.raises(ValueError, match="dropout=1.5"):
        KeyframeVAEConfig(dropout=1.5)


def test_kf_vae_overfits_keyframes_and_indices(two_clips):
    motion, lengths, idx, mean, std = two_clips
    kf = gather_keyframes(motion, idx)
    u = indices_to_positions(idx, lengths)
    torch.manual_seed(0)
    vae = KeyframeVAE(tiny_vae_config())
    vae.set_normalization(mean, std)
    opt = torch.optim.Adam(vae.parameters(), lr=3e-3)
    first = None
    for _ in range(400):   # generator 2.5's motion 0: 250 steps left an index 3 frames off, 400 none
        losses = vae.loss(kf, u, *vae(kf, u))
        first = first if first is not None else {k: v.item() for k, v in losses.items()}
        opt.zero_grad()
        losses["loss"].backward()
        opt.step()
    vae.eval()
    with torch.no_grad():
        rec_kf, rec_idx = decode_keyframes(vae, vae.encode(kf, u, sample=False).mu, lengths)
    err = float((rec_kf - kf).pow(2).mean())
    assert err < 0.05 * first["rec"], (err, first)
    assert int((rec_idx - idx).abs().max()) <= 2, (rec_idx, idx)
    assert torch.equal(rec_idx[:, 0], torch.zeros(2, dtype=torch.long))
    assert torch.equal(rec_idx[:, -1], lengths - 1)


# ----------------------------------------------------------------------------------- PST
@pytest.mark.parametrize("layers, pairs", [(4, ((0, 3), (1, 2))), (5, ((0, 4), (1, 3))), (1, ())])
def test_pst_skip_connections_are_wired_l_to_L_minus_l(layers, pairs):
    torch.manual_seed(0)
    pst = ParallelSkipTransformer(tiny_pst_config(num_cross_layers=layers)).eval()
    assert pst.skip_pairs == pairs
    receivers = {j for _, j in pairs}
    for i, layer in enumerate(pst.cross_layers):
        assert (layer.skip_x is not None) == (i in receivers) == (layer.skip_c is not None)
        if layer.skip_x is not None:
            assert layer.skip_x.in_features == 2 * pst.config.width and layer.skip_x.out_features == pst.config.width
    outputs, skip_inputs = {}, {}
    hooks = []
    for i, layer in enumerate(pst.cross_layers):
        hooks.append(layer.register_forward_hook(lambda m, a, out, i=i: outputs.__setitem__(i, out)))
        if layer.skip_x is not None:
            hooks.append(layer.skip_x.register_forward_hook(
                lambda m, a, out, i=i: skip_inputs.__setitem__(("x", i), a[0])))
            hooks.append(layer.skip_c.register_forward_hook(
                lambda m, a, out, i=i: skip_inputs.__setitem__(("c", i), a[0])))
    tb = HashTextEncoder().encode(["a person walks", "someone jumps high twice"])
    pst(torch.randn(2, 2, 16), torch.tensor([10, 500]), tb.features, tb.mask, torch.tensor([40, 120]))
    for h in hooks:
        h.remove()
    w = pst.config.width
    for src, dst in pairs:
        # second half of the concatenated input of layer dst = output of layer src (both streams)
        assert torch.equal(skip_inputs[("x", dst)][..., w:], outputs[src][0])
        assert torch.equal(skip_inputs[("c", dst)][..., w:], outputs[src][1])
        # first half = the stream coming from the previous layer
        assert torch.equal(skip_inputs[("x", dst)][..., :w], outputs[dst - 1][0])
    assert len(skip_inputs) == 2 * len(pairs)


def test_pst_cfg_batched_equals_two_passes_and_padding_is_ignored():
    torch.manual_seed(0)
    pst = ParallelSkipTransformer(tiny_pst_config()).eval()
    enc = HashTextEncoder()
    tb = enc.encode(["a person walks forward", "jumps"])
    null = enc.encode([""], allow_empty=True)
    x = torch.randn(2, 2, 16)
    t = torch.tensor([999, 20])
    lens = torch.tensor([40, 196])
    w = 3.5
    with torch.no_grad():
        guided = pst.guided(x, t, tb.features, tb.mask, null.features, null.mask, w, lens)
        cond = pst(x, t, tb.features, tb.mask, lens)
        uncond = pst(x, t, null.features.expand(2, -1, -1), null.mask.expand(2, -1), lens)
        torch.testing.assert_close(guided, uncond + w * (cond - uncond), atol=1e-5, rtol=1e-5)
        # extra padded text tokens change nothing
        pad_f = torch.cat([tb.features, torch.randn(2, 3, TEXT_DIM)], 1)
        pad_m = torch.cat([tb.mask, torch.zeros(2, 3, dtype=torch.bool)], 1)
        torch.testing.assert_close(pst(x, t, pad_f, pad_m, lens), cond, atol=1e-5, rtol=1e-5)
        # the condition matters: text, timestep and length all change the prediction
        assert not torch.allclose(cond, uncond, atol=1e-4)
        assert not torch.allclose(pst(x, torch.tensor([500, 500]), tb.features, tb.mask, lens), cond, atol=1e-4)
        assert not torch.allclose(pst(x, t, tb.features, tb.mask, torch.tensor([100, 100])), cond, atol=1e-4)
        assert torch.equal(pst.guided(x, t, tb.features, tb.mask, null.features, null.mask, 1.0, lens), cond)
    with pytest.raises(ValueError, match="pass lengths"):
        pst(x, t, tb.features, tb.mask)
    with pytest.raises(ValueError, match=r"x must be \(B, 2, 16\)"):
        pst(torch.randn(2, 3, 16), t, tb.features, tb.mask, lens)


def test_sample_latents_is_the_one_loop_with_two_pass_cfg_and_step_infos():
    """PST sampling through salad's one loop equals a literal two-pass CFG loop (eq. 8), and its
    callback gets the loop's StepInfo like every sampler."""
    from salad_core.keymotion.pst import sample_latents
    from salad_core.sampling import make_scheduler

    torch.manual_seed(0)
    pst = ParallelSkipTransformer(tiny_pst_config())                 # train mode: restored afterwards
    enc = HashTextEncoder()
    tb, null = enc.encode(["a person walks forward", "jumps"]), enc.encode([""], allow_empty=True)
    noise = torch.randn(2, 2, 16, generator=torch.Generator().manual_seed(1))
    lens, w = torch.tensor([40, 120]), 3.0
    seen = []
    z = sample_latents(pst, make_scheduler(PST_DIFFUSION, "ddim"), tb.features, tb.mask, null.features, null.mask,
                       noise, lengths=lens, guidance_scale=w, num_steps=4,
                       callback=lambda info, latents: seen.append((info, latents.clone())))
    assert pst.training
    sched = make_scheduler(PST_DIFFUSION, "ddim")
    sched.set_timesteps(4)
    ref = noise.clone()
    pst.eval()
    with torch.no_grad():
        for i, t in enumerate(sched.timesteps):
            c = pst(ref, t, tb.features, tb.mask, lens)
            u = pst(ref, t, null.features.expand(2, -1, -1), null.mask.expand(2, -1), lens)
            ref = sched.step(u + w * (c - u), t, ref).prev_sample
            info, latents = seen[i]
            assert (info.index, info.num_steps, info.timestep, info.cfg, info.batch_size) == (i, 4, float(t), True, 2)
            torch.testing.assert_close(latents, ref, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(z, ref, atol=1e-5, rtol=1e-5)
    only_cond = sample_latents(pst, make_scheduler(PST_DIFFUSION, "ddim"), tb.features, tb.mask, None, None, noise,
                               lengths=lens, guidance_scale=1.0, num_steps=2)
    assert only_cond.shape == noise.shape
    with pytest.raises(ValueError, match="needs the empty prompt"):
        sample_latents(pst, make_scheduler(PST_DIFFUSION, "ddim"), tb.features, tb.mask, None, None, noise,
                       lengths=lens, guidance_scale=2.0, num_steps=2)


def test_pst_guidance_rescale_and_interval():
    """A Guidance's rescale gives each sample's guided noise the std of its conditional one
    (Lin et al.); its interval leaves the steps outside ``lo <= t/T <= hi`` unguided (conditional
    branch only), and those steps' StepInfo says so."""
    from salad_core.keymotion.pst import sample_latents
    from salad_core.sampling import Guidance, make_scheduler

    torch.manual_seed(0)
    pst = ParallelSkipTransformer(tiny_pst_config()).eval()
    enc = HashTextEncoder()
    tb, null = enc.encode(["a person walks forward", "jumps"]), enc.encode([""], allow_empty=True)
    x, t, lens = torch.randn(2, 2, 16), torch.tensor([999, 20]), torch.tensor([40, 196])
    with torch.no_grad():
        cond = pst(x, t, tb.features, tb.mask, lens)
        plain = pst.guided(x, t, tb.features, tb.mask, null.features, null.mask, 6.0, lens)
        full = pst.guided(x, t, tb.features, tb.mask, null.features, null.mask, Guidance(6.0, rescale=1.0), lens)
        half = pst.guided(x, t, tb.features, tb.mask, null.features, null.mask, Guidance(6.0, rescale=0.5), lens)
    for b in range(2):
        assert float(full[b].std()) == pytest.approx(float(cond[b].std()), rel=1e-4)
        assert float(plain[b].std()) > 1.2 * float(cond[b].std())          # w 6 inflates the noise estimate
    torch.testing.assert_close(full, plain * (cond.flatten(1).std(1) / plain.flatten(1).std(1))[:, None, None])
    torch.testing.assert_close(half, 0.5 * full + 0.5 * plain)
    # interval: only the steps with t/T in [0, 0.5] are guided
    noise = torch.randn(2, 2, 16, generator=torch.Generator().manual_seed(1))
    seen = []
    z = sample_latents(pst, make_scheduler(PST_DIFFUSION, "ddim"), tb.features, tb.mask, null.features, null.mask,
                       noise, lengths=lens, guidance_scale=Guidance(4.0, interval=(0.0, 0.5)), num_steps=4,
                       callback=lambda info, latents: seen.append(info))
    assert [(info.timestep, info.cfg) for info in seen] == [(750.0, False), (500.0, True), (250.0, True), (0.0, True)]
    sched = make_scheduler(PST_DIFFUSION, "ddim")
    sched.set_timesteps(4)
    ref = noise.clone()
    with torch.no_grad():
        for step in sched.timesteps:
            c = pst(ref, step, tb.features, tb.mask, lens)
            if float(step) / 1000 <= 0.5:
                u = pst(ref, step, null.features.expand(2, -1, -1), null.mask.expand(2, -1), lens)
                c = u + 4.0 * (c - u)
            ref = sched.step(c, step, ref).prev_sample
    torch.testing.assert_close(z, ref, atol=1e-5, rtol=1e-5)


def test_pst_learns_epsilon_on_a_fixed_latent():
    """A short ε-prediction fit on two latents: the loss falls well below the untrained one."""
    from salad_core.sampling import make_scheduler

    torch.manual_seed(0)
    pst = ParallelSkipTransformer(tiny_pst_config())
    sched = make_scheduler(PST_DIFFUSION, "ddim")
    tb = HashTextEncoder().encode(["a person walks", "a person jumps"] * 4)
    z0 = torch.randn(2, 2, 16).repeat(4, 1, 1)
    lens = torch.tensor([60, 80] * 4)
    opt = torch.optim.Adam(pst.parameters(), lr=3e-3)
    gen = torch.Generator().manual_seed(1)
    losses = []
    for _ in range(100):
        t = torch.randint(0, 1000, (8,), generator=gen)
        noise = torch.randn(z0.shape, generator=gen)
        loss = torch.nn.functional.mse_loss(pst(sched.add_noise(z0, noise, t), t, tb.features, tb.mask, lens), noise)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert np.mean(losses[-20:]) < 0.5 * np.mean(losses[:20]), (losses[:5], losses[-5:])


# ---------------------------------------------------------------------------------- MMAE
def test_keyframe_lerp_is_exact_on_ramps_and_scatter_places_keyframes():
    n = 11
    ramp = torch.linspace(0, 1, n)[None, :, None] * torch.tensor([1.0, -2.0, 3.0])      # (1, N, 3)
    mask = torch.zeros(1, n, dtype=torch.bool)
    mask[0, [0, 4, 10]] = True
    garbage = torch.where(mask[..., None], ramp, torch.full_like(ramp, 7.0))
    torch.testing.assert_close(keyframe_lerp(garbage, mask), ramp)
    # before the first / after the last keyframe the value is held
    mask2 = torch.zeros(1, n, dtype=torch.bool)
    mask2[0, [3, 6]] = True
    out = keyframe_lerp(ramp, mask2)
    torch.testing.assert_close(out[0, :3], ramp[0, 3].expand(3, 3))
    torch.testing.assert_close(out[0, 7:], ramp[0, 6].expand(4, 3))
    kf = torch.randn(2, 3, 5)
    idx = torch.tensor([[0, 2, 9], [1, 5, 6]])
    canvas, m = scatter_keyframes(kf, idx, 10)
    assert canvas.shape == (2, 10, 5) and int(m.sum()) == 6
    torch.testing.assert_close(gather_keyframes(canvas, idx), kf)
    assert float(canvas[~m].abs().sum()) == 0.0


def test_mmae_reads_only_keyframes_and_valid_frames(two_clips):
    motion, lengths, idx, mean, std = two_clips
    torch.manual_seed(0)
    mmae = MotionMaskedAutoencoder(tiny_mmae_config(lerp_residual=False)).eval()
    tb = HashTextEncoder().encode(["a person walks", "a person walks"])
    _, kf_mask = scatter_keyframes(gather_keyframes(motion, idx), idx, motion.shape[1])
    frame_mask = torch.arange(motion.shape[1])[None] < lengths[:, None]
    with torch.no_grad():
        out = mmae(motion, kf_mask, frame_mask, tb.features, tb.mask)
        assert out.shape == motion.shape
        changed = motion + 3.0 * (~kf_mask)[..., None]               # alter every in-between frame
        torch.testing.assert_close(mmae(changed, kf_mask, frame_mask, tb.features, tb.mask), out)
        # text conditioning reaches the output
        other = HashTextEncoder().encode(["someone kicks", "someone kicks"])
        assert not torch.allclose(mmae(motion, kf_mask, frame_mask, other.features, other.mask), out, atol=1e-4)
        # sample 0 (60 frames) does not see sample padding beyond its length
        short = mmae(motion[:1, :60], kf_mask[:1, :60], frame_mask[:1, :60], tb.features[:1], tb.mask[:1])
        torch.testing.assert_close(short, out[:1, :60], atol=1e-5, rtol=1e-5)


def test_mmae_keeps_keyframes_and_learns_the_in_betweens(two_clips):
    motion, lengths, idx, mean, std = two_clips
    torch.manual_seed(0)
    mmae = MotionMaskedAutoencoder(tiny_mmae_config())
    mmae.set_normalization(mean, std)
    tb = HashTextEncoder().encode(["a person walks", "a person walks then turns"])
    kf = gather_keyframes(motion, idx)
    _, kf_mask = scatter_keyframes(kf, idx, motion.shape[1])
    frame_mask = torch.arange(motion.shape[1])[None] < lengths[:, None]
    between = frame_mask & ~kf_mask

    def between_error() -> float:
        with torch.no_grad():
            out = mmae.infill(kf, idx, lengths, tb.features, tb.mask)
        return float((out - motion).pow(2)[between].mean())

    mmae.eval()
    before = between_error()              # untrained = linear interpolation of the keyframes
    with torch.no_grad():
        lerp = keyframe_lerp(motion, kf_mask)
    assert before == pytest.approx(float((lerp - motion).pow(2)[between].mean()), rel=1e-5)
    mmae.train()
    opt = torch.optim.Adam(mmae.parameters(), lr=2e-3)
    for _ in range(120):
        loss = mmae.loss(mmae(motion, kf_mask, frame_mask, tb.features, tb.mask), motion, frame_mask)["loss"]
        opt.zero_grad()
        loss.backward()
        opt.step()
    mmae.eval()
    after = between_error()
    assert after < 0.5 * before, (before, after)
    with torch.no_grad():
        kept = mmae.infill(kf, idx, lengths, tb.features, tb.mask, keep_keyframes=True)
        free = mmae.infill(kf, idx, lengths, tb.features, tb.mask)
    assert torch.equal(gather_keyframes(kept, idx), kf)                       # exactly kept
    assert float((gather_keyframes(free, idx) - kf).pow(2).mean()) < 0.1      # and close without pasting
    assert float(kept[0, 60:].abs().sum()) == 0.0                             # padding is zero


# ------------------------------------------------------------------------------ pipeline
def test_pipeline_end_to_end_fields_and_determinism():
    pipe = tiny_pipeline()
    out = pipe(["a person walks forward", "someone jumps"], lengths=[40, 64], seed=3, guidance_scale=2.5,
               num_steps=5)
    assert isinstance(out, KeyMotionOutput)
    assert out.texts == ["a person walks forward", "someone jumps"] and out.lengths == [40, 64]
    assert out.features.shape == (2, 64, D) and out.features.dtype == np.float32
    assert float(np.abs(out.features[0, 40:]).sum()) == 0.0
    assert [j.shape for j in out.joints] == [(40, SK.num_joints, 3), (64, SK.num_joints, 3)]
    # joints are recovered as SALAD's pipeline recovers them: the skeleton fit by default, the raw reading kept
    assert pipe.recovery == "fit" and out.settings == {"recovery": "fit", "skeleton": SK.name, "side_check": True}
    np.testing.assert_allclose(out.raw_joints[1], features_to_joints(out.features[1], SK), atol=1e-5)
    bones = np.linalg.norm(out.joints[1][:, 1:] - out.joints[1][:, list(SK.parents[1:])], axis=-1)   # (N, J-1)
    np.testing.assert_allclose(bones, np.broadcast_to(np.asarray(SK.bone_lengths)[1:], bones.shape), atol=1e-4)
    raw_bones = np.linalg.norm(out.raw_joints[1][:, 1:] - out.raw_joints[1][:, list(SK.parents[1:])], axis=-1)
    assert np.abs(raw_bones - bones).max() > 1e-3                              # the untrained output stretches
    raw = pipe(["a person walks forward", "someone jumps"], lengths=[40, 64], seed=3, guidance_scale=2.5,
               num_steps=5, recovery="positions")
    np.testing.assert_array_equal(raw.features, out.features)
    np.testing.assert_allclose(raw.joints[1], out.raw_joints[1], atol=1e-6)
    with pytest.raises(ValueError, match="recovery must be one of"):
        pipe("a", recovery="ik")
    assert out.keyframe_features.shape == (2, K, D) and out.latents.shape == (2, 2, 16)
    for kf, n in zip(out.keyframes, out.lengths):
        assert kf.dtype == np.int64 and kf.shape == (K,)
        assert kf[0] == 0 and kf[-1] == n - 1 and np.all(np.diff(kf) > 0)
    again = pipe(["a person walks forward", "someone jumps"], lengths=[40, 64], seed=3, guidance_scale=2.5,
                 num_steps=5)
    np.testing.assert_array_equal(again.features, out.features)
    other = pipe(["a person walks forward", "someone jumps"], lengths=[40, 64], seed=4, guidance_scale=2.5,
                 num_steps=5)
    assert not np.allclose(other.latents, out.latents)
    single = pipe("a person walks forward", num_steps=2, guidance_scale=1.0)
    assert single.lengths == [40] and single.features.shape == (1, 40, D)
    with pytest.raises(ValueError, match="lengths\\[1\\]=5 is out of range: use 8"):
        pipe(["a", "b"], lengths=[40, 5])
    with pytest.raises(ValueError, match="2 entries for 1 prompts"):
        pipe(["a"], lengths=[40, 41])


def test_pipeline_rejects_mismatched_components():
    torch.manual_seed(0)
    with pytest.raises(ValueError, match="latents"):
        KeyMotionPipeline(KeyframeVAE(tiny_vae_config(latent_dim=8)), ParallelSkipTransformer(tiny_pst_config()),
                          MotionMaskedAutoencoder(tiny_mmae_config()), HashTextEncoder())
    with pytest.raises(ValueError, match="12-d text features"):
        KeyMotionPipeline(KeyframeVAE(tiny_vae_config()), ParallelSkipTransformer(tiny_pst_config(text_dim=12)),
                          MotionMaskedAutoencoder(tiny_mmae_config()), HashTextEncoder())


def test_pipeline_save_load_round_trip(tmp_path):
    pipe = tiny_pipeline(seed=1)
    pipe.mmae.set_normalization(np.full(D, 0.5, np.float32), np.full(D, 2.0, np.float32))
    pipe.kf_vae.set_normalization(np.full(D, 0.5, np.float32), np.full(D, 2.0, np.float32))
    root = pipe.save_pretrained(tmp_path / "km")
    doc = json.loads((root / "keymotion.json").read_text())
    assert doc["format"] == "keymotion_pipeline" and doc["text_encoder"] == "hash"
    assert doc["diffusion"]["prediction_type"] == "epsilon" and doc["diffusion"]["beta_schedule"] == "scaled_linear"
    assert doc["recovery"] == "fit"
    loaded = KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder())
    assert loaded.default_length == 40 and loaded.diffusion == PST_DIFFUSION and loaded.recovery == "fit"
    assert KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder(), recovery="fk").recovery == "fk"
    for a, b in ((pipe.kf_vae, loaded.kf_vae), (pipe.pst, loaded.pst), (pipe.mmae, loaded.mmae)):
        assert a.config == b.config
        sa, sb = a.state_dict(), b.state_dict()
        assert sorted(sa) == sorted(sb) and all(torch.equal(sa[k], sb[k]) for k in sa)
    kw = dict(lengths=[48], seed=7, guidance_scale=3.0, num_steps=4)
    np.testing.assert_array_equal(loaded(["a person waves"], **kw).features, pipe(["a person waves"], **kw).features)
    with pytest.raises(FileNotFoundError, match="no pst.json"):
        (root / "pst.json").unlink()
        KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder())


def test_pipeline_default_guidance_is_stored_with_the_weights(tmp_path):
    """keymotion.json's "guidance" is the default of a call; a number replaces only its weight, a
    Guidance replaces it all; folders without the entry default to w 7.5."""
    from salad_core.sampling import Guidance

    pipe = tiny_pipeline(seed=2)
    assert pipe.guidance == Guidance(7.5)
    kw = dict(lengths=[40], seed=3, num_steps=4)
    np.testing.assert_array_equal(pipe(["a person waves"], **kw).features,
                                  pipe(["a person waves"], guidance_scale=7.5, **kw).features)
    pipe.guidance = Guidance(2.0, interval=(0.0, 0.6))
    root = pipe.save_pretrained(tmp_path / "km")
    doc = json.loads((root / "keymotion.json").read_text())
    assert doc["guidance"] == {"scale": 2.0, "rescale": 0.0, "interval": [0.0, 0.6]}
    loaded = KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder())
    assert loaded.guidance == pipe.guidance
    assert loaded.resolve_guidance(5.0) == Guidance(5.0, interval=(0.0, 0.6))
    assert loaded.resolve_guidance(Guidance(3.0)) == Guidance(3.0)
    default = loaded(["a person waves"], **kw).features
    np.testing.assert_array_equal(default, loaded(["a person waves"], guidance_scale=pipe.guidance, **kw).features)
    assert not np.allclose(default, loaded(["a person waves"], guidance_scale=Guidance(2.0), **kw).features)
    with pytest.raises(TypeError, match="guidance_scale must be a number"):
        loaded(["a person waves"], guidance_scale="high", **kw)
    doc["guidance"] = {"scale": 2.0, "rescale": 3.0}
    (root / "keymotion.json").write_text(json.dumps(doc))
    with pytest.raises(ValueError, match='bad "guidance" entry'):
        KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder())
    del doc["guidance"]
    (root / "keymotion.json").write_text(json.dumps(doc))
    assert KeyMotionPipeline.from_pretrained(root, text_encoder=HashTextEncoder()).guidance == Guidance(7.5)


# ------------------------------------------------------------------------------ training
@pytest.fixture(scope="session")
def corpus(tmp_path_factory) -> Path:
    """The tiny procedural corpus (200 motions + mirrors, HumanML3D layout), built once."""
    from salad_core.data.procedural import build_corpus

    root = tmp_path_factory.mktemp("procedural_tiny")
    build_corpus(root, size="tiny", seed=0, progress=False)
    return root


def test_keyframe_dataset_items_and_collate(corpus):
    from salad_core.data.dataset import MotionTextDataset
    from salad_core.keymotion.train import KeyframeDataset, collate_keyframes

    base = MotionTextDataset(corpus, "train", random_crop=True, seed=0)
    ds = KeyframeDataset(base, K, "mdo")
    items = [ds[i] for i in range(4)]
    for it in items:
        n = it["length"]
        np.testing.assert_array_equal(it["keyframes"], select_keyframes(it["motion"][:n], K, "mdo"))
    assert len(ds._cache) == 4
    ds[0]
    assert len(ds._cache) == 4                                    # same crop: served from the cache
    batch = collate_keyframes(items)
    assert batch["keyframes"].shape == (4, K) and batch["keyframes"].dtype == torch.long
    assert batch["motion"].shape[1] == max(it["length"] for it in items)
    with pytest.raises(ValueError, match="fewer than num_keyframes=60"):
        KeyframeDataset(base, 60)


def test_train_keymotion_end_to_end_and_resume(tmp_path, corpus):
    from salad_core.keymotion.train import KeyMotionTrainConfig, train_keymotion
    from salad_core.train.distributed import DistEnv

    data = corpus
    tc = KeyMotionTrainConfig(batch_size=4, max_steps=3, lr=1e-3, warmup_steps=1, val_every=3, val_batches=1,
                              ckpt_every=0, log_every=1, num_threads=1, progress=False, seed=5, device="cpu")
    enc = HashTextEncoder()
    kw = dict(vae_config=tiny_vae_config(), pst_config=tiny_pst_config(), mmae_config=tiny_mmae_config(),
              vae_train=tc, text_encoder=enc, env=DistEnv())
    out = tmp_path / "run"
    res = train_keymotion(data, out, **kw)
    assert {k: r.step for k, r in res.items()} == {"kf_vae": 3, "pst": 3, "mmae": 3}
    assert all(np.isfinite(r.last_loss) for r in res.values())
    for stage in ("kf_vae", "pst", "mmae"):
        assert (out / stage / "latest.safetensors").is_file() and (out / stage / "train_state.safetensors").is_file()
        lines = [json.loads(l) for l in (out / stage / "log.jsonl").read_text().splitlines()]
        assert [l["step"] for l in lines if "loss" in l] == [1, 2, 3]
    vae_log = [json.loads(l) for l in (out / "kf_vae" / "log.jsonl").read_text().splitlines()]
    assert {"rec", "kl", "bone", "index"} <= set(vae_log[0])
    # the VAE and the MMAE carry the corpus statistics
    pipe = KeyMotionPipeline.from_pretrained(out, text_encoder=enc)
    np.testing.assert_allclose(pipe.mmae.norm.mean.numpy(), np.load(data / "Mean.npy"), rtol=1e-6)
    np.testing.assert_allclose(pipe.kf_vae.norm.std.numpy(), np.load(data / "Std.npy"), rtol=1e-6)
    gen = pipe(["a person walks"], lengths=[48], num_steps=3, guidance_scale=2.0)
    assert gen.features.shape == (1, 48, D) and np.isfinite(gen.features).all()
    # resuming finished stages trains nothing more and leaves the weights alone
    before = (out / "pst" / "latest.safetensors").read_bytes()
    again = train_keymotion(data, out, resume=True, **kw)
    assert {k: r.step for k, r in again.items()} == {"kf_vae": 3, "pst": 3, "mmae": 3}
    assert (out / "pst" / "latest.safetensors").read_bytes() == before
    with pytest.raises(FileExistsError, match="already holds a training run"):
        train_keymotion(data, out, **kw)


def test_pipeline_warns_only_when_the_normalisations_really_differ(caplog):
    """Float-rounding differences between two builds of a corpus pass; a real mismatch is named with its size."""
    import logging

    from salad_core.keymotion.models import normalisation_gap

    mean, std = np.full(D, 0.5, np.float32), np.full(D, 2.0, np.float32)
    torch.manual_seed(0)
    vae, pst, mmae = KeyframeVAE(tiny_vae_config()), ParallelSkipTransformer(tiny_pst_config()), \
        MotionMaskedAutoencoder(tiny_mmae_config())
    mmae.set_normalization(mean, std)
    vae.set_normalization(mean + 2e-3, std)           # 1e-3 of a std apart: the same corpus
    assert normalisation_gap(vae.norm.mean, vae.norm.std, mmae.norm.mean, mmae.norm.std) == pytest.approx(1e-3, rel=1e-3)
    with caplog.at_level(logging.WARNING, logger="salad_core.keymotion.pipeline"):
        KeyMotionPipeline(vae, pst, mmae, HashTextEncoder(), default_length=40)
    assert not [r for r in caplog.records if "normalisation" in r.getMessage()]
    vae.set_normalization(mean, std * 1.5)            # a different corpus: std half as large again
    assert normalisation_gap(vae.norm.mean, vae.norm.std, mmae.norm.mean, mmae.norm.std) == pytest.approx(0.5, rel=1e-6)
    with caplog.at_level(logging.WARNING, logger="salad_core.keymotion.pipeline"):
        KeyMotionPipeline(vae, pst, mmae, HashTextEncoder(), default_length=40)
    messages = [r.getMessage() for r in caplog.records if "normalisation" in r.getMessage()]
    assert len(messages) == 1 and "0.5 of a channel's std" in messages[0]


def test_planted_foot_velocity_loss_counts_only_truly_still_feet():
    from salad_core.keymotion.models import planted_foot_velocity_loss
    from salad_core.skeleton import get_skeleton

    sk = get_skeleton("humanml3d")
    t = 10
    true = torch.zeros(1, t, sk.num_joints, 3)
    ankle = sk.contact_joints[0]
    true[0, 5:, ankle, 0] = torch.arange(5, dtype=torch.float32) * 0.05     # 1 m/s from frame 5: not planted
    assert planted_foot_velocity_loss(true, true, sk).item() == 0.0
    pred = true.clone()
    pred[0, :, ankle, 2] += torch.arange(t, dtype=torch.float32) * 0.01     # slides 0.01 m/frame in z throughout
    loss = planted_foot_velocity_loss(pred, true, sk)
    # counted: 4 still joints x 9 pairs, except the ankle's 4 moving pairs (frames 5-9): 32 joint-pairs x 3 coords;
    # error: the ankle's 5 still pairs (frames 0-5) with 0.01 in z
    assert loss.item() == pytest.approx(5 * 0.01 / (32 * 3), rel=1e-5)
    # a gate above 1 m/s counts the moving pairs too (their error 0.01 each)
    assert planted_foot_velocity_loss(pred, true, sk, max_speed=2.0).item() == pytest.approx(9 * 0.01 / (36 * 3), rel=1e-5)
    mask = torch.zeros(1, t, dtype=torch.bool)
    assert planted_foot_velocity_loss(pred, true, sk, mask).item() == 0.0


def test_pst_middle_skip_pair_is_optional():
    """With 4 cross layers the pairs are (0, 3) and (1, 2); (1, 2) feeds layer 2 its own input twice, and
    middle_skip=False drops it (layer 2 then has no skip projection)."""
    from salad_core.keymotion.pst import ParallelSkipTransformer, PSTConfig

    base = dict(latent_size=2, latent_dim=8, text_dim=16, width=16, num_heads=2, ff_dim=32, num_cross_layers=4,
                dropout=0.0)
    paper = ParallelSkipTransformer(PSTConfig(**base))
    fixed = ParallelSkipTransformer(PSTConfig(**base, middle_skip=False))
    assert paper.skip_pairs == ((0, 3), (1, 2)) and fixed.skip_pairs == ((0, 3),)
    assert paper.cross_layers[2].skip_x is not None and fixed.cross_layers[2].skip_x is None
    five = ParallelSkipTransformer(PSTConfig(**{**base, "num_cross_layers": 5}, middle_skip=False))
    assert five.skip_pairs == ((0, 4), (1, 3))                     # odd L: nothing adjacent, nothing dropped
    x, text, mask = torch.randn(2, 2, 8), torch.randn(2, 3, 16), torch.ones(2, 3, dtype=torch.bool)
    assert fixed(x, torch.tensor([10, 20]), text, mask, lengths=torch.tensor([40, 60])).shape == (2, 2, 8)
    with pytest.raises(ValueError, match="middle_skip"):
        PSTConfig(**base, middle_skip=1)
