"""What issue 70 left after salad_core.limits: long batches and the files a weight folder or a run names.

* ``salad generate`` with more prompts than :data:`salad_core.limits.PROMPT_CHUNK` says how many and roughly how
  long (measured on the first chunk), shows a bar over the chunks, and writes the motions a single call gives;
* KeyMotion batches larger than the chunk size are denoised in chunks whose motions equal one piece (DDIM);
* ``salad train --config`` is read with the JSON limits and checked against the training config's schema;
* ``vocabulary.json`` and an ablation ``index.json``'s ``"stats"`` stay inside their folder unless allowed.

Tiny models everywhere (the SALAD test pipeline, a KeyMotion of a few thousand weights, a hashing text encoder):
seconds per test. The chunk sizes are monkeypatched small so that a batch of five prompts has three chunks.
"""
from __future__ import annotations

import json
import logging
import re
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from salad_core import cli, limits
from salad_core.cli import _common
from salad_core.cli import train as train_cli

pytestmark = pytest.mark.usefixtures("single_thread")

PROMPTS = ["a person walks forward", "a man jumps", "someone waves his left hand", "a person sits down",
           "a woman turns around"]


# =============================================================================================== the estimate
def test_the_estimate_line_reads_like_the_issue_asks():
    assert _common.batch_estimate(120, 32, 35.2) == \
        "generating 120 motions (about 2 min at 1.1 s each, measured on the first chunk)"
    assert _common.batch_estimate(1000, 32, 3200) == \
        "generating 1,000 motions (about 27.8 h at 100 s each, measured on the first chunk)"
    assert _common.batch_estimate(70, 32, 0.3).startswith("generating 70 motions (about 1 s at 0.01 s each")
    assert [_common.human_duration(s) for s in (0.2, 45, 120, 5400)] == ["1 s", "45 s", "2 min", "1.5 h"]


def test_batch_chunks_reports_once_after_the_first_chunk_and_draws_a_bar(capsys):
    said, seen = [], []
    for rows in _common.batch_chunks(10, 4, progress=True, report=said.append):
        seen.append((rows.start, rows.stop, len(said)))
    assert seen == [(0, 4, 0), (4, 8, 1), (8, 10, 1)]         # said between the first and the second chunk
    assert len(said) == 1 and said[0].startswith("generating 10 motions (about ")
    assert "motions (4 per chunk)" in capsys.readouterr().err
    said.clear()
    assert [r.stop for r in _common.batch_chunks(3, 4, progress=True, report=said.append)] == [3]
    assert said == [] and capsys.readouterr().err == ""       # one chunk: nothing to estimate, no bar


# =============================================================================================== salad generate
@pytest.fixture(scope="module")
def tiny_weights(make_tiny_pipeline, tmp_path_factory):
    pipe = make_tiny_pipeline(seed=0)
    pipe.recovery = "positions"         # the skeleton fit is not what is measured here
    return pipe.save_pretrained(tmp_path_factory.mktemp("weights"))


def _generate(weights: Path, out: Path, *extra: str) -> int:
    return cli.main(["generate", *PROMPTS, "--length", "8", "--steps", "1", "--no-render", "--no-attention",
                     "--weights", str(weights), "--out", str(out), *extra])


def test_a_long_generate_says_how_many_and_how_long_and_writes_what_one_call_writes(tiny_weights, tmp_path,
                                                                                    capsys, monkeypatch):
    from salad_core.pipeline import SaladPipeline

    monkeypatch.setattr(limits, "PROMPT_CHUNK", 100)                  # first: the batch in one call
    assert _generate(tiny_weights, tmp_path / "one") == 0
    one = capsys.readouterr()
    assert "generating" not in one.out and "per chunk" not in one.err

    monkeypatch.setattr(limits, "PROMPT_CHUNK", 2)                    # then: five prompts in chunks of two
    monkeypatch.setattr(SaladPipeline, "max_batch", 2)
    assert _generate(tiny_weights, tmp_path / "chunks") == 0
    got = capsys.readouterr()
    lines = [line for line in got.out.splitlines() if "frames):" in line or line.startswith("generating")]
    estimate = [i for i, line in enumerate(lines) if line.startswith("generating")]
    assert len(estimate) == 1 and estimate[0] == 2, lines     # after the first chunk's two motions
    assert re.fullmatch(r"generating 5 motions \(about \d+ (s|min) at [\d.]+ s each, measured on the first "
                        r"chunk\)", lines[2]), lines[2]
    assert len(lines) == 6 and "motions (2 per chunk)" in got.err
    for b, prompt in enumerate(PROMPTS):         # prompt b keeps seed 0 + b whichever chunk it is in
        name = f"{b:02d}_{_common._slug(prompt)}_features.npy"
        np.testing.assert_allclose(np.load(tmp_path / "chunks" / name), np.load(tmp_path / "one" / name),
                                   atol=1e-5, err_msg=name)


