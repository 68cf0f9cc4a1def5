"""Every edit class from ``salad edit``: --erase, --shift, --example-seed and --inpaint give exactly the motion
the same edit gives in Python, and in-painting keeps what it does not regenerate (shipped weights, few steps);
each edit's label, the source's and the edit's attention figures on one colour scale, and the labelled GIF
(``salad edit`` and ``salad invert``)."""
from __future__ import annotations

import dataclasses

import json

import numpy as np
import pytest

from salad_core import cli
from _weights import needs_weights

pytestmark = [pytest.mark.usefixtures("single_thread")]

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


@needs_weights
@pytest.mark.parametrize("flags, edits", [
    (["--erase", "waving his right hand"], lambda a: [a.Erase(words="waving his right hand")]),
    (["--shift", "waving=20"], lambda a: [a.Shift(words="waving", frames=20)]),
    (["--example-seed", "7"], lambda a: [a.ExampleBased(seed=7)]),
    (["--target", "a person walks forward while raising both arms", "--inpaint", "arms"],
     lambda a: [a.parse_inpaint("arms", blend=1)]),
    (["--target", "a person walks forward while raising both arms", "--inpaint", "arms", "--no-composite"],
     lambda a: [dataclasses.replace(a.parse_inpaint("arms", blend=1), composite=False)]),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-root", "edit", "--inpaint-fade", "4"],
     lambda a: [dataclasses.replace(a.parse_inpaint("@12:28", blend=1), root="edit", fade=4)]),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-smooth", "50", "--inpaint-smooth-window", "6",
      "--inpaint-resample", "2", "--inpaint-jump", "2", "--inpaint-guidance", "6"],
     lambda a: [dataclasses.replace(a.parse_inpaint("@12:28", blend=1), smooth=50.0, smooth_window=6, resample=2,
                                    jump=2, guidance=6.0)]),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-guidance", "motion", "--inpaint-smooth", "0"],
     lambda a: [dataclasses.replace(a.parse_inpaint("@12:28", blend=1), guidance=None, smooth=0.0)]),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-noise", "matched"],
     lambda a: [dataclasses.replace(a.parse_inpaint("@12:28", blend=1), noise="matched")]),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-noise", "fresh", "--inpaint-candidates", "2"],
     lambda a: [dataclasses.replace(a.parse_inpaint("@12:28", blend=1), noise="fresh", candidates=2)]),
])
def test_each_edit_flag_gives_the_python_edit(tmp_path, pipe, flags, edits):
    import salad_core.attention as a

    src, dst, _ = _run(tmp_path, flags[0].strip("-"), *flags)
    target = flags[flags.index("--target") + 1] if "--target" in flags else None
    want = pipe.edit(SOURCE, target, edits=edits(a), lengths=LENGTH, seed=SEED, num_steps=STEPS)
    np.testing.assert_array_equal(dst, want.edited.features[0, :LENGTH])
    np.testing.assert_array_equal(src, want.source.features[0, :LENGTH])
    assert np.abs(dst - src).max() > 1e-3                           # the edit changed the motion


@needs_weights
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


@needs_weights
@pytest.mark.parametrize("flags, message", [
    (["--shift", "waving=x"], "FRAMES 'x' is not a whole number"),
    (["--shift", "waving"], "--shift takes WORDS=FRAMES"),
    (["--inpaint", "arms"], "--inpaint needs --target"),
    (["--target", "a person runs", "--inpaint", "wings"], "--inpaint wings"),
    (["--example-seed", "-1"], "--example-seed -1"),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-resample", "0"], "Inpaint.resample=0"),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-guidance", "lots"],
     "--inpaint-guidance lots: give a number, 'auto' or 'motion'"),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-smooth", "-1"], "Inpaint.smooth=-1.0"),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-candidates", "0"], "Inpaint.candidates=0"),
    (["--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-candidates", "2", "--inpaint-prior", "none"],
     "candidates would be alike; give noise='fresh'"),
])
def test_bad_edit_flags_are_one_line_errors(tmp_path, capsys, flags, message):
    code = cli.main(["-q", "edit", SOURCE, *flags, "--length", "40", "--steps", "2", "--out", str(tmp_path / "x")])
    assert code == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())


