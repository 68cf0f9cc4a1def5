"""Fine-tuning a KeyMotion stage (issue 22): the MMAE's foot-contact term, the keyframe VAE's feature-group terms and
frozen encoder, starting either from a trained one, and the fine-tuning script."""
from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core.io import load_model
from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig
from salad_core.keymotion.mmae import MMAEConfig, MotionMaskedAutoencoder
from salad_core.keymotion.models import foot_contact_loss
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.pst import ParallelSkipTransformer, PSTConfig
from salad_core.keymotion.kf_vae import GROUP_TERMS, group_channels
from salad_core.keymotion.train import KeyframeVAEObjective, KeyMotionTrainConfig, load_kf_vae_init, load_mmae_init
from salad_core.skeleton import get_skeleton
from _doubles import HashTextEncoder, make_fake_corpus

SK = get_skeleton("humanml3d")
TEXT_DIM = 16

pytestmark = pytest.mark.usefixtures("single_thread")


def tiny_mmae_config(**kw) -> MMAEConfig:
    base = dict(text_dim=TEXT_DIM, width=32, num_layers=1, num_heads=4, ff_dim=64, dropout=0.0, max_length=96)
    base.update(kw)
    return MMAEConfig(**base)


def tiny_kf_vae_config(**kw) -> KeyframeVAEConfig:
    base = dict(num_keyframes=8, max_length=96, frame_dim=32, latent_dim=16, num_layers=1, ff_dim=64, dropout=0.0)
    base.update(kw)
    return KeyframeVAEConfig(**base)


def saved_pipeline(folder: Path, *, vae: KeyframeVAE | None = None, mmae: MotionMaskedAutoencoder | None = None,
                   stats: tuple[np.ndarray, np.ndarray] | None = None) -> Path:
    """A tiny KeyMotion pipeline saved at ``folder`` (the given models, new ones otherwise; ``stats`` (mean, std)
    set on both), as the source of a fine-tuning."""
    vae = vae if vae is not None else KeyframeVAE(tiny_kf_vae_config())
    mmae = mmae if mmae is not None else MotionMaskedAutoencoder(tiny_mmae_config())
    if stats is not None:
        for m in (vae, mmae):
            m.set_normalization(*stats)
    pst = ParallelSkipTransformer(PSTConfig(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4,
                                            ff_dim=64, num_cond_layers=1, num_cross_layers=2, dropout=0.0))
    return KeyMotionPipeline(vae, pst, mmae, HashTextEncoder(), default_length=40).save_pretrained(folder)


def finetune_inputs(tmp_path: Path, stage_sections: dict) -> tuple[Path, Path]:
    """``(corpus, source pipeline)`` for the fine-tuning script, and ``tmp_path / "recipe.json"``: tiny training
    settings plus ``stage_sections`` (the recipe's ``"mmae"`` / ``"kf_vae"`` sections)."""
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=4)
    torch.manual_seed(0)
    source = saved_pipeline(tmp_path / "source", stats=(np.load(data / "Mean.npy"), np.load(data / "Std.npy")))
    recipe = {"text_encoder": "hash", "train": {"batch_size": 4, "max_length": 96, "keyframe_method": "uniform",
                                                "num_threads": 1, "val_every": 2, "val_batches": 1, "ckpt_every": 1,
                                                "log_every": 1, "seed": 3}, **stage_sections}
    (tmp_path / "recipe.json").write_text(json.dumps(recipe))
    return data, source


def test_foot_contact_loss_is_the_planted_feet_speed():
    """Zero while planted feet stay put, the mean per-axis speed of a sliding planted foot, and a foot in the air
    (no contact) or an invalid frame does not count."""
    torch.manual_seed(0)
    joints = torch.zeros(1, 5, SK.num_joints, 3)
    contacts = torch.zeros(1, 5, 4)
    assert float(foot_contact_loss(joints, contacts, SK)) == 0.0                    # no contact: nothing to count
    contacts[0, :, 0] = 1.0                                                         # the first contact joint planted
    foot = SK.contact_joints[0]
    assert float(foot_contact_loss(joints, contacts, SK)) == 0.0                    # and still
    joints[0, :, foot, 0] = torch.arange(5.0) * 0.03                                # slides 3 cm/frame along x
    assert float(foot_contact_loss(joints, contacts, SK)) == pytest.approx(0.01)    # |0.03, 0, 0| / 3 axes
    other = SK.contact_joints[2]
    joints[0, :, other, 1] = torch.arange(5.0) * 0.5                               # a foot in the air moves freely
    assert float(foot_contact_loss(joints, contacts, SK)) == pytest.approx(0.01)
    mask = torch.tensor([[True, True, False, False, False]])                        # one valid velocity
    assert float(foot_contact_loss(joints, contacts, SK, mask)) == pytest.approx(0.01)
    joints[0, 2:, foot, 0] = 0.06                                                   # stops after frame 2
    assert float(foot_contact_loss(joints, contacts, SK)) == pytest.approx(0.06 / 3 / 4)