def test_quiet_long_generate_prints_no_estimate_and_no_bar(tiny_weights, tmp_path, capsys, monkeypatch):
    from salad_core.pipeline import SaladPipeline

    monkeypatch.setattr(limits, "PROMPT_CHUNK", 2)
    monkeypatch.setattr(SaladPipeline, "max_batch", 2)
    assert cli.main(["-q", "generate", *PROMPTS[:3], "--length", "8", "--steps", "1", "--no-render",
                     "--no-attention", "--weights", str(tiny_weights), "--out", str(tmp_path / "q")]) == 0
    got = capsys.readouterr()
    assert "generating" not in got.out and "per chunk" not in got.err
    assert len(list((tmp_path / "q").glob("*_features.npy"))) == 3


# =============================================================================================== KeyMotion
def _tiny_keymotion(seed: int = 0, solver: str = "ddim"):
    from _doubles import tiny_keymotion

    pipe = tiny_keymotion(seed, solver=solver, recovery="positions")
    pipe.side_check = False             # the comparison is about the sampler, not the mirror check
    return pipe


@pytest.fixture(scope="module")
def keymotion():
    return _tiny_keymotion()


def test_a_keymotion_batch_over_the_chunk_size_equals_one_piece(keymotion, monkeypatch, capsys, caplog):
    lengths = [40, 48, 40, 56, 44]                 # chunks of different longest lengths, padded back together
    monkeypatch.setattr(limits, "PROMPT_CHUNK", 100)
    whole = keymotion(PROMPTS, lengths=lengths, seed=3, num_steps=4, guidance_scale=2.0)
    monkeypatch.setattr(limits, "PROMPT_CHUNK", 2)
    assert keymotion.chunk_size() == 2
    with caplog.at_level(logging.INFO, logger="salad_core.keymotion.pipeline"):
        chunked = keymotion(PROMPTS, lengths=lengths, seed=3, num_steps=4, guidance_scale=2.0, progress=True)
    assert "generating 5 motions in chunks of 2" in caplog.text
    assert "motions (2 per chunk)" in capsys.readouterr().err
    assert chunked.features.shape == whole.features.shape == (5, 56, 263)
    np.testing.assert_allclose(chunked.latents, whole.latents, atol=1e-5)
    np.testing.assert_allclose(chunked.features, whole.features, atol=1e-5)
    np.testing.assert_array_equal(np.stack(chunked.keyframes), np.stack(whole.keyframes))
    for a, b in zip(chunked.joints, whole.joints):     # the root's path integrates the features' float32 noise
        np.testing.assert_allclose(a, b, atol=1e-4)     # over the frames: 0.1 mm (seen 4.5e-5 m on an AMD EPYC)
    assert not chunked.features[0, 40:].any() and not chunked.features[3, 56:].any()


def test_a_keymotion_motion_does_not_depend_on_its_chunk_neighbours(keymotion, monkeypatch):
    monkeypatch.setattr(keymotion, "max_batch", 1)
    one_by_one = keymotion(PROMPTS[:3], seed=5, num_steps=3)
    monkeypatch.setattr(keymotion, "max_batch", 3)
    together = keymotion(PROMPTS[:3], seed=5, num_steps=3)
    np.testing.assert_allclose(one_by_one.features, together.features, atol=1e-5)
    monkeypatch.setattr(keymotion, "max_batch", 0)
    with pytest.raises(ValueError, match="max_batch must be a positive int or None, got 0"):
        keymotion(PROMPTS[:3], num_steps=1)


def test_a_stochastic_solver_in_chunks_is_still_reproducible(monkeypatch):
    pipe = _tiny_keymotion(solver="ddpm")
    monkeypatch.setattr(limits, "PROMPT_CHUNK", 2)
    a = pipe(PROMPTS, seed=1, num_steps=3)
    b = pipe(PROMPTS, seed=1, num_steps=3)
    np.testing.assert_array_equal(a.features, b.features)     # same call, seed and chunk size: same motions


# =============================================================================================== salad train --config
def _train_fails(argv: list[str], capsys, out: Path, message: str) -> str:
    code = cli.main(["-q", "train", *argv, "--out", str(out)])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("salad train: error: ") and message in lines[0], lines[0]
    assert not out.exists()
    return lines[0]