# ------------------------------------------------------------------ labels, attention figures and GIFs (issue 67)
@pytest.mark.parametrize("edits, source, target, label", [
    (lambda a: [a.WordSwap(tau=0.8)], "a person walks forward", "a person jumps forward", "Swap(walks->jumps, 0.8)"),
    (lambda a: [a.Refine()], "a person walks", "a person walks slowly", "Refine(+slowly)"),
    (lambda a: [a.Reweight(words="high", scale=-1)], None, None, "Reweight(high=-1)"),
    (lambda a: [a.Reweight(words="high", scale=0.5, steps=(0, 0.5))], None, None, "Reweight(high=0.5, steps 0:0.5)"),
    (lambda a: [a.Mirror(parts="legs")], None, None, "Mirror(legs)"),
    (lambda a: [a.Mirror(parts="all"), a.MirrorSelfAttention(parts="all")], None, None,
     "Mirror(all) + MirrorSelf(all)"),
    (lambda a: [a.InjectSelfAttention()], None, None, "InjectSelf(temporal+skeletal)"),
    (lambda a: [a.Erase(words="slowly")], None, None, "Erase(slowly)"),
    (lambda a: [a.Erase(words=[(2, 4)], mode="others")], None, None, "Erase(words 2:4, others)"),
    (lambda a: [a.Shift(words="waving", frames=20)], None, None, "Shift(waving, +20 frames)"),
    (lambda a: [a.ShiftTemporal(parts=("left arm",), frames=-8)], None, None, "ShiftTemporal(left arm, -8 frames)"),
    (lambda a: [a.ExampleBased(seed=7)], None, None, "Example(seed=7)"),
    (lambda a: [a.parse_inpaint("arms@20:60")], None, None, "Inpaint(arms@20:60)"),
    (lambda a: [a.parse_inpaint("left_arm,head")], None, None, "Inpaint(left_arm,head)"),
    (lambda a: [a.parse_inpaint("@:40")], None, None, "Inpaint(all@:40)"),
    (lambda a: [a.Mirror(parts="legs"), a.Reweight(words="high", scale=2)], None, None,
     "Mirror(legs) + Reweight(high=2)"),
    (lambda a: [], None, None, "edited"),
])
def test_edit_label_names_each_edit(edits, source, target, label):
    import salad_core.attention as a
    from salad_core.attention import edit_label

    assert edit_label(edits(a), source, target) == label


def test_every_edit_class_has_a_label():
    import salad_core.attention as a
    from salad_core.attention.labels import _LABEL_PARTS

    classes = {n for n in a.__all__ if isinstance(getattr(a, n), type) and issubclass(getattr(a, n), a.EditSpec)}
    assert classes - {"EditSpec"} <= set(_LABEL_PARTS)


def _png_limits(path) -> tuple[float, float]:
    """The colour limits a figure was drawn with (its PNG text chunk ``Attention limits``)."""
    from PIL import Image

    with Image.open(path) as im:
        text = im.text["Attention limits"]                      # "vmin=... vmax=..."
    vmin, vmax = (float(part.split("=")[1]) for part in text.split())
    return vmin, vmax


def _gif_panels(path):
    """``(frames, panel width)`` of a side-by-side GIF of two panels (4 px apart)."""
    import imageio.v3 as iio

    frames = iio.imread(path, index=None)
    return frames, (frames.shape[2] - 4) // 2


