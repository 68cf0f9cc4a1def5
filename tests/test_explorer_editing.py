"""Editing from the Jupyter explorer (``explore_attention(..., editor=pipe)``): the target text box, the re-weight
slider of each selected word, the mirror toggles and the run button make an edit whose motion is bit for bit the
one the printed line of Python makes when it is run against the same pipeline; the result shows the source and
the edit with their heatmaps on one colour scale. The explorer without an editor is unchanged. Tiny random
weights (about a second per edit)."""
from __future__ import annotations

import html
import re

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

pytest.importorskip("ipywidgets")

from salad_core.attention import CaptureConfig
from salad_viz.widgets import explore_attention

pytestmark = [pytest.mark.usefixtures("single_thread")]

SOURCE = "a man raises his right hand high"
LENGTH, STEPS = 24, 4


@pytest.fixture(scope="module")
def generated(pipe):
    return pipe(SOURCE, lengths=LENGTH, num_steps=STEPS, seed=0, capture_attention=CaptureConfig(mode="full"))


@pytest.fixture
def explorer(pipe, generated):
    ex = explore_attention(generated.attention, None, generated.joints[0], editor=pipe, backend="raster",
                           size=(96, 80))
    yield ex
    ex.close()


def _namespace(pipe) -> dict:
    import salad_core.attention as a

    return {"pipe": pipe, **{n: getattr(a, n) for n in ("WordSwap", "Refine", "Reweight", "Mirror", "CaptureConfig")}}


def _same_motion(a, b) -> None:
    for branch in ("source", "edited"):
        x, y = getattr(a, branch), getattr(b, branch)
        assert np.array_equal(x.features, y.features), branch
        assert all(np.array_equal(p, q) for p, q in zip(x.joints, y.joints)), branch


def _shown_code(ex) -> str:
    return html.unescape(re.search(r"<pre[^>]*>(.*?)</pre>", ex.code.value, re.S).group(1))


def test_controls_make_the_edit_the_printed_line_makes(explorer, pipe):
    ex = explorer
    assert ex.target.value == SOURCE and ex.last_edit is None and ex.result.value == b""
    # select "high", re-weight it to -1, mirror the arms, swap "right" for "left", run
    ex.words.value = ex.word_ids("high")
    assert [s.description for s in ex.reweight_box.children] == ["re-weight high"]
    ex.reweight_slider("high").value = -1.0
    ex.words.value = ex.word_ids("raises")       # a re-weighted word keeps its slider when no longer selected
    assert [s.description for s in ex.reweight_box.children] == ["re-weight raises", "re-weight high"]
    ex.mirror_arms.value = True
    ex.target.value = "a man raises his left hand high"
    ex.run.click()
    assert ex.edit_status.value == ""
    code = ex.last_code
    assert code == ('pipe.edit("a man raises his right hand high", target="a man raises his left hand high", '
                    'edits=[WordSwap(), Reweight(words="high", scale=-1), Mirror(parts="arms")], lengths=24, seed=0, '
                    'num_steps=4, capture_attention=CaptureConfig(mode="full"))')
    assert "\n" not in code and _shown_code(ex) == code                 # the ONE line, shown as it runs
    want = eval(code, _namespace(pipe))
    _same_motion(ex.last_edit, want)
    exec("again = " + code, ns := _namespace(pipe))                     # as a statement, too
    _same_motion(ex.last_edit, ns["again"])
    assert not np.array_equal(want.edited.features, want.source.features)
    assert ex.edit_label == "Swap(right->left) + Reweight(high=-1) + Mirror(arms)"
    # the result: both motions and their heatmaps (the selected word and its counterpart), one colour scale
    assert ex.result.value[:4] == b"\x89PNG"
    src, dst = ex.result_maps
    np.testing.assert_allclose(src, want.source.attention.word_map(0, "raises"), rtol=2e-3, atol=1e-6)
    np.testing.assert_allclose(dst, want.edited.attention.word_map(0, "raises"), rtol=2e-3, atol=1e-6)
    fig = ex.result_figure()
    images = [im for ax in fig.axes for im in ax.get_images()]
    heat = [im for im in images if im.get_array().shape == src.shape]
    assert len(heat) == 2 and heat[0].norm.vmin == heat[1].norm.vmin and heat[0].norm.vmax == heat[1].norm.vmax
    # scrubbing redraws the result at the new frame
    before = ex.result.value
    ex.frame.value = 17
    assert ex.result.value != before