@pytest.mark.parametrize("doc, message", [
    ({"train": {"lrr": 1e-3}}, "'train': unknown key 'lrr' (did you mean 'lr'?); known keys: "),
    ({"batch_sise": 8}, "unknown key 'batch_sise' (did you mean 'batch_size'?)"),
    ({"trian": {"lr": 1e-3}}, "unknown key 'trian' (did you mean 'train'?)"),
    ({"train": {"lr": "fast"}}, "'train': 'lr' must be a number, got a string \"fast\""),
    ({"train": {"batch_size": 8}, "model": {"latent_dim": 10 ** 10}},
     "'model': 'latent_dim' = 10000000000 is out of range (at most 1,000,000 in magnitude)"),
    ({"train": {"batch_size": 8}, "model": {"n_layers": 100000}}, "'model': 'n_layers' = 100000 is out of range"),
    ({"train": [8]}, "'train' must be an object {...}, got an array [8]"),
    ({"train": {}, "task": {"vae": 5}}, "'task': 'vae' must be a string, got an integer 5"),
])
def test_a_training_config_is_checked_against_its_schema(doc, message, sample_dir, tmp_path, capsys):
    config = tmp_path / "conf.json"
    config.write_text(json.dumps(doc))
    line = _train_fails(["vae", "--config", str(config), "--data", str(sample_dir)], capsys, tmp_path / "run",
                        message)
    assert f"--config {config}" in line


def test_denoiser_and_keymotion_configs_name_their_sections(sample_dir, tmp_path, capsys):
    config = tmp_path / "conf.json"
    cases = [("denoiser", {"train": {"cond_drop_prob": 0.1}, "model": {"max_len": 10 ** 10}},
              "'model': 'max_len' = 10000000000 is out of range"),
             ("denoiser", {"train": {}, "diffusion": {"num_train_timestep": 10}},
              "'diffusion': unknown key 'num_train_timestep' (did you mean 'num_train_timesteps'?)"),
             ("keymotion", {"pst": {"train": {"lr": 1e-4}, "modle": {}}},
              "'pst': unknown key 'modle' (did you mean 'model'?)"),
             ("keymotion", {"mmae": {"train": {"max_step": 5}}},
              "'mmae': 'train': unknown key 'max_step' (did you mean 'max_steps'?)"),
             ("keymotion", {"kf_vae": 3}, "'kf_vae' must be an object {...} or null, got an integer 3")]
    for what, doc, message in cases:
        config.write_text(json.dumps(doc))
        _train_fails([what, "--config", str(config), "--data", str(sample_dir)], capsys, tmp_path / "run", message)


def test_a_config_file_that_is_no_json_document_says_why(sample_dir, tmp_path, capsys):
    config = tmp_path / "deep.json"
    config.write_text("[" * 100_000 + "]" * 100_000)
    _train_fails(["vae", "--config", str(config), "--data", str(sample_dir)], capsys, tmp_path / "run",
                 f"--config {config} is not a JSON document (it nests 100000 levels deep; at most 64 are read)")
    config.write_text("[1, 2]")
    _train_fails(["vae", "--config", str(config), "--data", str(sample_dir)], capsys, tmp_path / "run",
                 f"--config {config} is not a JSON document (it holds an array, not an object {{...}})")
    _train_fails(["keymotion", "--config", str(tmp_path / "missing.json"), "--data", str(sample_dir)], capsys,
                 tmp_path / "run", f"--config {tmp_path / 'missing.json'}: no such file")


