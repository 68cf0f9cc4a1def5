"""The ``salad`` command line: help with examples, outputs, refusal to overwrite, one-line errors."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core import cli


@pytest.fixture(scope="module")
def tiny_weights(tmp_path_factory, make_tiny_pipeline):
    """A tiny randomly initialised pipeline folder (fast; the motions are noise, the plumbing is real)."""
    return make_tiny_pipeline(seed=0).save_pretrained(tmp_path_factory.mktemp("weights"))


@pytest.mark.parametrize("command", ["demo", "generate", "render", "export", "corpus", "train"])
def test_every_command_help_shows_an_example(command, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main([command, "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "example:" in out and f"salad {command}" in out


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
    assert cli.main(["-q", "render", str(src), "--out", str(tmp_path), "--size", "96"]) == 0
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
