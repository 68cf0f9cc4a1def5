"""The MMAE's foot-contact term, starting an MMAE from a trained one, and the fine-tuning script (issue 22)."""
from __future__ import annotations

import dataclasses
import importlib.util
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
from salad_core.keymotion.train import load_mmae_init
from salad_core.skeleton import get_skeleton
from _doubles import HashTextEncoder, make_fake_corpus

SK = get_skeleton("humanml3d")
TEXT_DIM = 16

pytestmark = pytest.mark.usefixtures("single_thread")


def tiny_mmae_config(**kw) -> MMAEConfig:
    base = dict(text_dim=TEXT_DIM, width=32, num_layers=1, num_heads=4, ff_dim=64, dropout=0.0, max_length=96)
    base.update(kw)
    return MMAEConfig(**base)


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
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, max_length=96, frame_dim=32, latent_dim=16, num_layers=1,
                                        ff_dim=64, dropout=0.0))
    pst = ParallelSkipTransformer(PSTConfig(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4,
                                            ff_dim=64, num_cond_layers=1, num_cross_layers=2, dropout=0.0))
    folder = KeyMotionPipeline(vae, pst, trained, HashTextEncoder(), default_length=40).save_pretrained(tmp_path / "km")
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


def test_finetune_script_starts_from_a_pipeline_and_exports_one_with_the_new_mmae(tmp_path):
    spec = importlib.util.spec_from_file_location(
        "finetune_keymotion_mmae", Path(__file__).resolve().parents[1] / "scripts" / "finetune_keymotion_mmae.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    data = make_fake_corpus(tmp_path / "corpus", n_train=8, n_val=4)
    mean, std = np.load(data / "Mean.npy"), np.load(data / "Std.npy")
    torch.manual_seed(0)
    vae = KeyframeVAE(KeyframeVAEConfig(num_keyframes=8, max_length=96, frame_dim=32, latent_dim=16, num_layers=1,
                                        ff_dim=64, dropout=0.0))
    pst = ParallelSkipTransformer(PSTConfig(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4,
                                            ff_dim=64, num_cond_layers=1, num_cross_layers=2, dropout=0.0))
    mmae = MotionMaskedAutoencoder(tiny_mmae_config())
    for m in (vae, mmae):
        m.set_normalization(mean, std)
    enc = HashTextEncoder()
    source = KeyMotionPipeline(vae, pst, mmae, enc, default_length=40).save_pretrained(tmp_path / "source")
    recipe = {"text_encoder": "hash", "train": {"batch_size": 4, "max_length": 96, "keyframe_method": "uniform",
                                                "num_threads": 1, "val_every": 2, "val_batches": 1, "ckpt_every": 1,
                                                "log_every": 1, "seed": 3},
              "mmae": {"model": dataclasses.asdict(tiny_mmae_config()), "train": {"keyframe_ratio": 0.1}}}
    (tmp_path / "recipe.json").write_text(json.dumps(recipe))
    argv = ["--data", str(data), "--out", str(tmp_path / "run"), "--source", str(source), "--recipe",
            str(tmp_path / "recipe.json"), "--steps", "2", "--lr", "1e-3", "--lambda-foot", "3",
            "--export", str(tmp_path / "out")]
    assert script.main(argv, text_encoder=enc) == 0
    rows = [json.loads(line) for line in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    assert any("foot" in r for r in rows)                                            # the term is trained
    doc = json.loads((tmp_path / "run" / "config.json").read_text())
    assert doc["train"]["init_from"] == str(source) and doc["model"]["lambda_foot"] == 3.0
    out = KeyMotionPipeline.from_pretrained(tmp_path / "out", text_encoder=enc)
    assert out.mmae.config.lambda_foot == 3.0
    for name in ("kf_vae", "pst"):                       # the source's other two components, unchanged
        a, _, _ = load_model(source / name)
        b, _, _ = load_model(tmp_path / "out" / name)
        assert all(torch.equal(x.half(), y.half()) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
    before, _, _ = load_model(source / "mmae")
    assert any(not torch.equal(x.half(), y.half()) for x, y in
               zip(before.state_dict().values(), out.mmae.state_dict().values()))    # the MMAE moved
    with pytest.raises(SystemExit):
        script.main(["--data", str(data), "--out", str(tmp_path / "x"), "--source", str(tmp_path)])