def test_mmae_loss_adds_the_foot_term_only_when_weighted():
    torch.manual_seed(0)
    plain = MotionMaskedAutoencoder(tiny_mmae_config())
    footed = MotionMaskedAutoencoder(tiny_mmae_config(lambda_foot=2.0))
    footed.load_state_dict(plain.state_dict())
    target = torch.randn(2, 12, SK.feature_dim)
    pred = target + 0.1 * torch.randn_like(target)
    mask = torch.ones(2, 12, dtype=torch.bool)
    a, b = plain.loss(pred, target, mask), footed.loss(pred, target, mask)
    assert "foot" not in a and float(b["foot"]) > 0
    assert float(b["loss"]) == pytest.approx(float(a["loss"]) + 2.0 * float(b["foot"]), rel=1e-5)
    no_contact = target.clone()
    no_contact[..., SK.feature_slices["contacts"]] = 0.0                             # (identity normalisation)
    assert float(footed.loss(pred, no_contact, mask)["foot"]) == 0.0                 # only planted feet count


def test_load_mmae_init_takes_a_pipelines_mmae_and_refuses_another_architecture(tmp_path):
    torch.manual_seed(1)
    trained = MotionMaskedAutoencoder(tiny_mmae_config())
    trained.set_normalization(np.full(SK.feature_dim, 0.5, np.float32), np.full(SK.feature_dim, 2.0, np.float32))
    folder = saved_pipeline(tmp_path / "km", mmae=trained)
    fresh = MotionMaskedAutoencoder(tiny_mmae_config(lambda_foot=5.0, dropout=0.1))   # loss weights may differ
    assert load_mmae_init(fresh, folder) == folder / "mmae"
    assert all(torch.equal(fresh.state_dict()[k], v) for k, v in trained.state_dict().items())
    assert float(fresh.norm.mean[0]) == 0.5                                          # its normalisation comes along
    with pytest.raises(ValueError, match="another architecture.*width"):
        load_mmae_init(MotionMaskedAutoencoder(tiny_mmae_config(width=64)), folder)
    with pytest.raises(ValueError, match="not a 'keymotion_mmae'"):
        load_mmae_init(fresh, folder / "pst")
    with pytest.raises(FileNotFoundError, match="neither"):
        load_mmae_init(fresh, tmp_path / "nothing")


# ------------------------------------------------------------------------------------------------ keyframe VAE
def test_kf_vae_group_terms_are_the_mse_of_their_channels_added_with_their_weight():
    torch.manual_seed(0)
    plain = KeyframeVAE(tiny_kf_vae_config())
    weighted = KeyframeVAE(tiny_kf_vae_config(lambda_root=2.0, lambda_local_vel=3.0, lambda_contact=0.5))
    weighted.load_state_dict(plain.state_dict())
    keyframes, positions = torch.randn(3, 8, SK.feature_dim), torch.linspace(0, 1, 8).expand(3, -1)
    with torch.no_grad():
        decoding, mu, logvar = plain(keyframes, positions, torch.zeros(3, 2, 16))
    decoding = decoding._replace(keyframes=keyframes.clone())
    decoding.keyframes[..., 3] += 0.5                                     # root height off by 0.5 everywhere
    decoding.keyframes[..., SK.feature_slices["contacts"]] -= 1.0         # every contact channel off by 1
    a = plain.loss(keyframes, positions, decoding, mu, logvar)
    b = weighted.loss(keyframes, positions, decoding, mu, logvar)
    assert set(GROUP_TERMS.values()) - set(a) == {"root", "local_vel", "contacts", "feet_height"}  # off: not reported
    assert float(b["root"]) == pytest.approx(0.25 / 4)                   # one of the 4 root channels, 0.5^2
    assert float(b["local_vel"]) == 0.0 and float(b["contacts"]) == pytest.approx(1.0) and "feet_height" not in b
    assert float(b["rec"]) == pytest.approx(float(a["rec"]))
    assert float(b["loss"]) == pytest.approx(float(a["loss"]) + 2.0 * 0.25 / 4 + 0.5 * 1.0, rel=1e-5)
    feet = KeyframeVAE(tiny_kf_vae_config(lambda_feet_height=1.0))
    cols = group_channels(SK, "feet_height")                              # the y of the 4 contact joints' ric
    ric = SK.feature_slices["ric"].start
    assert cols == [ric + 3 * (j - 1) + 1 for j in SK.contact_joints] and len(cols) == 4
    decoding.keyframes[..., cols[0]] += 2.0                               # one foot 2 units too high
    assert float(feet.loss(keyframes, positions, decoding, mu, logvar)["feet_height"]) == pytest.approx(4.0 / 4)
    with pytest.raises(ValueError, match="unknown feature group"):
        group_channels(SK, "hands")
    with pytest.raises(ValueError, match="lambda_root"):
        tiny_kf_vae_config(lambda_root=-1.0)


