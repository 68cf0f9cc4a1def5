"""lab/scripts/keymotion/finetune_keymotion.py: one stage of a trained KeyMotion pipeline fine-tuned or trained again,
then assembled into a pipeline to measure (moved from tests/test_keymotion_finetune.py, whose tiny models it uses)."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

from _doubles import HashTextEncoder
from _lab import load_script
from salad_core.io import load_model
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.train import KeyMotionTrainConfig
from test_keymotion_finetune import TEXT_DIM, finetune_inputs, tiny_kf_vae_config, tiny_mmae_config

pytestmark = pytest.mark.usefixtures("single_thread")


def test_finetune_script_starts_from_a_pipeline_and_exports_one_with_the_new_mmae(tmp_path):
    script = load_script("finetune_keymotion")
    data, source = finetune_inputs(tmp_path, {"mmae": {"model": dataclasses.asdict(tiny_mmae_config()),
                                                       "train": {"keyframe_ratio": 0.1}}})
    enc = HashTextEncoder()
    argv = ["--stage", "mmae", "--data", str(data), "--out", str(tmp_path / "run"), "--source", str(source), "--recipe",
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
        script.main(["--stage", "mmae", "--data", str(data), "--out", str(tmp_path / "x"), "--source", str(tmp_path)])
    argv = ["--stage", "mmae", "--data", str(data), "--out", str(tmp_path / "rt"), "--source", str(source), "--recipe",
            str(tmp_path / "recipe.json"), "--steps", "1", "--roundtrip", "1"]
    assert script.main(argv, text_encoder=enc) == 0                              # on the source VAE's keyframes
    train = json.loads((tmp_path / "rt" / "config.json").read_text())["train"]
    assert train["keyframe_roundtrip"] == 1.0 and train["roundtrip_vae"] == str(source)
    assert train["keyframe_ratio"] == 0.0                                        # the VAE's fixed keyframes
    with pytest.raises(SystemExit):
        script.main(argv[:-1] + ["1.5"], text_encoder=enc)


def test_finetune_script_trains_a_new_mmae_of_the_recipes_architecture_with_scratch(tmp_path):
    """--stage mmae --scratch: an MMAE of another width than the source's (which --scratch-less fine-tuning
    refuses), from its initialisation (no init_from), with the recipe's loss weights and schedule; --export puts it
    beside the source's keyframe VAE and PST."""
    script = load_script("finetune_keymotion")
    wide = dataclasses.asdict(tiny_mmae_config(width=64, num_layers=2, lambda_foot=0.0))
    data, source = finetune_inputs(tmp_path, {"mmae": {"model": wide, "train": {"keyframe_ratio": 0.1, "lr": 3e-4,
                                                                                 "milestones": [1]}}})
    enc = HashTextEncoder()
    common = ["--stage", "mmae", "--data", str(data), "--source", str(source), "--recipe",
              str(tmp_path / "recipe.json"), "--steps", "2"]
    with pytest.raises(ValueError, match="another architecture"):
        script.main(common + ["--out", str(tmp_path / "bad")], text_encoder=enc)
    assert script.main(common + ["--scratch", "--out", str(tmp_path / "run"), "--export", str(tmp_path / "out")],
                       text_encoder=enc) == 0
    doc = json.loads((tmp_path / "run" / "config.json").read_text())
    assert doc["train"]["init_from"] is None and doc["model"]["width"] == 64
    assert doc["model"]["lambda_foot"] == 0.0                       # the recipe's weight, not the fine-tuning's 5
    assert doc["train"]["lr"] == 3e-4 and doc["train"]["milestones"] == [1] and doc["train"]["max_steps"] == 2
    out = KeyMotionPipeline.from_pretrained(tmp_path / "out", text_encoder=enc)
    assert out.mmae.config.width == 64 and out.mmae.config.num_layers == 2
    np.testing.assert_allclose(out.mmae.norm.std.float().numpy(), np.load(data / "Std.npy"), rtol=1e-3)
    for name in ("kf_vae", "pst"):
        a, _, _ = load_model(source / name)
        b, _, _ = load_model(tmp_path / "out" / name)
        assert all(torch.equal(x.half(), y.half()) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
    with pytest.raises(SystemExit):                                 # a new keyframe VAE has no encoder to freeze
        script.main(["--stage", "kf_vae", "--scratch", "--parts", "decoder", "--data", str(data), "--out",
                     str(tmp_path / "x")])


def test_finetune_script_trains_a_new_kf_vae_of_the_recipes_architecture_with_scratch(tmp_path):
    """--stage kf_vae --scratch: a keyframe VAE of the recipe's architecture (here absolute keyframe timing, which a
    fine-tuning of the relative source could not load) from its initialisation, every part trained."""
    script = load_script("finetune_keymotion")
    model = dataclasses.asdict(tiny_kf_vae_config(timing="absolute"))
    data, source = finetune_inputs(tmp_path, {"kf_vae": {"model": model, "train": {"lr": 1e-3}}})
    argv = ["--stage", "kf_vae", "--scratch", "--data", str(data), "--source", str(source), "--recipe",
            str(tmp_path / "recipe.json"), "--steps", "2", "--out", str(tmp_path / "run")]
    assert script.main(argv, text_encoder=HashTextEncoder()) == 0
    doc = json.loads((tmp_path / "run" / "config.json").read_text())
    assert doc["train"]["init_from"] is None and doc["train"]["train_parts"] == "all"
    assert doc["model"]["timing"] == "absolute" and doc["train"]["lr"] == 1e-3 and doc["train"]["max_steps"] == 2
    vae, _, _ = load_model(tmp_path / "run" / "latest")
    assert vae.position_span == vae.config.max_length - 1


def test_finetune_script_fine_tunes_the_kf_vae_decoder_and_exports_a_pipeline_whose_pst_still_fits(tmp_path):
    script = load_script("finetune_keymotion")
    data, source = finetune_inputs(tmp_path, {"kf_vae": {"model": dataclasses.asdict(tiny_kf_vae_config())}})
    enc = HashTextEncoder()
    common = ["--data", str(data), "--source", str(source), "--recipe", str(tmp_path / "recipe.json")]
    argv = ["--stage", "kf_vae", *common, "--out", str(tmp_path / "run"), "--steps", "2", "--lr", "1e-2",
            "--lambda-local-vel", "2", "--lambda-root", "1", "--export", str(tmp_path / "out")]
    assert script.main(argv, text_encoder=enc) == 0
    rows = [json.loads(line) for line in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    assert any("local_vel" in r and "root" in r for r in rows)                     # the terms are trained
    doc = json.loads((tmp_path / "run" / "config.json").read_text())
    assert doc["train"]["train_parts"] == "decoder" and doc["model"]["lambda_local_vel"] == 2.0
    out = KeyMotionPipeline.from_pretrained(tmp_path / "out", text_encoder=enc)
    before, _, _ = load_model(source / "kf_vae")
    old, new = before.state_dict(), out.kf_vae.state_dict()
    encoder_keys = [k for k in old if k.split(".")[0] in ("frame_embed", "index_embed", "encoder", "encoder_norm",
                                                           "to_dist", "latent_tokens")]
    assert encoder_keys and all(torch.equal(old[k].half(), new[k].half()) for k in encoder_keys)   # encoder kept
    assert any(not torch.equal(old[k].half(), new[k].half()) for k in old if k.startswith("decoder."))
    for name in ("pst", "mmae"):                         # the source's other two components, unchanged
        a, _, _ = load_model(source / name)
        b, _, _ = load_model(tmp_path / "out" / name)
        assert all(torch.equal(x.half(), y.half()) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
    with pytest.raises(SystemExit):                      # a flag of the other stage is refused
        script.main(["--stage", "kf_vae", *common, "--out", str(tmp_path / "x"), "--lambda-foot", "3"])
    with pytest.raises(SystemExit):
        script.main(["--stage", "mmae", *common, "--out", str(tmp_path / "x"), "--parts", "all"])


def test_finetune_script_trains_a_latent_norm_pst_from_scratch_on_the_source_vae(tmp_path):
    """--stage pst --latent-norm: refused from a source PST without it (another latent space), trained from scratch
    with --scratch (the statistics of the source VAE's latents set, the source PST's weights not used)."""
    script = load_script("finetune_keymotion")
    pst_model = dict(latent_size=2, latent_dim=16, text_dim=TEXT_DIM, width=32, num_heads=4, ff_dim=64,
                     num_cond_layers=1, num_cross_layers=2, dropout=0.0, max_length=96)
    data, source = finetune_inputs(tmp_path, {"pst": {"model": pst_model, "train": {"latent_cache": False}}})
    enc = HashTextEncoder()
    common = ["--stage", "pst", "--latent-norm", "--data", str(data), "--source", str(source), "--recipe",
              str(tmp_path / "recipe.json"), "--steps", "2"]
    with pytest.raises(ValueError, match="latent_norm"):
        script.main(common + ["--out", str(tmp_path / "bad")], text_encoder=enc)
    assert script.main(common + ["--scratch", "--out", str(tmp_path / "run")], text_encoder=enc) == 0
    doc = json.loads((tmp_path / "run" / "config.json").read_text())
    assert doc["model"]["latent_norm"] is True and doc["train"]["init_from"] is None
    new, _, _ = load_model(tmp_path / "run" / "latest")
    old, _, _ = load_model(source / "pst")
    assert float(new.latent_std.min()) > 0 and not torch.equal(new.latent_std, torch.ones_like(new.latent_std))
    assert not torch.equal(new.out.weight.half(), old.out.weight.half())


def test_finetune_script_trains_a_pst_on_another_kf_vae_and_exports_them_together(tmp_path):
    """--kf-vae RUN (with --scratch): the PST trains on a wider keyframe VAE's latents, and --export assembles that
    VAE, the new PST and the source's MMAE into a pipeline that loads and samples; runs.json names both runs."""
    from salad_core.keymotion.export import export_with_components
    from salad_core.keymotion.train import train_kf_vae

    script = load_script("finetune_keymotion")
    pst_model = dict(latent_size=2, latent_dim=24, text_dim=TEXT_DIM, width=32, num_heads=4, ff_dim=64,
                     num_cond_layers=1, num_cross_layers=2, dropout=0.0, max_length=96)
    data, source = finetune_inputs(tmp_path, {"pst": {"model": pst_model, "train": {"latent_cache": False}}})
    torch.manual_seed(1)
    wide = tmp_path / "wide_vae"
    train_kf_vae(data, wide, tiny_kf_vae_config(latent_dim=24),
                 KeyMotionTrainConfig(batch_size=4, max_length=96, keyframe_method="uniform", num_threads=1,
                                      max_steps=1, val_every=1, val_batches=1, ckpt_every=1, log_every=1,
                                      progress=False))
    enc = HashTextEncoder()
    common = ["--stage", "pst", "--latent-norm", "--data", str(data), "--source", str(source), "--recipe",
              str(tmp_path / "recipe.json"), "--steps", "2", "--kf-vae", str(wide)]
    with pytest.raises(SystemExit):                          # a trained PST fits only its own VAE
        script.main(common + ["--out", str(tmp_path / "bad")], text_encoder=enc)
    assert script.main(common + ["--scratch", "--out", str(tmp_path / "run"), "--export", str(tmp_path / "out")],
                       text_encoder=enc) == 0
    out = KeyMotionPipeline.from_pretrained(tmp_path / "out", text_encoder=enc)
    assert out.kf_vae.config.latent_dim == 24 and out.pst.config.latent_dim == 24 and out.pst.config.latent_norm
    trained, _, _ = load_model(wide / "best")
    assert all(torch.equal(a.half(), b) for a, b in zip(trained.state_dict().values(),
                                                         out.kf_vae.half().state_dict().values()))
    old_mmae, _, _ = load_model(source / "mmae")
    assert all(torch.equal(a.half(), b.half()) for a, b in zip(old_mmae.state_dict().values(),
                                                                out.mmae.state_dict().values()))
    records = json.loads((tmp_path / "out" / "runs.json").read_text())
    assert records["kf_vae"]["config"]["model"]["latent_dim"] == 24 and records["pst"]["step"] == 2
    motion = KeyMotionPipeline.from_pretrained(tmp_path / "out", text_encoder=enc)(
        "a person walks", lengths=40, num_steps=2, seed=0)
    assert np.isfinite(np.asarray(motion.features)).all()
    # one stage at a time cannot be assembled (the source's PST does not fit the wider VAE), nor a wrong run
    with pytest.raises(ValueError, match="latents"):
        export_with_components(source, {"kf_vae": wide}, tmp_path / "x", text_encoder=enc)
    with pytest.raises(ValueError, match="not the kf_vae"):
        export_with_components(source, {"kf_vae": tmp_path / "run"}, tmp_path / "x", text_encoder=enc)
    with pytest.raises(ValueError, match="not a KeyMotion component"):
        export_with_components(source, {"vae": wide}, tmp_path / "x", text_encoder=enc)
    assert not (tmp_path / "x").exists()                     # nothing written by a refused export