def test_refinement_and_both_mirrors(explorer, pipe):
    ex = explorer
    ex.target.value = "a man slowly raises his right hand high"
    ex.mirror_arms.value = ex.mirror_legs.value = True
    assert ex.edit_code == ('pipe.edit("a man raises his right hand high", target="a man slowly raises his right '
                            'hand high", edits=[Refine(), Mirror(parts="all")], lengths=24, seed=0, num_steps=4, '
                            'capture_attention=CaptureConfig(mode="full"))')
    assert ex.edit_label == "Refine(+slowly) + Mirror(all)"
    out = ex.run_edit()
    _same_motion(out, eval(ex.last_code, _namespace(pipe)))
    # a word swap asked for explicitly, with a target of another length, is the pipeline's error, said beside
    # the button; the last result stays
    ex.replace.value = "swap"
    ex.run.click()
    assert ex.edit_status.value.startswith("ValueError") and ex.last_edit is out


def test_nothing_to_edit_is_said_and_runs_nothing(explorer):
    ex = explorer
    ex.reweight_slider("raises").value = 1.0                      # 1 = unchanged
    ex.run.click()
    assert "nothing to edit" in ex.edit_status.value and ex.last_edit is None
    with pytest.raises(ValueError, match="nothing to edit"):
        ex.edit_code
    with pytest.raises(ValueError, match="not a word of the prompt"):
        ex.reweight_slider("jumps")


def test_a_callable_editor_and_options(pipe, generated):
    def my_edit(*args, **kwargs):
        return pipe.edit(*args, **kwargs)

    bare = explore_attention(generated.attention, None, generated.joints[0], editor=my_edit, backend="raster",
                             size=(64, 48))
    try:                                 # a plain function brings no edit classes: the error says what to pass
        bare.reweight_slider("raises").value = 2.0
        with pytest.raises(TypeError, match="edit_names="):
            bare.run_edit()
    finally:
        bare.close()
    ex = explore_attention(generated.attention, None, generated.joints[0], editor=my_edit, backend="raster",
                           size=(64, 48), edit_options=dict(seed=5, guidance_scale=2.5),
                           edit_names=pipe.edit_namespace())
    try:
        ex.reweight_slider("raises").value = 2.0
        out = ex.run_edit()
        assert ex.last_code.startswith('my_edit("a man raises his right hand high", edits=[Reweight(words="raises", '
                                       'scale=2)], lengths=24, seed=5, num_steps=4, guidance_scale=2.5, ')
        _same_motion(out, eval(ex.last_code, {**_namespace(pipe), "my_edit": my_edit}))
        page = ex.edit_page()
        assert page.count("</script>") == 2 and "Reweight(raises=2)" in page
    finally:
        ex.close()
    with pytest.raises(ValueError, match="plain Python literal"):
        explore_attention(generated.attention, None, generated.joints[0], editor=pipe, backend="raster",
                          size=(64, 48), edit_options=dict(noise_scale=np.float32(1) + 1j))
    with pytest.raises(ValueError, match="may not set 'edits'"):
        explore_attention(generated.attention, None, generated.joints[0], editor=pipe, backend="raster",
                          size=(64, 48), edit_options=dict(edits=[]))
    with pytest.raises(TypeError, match="editor must be"):
        explore_attention(generated.attention, None, generated.joints[0], editor=42, backend="raster", size=(64, 48))


def test_the_explorer_without_an_editor_is_unchanged(generated):
    ex = explore_attention(generated.attention, None, generated.joints[0], backend="raster", size=(64, 48))
    try:
        assert ex.target is None and ex.run is None and len(ex.widget.children) == 4
        with pytest.raises(RuntimeError, match="no editor"):
            ex.edit_code
        ex.frame.value = 5                                        # scrubbing still works, nothing to redraw
        assert ex.drawn["frame"] == 5
    finally:
        ex.close()