def test_kf_vae_decoder_finetuning_keeps_the_encoder_and_its_posteriors():
    """Frozen encoder: no gradient reaches it, it stays in eval mode (no dropout) while the objective trains, the
    decoder still learns, and an optimiser step leaves the posterior of a batch exactly as it was."""
    torch.manual_seed(2)
    vae = KeyframeVAE(tiny_kf_vae_config(dropout=0.3, lambda_local_vel=1.0))
    objective = KeyframeVAEObjective(vae, freeze_encoder=True).train()
    assert not any(m.training for m in vae.encoder_modules()) and vae.decoder.training
    keyframes, positions = torch.randn(4, 8, SK.feature_dim), torch.linspace(0, 1, 8).expand(4, -1)
    with torch.no_grad():
        before = vae.encode(keyframes, positions, sample=False)
    decoder_before = [p.detach().clone() for p in vae.decoder.parameters()]
    opt = torch.optim.SGD([p for p in vae.parameters() if p.requires_grad], lr=0.1)
    objective(keyframes, positions, torch.randn(4, 2, 16))["loss"].backward()
    assert vae.latent_tokens.grad is None and all(p.grad is None for p in vae.to_dist.parameters())
    opt.step()
    with torch.no_grad():
        after = vae.encode(keyframes, positions, sample=False)
    assert torch.equal(before.mu, after.mu) and torch.equal(before.logvar, after.logvar)
    assert any(not torch.equal(a, b) for a, b in zip(decoder_before, vae.decoder.parameters()))
    with pytest.raises(ValueError, match="needs init_from"):
        KeyMotionTrainConfig(train_parts="decoder")
    with pytest.raises(ValueError, match="train_parts"):
        KeyMotionTrainConfig(train_parts="encoder", init_from="x")


def test_kf_vae_latent_noise_moves_only_the_decoders_input_by_its_scale():
    """``latent_noise`` S: the decoder reads mu + sigma * eps + S * noise (the KL term still sees the posterior);
    0 or no noise tensor gives exactly the plain objective; a negative scale is refused."""
    torch.manual_seed(3)
    keyframes, positions = torch.randn(3, 8, SK.feature_dim), torch.linspace(0, 1, 8).expand(3, -1)
    eps, noise = torch.randn(3, 2, 16), torch.randn(3, 2, 16)
    noisy = KeyframeVAE(tiny_kf_vae_config(latent_noise=0.5)).eval()
    plain = KeyframeVAE(tiny_kf_vae_config()).eval()
    plain.load_state_dict(noisy.state_dict())
    with torch.no_grad():
        base = KeyframeVAEObjective(plain)(keyframes, positions, eps)
        assert torch.equal(KeyframeVAEObjective(plain)(keyframes, positions, eps, noise)["loss"], base["loss"])
        assert torch.equal(KeyframeVAEObjective(noisy)(keyframes, positions, eps)["loss"], base["loss"])
        out = KeyframeVAEObjective(noisy)(keyframes, positions, eps, noise)
        enc = noisy.encode(keyframes, positions, sample=False)
        expect = noisy.loss(keyframes, positions, noisy.decode(enc.mu + eps * torch.exp(0.5 * enc.logvar) + 0.5 * noise),
                            enc.mu, enc.logvar)
    assert torch.allclose(out["loss"], expect["loss"]) and not torch.allclose(out["loss"], base["loss"])
    assert torch.equal(out["kl"], base["kl"])
    with pytest.raises(ValueError, match="latent_noise"):
        tiny_kf_vae_config(latent_noise=-0.1)


