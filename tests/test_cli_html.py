"""``salad generate|edit|invert --html``: one offline explorer page per motion (generate) or per edit (the source and
the edit side by side, the edit named), each one self-contained file whose embedded maps are the captured
``AttentionMaps`` (to the page's rounding) and whose motion is the one the command wrote; asking for the page
changes no motion. Tiny random weights (seconds); one slow test with the shipped weights."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from salad_core import cli
from salad_core.attention import CaptureConfig
from test_explorer_html import _embedded, _full_reference
from _weights import needs_weights

pytestmark = [pytest.mark.usefixtures("single_thread")]

PROMPTS = ["a person walks and waves", "a man jumps forward"]
LENGTH, STEPS, SEED = 24, 4, 2


@pytest.fixture(scope="module")
def tiny_weights(tmp_path_factory, make_tiny_pipeline):
    """A tiny randomly initialised pipeline folder (fast; the motions are noise, the plumbing is real)."""
    return make_tiny_pipeline(seed=0).save_pretrained(tmp_path_factory.mktemp("weights"))


@pytest.fixture(scope="module")
def tiny_pipe(tiny_weights):
    from salad_core.pipeline import SaladPipeline

    return SaladPipeline.from_pretrained(tiny_weights)


def _offline(page: str) -> None:
    """One self-contained file: no URL, no src/href, no stylesheet link, a policy that forbids every request."""
    assert 'src="http' not in page and 'href="http' not in page
    assert not re.search(r"https?://|\bsrc\s*=|\bhref\s*=|<link|@import|url\(", page)
    assert "default-src 'none'" in page


def _att(panel: dict, unit: float) -> np.ndarray:
    return np.asarray(panel["att"], dtype=np.float64).reshape(panel["shape"]) * unit


def _assert_panel_is(panel: dict, unit: float, maps, b: int = 0) -> None:
    """Every word x step x layer map of a page's panel is the captured full map of sample ``b``."""
    att = _att(panel, unit)
    words, steps, layers = att.shape[:3]
    assert [w["text"] for w in panel["words"]] == maps.words(b)
    assert (steps, layers) == (maps.num_steps, len(maps.captured_layers))
    for k, word in enumerate(panel["words"]):
        assert word["tokens"] == maps.word_columns(b, k)
        for s in range(steps):
            for layer in range(layers):
                np.testing.assert_allclose(att[k, s, layer], _full_reference(maps, b, [s], [layer], word["tokens"]),
                                           atol=unit / 2 + 1e-7)


def _base(weights, *extra):
    return ["-q", *extra, "--length", str(LENGTH), "--steps", str(STEPS), "--seed", str(SEED),
            "--weights", str(weights)]


# ------------------------------------------------------------------------------------------------ generate
def test_generate_writes_one_page_per_prompt_with_the_captured_maps(tiny_weights, tiny_pipe, tmp_path):
    out = tmp_path / "gen"
    code = cli.main(["-q", "generate", *PROMPTS, "--length", str(LENGTH), "--steps", str(STEPS), "--seed", str(SEED),
                     "--weights", str(tiny_weights), "--no-render", "--html", "--out", str(out)])
    assert code == 0
    pages = sorted(out.glob("*.html"))
    assert [p.name for p in pages] == ["00_a_person_walks_and_waves_explorer.html",
                                       "01_a_man_jumps_forward_explorer.html"]
    want = tiny_pipe(PROMPTS, lengths=LENGTH, seed=SEED, num_steps=STEPS, capture_attention=CaptureConfig(mode="full"))
    plain = tiny_pipe(PROMPTS, lengths=LENGTH, seed=SEED, num_steps=STEPS)
    for b, page in enumerate(pages):
        text = page.read_text(encoding="utf-8")
        _offline(text)
        data = _embedded(text)
        (panel,) = data["panels"]
        assert data["prompt"] == PROMPTS[b] and data["model"] == f"SALAD ({tiny_weights})"
        assert data["steps"]["total"] == STEPS and len(data["steps"]["groups"]) == STEPS    # every step kept
        _assert_panel_is(panel, data["scale"], want.attention, b)
        # the page's motion is the one written beside it, and --html changed no motion
        stem = page.name.removesuffix("_explorer.html")
        joints = np.load(out / f"{stem}_joints.npy")
        page_joints = np.asarray(panel["joints"], dtype=np.float64).reshape(joints.shape) * data["jointScale"]
        np.testing.assert_allclose(page_joints, joints, atol=5e-4 + 1e-6)
        features = np.load(out / f"{stem}_features.npy")
        assert np.array_equal(features, plain.features[b, :LENGTH].astype(np.float32))


