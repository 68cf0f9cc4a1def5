"""salad_viz.widgets: the explorer's controls drive the map, the heatmap and the skeleton together;
every skeleton frame is rendered on the explorer's own thread, whichever thread the callback runs on."""
from __future__ import annotations

import doctest
import io
import threading

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pytest

pytest.importorskip("ipywidgets")

from salad_core.skeleton import PART_NAMES, get_skeleton
from salad_viz.attention import reduce_attention
from salad_viz.attention import joint_attention_colors
from salad_viz.render import SkeletonRenderer, offscreen_available
from salad_viz.synthetic import synthetic_motion
from salad_viz.widgets import SELECTION_HINT, AttentionExplorer, RenderThread, explore_attention, first_content_word

SKEL = get_skeleton("humanml3d")
TOKENS = ["[CLS]", "a", "person", "walks", "and", "waves", "[SEP]"]
S, L, NL = 6, 3, 5  # steps, layers, latent frames


def _png_array(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


@pytest.fixture
def explorer():
    rng = np.random.default_rng(0)
    att = rng.random((S, L, NL, len(PART_NAMES), len(TOKENS)))  # s l n p w
    # 'walks' (token 3): legs only, and only in layer 2 of the late steps
    att[3:, 2, :, :, 3] = 0.0
    att[3:, 2, :, [1, 2], 3] = 5.0
    joints = synthetic_motion(SKEL, NL * 4)
    ex = explore_attention(att, TOKENS, joints, SKEL, axes="slnpw", backend="raster", size=(120, 100))
    yield ex, att
    ex.close()


def test_controls_reflect_the_data(explorer):
    ex, _ = explorer
    assert [label for label, _ in ex.words.options] == ["1: a", "2: person", "3: walks", "4: and", "5: waves"]
    assert ex.selected_words == ["walks"] and ex.words.value == ((3,),)   # the first content word
    assert ex.drawn == {"words": ["walks"], "layers": [0, 1, 2], "steps": [0, S - 1], "frame": 0}
    assert ex.layers.value == (0, 1, 2)
    assert (ex.steps.min, ex.steps.max) == (0, S - 1)
    assert ex.frame.max == NL * 4 - 1
    assert ex.heatmap.value[:4] == b"\x89PNG" and ex.skeleton_view.value[:4] == b"\x89PNG"


def test_selection_changes_the_map_like_reduce_attention(explorer):
    ex, att = explorer
    ex.words.value = ((3,), (5,))  # 'walks' + 'waves' are summed
    full = reduce_attention(att, "slnpw")
    np.testing.assert_allclose(ex.selected_map, full[:, :, 3] + full[:, :, 5])
    ex.words.value = ((3,),)
    ex.layers.value = (2,)
    ex.steps.value = (3, 5)
    np.testing.assert_allclose(ex.selected_map, reduce_attention(att, "slnpw", steps=(3, 6), layers=2)[:, :, 3])
    legs = [PART_NAMES.index("left leg"), PART_NAMES.index("right leg")]
    assert ex.selected_map[legs].min() == 5.0 and np.delete(ex.selected_map, legs, axis=0).max() == 0.0


def test_views_update_together_and_joints_show_the_attention(explorer):
    ex, _ = explorer
    ex.words.value = ((3,),)
    ex.layers.value = (2,)
    ex.steps.value = (3, 5)
    heat0, skel0 = ex.heatmap.value, ex.skeleton_view.value
    ex.frame.value = 10
    assert ex.heatmap.value != heat0 and ex.skeleton_view.value != skel0  # cursor moved, pose moved
    img = _png_array(ex.skeleton_view.value).reshape(-1, 3).astype(int)
    # legs carry all the attention: viridis yellow (253, 231, 37) on the legs, dark purple elsewhere
    yellow = (np.abs(img - [253, 231, 37]).max(axis=1) < 40).sum()
    purple = (np.abs(img - [68, 1, 84]).max(axis=1) < 40).sum()
    assert yellow > 20 and purple > 20


def test_empty_selection_reports_instead_of_failing(explorer):
    ex, _ = explorer
    before = ex.heatmap.value
    ex.layers.value = ()
    assert ex.status.value == "select at least one layer"
    assert ex.heatmap.value == before
    ex.layers.value = (0,)
    assert ex.status.value == ""


def test_token_count_mismatch_is_an_error():
    att = np.ones((NL, len(PART_NAMES), 3))
    with pytest.raises(ValueError, match="tokens has 7 entries but attention has W = 3"):
        explore_attention(att, TOKENS, synthetic_motion(SKEL, 8), SKEL, axes="npw", backend="raster")


# ----------------------------------------------------------------------------- opening word, words
def test_first_content_word_skips_function_words_and_the_subject():
    assert first_content_word(["a", "man", "jumps", "forward"]) == 2
    assert first_content_word(["the", "person", "is", "slowly", "walking"]) == 3
    assert first_content_word(["and", "the"]) == 0          # nothing else: the first word


def test_words_argument_and_word_ids(explorer):
    ex, att = explorer
    assert ex.word_ids("waves", "walks") == ((3,), (5,))
    with pytest.raises(ValueError, match=r"words \['runs'\] are not in the prompt"):
        ex.word_ids("runs")
    other = explore_attention(att, TOKENS, synthetic_motion(SKEL, NL * 4), SKEL, axes="slnpw", backend="raster",
                              size=(64, 48), words=["person", "waves"])
    try:
        assert other.selected_words == ["person", "waves"]
    finally:
        other.close()


def test_the_hint_says_how_to_select_several_words(explorer):
    ex, _ = explorer
    hints = [w.value for w in ex.widget.children if hasattr(w, "value") and isinstance(w.value, str)]
    assert any("Ctrl-click" in h and "Shift-click" in h for h in hints)
    assert ex.words.tooltip == SELECTION_HINT
    assert "salad-explorer" in ex.widget._dom_classes and f"salad-explorer-id-{ex.uid}" in ex.widget._dom_classes
    assert AttentionExplorer.find(ex.uid) is ex


# ----------------------------------------------------------------------------- threads
def _thread_name(renderer):
    return threading.current_thread().name


def test_render_thread_owns_the_renderer_and_stops():
    rt = RenderThread(SKEL, size=(64, 48), backend="raster")
    try:
        names = {rt.call(_thread_name) for _ in range(3)}
        assert names == {rt.thread.name} and rt.thread.name != threading.current_thread().name
        joints = synthetic_motion(SKEL, 8)
        with SkeletonRenderer(SKEL, size=(64, 48), backend="raster") as direct:
            np.testing.assert_array_equal(rt.render(joints, 5), direct.render(joints, 5))
        with pytest.raises(ValueError, match="frame"):
            rt.render(joints, 99)                           # errors come back to the caller
    finally:
        rt.close()
    assert not rt.thread.is_alive()
    with pytest.raises(RuntimeError, match="closed"):
        rt.call(_thread_name)


def test_render_thread_reports_a_bad_backend_to_the_caller():
    with pytest.raises(ValueError, match="backend must be one of"):
        RenderThread(SKEL, backend="opengl")


def _expected_skeleton(ex, frame: int, renderer: SkeletonRenderer | None = None) -> np.ndarray:
    """A render of ``frame`` made here, on this thread, from the public functions."""
    colors = joint_attention_colors(ex.selected_map, SKEL, len(ex.joints), frames_per_latent=ex.fpl, cmap=ex.cmap)
    if renderer is None:
        with SkeletonRenderer(SKEL, size=ex.size, backend=ex.backend) as r:
            return _expected_skeleton(ex, frame, r)
    return renderer.render(ex.joints, frame, view=ex.view, joint_colors=colors, title=f"frame {frame}")


def _callbacks_from_other_threads(ex, frames) -> None:
    """Set the frame from several threads at once, as JupyterLab's comm subshells do."""
    threads = [threading.Thread(target=lambda f=f: setattr(ex.frame, "value", f), name=f"subshell-test-{f}")
               for f in frames]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)


