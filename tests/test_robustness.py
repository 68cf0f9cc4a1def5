"""Bad input the issue lists that other test files do not cover: non-text prompts, prompts over the
encoder's limit, lengths that are not multiples of 4, a VAE and a denoiser that do not fit, truncated
or corrupt weight files, a dataset folder missing pieces (all through the ``salad`` command: one
line, exit status 2), and bit-identical results of two separate ``salad generate`` processes.

Covered elsewhere (see the report): empty prompts and missing weights (test_cli), the truncation
warning of the encoders (test_text), disk full during a checkpoint and SIGINT-then-resume
(test_train), dataset errors of the loader itself (test_data), unknown skeleton names (test_skeleton).
"""
from __future__ import annotations

import json
import re
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from salad_core import cli


@pytest.fixture(scope="module")
def tiny_pipe(make_tiny_pipeline):
    return make_tiny_pipeline(seed=0)


@pytest.fixture(scope="module")
def tiny_weights(tiny_pipe, tmp_path_factory):
    return tiny_pipe.save_pretrained(tmp_path_factory.mktemp("weights"))


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


# ----------------------------------------------------------------------------- prompts
@pytest.mark.parametrize("prompts, message", [
    (123, "prompts must be a string or a list of strings, got int"),
    (b"a person walks", "prompts must be a string or a list of strings, got bytes"),
    (["a person walks", None], "prompt 1 must be a string, got NoneType"),
    (["a person walks", 3.5], "prompt 1 must be a string, got float"),
    ([["a person walks"]], "prompt 0 must be a string, got list"),
])
def test_non_text_prompts_are_refused_by_generate_edit_and_invert(tiny_pipe, sample_features, prompts, message):
    from salad_core.attention import Mirror

    with pytest.raises(TypeError, match=message):
        tiny_pipe(prompts, lengths=8, num_steps=1)
    with pytest.raises(TypeError, match=message):
        tiny_pipe.edit(prompts, edits=[Mirror()], lengths=8, num_steps=1)
    with pytest.raises(TypeError, match=message):
        tiny_pipe.invert([sample_features[:8]] * (len(prompts) if isinstance(prompts, list) else 1), prompts,
                         num_steps=1)
    with pytest.raises(TypeError, match=message):
        tiny_pipe.edit("a person walks", target=prompts, edits=[Mirror()], lengths=8, num_steps=1)


def test_prompt_over_the_encoder_limit_warns_naming_the_dropped_words(tiny_weights, tmp_path, capsys):
    """MiniLM keeps 512 tokens: the CLI generates from the kept part and the warning (one line, no
    source line) names the rest."""
    prompt = "a person walks " * 200 + "and finally jumps"
    out = tmp_path / "long"
    code = cli.main(["-q", "generate", prompt, "--length", "16", "--steps", "1", "--weights", str(tiny_weights),
                     "--out", str(out), "--no-render", "--no-attention"])
    assert code == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("salad generate: warning: ")
    assert re.search(r"over the minilm limit of 512.*dropping the words: .*and finally jumps", err[0])
    (features,) = out.glob("*_features.npy")
    assert np.load(features).shape == (16, 263)
    # the file name is cut at a word boundary
    assert features.name == "00_a_person_walks_a_person_walks_a_person_features.npy"


def test_length_not_a_multiple_of_4_is_floored_with_one_note(tiny_weights, tmp_path, capsys):
    out = tmp_path / "len"
    code = cli.main(["-q", "generate", "a person walks", "--length", "42", "--steps", "1", "--weights",
                     str(tiny_weights), "--out", str(out), "--no-render", "--no-attention"])
    assert capsys.readouterr().err.strip() == ("salad generate: note: --length 42 is not a multiple of 4; "
                                               "generating 40 frames")
    assert code == 0 and np.load(out / "00_a_person_walks_features.npy").shape == (40, 263)


# ----------------------------------------------------------------------------- weights
def test_vae_and_denoiser_that_do_not_fit_are_refused(tiny_pipe):
    from salad_core.models import Denoiser, DenoiserConfig
    from salad_core.pipeline import SaladPipeline

    small = Denoiser(DenoiserConfig(width=32, heads=2, ff_dim=64, layers=3, text_dim=384, latent_dim=16))
    with pytest.raises(ValueError, match=r"do not fit together: VAE latent \(P=7, Dz=32\) vs denoiser \(P=7, Dz=16\)"):
        SaladPipeline(tiny_pipe.vae, small, tiny_pipe.text_encoder, tiny_pipe.mean, tiny_pipe.std)
    clip_sized = Denoiser(DenoiserConfig(width=32, heads=2, ff_dim=64, layers=3, text_dim=512))
    with pytest.raises(ValueError, match="text encoder gives 384-d features; the denoiser expects 512-d"):
        SaladPipeline(tiny_pipe.vae, clip_sized, tiny_pipe.text_encoder, tiny_pipe.mean, tiny_pipe.std)