def test_html_goes_with_attention_and_with_salad_only(tiny_weights, tmp_path, capsys):
    base = ["-q", "generate", "a person walks", "--length", "16", "--steps", "2", "--weights", str(tiny_weights),
            "--html"]
    assert cli.main([*base, "--no-attention", "--out", str(tmp_path / "a")]) == 2
    assert "--no-attention" in capsys.readouterr().err
    assert cli.main(["-q", "generate", "a person walks", "--keymotion", "--html", "--out", str(tmp_path / "b")]) == 2
    assert "KeyMotion" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_existing_page_is_not_overwritten(tiny_weights, tmp_path, capsys):
    out = tmp_path / "gen"
    out.mkdir()
    (out / "00_a_person_walks_explorer.html").write_text("mine")
    code = cli.main(["-q", "generate", "a person walks", "--length", "16", "--steps", "2", "--weights",
                     str(tiny_weights), "--no-render", "--html", "--out", str(out)])
    assert code == 2 and "00_a_person_walks_explorer.html" in capsys.readouterr().err
    assert (out / "00_a_person_walks_explorer.html").read_text() == "mine"
    assert sorted(p.name for p in out.iterdir()) == ["00_a_person_walks_explorer.html"]     # nothing else written


@pytest.mark.parametrize("command", ["generate", "edit", "invert"])
def test_help_and_docs_name_the_flag(command, capsys):
    with pytest.raises(SystemExit):
        cli.main([command, "--help"])
    assert "--html" in capsys.readouterr().out
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "command-line.md").read_text()
    assert "--html" in doc and "_explorer.html" in doc


# ------------------------------------------------------------------------------------------------ edit, invert
def test_edit_page_shows_source_and_edit_side_by_side_and_names_the_edit(tiny_weights, tiny_pipe, tmp_path):
    from salad_core.attention import Reweight

    source = "a man raises his right hand high"
    out = tmp_path / "ed"
    assert cli.main([*_base(tiny_weights, "edit", source), "--reweight", "high=-1", "--html", "--out", str(out)]) == 0
    text = (out / "source_vs_edited_explorer.html").read_text(encoding="utf-8")
    _offline(text)
    data = _embedded(text)
    assert data["edit"] == "Reweight(high=-1)" and "Reweight(high=-1)" in text.split("<script")[0]   # <title> too
    src, dst = data["panels"]
    assert (src["label"], dst["label"]) == ("source", "edited")
    # it opens on the re-weighted word, in both motions
    assert [src["words"][i]["text"] for i in src["selected"]] == ["high"]
    assert [dst["words"][i]["text"] for i in dst["selected"]] == ["high"]
    want = tiny_pipe.edit(source, edits=[Reweight(words="high", scale=-1)], lengths=LENGTH, seed=SEED,
                          num_steps=STEPS, capture_attention=CaptureConfig(mode="full"))
    _assert_panel_is(src, data["scale"], want.source.attention)
    _assert_panel_is(dst, data["scale"], want.edited.attention)
    high = [w["text"] for w in dst["words"]].index("high")
    assert _att(dst, data["scale"])[high].max() <= 0 < _att(src, data["scale"])[high].max()   # negative after -1
    np.testing.assert_array_equal(np.load(out / "edited_features.npy"), want.edited.features[0, :LENGTH])