def test_callbacks_on_other_threads_render_the_right_frame(explorer):
    ex, _ = explorer
    _callbacks_from_other_threads(ex, [3, 7, 11, 15])
    final = ex.frame.value
    assert ex.drawn["frame"] == final                       # the last callback drew the last value
    np.testing.assert_array_equal(_png_array(ex.skeleton_view.value), _expected_skeleton(ex, final))


@pytest.mark.skipif(not offscreen_available(), reason="no off-screen OpenGL here (pyvista backend)")
def test_pyvista_explorer_renders_from_subshell_like_threads():
    """The issue's failure: a pyvista renderer made on one thread and used from another draws black
    frames or noise. The explorer's images must equal renders made on this thread."""
    rng = np.random.default_rng(1)
    att = rng.random((NL, len(PART_NAMES), len(TOKENS)))
    ex = explore_attention(att, TOKENS, synthetic_motion(SKEL, NL * 4), SKEL, axes="npw", backend="pyvista",
                           size=(96, 80))
    reference = SkeletonRenderer(SKEL, size=ex.size, backend="pyvista")    # this thread's own context
    try:
        assert ex.backend == "pyvista"
        for frames in ([4], [9, 2], [13, 6, 17]):
            _callbacks_from_other_threads(ex, frames)
            shown = _png_array(ex.skeleton_view.value)
            expected = _expected_skeleton(ex, ex.frame.value, reference)
            agree = (np.abs(shown.astype(int) - expected.astype(int)).max(-1) <= 24).mean()
            assert agree > 0.98, f"frames {frames}: {agree:.1%} of the pixels agree"
    finally:
        reference.close()
        ex.close()
    assert not ex._renderer.thread.is_alive()