@needs_weights
def test_edit_writes_both_attention_figures_on_one_symmetric_scale_and_a_labelled_gif(tmp_path, pipe):
    import salad_core.attention as a
    from salad_core.cli.generate import edit_attention_limits

    source = "a man raises his right hand high"
    _, _, out = _run(tmp_path, "rw", "--reweight", "high=-1", "--attention", source=source)
    names = ("source_attention.png", "edited_attention.png", "attention_compare.png")
    limits = [_png_limits(out / n) for n in names]
    assert limits[0] == limits[1] == limits[2]                          # one scale for the source and the edit
    vmin, vmax = limits[0]
    assert vmin < 0 < vmax and vmin == -vmax                           # negative re-weight: diverging, centred at 0
    # the scale is the largest |value| of the drawn maps of both motions (the same run in Python)
    want = pipe.edit(source, edits=[a.Reweight(words="high", scale=-1)], lengths=LENGTH, seed=SEED,
                     num_steps=STEPS, capture_attention=True)
    expected = edit_attention_limits([("source", want.source), ("edited", want.edited)])
    assert vmax == pytest.approx(expected[1], rel=1e-5) and expected[0] == -expected[1]
    high = want.edited.attention.word_map(0, "high")
    assert high.max() <= 0 and 0 < -high.min() <= vmax                 # the re-weighted word: negative, on the scale
    frames, w = _gif_panels(out / "source_vs_edited.gif")
    assert frames.shape[1] >= 360 and w >= 360                          # large enough for a projector
    # each panel its own caption: the bands above the scenes differ, and each is dark text on white
    left, right = frames[0, :40, :w].astype(int), frames[0, :40, w + 4:].astype(int)
    assert np.abs(left - right).mean() > 1 and (left.max(-1) < 90).any() and (right.max(-1) < 90).any()


def _sample_take(tmp_path, sample_dir):
    """The first 40 frames of the HumanML3D sample's features, saved as ``tmp_path / "take.npy"``."""
    take = tmp_path / "take.npy"
    np.save(take, np.load(sample_dir / "new_joint_vecs" / "012314.npy")[:40])
    return take


@needs_weights
def test_invert_writes_the_reconstructions_and_the_edits_attention_and_labels_the_edit(tmp_path, sample_dir):
    take = _sample_take(tmp_path, sample_dir)
    out = tmp_path / "inv"
    assert cli.main(["-q", "invert", str(take), "--prompt", "a person walks forward", "--mirror", "legs",
                     "--attention", "--steps", "3", "--out", str(out)]) == 0
    names = ("take_reconstruction_attention.png", "take_edited_attention.png", "take_attention_compare.png")
    limits = [_png_limits(out / n) for n in names]
    assert limits[0] == limits[1] == limits[2] and limits[0][0] == 0 < limits[0][1] <= 1   # mirroring: no sign
    assert json.loads((out / "take_inversion.json").read_text())["edit"]["label"] == "Mirror(legs)"
    frames, w = _gif_panels(out / "take_source_vs_edited.gif")
    assert frames.shape[1] >= 360 and w >= 360
    # without an edit flag: the reconstruction's figure alone (maps captured in one more pass)
    out2 = tmp_path / "inv2"
    assert cli.main(["-q", "invert", str(take), "--prompt", "a person walks forward", "--attention", "--steps", "3",
                     "--no-render", "--out", str(out2)]) == 0
    assert sorted(p.name for p in out2.glob("*.png")) == ["take_reconstruction_attention.png"]


def test_inpaint_noise_flag_offers_every_noise_mode():
    from salad_core.attention.inpaint import NOISE_MODES
    from salad_core.cli.generate import INPAINT_NOISE

    assert INPAINT_NOISE == NOISE_MODES


def test_unknown_inpaint_noise_is_refused_by_the_parser(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["-q", "edit", SOURCE, "--target", "a person jumps", "--inpaint", "@12:28", "--inpaint-noise",
                  "white", "--out", str(tmp_path / "x")])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "--inpaint-noise: invalid choice: 'white'" in err and "'matched'" in err
    assert not (tmp_path / "x").exists()