def test_edit_page_of_a_word_swap_opens_on_the_swapped_words(tiny_weights, tmp_path):
    out = tmp_path / "swap"
    assert cli.main([*_base(tiny_weights, "edit", "a person walks forward"), "--target", "a person runs forward",
                     "--swap", "0.8", "--html", "--out", str(out)]) == 0
    data = _embedded((out / "source_vs_edited_explorer.html").read_text(encoding="utf-8"))
    src, dst = data["panels"]
    assert data["edit"] == "Swap(walks->runs, 0.8)"
    assert [src["words"][i]["text"] for i in src["selected"]] == ["walks"]
    assert [dst["words"][i]["text"] for i in dst["selected"]] == ["runs"]
    assert src["prompt"] == "a person walks forward" and dst["prompt"] == "a person runs forward"


def test_invert_writes_the_edit_page_or_the_reconstructions(tiny_weights, tmp_path, sample_dir):
    take = tmp_path / "take.npy"
    np.save(take, np.load(sample_dir / "new_joint_vecs" / "012314.npy")[:24])
    out = tmp_path / "inv"
    assert cli.main(["-q", "invert", str(take), "--prompt", "a person walks forward", "--mirror", "legs", "--html",
                     "--steps", "3", "--no-render", "--weights", str(tiny_weights), "--out", str(out)]) == 0
    text = (out / "take_source_vs_edited_explorer.html").read_text(encoding="utf-8")
    _offline(text)
    data = _embedded(text)
    assert data["edit"] == "Mirror(legs)" and len(data["panels"]) == 2
    assert json.loads((out / "take_inversion.json").read_text())["edit"]["label"] == "Mirror(legs)"
    assert data["steps"]["total"] == 3
    out2 = tmp_path / "inv2"
    assert cli.main(["-q", "invert", str(take), "--prompt", "a person walks forward", "--html", "--steps", "3",
                     "--no-render", "--weights", str(tiny_weights), "--out", str(out2)]) == 0
    assert sorted(p.name for p in out2.glob("*.html")) == ["take_reconstruction_explorer.html"]
    data = _embedded((out2 / "take_reconstruction_explorer.html").read_text(encoding="utf-8"))
    assert len(data["panels"]) == 1 and data["edit"] is None and data["prompt"] == "a person walks forward"


# ------------------------------------------------------------------------------------------------ shipped weights
@needs_weights
@pytest.mark.slow
def test_shipped_edit_page_is_the_python_edit(tmp_path):
    """The README's edit with the shipped weights: a page under 8 MB whose maps and motion are pipe.edit's."""
    from salad_core.attention import Reweight
    from salad_core.pipeline import SaladPipeline
    from salad_viz.explorer_html import MAX_BYTES

    source, length, steps = "a man raises his right hand high", 100, 10
    out = tmp_path / "ed"
    assert cli.main(["-q", "edit", source, "--reweight", "high=-1", "--html", "--length", str(length), "--steps",
                     str(steps), "--out", str(out)]) == 0
    path = out / "source_vs_edited_explorer.html"
    assert path.stat().st_size <= MAX_BYTES
    data = _embedded(path.read_text(encoding="utf-8"))
    assert data["model"] == "SALAD (shipped weights)" and data["edit"] == "Reweight(high=-1)"
    pipe = SaladPipeline.from_pretrained()
    want = pipe.edit(source, edits=[Reweight(words="high", scale=-1)], lengths=length, seed=0, num_steps=steps,
                     capture_attention=CaptureConfig(mode="full"))
    _assert_panel_is(data["panels"][0], data["scale"], want.source.attention)
    _assert_panel_is(data["panels"][1], data["scale"], want.edited.attention)
    np.testing.assert_array_equal(np.load(out / "edited_features.npy"), want.edited.features[0, :length])