def test_load_kf_vae_init_takes_a_pipelines_vae_and_refuses_another_architecture(tmp_path):
    torch.manual_seed(1)
    trained = KeyframeVAE(tiny_kf_vae_config())
    trained.set_normalization(np.full(SK.feature_dim, 0.5, np.float32), np.full(SK.feature_dim, 2.0, np.float32))
    folder = saved_pipeline(tmp_path / "km", vae=trained)
    fresh = KeyframeVAE(tiny_kf_vae_config(lambda_root=4.0, dropout=0.1))     # loss weights and dropout may differ
    assert load_kf_vae_init(fresh, folder) == folder / "kf_vae"
    assert all(torch.equal(fresh.state_dict()[k], v) for k, v in trained.state_dict().items())
    assert float(fresh.norm.std[0]) == 2.0
    with pytest.raises(ValueError, match="another architecture.*latent_dim"):
        load_kf_vae_init(KeyframeVAE(tiny_kf_vae_config(latent_dim=8)), folder)
    with pytest.raises(ValueError, match="not a 'keymotion_kf_vae'"):
        load_kf_vae_init(fresh, folder / "mmae")


# ------------------------------------------------------------------------------------- MMAE on decoded keyframes
def test_mmae_roundtrip_items_get_the_keyframe_vaes_reconstruction_at_its_frames(tmp_path):
    """keyframe_roundtrip 1: every item's input keyframes are the VAE's decoded keyframes scattered at the decoded
    frames (first 0, last L - 1); 0: the true keyframes; the target stays the true motion either way."""
    from salad_core.keymotion.mmae import scatter_keyframes
    from salad_core.keymotion.train import build_mmae_task, roundtrip_keyframes
    from salad_core.train.common import StepContext
    from salad_core.train.distributed import DistEnv, GlobalBatchRandom

    data = make_fake_corpus(tmp_path / "corpus", n_train=6, n_val=3)
    torch.manual_seed(0)
    source = saved_pipeline(tmp_path / "km", stats=(np.load(data / "Mean.npy"), np.load(data / "Std.npy")))
    env = DistEnv()
    base = KeyMotionTrainConfig(max_length=96, num_threads=1, progress=False, batch_size=3, keyframe_method="uniform")
    inputs = {}
    for share in (0.0, 1.0):
        cfg = base.replace(keyframe_roundtrip=share, roundtrip_vae=str(source) if share else None)
        task = build_mmae_task(data, tiny_mmae_config(), cfg, env, HashTextEncoder(), 8)
        batch = task.collate([task.train_set[i] for i in range(3)])
        ctx = StepContext(GlobalBatchRandom(torch.Generator().manual_seed(1), env), env, train=True, step=0)
        inputs[share] = task.prepare(batch, ctx)
        assert torch.equal(inputs[share]["motion"], batch["motion"])                  # the target: the true motion
    motion, idx, length = batch["motion"], batch["keyframes"], batch["length"]
    true_kf = torch.gather(motion, 1, idx[..., None].expand(-1, -1, motion.shape[-1]))
    expected_true, _ = scatter_keyframes(true_kf, idx, motion.shape[1])
    assert torch.equal(inputs[0.0]["inputs"], expected_true)
    loaded = KeyMotionPipeline.from_pretrained(source, text_encoder=HashTextEncoder()).kf_vae
    kf_rt, idx_rt = roundtrip_keyframes(loaded, true_kf, idx, length)
    assert torch.equal(idx_rt[:, 0], torch.zeros(3, dtype=torch.long)) and torch.equal(idx_rt[:, -1], length - 1)
    assert bool((idx_rt.diff(dim=1) > 0).all())
    expected_rt, mask_rt = scatter_keyframes(kf_rt, idx_rt, motion.shape[1])
    assert torch.allclose(inputs[1.0]["inputs"], expected_rt, atol=1e-6)
    assert torch.equal(inputs[1.0]["keyframe_mask"], mask_rt)
    assert not torch.allclose(inputs[1.0]["inputs"], inputs[0.0]["inputs"])
    with pytest.raises(ValueError, match="needs roundtrip_vae"):
        KeyMotionTrainConfig(keyframe_roundtrip=0.5)
    with pytest.raises(ValueError, match="needs keyframe_ratio=0"):
        KeyMotionTrainConfig(keyframe_roundtrip=0.5, roundtrip_vae="x", keyframe_ratio=0.1)
    from salad_core.keymotion.train import build_kf_vae_task
    with pytest.raises(ValueError, match="keyframe_roundtrip=.* is for the MMAE only"):
        build_kf_vae_task(data, tiny_kf_vae_config(), cfg, env)
    with pytest.raises(ValueError, match="has 8 keyframes; this MMAE run selects num_keyframes=6"):
        build_mmae_task(data, tiny_mmae_config(), cfg, env, HashTextEncoder(), 6)