# ----------------------------------------------------------------------------- AttentionMaps in
@pytest.fixture(scope="module")
def generated(make_tiny_pipeline):
    from salad_core.attention import CaptureConfig

    pipe = make_tiny_pipeline(0)
    prompt = "a person walks and waves"
    full = pipe(prompt, lengths=24, num_steps=4, seed=0, capture_attention=CaptureConfig(mode="full"))
    mean = pipe(prompt, lengths=24, num_steps=4, seed=0, capture_attention=True)
    return full, mean


def test_explorer_takes_the_pipelines_attention_maps(generated):
    full, mean = generated
    maps = full.attention
    ex = explore_attention(maps, None, full.joints[0], "humanml3d", backend="raster", size=(64, 48))
    try:
        assert ex.axes == "slhnpw" and ex.tokens == maps.tokens(0) and ex.fpl == maps.unit_length
        assert (ex.steps.max, len(ex.layers.options)) == (3, 3)          # 4 steps, 3 layers
        assert ex.selected_words == ["walks"]
        np.testing.assert_allclose(ex.selected_map, maps.word_map(0, "walks"), rtol=2e-3, atol=1e-5)
        ex.words.value = ex.word_ids("walks", "waves")
        ex.layers.value = (1,)
        np.testing.assert_allclose(ex.selected_map, maps.select(layers=[1]).word_map(0, "walks")
                                   + maps.select(layers=[1]).word_map(0, "waves"), rtol=2e-3, atol=1e-5)
    finally:
        ex.close()
    # the default (mean) capture: one map per layer, no step axis
    ex = explore_attention(mean.attention, mean.attention.tokens(0), mean.joints[0], backend="raster", size=(64, 48))
    try:
        assert ex.axes == "lpnw" and ex.steps is None
        ex.layers.value = (2,)
        np.testing.assert_allclose(ex.selected_map, mean.attention.select(layers=[2]).word_map(0, "walks"),
                                   rtol=1e-5, atol=1e-7)
    finally:
        ex.close()


def test_array_attention_needs_tokens():
    with pytest.raises(ValueError, match="tokens is required"):
        explore_attention(np.ones((NL, 7, 3)), None, synthetic_motion(SKEL, 8), SKEL, backend="raster")


@pytest.mark.slow
def test_module_example_runs_as_written():
    """The module docstring's example (shipped weights, 10 steps) runs and prints what it says."""
    import salad_viz.widgets as widgets

    finder = doctest.DocTestFinder()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    tests = [t for t in finder.find(widgets) if t.examples]
    assert any("SaladPipeline.from_pretrained" in ex.source for t in tests for ex in t.examples)
    for t in tests:
        runner.run(t)
    assert runner.summarize(verbose=False).failed == 0
