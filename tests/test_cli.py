"""The ``salad`` command line: help with examples, outputs, refusal to overwrite, one-line errors."""
from __future__ import annotations

import json

import numpy as np
import pytest

from salad_core import cli
from salad_core.cli import generate


@pytest.fixture(scope="module")
def tiny_weights(tmp_path_factory, make_tiny_pipeline):
    """A tiny randomly initialised pipeline folder (fast; the motions are noise, the plumbing is real)."""
    return make_tiny_pipeline(seed=0).save_pretrained(tmp_path_factory.mktemp("weights"))


@pytest.mark.parametrize("command", ["demo", "generate", "edit", "invert", "render", "export", "corpus", "train",
                                     "bench"])
def test_every_command_help_shows_an_example(command, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and f"salad {command}" in out


def test_train_help_and_choices_come_from_the_trainers_cli(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["train", "keymotion", "--help"])
    assert exc.value.code == 0
    assert "--steps-per-stage" in capsys.readouterr().out      # the trainers' own parser answered
    with pytest.raises(SystemExit) as exc:
        cli.main(["train", "gan", "--data", "d", "--out", "o"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'gan'" in err and "'keymotion'" in err


def test_sampler_preset_sets_solver_and_steps(tiny_weights, tmp_path, capsys, monkeypatch):
    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import SAMPLER_PRESETS, sampler_preset

    seen = []
    original = SaladPipeline.__call__

    def spy(self, *a, **kw):
        seen.append((kw["solver"], kw["num_steps"]))
        return original(self, *a, **kw)

    monkeypatch.setattr(SaladPipeline, "__call__", spy)
    base = ["-q", "generate", "a person walks", "--length", "16", "--weights", str(tiny_weights), "--no-render",
            "--no-attention"]
    assert cli.main([*base, "--out", str(tmp_path / "a"), "--preset", "fast"]) == 0
    assert cli.main([*base, "--out", str(tmp_path / "b")]) == 0
    assert seen == [("dpm++", 20), (None, 50)] and sampler_preset("fast") == SAMPLER_PRESETS["fast"]
    with pytest.raises(SystemExit) as exc:
        cli.main([*base, "--out", str(tmp_path / "c"), "--preset", "fast", "--steps", "10"])
    assert exc.value.code == 2 and "not both" in capsys.readouterr().err
    with pytest.raises(ValueError, match="choose one of \\['fast', 'paper'\\]"):
        sampler_preset("turbo")


def test_realtime_preset_samples_as_its_folder_says_and_names_a_missing_one(tiny_weights, tmp_path, capsys,
                                                                          monkeypatch):
    import json
    import shutil

    from salad_core.pipeline import SaladPipeline

    folder = tmp_path / "realtime"
    shutil.copytree(tiny_weights, folder)
    doc = json.loads((folder / "pipeline.json").read_text())
    doc.update(solver="lcm", num_steps=2, guidance={"scale": 1.0, "rescale": 0.0, "interval": None})
    (folder / "pipeline.json").write_text(json.dumps(doc))
    seen = []
    original = SaladPipeline.__call__

    def spy(self, *a, **kw):
        seen.append((kw["solver"], kw["num_steps"], self.solver, self.num_steps))
        return original(self, *a, **kw)

    monkeypatch.setattr(SaladPipeline, "__call__", spy)
    base = ["-q", "generate", "a person walks", "--length", "16", "--no-render", "--no-attention", "--preset",
            "realtime"]
    assert cli.main([*base, "--weights", str(folder), "--out", str(tmp_path / "a")]) == 0
    assert seen == [(None, None, "lcm", 2)]              # the call leaves solver and steps to the folder
    assert cli.main([*base, "--weights", str(tmp_path / "none"), "--out", str(tmp_path / "b")]) != 0
    err = capsys.readouterr().err
    assert "'realtime' weights are missing" in err and "distill_realtime.py" in err
    with pytest.raises(SystemExit) as exc:
        cli.main([*base, "--weights", str(folder), "--out", str(tmp_path / "c"), "--steps", "4"])
    assert exc.value.code == 2 and "not both" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        cli.main(["-q", "edit", "a person walks", "--target", "a person runs", "--preset", "realtime", "--out",
                  str(tmp_path / "d")])
    assert exc.value.code == 2 and "50-step weights" in capsys.readouterr().err


def test_generate_and_edit_sample_at_the_weights_own_guidance(make_tiny_pipeline, tmp_path, capsys, monkeypatch):
    # the shipped weights choose their guidance (pipeline.json); the CLI used to override it with 7.5
    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import Guidance

    pipe = make_tiny_pipeline(seed=0)
    pipe.guidance = Guidance(3.0)
    weights = pipe.save_pretrained(tmp_path / "w3")
    used = []                                    # the weights each sampling call resolves to
    original = SaladPipeline.resolve_guidance

    def spy(self, guidance_scale=None):
        g = original(self, guidance_scale)
        used.append(g.scale)
        return g

    monkeypatch.setattr(SaladPipeline, "resolve_guidance", spy)
    base = ["generate", "a person walks", "--length", "16", "--steps", "2", "--weights", str(weights),
            "--no-render", "--no-attention"]
    assert cli.main([*base, "--out", str(tmp_path / "a")]) == 0
    assert "guidance w = 3 (the weights' default, pipeline.json)" in capsys.readouterr().out
    assert set(used) == {3.0}
    used.clear()
    assert cli.main([*base, "--out", str(tmp_path / "b"), "--guidance", "7.5"]) == 0
    assert "guidance w = 7.5 (--guidance)" in capsys.readouterr().out
    assert set(used) == {7.5}
    used.clear()
    assert cli.main(["-q", "edit", "a person walks", "--reweight", "walks=2", "--length", "16", "--steps", "2",
                     "--weights", str(weights), "--out", str(tmp_path / "e")]) == 0
    assert set(used) == {3.0}


def test_guidance_rescale_and_interval_reach_the_sampler_and_change_the_motion(make_tiny_pipeline, tmp_path,
                                                                                capsys, monkeypatch):
    # --guidance-rescale / --guidance-interval refine the weights' own guidance (their weight kept unless --guidance)
    import numpy as np

    from salad_core.pipeline import SaladPipeline
    from salad_core.sampling import Guidance

    pipe = make_tiny_pipeline(seed=0)
    pipe.guidance = Guidance(3.0)
    weights = pipe.save_pretrained(tmp_path / "w3")
    used = []
    original = SaladPipeline.resolve_guidance

    def spy(self, guidance_scale=None):
        g = original(self, guidance_scale)
        used.append(g)
        return g

    monkeypatch.setattr(SaladPipeline, "resolve_guidance", spy)
    base = ["generate", "a person walks", "--length", "16", "--steps", "3", "--weights", str(weights),
            "--no-render", "--no-attention"]
    assert cli.main([*base, "--out", str(tmp_path / "plain")]) == 0
    capsys.readouterr()
    used.clear()
    assert cli.main([*base, "--out", str(tmp_path / "refined"), "--guidance-rescale", "0.7",
                     "--guidance-interval", "0:0.5"]) == 0
    out = capsys.readouterr().out
    assert "guidance w = 3 (rescale 0.7, interval (0.0, 0.5)) (--guidance-rescale, --guidance-interval)" in out
    assert used[-1] == Guidance(3.0, rescale=0.7, interval=(0.0, 0.5))
    plain = np.load(tmp_path / "plain" / "00_a_person_walks_features.npy")
    refined = np.load(tmp_path / "refined" / "00_a_person_walks_features.npy")
    api = SaladPipeline.from_pretrained(weights)("a person walks", lengths=16, seed=0, num_steps=3,
                                                 guidance_scale=Guidance(3.0, rescale=0.7, interval=(0.0, 0.5)))
    assert np.abs(refined - plain).max() > 1e-3                  # the refinement changes the motion ...
    np.testing.assert_allclose(refined, api.features[0, :16], atol=1e-5)   # ... exactly as the Python API does
    used.clear()
    assert cli.main(["-q", "edit", "a person walks", "--reweight", "walks=2", "--length", "16", "--steps", "2",
                     "--weights", str(weights), "--out", str(tmp_path / "e"), "--guidance", "5",
                     "--guidance-rescale", "0.5"]) == 0
    assert used[-1] == Guidance(5.0, rescale=0.5)             # the last resolution is the sampling call's
    assert cli.main([*base, "--out", str(tmp_path / "w1"), "--guidance", "1", "--guidance-rescale", "0.7"]) == 0
    assert "change nothing at w = 1" in capsys.readouterr().err


@pytest.mark.parametrize("extra, message", [
    (["--guidance-rescale", "1.5"], "--guidance-rescale 1.5 is out of range; allowed: 0..1"),
    (["--guidance-rescale", "nan"], "--guidance-rescale must be a finite number, got nan"),
    (["--guidance-interval", "0.5:0.2"], "--guidance-interval 0.5:0.2: allowed 0 <= LO < HI <= 1"),
    (["--guidance-interval", "0:2"], "--guidance-interval 0:2: allowed 0 <= LO < HI <= 1"),
    (["--guidance-interval", "half"], "--guidance-interval 'half': expected LO:HI"),
    (["--guidance-interval", "0:0.2:0.5"], "expected LO:HI"),
])
def test_guidance_refinements_are_checked_before_weights_load(tmp_path, capsys, extra, message):
    code = cli.main(["-q", "generate", "a person walks", *extra, "--weights", str(tmp_path / "nowhere"),
                     "--out", str(tmp_path / "g")])
    assert code == 2 and message in _one_line_error(capsys)
    assert not (tmp_path / "g").exists()


def test_generate_writes_outputs_and_refuses_to_overwrite(tiny_weights, tmp_path, capsys):
    out = tmp_path / "gen"
    args = ["generate", "a person walks forward", "--length", "40", "--steps", "3", "--weights",
            str(tiny_weights), "--out", str(out), "--no-render"]
    assert cli.main(["-q", *args]) == 0
    files = sorted(p.name for p in out.iterdir())
    stem = "00_a_person_walks_forward"
    assert f"{stem}_features.npy" in files and f"{stem}_joints.npy" in files and f"{stem}.bvh" in files
    feats = np.load(out / f"{stem}_features.npy")
    joints = np.load(out / f"{stem}_joints.npy")
    assert feats.shape == (40, 263) and joints.shape == (40, 22, 3)
    assert not any(name.endswith(".tmp") for name in files)
    before = (out / f"{stem}_features.npy").read_bytes()
    capsys.readouterr()
    assert cli.main(["-q", *args]) == 2                      # exists: refused
    err = capsys.readouterr().err
    assert "--force" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert (out / f"{stem}_features.npy").read_bytes() == before
    assert cli.main(["-q", *args, "--force", "--seed", "5"]) == 0
    assert (out / f"{stem}_features.npy").read_bytes() != before


@pytest.mark.parametrize("length, message", [("0", "allowed: 4..196"), ("-8", "allowed: 4..196"),
                                             ("400", "allowed: 4..196")])
def test_bad_length_is_one_line_error(tiny_weights, tmp_path, capsys, length, message):
    code = cli.main(["-q", "generate", "a person walks", "--length", length, "--weights", str(tiny_weights),
                     "--out", str(tmp_path / "x"), "--steps", "2"])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err


def test_empty_prompt_error(tiny_weights, tmp_path, capsys):
    code = cli.main(["-q", "generate", "   ", "--weights", str(tiny_weights), "--out", str(tmp_path / "x")])
    assert code == 2 and "empty" in capsys.readouterr().err


def test_missing_weights_error(tmp_path, capsys):
    code = cli.main(["-q", "generate", "a person walks", "--weights", str(tmp_path / "nowhere"), "--out",
                     str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and "pipeline.json" in err


def test_debug_shows_traceback(tmp_path):
    with pytest.raises(Exception):
        cli.main(["--debug", "-q", "generate", "a person walks", "--weights", str(tmp_path / "nowhere"),
                  "--out", str(tmp_path / "x")])


def test_unwritable_output_folder(tiny_weights, tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    code = cli.main(["-q", "generate", "a person walks", "--weights", str(tiny_weights), "--out", str(blocker)])
    assert code == 2 and "not a folder" in capsys.readouterr().err


def test_export_and_render_from_features(sample_dir, tmp_path, capsys):
    src = sample_dir / "new_joint_vecs" / "012314.npy"
    assert cli.main(["-q", "export", str(src), "--format", "bvh", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "012314.bvh").read_text()
    assert text.startswith("HIERARCHY") and "Frame Time: 0.05" in text
    short = tmp_path / "short" / "012314.npy"        # a 24-frame crop: rendering costs ~0.1 s a frame
    short.parent.mkdir()
    np.save(short, np.load(src)[:24])
    assert cli.main(["-q", "render", str(short), "--out", str(tmp_path), "--size", "96"]) == 0
    assert (tmp_path / "012314.gif").stat().st_size > 1000


def test_export_rejects_bad_motion_file(tmp_path, capsys):
    bad = tmp_path / "bad.npy"
    np.save(bad, np.zeros((10, 100), np.float32))
    assert cli.main(["-q", "export", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "263" in capsys.readouterr().err
    nan = tmp_path / "nan.npy"
    arr = np.zeros((10, 263), np.float32)
    arr[3, 5] = np.nan
    np.save(nan, arr)
    assert cli.main(["-q", "export", str(nan), "--out", str(tmp_path / "o")]) == 2
    assert "NaN" in capsys.readouterr().err


def test_corpus_build_refuses_non_empty_folder(tmp_path, capsys):
    (tmp_path / "keep.txt").write_text("x")
    assert cli.main(["-q", "corpus", "build", "--out", str(tmp_path), "--size", "tiny"]) == 2
    assert "--force" in capsys.readouterr().err


def test_edit_writes_source_and_edited(tiny_weights, tmp_path):
    out = tmp_path / "edit"
    code = cli.main(["-q", "edit", "a man raises his right hand high", "--mirror", "all", "--reweight", "high=-1",
                     "--length", "40", "--steps", "3", "--weights", str(tiny_weights), "--out", str(out)])
    assert code == 0
    src, dst = np.load(out / "source_joints.npy"), np.load(out / "edited_joints.npy")
    assert src.shape == dst.shape == (40, 22, 3) and not np.allclose(src, dst)
    assert (out / "source_vs_edited.gif").is_file()


@pytest.mark.parametrize("extra, message", [([], "give at least one edit"), (["--reweight", "high"], "WORD=SCALE"),
                                            (["--reweight", "jumps=2"], "not in the prompt"),
                                            (["--reweight", "high=9"], "[-3, 3]")])
def test_edit_errors(tiny_weights, tmp_path, capsys, extra, message):
    code = cli.main(["-q", "edit", "a man raises his right hand high", *extra, "--steps", "2",
                     "--weights", str(tiny_weights), "--out", str(tmp_path / "e")])
    err = capsys.readouterr().err
    assert code == 2 and message in err and "Traceback" not in err


def _one_line_error(capsys) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    return err


# ----------------------------------------------------------------------------- edit: bad windows and scales
@pytest.mark.parametrize("extra, message", [
    (["--swap", "1.5"], "--swap 1.5: WordSwap.tau=1.5 must be in [0, 1)"),
    (["--swap", "-0.2"], "--swap -0.2: WordSwap.tau=-0.2 must be in [0, 1)"),
    (["--swap", "nan"], "--swap nan: WordSwap.tau=nan must be in [0, 1)"),
    (["--refine", "--window", "0.5:1.5"],
     "--refine --window 0.5:1.5: Refine.steps=(0.5, 1.5) must satisfy 0 <= start < stop <= 1"),
    (["--mirror", "all", "--window=-0.1:0.5"], "Mirror.steps=(-0.1, 0.5) must satisfy 0 <= start < stop <= 1"),
    (["--reweight", "high=2", "--window", "0.8:0.2"], "Reweight.steps=(0.8, 0.2) must satisfy 0 <= start < stop"),
    (["--mirror", "all", "--window", "0:inf"], "must satisfy 0 <= start < stop <= 1"),
    (["--mirror", "all", "--window", "half"], "--window takes START:STOP"),
    (["--swap", "0.8", "--window", "0:0.5"], "--window applies to --refine, --reweight, --mirror, --erase and --shift"),
    (["--reweight", "high=2", "--mirror-self-attention"], "--mirror-self-attention goes with --mirror PARTS"),
    (["--reweight", "high=nan"], "--reweight high=nan: Reweight.scale must be a finite number, got nan"),
    (["--reweight", "high=inf"], "--reweight high=inf: Reweight.scale must be a finite number, got inf"),
    (["--reweight", "high=-inf"], "Reweight.scale must be a finite number"),
    (["--mirror", "all", "--guidance", "nan"], "--guidance must be a finite number, got nan"),
    (["--mirror", "all", "--guidance", "inf"], "--guidance must be a finite number, got inf"),
])
def test_edit_rejects_windows_outside_unit_interval_and_non_finite_scales(tmp_path, capsys, extra, message):
    # refused before any weights are read: the weights folder does not even exist
    code = cli.main(["-q", "edit", "a man raises his right hand high", *extra, "--steps", "2",
                     "--weights", str(tmp_path / "nowhere"), "--out", str(tmp_path / "e")])
    assert code == 2
    err = _one_line_error(capsys)
    assert err.startswith("salad edit: error: ") and message in err


def test_generate_rejects_non_finite_guidance(tmp_path, capsys):
    code = cli.main(["-q", "generate", "a person walks", "--guidance=-inf", "--weights", str(tmp_path / "nowhere"),
                     "--out", str(tmp_path / "g")])
    assert code == 2 and "--guidance must be a finite number, got -inf" in _one_line_error(capsys)
    assert not (tmp_path / "g").exists()


def test_edit_flags_build_the_specs_with_their_window():
    from salad_core.attention import Mirror, MirrorSelfAttention, Refine, Reweight, WordSwap

    parser = cli.build_parser()
    args = parser.parse_args(["edit", "a man raises his hand", "--target", "a man slowly raises his hand high",
                              "--refine", "--reweight", "high=-1.5", "--mirror", "arms", "--window", "0.2:0.6",
                              "--out", "x"])
    assert generate._edit_specs(args) == [Refine(steps=(0.2, 0.6)), Reweight("high", -1.5, steps=(0.2, 0.6)),
                                     Mirror("arms", steps=(0.2, 0.6))]
    args = parser.parse_args(["invert", "m.npy", "--prompt", "a man walks", "--mirror", "legs", "--mirror-self-attention",
                              "--window", "0:0.5", "--out", "x"])
    assert generate._edit_specs(args) == [Mirror("legs", steps=(0.0, 0.5)), MirrorSelfAttention("legs", steps=(0.0, 0.5))]
    args = parser.parse_args(["invert", "m.npy", "--prompt", "a man walks", "--swap", "0.7", "--out", "x"])
    assert generate._edit_specs(args, required=False) == [WordSwap(tau=0.7)]
    args = parser.parse_args(["invert", "m.npy", "--prompt", "a man walks", "--out", "x"])
    assert args.exact is True
    assert parser.parse_args(["invert", "m.npy", "--prompt", "a man walks", "--out", "x", "--no-exact"]).exact is False
    assert generate._edit_specs(args, required=False) == []
    with pytest.raises(cli.UserError, match="give at least one edit"):
        generate._edit_specs(args)


# ----------------------------------------------------------------------------- unknown skeleton
def test_unknown_skeleton_is_one_line_error(sample_dir, tmp_path, capsys):
    src = sample_dir / "new_joint_vecs" / "012314.npy"
    assert cli.main(["-q", "export", str(src), "--skeleton", "smpl", "--out", str(tmp_path)]) == 2
    err = _one_line_error(capsys)
    assert "--skeleton" in err and "smpl" in err and "humanml3d" in err and "kit" in err
    assert cli.main(["-q", "invert", str(src), "--prompt", "a person walks", "--skeleton", "smpl",
                     "--out", str(tmp_path)]) == 2
    assert "smpl" in _one_line_error(capsys)


# ----------------------------------------------------------------------------- invert
@pytest.fixture(scope="module")
def inverted(tiny_weights, tmp_path_factory, sample_dir):
    """One ``salad invert`` run with a mirror edit on the real sample motion (170 frames)."""
    out = tmp_path_factory.mktemp("inv")
    src = sample_dir / "new_joint_vecs" / "012314.npy"
    args = ["-q", "invert", str(src), "--prompt", "a person walks forward", "--mirror", "arms", "--steps", "4", "--no-render",
            "--weights", str(tiny_weights), "--out", str(out)]
    assert cli.main(args) == 0
    return out, src, args


def test_invert_writes_reconstruction_edit_and_report(inverted):
    out, src, _ = inverted
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted([f"012314_{b}{e}" for b in ("reconstruction", "edited")
                            for e in ("_features.npy", "_joints.npy", ".bvh")] + ["012314_inversion.json"])
    rec = np.load(out / "012314_reconstruction_features.npy")
    edited = np.load(out / "012314_edited_features.npy")
    assert rec.shape == edited.shape == (168, 263)            # 170 frames cropped to a multiple of 4
    assert np.load(out / "012314_reconstruction_joints.npy").shape == (168, 22, 3)
    assert not np.allclose(rec, edited)                       # the mirror changed the motion
    assert (out / "012314_reconstruction.bvh").read_text().startswith("HIERARCHY")
    report = json.loads((out / "012314_inversion.json").read_text())
    assert report["method"] == "fixed_point" and report["num_steps"] == 4 and report["frames"] == 168
    assert report["exact"] is True                            # the default; --no-exact turns it off
    assert report["input_frames"] == 170 and report["edit"]["edits"] == ["Mirror(parts='arms', steps=(0.0, 1.0))"]


def test_invert_reports_the_reconstruction_mpjpe_in_cm(inverted, sample_features):
    from salad_core.eval.metrics import mpjpe
    from salad_core.motion import features_to_joints

    out, _, _ = inverted
    errors = json.loads((out / "012314_inversion.json").read_text())["errors"]
    gt = features_to_joints(sample_features[:168], "humanml3d")
    # the errors measure the representation: raw position features on both sides (the joints file
    # holds the fixed-bone fit of the same features, see SaladPipeline.recovery)
    rec = features_to_joints(np.load(out / "012314_reconstruction_features.npy"), "humanml3d")
    fitted = np.load(out / "012314_reconstruction_joints.npy")
    assert 0 < 100 * mpjpe(fitted, rec) < 20.0         # a 4-step reconstruction: rough features, large fit
    assert errors["mpjpe_cm"] == pytest.approx(100 * mpjpe(rec, gt), rel=1e-4)
    assert errors["mpjpe_global_cm"] == pytest.approx(100 * mpjpe(rec, gt, root_aligned=False), rel=1e-4)
    assert errors["mpjpe_cm"] > 0 and errors["vae_mpjpe_cm"] > 0


def test_invert_prints_mpjpe_and_refuses_to_overwrite(inverted, capsys):
    out, _, args = inverted
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert cli.main(args) == 2                                  # refused before any work
    err = _one_line_error(capsys)
    assert "--force" in err and "012314_reconstruction_features.npy" in err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    no_edit = [a for a in args if a not in ("--mirror", "arms")]
    assert cli.main([*no_edit, "--force", "--steps", "2"]) == 0
    printed = capsys.readouterr().out
    report = json.loads((out / "012314_inversion.json").read_text())
    assert report["num_steps"] == 2 and report["edit"] is None
    assert f"reconstruction MPJPE {report['errors']['mpjpe_cm']:.2f} cm" in printed
    assert (out / "012314_reconstruction_features.npy").read_bytes() != before["012314_reconstruction_features.npy"]


def _bad_files(tmp_path, sample_features):
    wide = np.zeros((40, 100), np.float32)
    nan = np.array(sample_features[:40], np.float32)
    nan[3, 5] = np.nan
    files = {"wide.npy": wide, "nan.npy": nan, "joints.npy": np.zeros((40, 22, 3), np.float32),
             "long.npy": np.zeros((300, 263), np.float32), "short.npy": np.zeros((3, 263), np.float32)}
    for name, arr in files.items():
        np.save(tmp_path / name, arr)
    np.save(tmp_path / "obj.npy", np.array([{"a": 1}], dtype=object), allow_pickle=True)
    (tmp_path / "corrupt.npy").write_bytes(b"\x93NUMPY garbage" * 3)
    good = tmp_path / "good.npy"
    np.save(good, sample_features[:40])
    (tmp_path / "truncated.npy").write_bytes(good.read_bytes()[:2000])


@pytest.mark.parametrize("name, message", [
    ("wide.npy", "263"), ("nan.npy", "NaN"), ("joints.npy", "inversion needs HumanML3D features"),
    ("long.npy", "300 frames; allowed: 4..196"), ("short.npy", "3 frames; allowed: 4..196"),
    ("obj.npy", "cannot read"), ("corrupt.npy", "cannot read"), ("truncated.npy", "cannot read"),
    ("missing.npy", "motion file not found")])
def test_invert_rejects_bad_motion_files(tmp_path, capsys, sample_features, name, message):
    _bad_files(tmp_path, sample_features)
    code = cli.main(["-q", "invert", str(tmp_path / name), "--prompt", "a person walks",
                     "--weights", str(tmp_path / "nowhere"), "--out", str(tmp_path / "o")])
    assert code == 2 and message in _one_line_error(capsys)


@pytest.mark.parametrize("extra, message", [(["--method", "magic"], "allowed: ddim, fixed_point, null_text"),
                                            (["--prompt", "  "], "--prompt is empty"),
                                            (["--swap", "2"], "WordSwap.tau=2.0 must be in [0, 1)")])
def test_invert_rejects_bad_options(tmp_path, capsys, sample_dir, extra, message):
    src = sample_dir / "new_joint_vecs" / "012314.npy"
    args = ["-q", "invert", str(src), "--prompt", "a person walks", *extra, "--weights", str(tmp_path / "nowhere"),
            "--out", str(tmp_path / "o")]
    assert cli.main(args) == 2 and message in _one_line_error(capsys)


def test_edit_given_motion_uses_the_same_loader(tiny_weights, tmp_path, capsys, sample_features):
    _bad_files(tmp_path, sample_features)
    code = cli.main(["-q", "edit", "a person walks", "--mirror", "all", "--motion", str(tmp_path / "nan.npy"),
                     "--weights", str(tiny_weights), "--out", str(tmp_path / "o")])
    assert code == 2 and "NaN" in _one_line_error(capsys)


# ----------------------------------------------------------------------------- bench (not run: too slow)
def test_bench_refuses_to_overwrite_its_table(tmp_path, capsys):
    table = tmp_path / "bench.md"
    table.write_text("old")
    assert cli.main(["bench", "--quick", "--out", str(table)]) == 2
    assert "--force" in _one_line_error(capsys) and table.read_text() == "old"


def test_quiet_silences_every_progress_bar(tiny_weights, tmp_path):
    """-q: nothing on stderr from a clean run, not even transformers' "Loading weights" bar (a fresh
    process, as a user runs it)."""
    import subprocess
    import sys

    run = subprocess.run([sys.executable, "-m", "salad_core.cli", "-q", "generate", "a person walks", "--length", "8",
                          "--steps", "1", "--no-render", "--weights", str(tiny_weights), "--out", str(tmp_path / "q")],
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    # the tiny random model's BVH may log a fit warning; no progress bar of any kind
    assert "Loading weights" not in run.stderr + run.stdout and "it/s" not in run.stderr and "%|" not in run.stderr
    assert (tmp_path / "q" / "00_a_person_walks_attention.png").is_file()


def test_help_texts_name_every_option(capsys):
    """Every option of the user-facing commands says what it does."""
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    for name in ("demo", "generate", "edit", "invert", "import", "render", "export", "corpus"):
        for action in sub.choices[name]._actions:
            if action.option_strings and action.dest != "help":
                assert action.help, f"salad {name} {action.option_strings[0]} has no help text"


def test_generate_with_keymotion_writes_the_pipelines_motions(tmp_path, capsys):
    """``--keymotion`` writes what KeyMotionPipeline returns for prompt b at seed SEED + b, and no attention figure."""
    from salad_core.keymotion.pipeline import KeyMotionPipeline

    out = tmp_path / "km"
    prompts = ["a person walks forward", "a man waves his right hand"]
    assert cli.main(["-q", "generate", *prompts, "--keymotion", "--length", "40", "--steps", "3", "--seed", "7",
                     "--no-render", "--out", str(out)]) == 0
    stems = ["00_a_person_walks_forward", "01_a_man_waves_his_right_hand"]
    assert sorted(p.name for p in out.iterdir()) == sorted(f"{st}{ext}" for st in stems
                                                          for ext in ("_features.npy", "_joints.npy", ".bvh"))
    pipe = KeyMotionPipeline.from_pretrained()
    for b, (prompt, stem) in enumerate(zip(prompts, stems)):
        ref = pipe(prompt, lengths=40, seed=7 + b, num_steps=3)
        feats, joints = np.load(out / f"{stem}_features.npy"), np.load(out / f"{stem}_joints.npy")
        assert feats.shape == (40, 263) and joints.shape == (40, 22, 3)
        np.testing.assert_allclose(feats, ref.features[0], rtol=0, atol=1e-6)
        np.testing.assert_allclose(joints, ref.joints[0], rtol=0, atol=1e-6)
    # the two prompts' motions differ (not one motion written twice)
    assert np.abs(np.load(out / f"{stems[0]}_joints.npy") - np.load(out / f"{stems[1]}_joints.npy")).max() > 0.05


def test_generate_with_keymotion_refuses_what_it_cannot_do(tiny_weights, tmp_path, capsys):
    base = ["-q", "generate", "a person walks", "--keymotion", "--steps", "2", "--no-render"]
    code = cli.main([*base, "--weights", str(tiny_weights), "--out", str(tmp_path / "a")])
    assert code == 2 and "--keymotion DIR" in _one_line_error(capsys) and not (tmp_path / "a").exists()
    code = cli.main([*base, "--length", "12", "--out", str(tmp_path / "b")])
    assert code == 2 and "allowed: 20..196" in _one_line_error(capsys) and not (tmp_path / "b").exists()
    code = cli.main(["-q", "generate", "a person walks", "--keymotion", str(tmp_path / "nowhere"),
                     "--out", str(tmp_path / "c")])
    assert code == 2 and "nowhere" in _one_line_error(capsys) and not (tmp_path / "c").exists()


def test_edit_writes_a_report_of_what_was_run(tiny_weights, tmp_path):
    """``edit.json``: the prompts, the edits as run, the seed and the edit's settings, so an edit can be re-run and
    its in-painting candidate found again."""
    import json

    out = tmp_path / "edit"
    code = cli.main(["-q", "edit", "a man raises his right hand high", "--reweight", "high=-1", "--length", "40",
                     "--steps", "3", "--seed", "5", "--weights", str(tiny_weights), "--out", str(out)])
    assert code == 0
    report = json.loads((out / "edit.json").read_text())
    assert report["source"] == report["target"] == "a man raises his right hand high"
    assert report["label"] == "Reweight(high=-1)" and report["seed"] == 5 and report["frames"] == 40
    assert report["motion"] is None and report["inversion"] is None
    assert len(report["edits"]) == 1 and report["edits"][0].startswith("Reweight(")
    assert report["settings"]["num_steps"] == 3
    # a second run into the same folder refuses to overwrite it without --force
    assert cli.main(["-q", "edit", "a man raises his right hand high", "--reweight", "high=-1", "--length", "40",
                     "--steps", "3", "--weights", str(tiny_weights), "--out", str(out)]) == 2
