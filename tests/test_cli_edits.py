"""Every edit class from ``salad edit``: --erase, --shift, --example-seed and --inpaint give exactly the motion
the same edit gives in Python, and in-painting keeps what it does not regenerate (shipped weights, few steps)."""
from __future__ import annotations

import numpy as np
import pytest

from salad_core import cli
from salad_core.pipeline import default_weights_dir

pytestmark = [
    pytest.mark.usefixtures("single_thread"),
    pytest.mark.skipif(not (default_weights_dir() / "pipeline.json").is_file(), reason="needs the shipped weights"),
]

SOURCE = "a person walks forward while waving his right hand"
STEPS, LENGTH, SEED = 5, 40, 3


@pytest.fixture(scope="module")
def pipe():
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained()


def _run(tmp_path, name, *flags, source=SOURCE):
    out = tmp_path / name
    code = cli.main(["-q", "edit", source, *flags, "--length", str(LENGTH), "--steps", str(STEPS),
                     "--seed", str(SEED), "--out", str(out)])
    assert code == 0
    return np.load(out / "source_features.npy"), np.load(out / "edited_features.npy"), out


@pytest.mark.parametrize("flags, edits", [
    (["--erase", "waving his right hand"], lambda a: [a.Erase(words="waving his right hand")]),
    (["--shift", "waving=20"], lambda a: [a.Shift(words="waving", frames=20)]),
    (["--example-seed", "7"], lambda a: [a.ExampleBased(seed=7)]),
    (["--target", "a person walks forward while raising both arms", "--inpaint", "arms"],
     lambda a: [a.parse_inpaint("arms", blend=1)]),
])
def test_each_edit_flag_gives_the_python_edit(tmp_path, pipe, flags, edits):
    import salad_core.attention as a

    src, dst, _ = _run(tmp_path, flags[0].strip("-"), *flags)
    target = flags[flags.index("--target") + 1] if "--target" in flags else None
    want = pipe.edit(SOURCE, target, edits=edits(a), lengths=LENGTH, seed=SEED, num_steps=STEPS)
    np.testing.assert_array_equal(dst, want.edited.features[0, :LENGTH])
    np.testing.assert_array_equal(src, want.source.features[0, :LENGTH])
    assert np.abs(dst - src).max() > 1e-3                           # the edit changed the motion


def test_inpainting_the_arms_keeps_the_legs(tmp_path):
    from salad_core.skeleton import get_skeleton

    _, _, out = _run(tmp_path, "inpaint", "--target", "a person walks forward while raising both arms",
                     "--inpaint", "arms")
    sk = get_skeleton("humanml3d")
    src, dst = np.load(out / "source_joints.npy"), np.load(out / "edited_joints.npy")
    legs = [sk.joint_names.index(n) for n in ("left_knee", "right_knee", "left_ankle", "right_ankle")]
    arms = [sk.joint_names.index(n) for n in ("left_wrist", "right_wrist")]
    rel = lambda x, j: x[:, j] - x[:, :1]                           # root-aligned
    assert np.linalg.norm(rel(dst, legs) - rel(src, legs), axis=-1).mean() < 0.03
    assert np.linalg.norm(rel(dst, arms) - rel(src, arms), axis=-1).mean() > 0.05


@pytest.mark.parametrize("flags, message", [
    (["--shift", "waving=x"], "FRAMES 'x' is not a whole number"),
    (["--shift", "waving"], "--shift takes WORDS=FRAMES"),
    (["--inpaint", "arms"], "--inpaint needs --target"),
    (["--target", "a person runs", "--inpaint", "wings"], "--inpaint wings"),
    (["--example-seed", "-1"], "--example-seed -1"),
])
def test_bad_edit_flags_are_one_line_errors(tmp_path, capsys, flags, message):
    code = cli.main(["-q", "edit", SOURCE, *flags, "--length", "40", "--steps", "2", "--out", str(tmp_path / "x")])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())
