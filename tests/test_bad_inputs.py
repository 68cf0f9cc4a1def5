"""A catalogue of bad inputs (issues 25 and 28), each with the one line the user gets.

Command line: every bad call exits 2 with one line ``salad <cmd>: error: ...`` naming the problem,
leaves no file or folder behind, and bad sampling arguments are refused before any weights load
(``salad_core.cli.generate._load_pipeline`` is replaced by a function that fails the test). Python API: the error type and
message, or the warning, of each case.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch

from salad_core import cli
from salad_core.cli import _common, generate

SAMPLE = "tests/data/humanml3d_sample"


@pytest.fixture(scope="module")
def tiny_pipe(make_tiny_pipeline):
    return make_tiny_pipeline(seed=0)


@pytest.fixture(scope="module")
def tiny_weights(tiny_pipe, tmp_path_factory):
    return tiny_pipe.save_pretrained(tmp_path_factory.mktemp("weights"))


@pytest.fixture(scope="module")
def features(sample_dir):
    return np.load(sample_dir / "new_joint_vecs" / "012314.npy")[:40]


@pytest.fixture()
def no_weights(monkeypatch):
    """Fail the test if the command loads weights."""
    def refuse(weights):
        raise AssertionError("weights were loaded before the arguments were checked")
    monkeypatch.setattr(generate, "_load_pipeline", refuse)   # demo, generate, edit, invert


def _fails_cleanly(argv, capsys, out, message) -> str:
    code = cli.main(["-q", *argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert code == 2, err
    assert len(lines) == 1 and "Traceback" not in err and "weights were loaded" not in err, err
    assert message in lines[0], lines[0]
    assert not out.exists(), f"{out} was left behind: {sorted(p.name for p in out.rglob('*'))}"
    return lines[0]


# ----------------------------------------------------------------------------- CLI, before weights load
GENERATE = ["generate", "a person walks", "--length", "16", "--steps", "2", "--no-render"]


@pytest.mark.parametrize("extra, message", [
    (["--length", "0"], "--length 0 frames is out of range; allowed: 4..196"),
    (["--length", "-4"], "--length -4 frames is out of range; allowed: 4..196"),
    (["--length", "400"], "--length 400 frames is out of range; allowed: 4..196"),
    (["--steps", "0"], "--steps 0: allowed 1..1000"),
    (["--steps", "5000"], "--steps 5000: allowed 1..1000"),
    (["--solver", "plms"], "--solver 'plms' is unknown; allowed: ddim, ddpm, dpm++"),
    (["--seed", "99999999999999999999999"], "--seed 99999999999999999999999 is out of range"),
    (["--guidance", "1e30"], "--guidance 1e+30 is out of range; allowed: -100..100"),
    (["--guidance", "nan"], "--guidance must be a finite number"),
])
def test_generate_refuses_bad_arguments_before_loading_weights(extra, message, tmp_path, capsys, no_weights):
    out = tmp_path / "gen"
    _fails_cleanly([*GENERATE, *extra, "--out", str(out)], capsys, out, message)


def test_a_seed_that_overflows_for_a_later_prompt_is_refused(tmp_path, capsys, no_weights):
    out = tmp_path / "gen"
    line = _fails_cleanly(["generate", "a", "b", "--seed", str(2 ** 64 - 1), "--out", str(out)], capsys, out,
                          f"--seed {2 ** 64 - 1} is out of range")
    assert "prompt b uses seed + b" in line


@pytest.mark.parametrize("extra, message", [
    (["--swap", "0.8"], "--swap needs --target, a prompt that differs from the source"),
    (["--swap", "0.8", "--target", "A person   walks"], "--swap needs --target"),
    (["--refine"], "--refine needs --target"),
    ([], "give at least one edit"),
    (["--mirror", "legs", "--steps", "0"], "--steps 0: allowed 1..1000"),
])
def test_edits_that_do_nothing_are_refused_before_loading_weights(extra, message, tmp_path, capsys, no_weights):
    out = tmp_path / "edit"
    _fails_cleanly(["edit", "a person walks", *extra, "--out", str(out)], capsys, out, message)


def test_invert_checks_its_arguments_and_the_motion_before_loading_weights(features, tmp_path, capsys, no_weights):
    huge = tmp_path / "huge.npy"
    np.save(huge, features * 1e30)
    out = tmp_path / "inv"
    _fails_cleanly(["invert", str(huge), "--prompt", "a person walks", "--out", str(out)], capsys, out,
                   "reach |value| = 1.94e+30, beyond 10000: not HumanML3D features")
    ok = tmp_path / "ok.npy"
    np.save(ok, features)
    _fails_cleanly(["invert", str(ok), "--prompt", "a person walks", "--swap", "0.8", "--out", str(out)], capsys,
                   out, "--swap needs --target")
    _fails_cleanly(["invert", str(ok), "--prompt", "a person walks", "--guidance=-1e9", "--out", str(out)],
                   capsys, out, "--guidance -1e+09 is out of range")


def test_render_size_is_limited_before_anything_is_created(sample_dir, tmp_path, capsys):
    out = tmp_path / "r"
    motion = str(sample_dir / "new_joints" / "012314.npy")
    for size in ("100000", "20000", "4"):
        _fails_cleanly(["render", motion, "--size", size, "--out", str(out)], capsys, out,
                       f"--size {size}: allowed 8..4096 pixels")


def test_export_of_zero_joints_names_the_zero_length_bones_and_leaves_nothing(tmp_path, capsys):
    zeros = tmp_path / "zero_joints.npy"
    np.save(zeros, np.zeros((40, 22, 3), np.float32))
    out = tmp_path / "exports" / "deeper"
    _fails_cleanly(["export", str(zeros), "--format", "bvh", "--out", str(out)], capsys, out,
                   "joints: 21 bone(s) have zero length (pelvis->left_hip")
    assert not (tmp_path / "exports").exists()     # the parent it created is gone too


@pytest.mark.parametrize("array, message", [
    (np.zeros((40, 263), np.complex64), "does not hold a numeric array (got complex64)"),
    (np.array([["1.0"] * 263] * 8), "does not hold a numeric array (got <U3)"),
])
def test_complex_and_string_motion_files_are_refused(array, message, tmp_path, capsys):
    path = tmp_path / "odd.npy"
    np.save(path, array)
    out = tmp_path / "r"
    _fails_cleanly(["render", str(path), "--out", str(out)], capsys, out, message)


def test_corpus_check_of_a_folder_that_is_not_a_corpus(tmp_path, capsys):
    (tmp_path / "stuff").mkdir()
    for target, message in ((tmp_path / "stuff", "is not a corpus folder (no all.txt, new_joint_vecs, texts)"),
                            (tmp_path / "nowhere", "is not a corpus folder (no such folder)")):
        code = cli.main(["-q", "corpus", "check", "--out", str(target)])
        err = capsys.readouterr().err.strip()
        assert code == 2 and message in err and "salad corpus build --out" in err and len(err.splitlines()) == 1


# ----------------------------------------------------------------------------- CLI, with (tiny) weights
def test_generate_checks_every_output_name_before_writing_any(tiny_weights, tmp_path, capsys):
    out = tmp_path / "d"
    out.mkdir()
    (out / "01_b_features.npy").write_bytes(b"B's earlier file")
    code = cli.main(["-q", "generate", "a", "b", "--length", "8", "--steps", "1", "--no-render", "--weights",
                     str(tiny_weights), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "already holds 01_b_features.npy" in err
    assert sorted(p.name for p in out.iterdir()) == ["01_b_features.npy"]      # nothing of A was written


def test_a_failure_after_writing_removes_what_the_call_wrote(tiny_weights, tmp_path, capsys, monkeypatch):
    import salad_viz

    def broken(*a, **k):
        raise RuntimeError("disk on fire")
    monkeypatch.setattr(salad_viz, "export_bvh", broken)
    out = tmp_path / "new" / "gen"
    code = cli.main(["-q", "generate", "a person walks", "--length", "8", "--steps", "1", "--no-render",
                     "--no-attention", "--weights", str(tiny_weights), "--out", str(out)])
    assert code == 2 and "disk on fire" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_a_prompt_without_words_gets_a_warning_and_no_attention_figure(tiny_weights, tmp_path, capsys):
    out = tmp_path / "g"
    code = cli.main(["-q", "generate", "🕺💃🤸", "a person walks forward and walks forward", "--length", "8",
                     "--steps", "1", "--no-render", "--weights", str(tiny_weights), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 0
    assert err == ["salad generate: warning: prompt 0 '🕺💃🤸' has no words: no attention figure for it"]
    names = sorted(p.name for p in out.iterdir())
    assert "00_motion_features.npy" in names and not any(n.startswith("00_") and "attention" in n for n in names)
    # every other prompt gets its own figure (not only the first)
    assert "01_a_person_walks_forward_and_walks_forward_attention.png" in names


def test_negative_guidance_runs_with_one_warning_line(tiny_weights, tmp_path, capsys):
    out = tmp_path / "g"
    code = cli.main(["-q", "generate", "a person walks", "--guidance", "-5", "--length", "8", "--steps", "1",
                     "--no-render", "--no-attention", "--weights", str(tiny_weights), "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 0 and err == ["salad generate: warning: --guidance -5 is negative: the motion is steered away "
                                 "from the prompt (1 = no guidance, 7.5 = the paper's)"]


def test_slug_cuts_file_names_at_word_boundaries():
    assert _common._slug("a man jumps forward and then walks forward, while waving") == \
        "a_man_jumps_forward_and_then_walks"
    assert len(_common._slug("word " * 30)) <= 40 and not _common._slug("word " * 30).endswith("_")
    assert _common._slug("x" * 60) == "x" * 40 and _common._slug("!!! ???") == "motion"


# ----------------------------------------------------------------------------- Python API
@pytest.mark.parametrize("kwargs, error, message", [
    (dict(solver=3), TypeError, "solver must be a solver name .* got int 3"),
    (dict(solver=""), ValueError, "solver='' is unknown; allowed: ddim"),
    (dict(guidance_scale="7.5"), TypeError, "guidance_scale must be a number .* got str '7.5'"),
    (dict(guidance_scale=1e30), ValueError, "guidance_scale=1e\\+30 is out of range; allowed: -100..100"),
    (dict(seed=2 ** 64), ValueError, "seed 18446744073709551616 is out of range"),
    (dict(num_steps=5000), ValueError, "num_steps=5000 is more than the 1000 diffusion timesteps"),
    (dict(lengths=-4), ValueError, "^length = -4 frames is out of range; allowed: 4..196"),
])
def test_pipeline_call_refuses(tiny_pipe, kwargs, error, message):
    call = dict(lengths=8, num_steps=1) | kwargs
    with pytest.raises(error, match=message):
        tiny_pipe("a person walks", **call)


def test_pipeline_lengths_name_the_entry_only_for_several(tiny_pipe):
    with pytest.raises(ValueError, match=r"^lengths\[1\] = 0 frames is out of range"):
        tiny_pipe(["a", "b"], lengths=[8, 0], num_steps=1)


def test_negative_guidance_warns(tiny_pipe):
    with pytest.warns(UserWarning, match="guidance_scale=-50 is negative"):
        tiny_pipe("a person walks", lengths=8, num_steps=1, guidance_scale=-50)


def test_edit_refusals_and_warnings(tiny_pipe):
    from salad_core.attention import Mirror, Refine, WordSwap

    with pytest.raises(TypeError, match="inversion must be the Inversion that pipe.invert"):
        tiny_pipe.edit("a person walks", edits=[Mirror()], inversion="x")
    with pytest.raises(TypeError, match="solver must be a solver name"):
        tiny_pipe.edit("a person walks", edits=[Mirror()], solver=3, lengths=8, num_steps=1)
    with pytest.raises(ValueError, match="WordSwap needs a target prompt that differs from the source"):
        tiny_pipe.edit("a person walks", edits=[WordSwap(0.8)], lengths=8, num_steps=1)
    with pytest.warns(UserWarning, match="edits is empty and the target is the source"):
        tiny_pipe.edit("a person walks", edits=[], lengths=8, num_steps=1)
    with pytest.warns(UserWarning, match="shares no word with the source"):
        tiny_pipe.edit("a person walks", "someone jumps high", edits=[Refine()], lengths=8, num_steps=1)


@pytest.mark.parametrize("motion, error, message", [
    ("complex", TypeError, "motion 0 must hold real numbers, got dtype complex"),
    ("string", TypeError, "motion 0 must hold real numbers, got dtype <U"),
    ("huge", ValueError, "motion 0 reaches |value| = 1.94e\\+30, beyond 10000"),
])
def test_invert_refuses_complex_string_and_absurd_motions(tiny_pipe, features, motion, error, message):
    bad = {"complex": features.astype(np.complex64), "string": features.astype(str), "huge": features * 1e30}[motion]
    with warnings.catch_warnings():
        warnings.simplefilter("error")            # no ComplexWarning on the way
        with pytest.raises(error, match=message):
            tiny_pipe.invert(bad, "a person walks", num_steps=1)


def test_invert_warns_when_it_crops(tiny_pipe, sample_dir):
    f = np.load(sample_dir / "new_joint_vecs" / "012314.npy")[:42]
    with pytest.warns(UserWarning, match="motion 0 has 42 frames, not a multiple of 4; using the first 40"):
        inv = tiny_pipe.invert(f, "a person walks", num_steps=1, reconstruct=False)
    assert inv.lengths == [40]


def test_inversion_divergence_is_named(tiny_pipe):
    from salad_core.attention.inversion import invert_latents
    from salad_core.sampling import make_scheduler

    text, null = tiny_pipe.encode_text(["a person walks"])
    den = tiny_pipe.denoiser
    latents = torch.full((1, 2, *tiny_pipe.latent_shape), 1e30)
    with pytest.raises(ValueError, match=r"the inversion diverged at step 1 of 2 .* \|z\| = 1e\+30"):
        invert_latents(den, make_scheduler(tiny_pipe.diffusion, "ddim"), latents,
                       den.prepare_text(text.features, text.mask), den.prepare_text(null.features, null.mask),
                       method="fixed_point", guidance_scale=7.5, num_steps=2)


def test_motion_conversions_refuse_complex_string_absurd_and_collapsed(features):
    from salad_core.motion import features_to_joints

    with pytest.raises(ValueError, match=r"features reach \|value\| = 1.94e\+30, beyond 10000"):
        features_to_joints(features * 1e30)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TypeError, match="features must hold real numbers, got dtype complex64"):
            features_to_joints(features.astype(np.complex64))
        with pytest.raises(TypeError, match="features must hold real numbers, got a torch.complex64 tensor"):
            features_to_joints(torch.from_numpy(features.astype(np.complex64)))
        with pytest.raises(TypeError, match="features must hold real numbers, got dtype <U"):
            features_to_joints(features.astype(str))
    assert np.isfinite(features_to_joints(features)).all()       # the real sample passes


def test_viz_refuses_collapsed_joints_nan_fps_and_oversize_frames(sample_dir, tmp_path):
    from salad_viz import animate, export_bvh, render_frames

    joints = np.load(sample_dir / "new_joints" / "012314.npy")[:8]
    with pytest.raises(ValueError, match="21 bone\\(s\\) have zero length"):
        export_bvh(np.zeros((40, 22, 3)), "humanml3d", tmp_path / "z.bvh")
    with pytest.raises(ValueError, match="fps must be a positive finite number .* got nan"):
        export_bvh(joints, "humanml3d", tmp_path / "n.bvh", fps=float("nan"))
    with pytest.raises(ValueError, match="at most 4096x4096 pixels, got \\(100000, 100000\\)"):
        animate(joints, "humanml3d", tmp_path / "big.gif", size=(100000, 100000))
    with pytest.raises(ValueError, match="fps must be a positive finite number"):
        animate(joints, "humanml3d", tmp_path / "f.gif", fps=float("inf"))
    long = np.repeat(joints, 25, axis=0)                               # 200 frames
    with pytest.raises(ValueError, match="would need 9.4 GiB for 200 frames of 4096x4096"):
        render_frames(long, "humanml3d", size=(4096, 4096))
    with pytest.raises(TypeError, match="must hold real numbers, got dtype complex128"):
        animate(joints.astype(complex), "humanml3d", tmp_path / "c.gif")
    assert list(tmp_path.iterdir()) == []                              # nothing was created


def test_a_dataset_motion_that_is_really_a_text_file_is_named(features, tmp_path):
    from salad_core.data.dataset import MotionTextDataset

    root = tmp_path / "data"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    np.save(root / "new_joint_vecs" / "good.npy", features)
    (root / "new_joint_vecs" / "bad.npy").write_text("0.1 0.2 0.3\n")
    for name in ("good", "bad"):
        (root / "texts" / f"{name}.txt").write_text("a person walks.#a/DET person/NOUN walk/VERB#0.0#0.0\n")
    (root / "train.txt").write_text("good\nbad\n")
    with pytest.raises(ValueError, match=r"cannot read .*bad.npy as a .npy array \(a text, pickled") as err:
        MotionTextDataset(root, normalize=False)
    assert "allow_pickle" not in str(err.value)


def test_train_config_that_is_not_json_is_named(sample_dir, tmp_path, capsys):
    binary, text = tmp_path / "not_json.npy", tmp_path / "bad.json"
    np.save(binary, np.zeros(3))
    text.write_text('{"a":\n')
    for config, why in ((binary, "it is not UTF-8 text"), (text, "Expecting value at line 2, column 1")):
        out = tmp_path / "run"
        _fails_cleanly(["train", "vae", "--config", str(config), "--data", str(sample_dir), "--out", str(out)],
                       capsys, out, f"--config {config} is not a JSON document ({why})")


def test_a_motion_npy_that_is_really_text_never_suggests_unpickling(tmp_path, capsys):
    path = tmp_path / "text.npy"
    path.write_text("0.1 0.2 0.3\n")
    out = tmp_path / "e"
    line = _fails_cleanly(["export", str(path), "--out", str(out)], capsys, out,
                          f"cannot read {path} as a .npy array (a text, pickled, truncated or corrupt file")
    assert "allow_pickle" not in line and "pickle.load" not in line


def test_ctrl_c_exits_130_and_removes_what_the_call_wrote(tiny_weights, tmp_path, capsys, monkeypatch):
    import salad_viz

    def interrupted(*a, **k):
        raise KeyboardInterrupt
    monkeypatch.setattr(salad_viz, "export_bvh", interrupted)
    out = tmp_path / "gen"
    code = cli.main(["-q", "generate", "a person walks", "--length", "8", "--steps", "1", "--no-render",
                     "--no-attention", "--weights", str(tiny_weights), "--out", str(out)])
    assert code == 130 and capsys.readouterr().err.strip() == "salad generate: interrupted"
    assert not out.exists()


def test_invert_says_once_that_it_crops(tiny_weights, sample_dir, tmp_path, capsys):
    path = tmp_path / "take_features.npy"
    np.save(path, np.load(sample_dir / "new_joint_vecs" / "012314.npy")[:42])
    code = cli.main(["-q", "invert", str(path), "--prompt", "a person walks", "--steps", "1", "--no-render",
                     "--weights", str(tiny_weights), "--out", str(tmp_path / "inv")])
    assert code == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "salad_viz.export" not in line]
    assert err == ["salad invert: note: the motion has 42 frames, not a multiple of 4; inverting the first 40"]
    assert np.load(tmp_path / "inv" / "take_features_reconstruction_features.npy").shape == (40, 263)