@needs_weights
def test_invert_records_the_inpaint_noise_mode(tmp_path, sample_dir):
    """``salad invert --inpaint ... --inpaint-noise matched``: the report's edit names the noise mode."""
    take = _sample_take(tmp_path, sample_dir)
    out = tmp_path / "inv"
    assert cli.main(["-q", "invert", str(take), "--prompt", "a person walks forward", "--target", "a person jumps",
                     "--inpaint", "@12:28", "--inpaint-noise", "matched", "--steps", "3", "--no-render",
                     "--out", str(out)]) == 0
    edit = json.loads((out / "take_inversion.json").read_text())["edit"]
    edits = edit["edits"]
    assert len(edits) == 1 and "noise='matched'" in edits[0] and edits[0].startswith("Inpaint(")
    # a span of a given take is ranked over 8 seeds by default, the closest among those whose seams are within 1.5x:
    # the report keeps every score and seam ratio and the chosen seed
    from salad_core.attention.inpaint import SEAM_BOUND, SPAN_CANDIDATES
    from salad_core.attention.ranking import pick_candidate

    ranked = edit["inpaint_candidates"]
    assert len(ranked["seeds"]) == len(ranked["distances"]) == len(ranked["seam_ratios"]) == SPAN_CANDIDATES
    assert ranked["seam_bound"] == SEAM_BOUND
    assert ranked["chosen"] == pick_candidate(ranked["distances"], ranked["seam_ratios"], SEAM_BOUND)
    assert f"seed={ranked['seed']}," in edits[0] and ranked["seed"] == ranked["seeds"][ranked["chosen"]]
    # what was pasted (the prompt alone, held for 30 % of the steps) and whether the kept frames follow a turn
    assert edit["inpaint_prior"]["mode"] == "prompt" and edit["inpaint_prior"]["strength"] == 0.7
    assert edit["composite"]["edits"] == ["Inpaint"] and edit["composite"]["followed_turns"] in ([[]], [[12, 28]])


def test_invert_mirror_take_all_gives_the_takes_mirror_image(tmp_path, sample_dir):
    """``salad invert --mirror-take all``: the edited take is the mirror image of the take (the inversion of its
    exact mirror image, regenerated), labelled as such; ``--no-ground`` is accepted; ``salad edit`` of a generated
    motion refuses the flag with one line."""
    from salad_core.motion import mirror_joints

    take = _sample_take(tmp_path, sample_dir)
    out = tmp_path / "inv"
    assert cli.main(["-q", "invert", str(take), "--prompt", "a person walks forward", "--mirror-take", "all",
                     "--no-ground", "--steps", "3", "--out", str(out)]) == 0
    assert (out / "take_source_vs_edited.gif").is_file()                 # named as an edit's, not a reconstruction's
    assert not (out / "take_source_vs_reconstruction.gif").exists()
    rec = np.load(out / "take_reconstruction_joints.npy")
    edited = np.load(out / "take_edited_joints.npy")
    rel = lambda x: x - x[:, :1]                                    # root-aligned (the two VAE round trips differ)
    to_mirror = np.linalg.norm(rel(edited) - rel(mirror_joints(rec)), axis=-1).mean()
    to_take = np.linalg.norm(rel(edited) - rel(rec), axis=-1).mean()
    assert to_mirror < 0.05 and to_mirror < 0.5 * to_take, (to_mirror, to_take)        # metres
    assert json.loads((out / "take_inversion.json").read_text())["edit"]["label"] == "MirrorTake(all)"


@needs_weights
def test_mirror_take_of_a_generated_motion_is_a_one_line_error(tmp_path, capsys):
    code = cli.main(["-q", "edit", SOURCE, "--mirror-take", "legs", "--length", "40", "--steps", "2",
                     "--out", str(tmp_path / "x")])
    assert code == 2 and "--mirror-take mirrors a given take" in capsys.readouterr().err


@pytest.mark.parametrize("command", [["edit", SOURCE], ["invert", "take.npy", "--prompt", SOURCE]])
def test_inpaint_candidates_flag_reaches_the_spec(command):
    from salad_core.cli.generate import _edit_specs

    flags = ["--target", "a person jumps", "--inpaint", "@12:28", "--out", "x"]
    args = cli.build_parser().parse_args(command + flags + ["--inpaint-candidates", "3"])
    assert _edit_specs(args)[0].candidates == 3
    assert _edit_specs(cli.build_parser().parse_args(command + flags))[0].candidates == "auto"
