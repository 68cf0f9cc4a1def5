"""lab/scripts/keymotion: the side-cue fine-tuning of finetune_keymotion.py and keymotion_flight_chain.py (moved from
tests/test_keymotion_sides.py and tests/test_report.py, whose tiny models and fixtures they use)."""
from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from _doubles import HashTextEncoder
from _lab import load_script, script_path
from salad_core.io import load_model
from salad_core.keymotion.mmae import MMAEConfig, MotionMaskedAutoencoder
from salad_core.keymotion.pipeline import KeyMotionPipeline
from salad_core.keymotion.pst import ParallelSkipTransformer
from test_keymotion_sides import TEXT_DIM, _keyframe_sets, _tiny_kf_vae, side_corpus, tiny_pst_config  # noqa: F401
from test_report import keymotion_pipe  # noqa: F401  (a fixture)

pytestmark = pytest.mark.usefixtures("single_thread")


def test_finetune_script_starts_from_a_pipeline_and_exports_one_with_the_cue(side_corpus, tmp_path):
    """scripts/finetune_keymotion.py --stage pst --side-cue: a cue PST fine-tuned from a pipeline's PST on its own
    keyframe VAE, then a pipeline with the source's keyframe VAE and MMAE and the new PST."""
    script = load_script("finetune_keymotion")
    train, _ = _keyframe_sets(side_corpus)
    vae = _tiny_kf_vae(train)
    torch.manual_seed(0)
    plain = ParallelSkipTransformer(tiny_pst_config(max_length=96))
    mmae = MotionMaskedAutoencoder(MMAEConfig(text_dim=TEXT_DIM, width=32, num_layers=1, num_heads=4, ff_dim=64,
                                              dropout=0.0, max_length=96))
    mmae.set_normalization(train.mean, train.std)
    enc = HashTextEncoder()
    source = KeyMotionPipeline(vae, plain, mmae, enc, default_length=40).save_pretrained(tmp_path / "source")
    pst_model = dataclasses.asdict(tiny_pst_config(max_length=96))
    recipe = {"text_encoder": "hash", "train": {"batch_size": 4, "max_length": 96, "keyframe_method": "uniform",
                                                "num_threads": 1, "val_every": 2, "val_batches": 1, "ckpt_every": 1,
                                                "log_every": 1, "seed": 3},
              "pst": {"model": pst_model, "train": {}}}
    (tmp_path / "recipe.json").write_text(json.dumps(recipe))
    argv = ["--stage", "pst", "--side-cue", "--data", str(side_corpus), "--out", str(tmp_path / "run"), "--source",
            str(source), "--recipe", str(tmp_path / "recipe.json"), "--steps", "2", "--lr", "1e-3", "--export",
            str(tmp_path / "out")]
    assert script.main(argv, text_encoder=enc) == 0
    out = KeyMotionPipeline.from_pretrained(tmp_path / "out", text_encoder=enc)
    assert out.pst.config.side_cue is True and torch.count_nonzero(out.pst.side_embed.weight[1:]) > 0
    for name in ("kf_vae", "mmae"):                       # the source's other two components, unchanged
        a, _, _ = load_model(source / name)
        b, _, _ = load_model(tmp_path / "out" / name)
        assert all(torch.equal(x.half(), y.half()) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
    doc = json.loads((tmp_path / "run" / "config.json").read_text())
    assert doc["train"]["init_from"] == str(source) and doc["train"]["max_steps"] == 2
    with pytest.raises(SystemExit):
        script.main(["--stage", "pst", "--data", str(side_corpus), "--out", str(tmp_path / "x"), "--source",
                     str(tmp_path)])
    with pytest.raises(SystemExit):                       # a flag of another stage
        script.main(["--stage", "mmae", "--side-cue", "--data", str(side_corpus), "--out", str(tmp_path / "x")])


def test_flight_chain_script_writes_each_stage_with_its_recovery(keymotion_pipe, tiny_procedural_corpus, tmp_path,
                                                                  capsys):
    """``scripts/keymotion_flight_chain.py --recovery fit``: a table row per stage, the setting in the JSON."""
    import importlib.util

    from salad_core.eval.keymotion_roundtrip import CHAIN_STAGES

    path = script_path("keymotion_flight_chain.py")
    spec = importlib.util.spec_from_file_location("keymotion_flight_chain", path)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    out = tmp_path / "chain.json"
    assert script.main(["--data", str(tiny_procedural_corpus), "--words", "a", "--exclude", "--limit", "2",
                        "--recovery", "fit", "--guidance", "2.5", "--out", str(out)], pipe=keymotion_pipe) == 0
    doc = json.loads(out.read_text())
    assert doc["recovery"] == "fit" and doc["guidance"] == 2.5 and len(doc["clips"]) == 2
    assert list(doc["table"]) == list(CHAIN_STAGES)
    assert all(len(doc["reports"][s]) == 2 for s in CHAIN_STAGES)
    row = next(line for line in capsys.readouterr().out.splitlines() if line.startswith("| generated |"))
    cells = [c.strip() for c in row.strip("|").split("|")][1:]
    keys = [k for k, _, _ in script.COLUMNS]
    # skating printed to the millimetre per second (the stages differ by a few cm/s), the JSON's value
    assert cells[keys.index("skate_mean_ms")] == f"{doc['table']['generated']['skate_mean_ms']:.3f}"
    assert cells[keys.index("flight_frames")] == f"{doc['table']['generated']['flight_frames']:.2f}"
    with pytest.raises(SystemExit):
        script.main(["--data", str(tiny_procedural_corpus), "--recovery", "ik"], pipe=keymotion_pipe)
    # --kf-vae: another keyframe VAE (another latent width, which the weights' PST cannot denoise) in place of
    # the weights' own; the chain stops before the generated stage and its VAE stage is that VAE's
    from salad_core.io import save_checkpoint
    from salad_core.keymotion.kf_vae import KeyframeVAE, KeyframeVAEConfig

    own = keymotion_pipe.kf_vae
    torch.manual_seed(5)
    wide_cfg = KeyframeVAEConfig(**{**own.config.__dict__, "latent_dim": 32})
    wide = KeyframeVAE(wide_cfg)
    wide.norm.load_state_dict(own.norm.state_dict())             # the same data statistics
    save_checkpoint(tmp_path / "wide" / "best", wide, model_type="keymotion_kf_vae", config=wide_cfg)
    wout = tmp_path / "wide.json"
    try:
        assert script.main(["--data", str(tiny_procedural_corpus), "--words", "a", "--exclude", "--limit", "2",
                            "--recovery", "fit", "--kf-vae", str(tmp_path / "wide"), "--out", str(wout)],
                           pipe=keymotion_pipe) == 0
    finally:
        keymotion_pipe.kf_vae = own                               # the fixture is shared
    wdoc = json.loads(wout.read_text())
    assert list(wdoc["table"]) == ["true", "true_keyframes", "vae_keyframes"] and wdoc["kf_vae"].endswith("wide")
    assert wdoc["reports"]["true_keyframes"] == doc["reports"]["true_keyframes"]      # the same MMAE, clips, keyframes
    assert wdoc["reports"]["vae_keyframes"] != doc["reports"]["vae_keyframes"]        # another VAE
    assert "| generated |" not in capsys.readouterr().out