def test_the_trainer_entry_point_itself_says_it_in_one_line(sample_dir, tmp_path, capsys):
    config = tmp_path / "conf.json"
    config.write_text(json.dumps({"train": {"guidence": 2}}))
    out = tmp_path / "run"
    assert train_cli.main(["vae", "--data", str(sample_dir), "--out", str(out), "--config", str(config)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"salad train: error: --config {config}: 'train': unknown key")
    assert not out.exists()


@pytest.mark.parametrize("path, what", [("configs/salad-0.3/vae.json", "vae"),
                                        ("configs/salad-0.3/denoiser.json", "denoiser"),
                                        ("configs/general-vae.json", "vae"),
                                        ("configs/keymotion-0.2.json", "keymotion")])
def test_the_shipped_training_configs_pass_the_schema(path, what):
    root = Path(__file__).resolve().parents[1]
    train_cli.check_config_doc(json.loads((root / path).read_text()), what, path)


# =============================================================================================== folders' own files
def test_a_vocabulary_that_links_out_of_the_folder_is_refused_unless_allowed(tmp_path, caplog):
    from salad_core.vocabulary import load_vocabulary, vocabulary_and_source, write_vocabulary

    outside = write_vocabulary(["walk", "jump"], tmp_path / "elsewhere")
    root = tmp_path / "weights"
    root.mkdir()
    (root / "vocabulary.json").symlink_to(outside)
    with pytest.raises(ValueError) as err:
        load_vocabulary(root)
    assert (f"'vocabulary.json' = \"vocabulary.json\" leads (through a symbolic link or the folder's own name) to "
            f"{outside.resolve()}, outside the weights folder {root.resolve()}") in str(err.value)
    with caplog.at_level(logging.WARNING, logger="salad_core.vocabulary"):
        assert vocabulary_and_source(root) == (None, None)       # the weights still load, without it
    assert "outside the weights folder" in caplog.text and "unknown words will not be reported" in caplog.text
    assert load_vocabulary(root, allow_outside_paths=True) == {"walk", "jump"}
    assert load_vocabulary(root, allow_outside_paths=tmp_path / "elsewhere") == {"walk", "jump"}


def test_keymotion_reads_a_linked_vocabulary_only_when_allowed(keymotion, tmp_path):
    from salad_core.keymotion.pipeline import KeyMotionPipeline
    from salad_core.vocabulary import write_vocabulary

    root = keymotion.save_pretrained(tmp_path / "km")
    outside = write_vocabulary(["walk"], tmp_path / "elsewhere")
    (root / "vocabulary.json").symlink_to(outside)
    enc = keymotion.text_encoder
    assert KeyMotionPipeline.from_pretrained(root, text_encoder=enc).vocabulary is None
    assert KeyMotionPipeline.from_pretrained(root, text_encoder=enc, allow_outside_paths=True).vocabulary == {"walk"}


@pytest.fixture()
def ablation_root(tmp_path):
    """A one-VAE ablation folder made from the shipped one (skipped when the shipped weights are missing)."""
    from salad_core.ablation_models import ablations_dir

    src = ablations_dir()
    if not (src / "vae_st_long" / "vae.json").is_file():
        pytest.skip("the shipped ablation weights are not installed")
    root = tmp_path / "ablations"
    shutil.copytree(src / "vae_st_long", root / "vae_x")
    (root / "index.json").write_text(json.dumps({"vae_x": {"kind": "vae", "variant": "x"}}))
    return root


def test_an_ablation_index_stats_path_stays_inside_unless_allowed(ablation_root, tmp_path):
    from salad_core.ablation_models import load_ablation_vae

    vae, mean, std = load_ablation_vae("x", ablation_root)           # the folder's own statistics
    assert mean.shape == std.shape == (263,)
    outside = tmp_path / "outside"
    outside.mkdir()
    shutil.move(ablation_root / "vae_x" / "stats.safetensors", outside / "stats.safetensors")
    index = ablation_root / "index.json"
    for value, how in (("../outside/stats.safetensors", "climbs out with '..'"),
                       (str(outside / "stats.safetensors"), "is an absolute path")):
        index.write_text(json.dumps({"vae_x": {"kind": "vae", "variant": "x", "stats": value}}))
        with pytest.raises(ValueError) as err:
            load_ablation_vae("x", ablation_root)
        assert (f"{index}: 'vae_x': 'stats' = \"{value}\" {how} to {(outside / 'stats.safetensors').resolve()}, "
                "outside the weights folder") in str(err.value)
        _, mean2, _ = load_ablation_vae("x", ablation_root, allow_outside_paths=True)
        np.testing.assert_array_equal(mean2, mean)


def test_an_ablation_index_of_the_wrong_shape_is_named(ablation_root):
    from salad_core.ablation_models import list_ablations, load_ablation_vae

    index = ablation_root / "index.json"
    index.write_text(json.dumps({"vae_x": ["vae"]}))
    with pytest.raises(TypeError, match=re.escape(f"{index}: entry 'vae_x' must be an object {{...}}")):
        list_ablations(ablation_root)
    index.write_text("{" * 1000 + "}" * 1000)
    with pytest.raises(ValueError, match="the ablation index nests 1000 levels deep; at most 64 are read"):
        list_ablations(ablation_root)
    index.write_text(json.dumps({"vae_x": {"kind": "vae", "variant": "x", "stats": 5}}))
    with pytest.raises(TypeError, match="'stats' must be a non-empty path string relative to the folder"):
        load_ablation_vae("x", ablation_root)


def test_a_long_keymotion_generate_says_how_many_and_how_long(tmp_path, capsys, monkeypatch):
    """``salad generate --keymotion`` with more prompts than ``PROMPT_CHUNK`` says how many motions and roughly how
    long after the first one, and writes the motions one call per prompt would (seed SEED + b)."""
    monkeypatch.setattr(limits, "PROMPT_CHUNK", 2)
    prompts = ["a person walks forward", "a man waves his right hand", "a person jumps"]
    out = tmp_path / "km"
    assert cli.main(["generate", *prompts, "--keymotion", "--length", "40", "--steps", "2", "--seed", "4",
                     "--no-render", "--out", str(out)]) == 0
    got = capsys.readouterr()
    estimate = [line for line in got.out.splitlines() if line.startswith("generating")]
    assert len(estimate) == 1 and re.fullmatch(r"generating 3 motions \(about \d+ (s|min) at [\d.]+ s each, "
                                               r"measured on the first chunk\)", estimate[0]), got.out
    assert len(list(out.glob("*_features.npy"))) == 3