def _swap_denoiser(root: Path, **changes) -> None:
    from salad_core.io import save_checkpoint
    from salad_core.models import Denoiser, DenoiserConfig

    cfg = DenoiserConfig(**{**dict(width=32, heads=2, ff_dim=64, layers=3, text_dim=384), **changes})
    save_checkpoint(root / "denoiser", Denoiser(cfg), model_type="denoiser", config=cfg)


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


@pytest.mark.parametrize("damage, message", [
    (lambda r: _swap_denoiser(r, latent_dim=16), "the VAE and the denoiser do not fit together"),
    (lambda r: _swap_denoiser(r, num_parts=1), "VAE latent (P=7, Dz=32) vs denoiser (P=1, Dz=32)"),
    (lambda r: _swap_denoiser(r, text_dim=512), "the denoiser expects 512-d"),
    (lambda r: _truncate(r / "vae.safetensors"), "vae.safetensors (truncated or corrupt?)"),
    (lambda r: _truncate(r / "denoiser.safetensors"), "denoiser.safetensors (truncated or corrupt?)"),
    (lambda r: (r / "stats.safetensors").write_bytes(os.urandom(64)), "stats.safetensors (truncated or corrupt?)"),
    (lambda r: (r / "stats.safetensors").unlink(), "weight file not found"),
    (lambda r: (r / "denoiser.json").write_text("{not json"), "denoiser.json is not valid JSON"),
    (lambda r: (r / "pipeline.json").write_text('{"vae": "vae",'), "pipeline.json is not valid JSON"),
])
def test_damaged_weights_folder_is_a_one_line_error(tiny_weights, tmp_path, capsys, damage, message):
    root = Path(shutil.copytree(tiny_weights, tmp_path / "weights"))
    damage(root)
    code = cli.main(["-q", "generate", "a person walks", "--length", "16", "--steps", "1", "--weights", str(root),
                     "--out", str(tmp_path / "out"), "--no-render"])
    err = _one_line_error(capsys)
    assert code == 2 and err.startswith("salad generate: error: ") and message in err
    assert not list((tmp_path / "out").glob("*.npy"))


# ----------------------------------------------------------------------------- dataset folders
@pytest.fixture
def data_dir(tmp_path, sample_dir) -> Path:
    """The smallest VAE training folder: one clip, its split file, Mean.npy and Std.npy."""
    root = tmp_path / "data"
    (root / "new_joint_vecs").mkdir(parents=True)
    shutil.copy(sample_dir / "new_joint_vecs" / "012314.npy", root / "new_joint_vecs" / "A.npy")
    (root / "train.txt").write_text("A\n")
    for name in ("Mean.npy", "Std.npy"):
        shutil.copy(sample_dir / name, root / name)
    return root


@pytest.mark.parametrize("damage, message", [
    (lambda r: (r / "Mean.npy").unlink(), "Mean.npy not found: looked for"),
    (lambda r: (r / "Std.npy").unlink(), "Std.npy not found: looked for"),
    (lambda r: np.save(r / "Std.npy", np.zeros(263, np.float32)), "Std.npy has non-positive entries"),
    (lambda r: np.save(r / "Mean.npy", np.zeros(251, np.float32)), "skeleton 'humanml3d' expects (263,)"),
    (lambda r: (r / "train.txt").unlink(), "train.txt"),
    (lambda r: shutil.rmtree(r / "new_joint_vecs"), "motion folder not found"),
    (lambda r: (r / "train.txt").write_text("A\nB\n"), "split id 'B' has no motion file"),
    (lambda r: shutil.rmtree(r), "does not exist"),
])
def test_dataset_folder_missing_pieces_is_a_one_line_error(data_dir, tmp_path, capsys, damage, message):
    damage(data_dir)
    config = tmp_path / "train.json"   # if a case ever got through, it would train one tiny step on one thread
    config.write_text(json.dumps({"batch_size": 1, "max_steps": 1, "window": 8, "num_threads": 1,
                                  "val_every": 0, "progress": False}))
    code = cli.main(["-q", "train", "vae", "--data", str(data_dir), "--out", str(tmp_path / "run"),
                     "--config", str(config)])
    err = _one_line_error(capsys)
    assert code == 2 and err.startswith("salad train: error: ") and message in err


# ----------------------------------------------------------------------------- determinism across processes
def test_same_seed_gives_identical_files_in_two_separate_processes(tiny_weights, tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1",
           "TRANSFORMERS_OFFLINE": "1"}
    outs = []
    for run in ("a", "b"):
        out = tmp_path / run
        proc = subprocess.run([sys.executable, "-m", "salad_core.cli", "-q", "generate", "a man jumps high",
                               "a person walks", "--length", "40", "--steps", "4", "--seed", "7", "--weights",
                               str(tiny_weights), "--out", str(out), "--no-render", "--no-attention"],
                              env=env, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0, proc.stderr
        outs.append(out)
    names = sorted(p.name for p in outs[0].glob("*.npy"))
    assert len(names) == 4                      # features and joints of both prompts
    for name in names:
        assert (outs[0] / name).read_bytes() == (outs[1] / name).read_bytes(), name
    first = np.load(outs[0] / "00_a_man_jumps_high_features.npy")
    assert first.shape == (40, 263) and np.abs(first).sum() > 0
